//! Articulated-body algorithm (Featherstone, Table 7.1): O(n) forward dynamics q̈ = M⁻¹(τ − C q̇ − g + Jᵀ f_ext).

use nalgebra::DVector;

use super::{joint_motion, joint_placement};
use crate::model::{Data, Joint, Model};
use crate::spatial::{cross_force, cross_motion, Force, Motion};

/// Joint accelerations for configuration `q`, velocity `v` and joint forces `tau`; `f_ext` as in `rnea`.
/// Writes `data.ddq` and returns it; `data.a` holds each body's acceleration (gravity included, §5.3).
pub fn aba<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>) -> &'d DVector<f64> {
    let n = model.nbodies();
    // Pass 1: velocities, velocity-product accelerations and rigid-body bias forces.
    for i in 0..n {
        let li = joint_placement(model, i, q);
        let v_parent = if i == 0 { Motion::zeros() } else { data.v[model.parent(i)] };
        let v_joint = joint_motion(model, i, v);
        data.li_m_i[i] = li;
        data.v[i] = li.inv_act_motion(&v_parent) + v_joint;
        data.c[i] = cross_motion(&data.v[i], &v_joint);
        let inertia = model.inertia(i);
        data.inertia[i] = *inertia;
        data.bias[i] = cross_force(&data.v[i], &(inertia * data.v[i]));
        if let Some(f_ext) = f_ext {
            data.bias[i] -= f_ext[i];
        }
    }
    // Pass 2: articulated inertias and bias forces, leaves to root (eq. 7.38–7.44).
    for i in (1..n).rev() {
        let k = model.idx_v(i);
        let mut ia = data.inertia[i];
        let mut pa = data.bias[i];
        if let Some(s) = model.joint(i).axis_motion() {
            let u = ia * s;
            let d = s.dot(&u);
            let u_scalar = tau[k] - s.dot(&pa);
            let u_over_d = u / d;
            ia -= u * u_over_d.transpose();
            pa += u_over_d * u_scalar;
            data.u[i] = u;
            data.d[i] = d;
            data.ddq[k] = u_scalar;
        }
        pa += ia * data.c[i];
        let (p, li) = (model.parent(i), data.li_m_i[i]);
        data.inertia[p] += li.act_inertia(&ia);
        data.bias[p] += li.act_force(&pa);
    }
    // Pass 3: accelerations, root to leaves (eq. 7.45–7.47).
    let gravity = model.gravity_bias();
    for i in 0..n {
        let k = model.idx_v(i);
        let a_parent = if i == 0 { gravity } else { data.a[model.parent(i)] };
        let a_prime = data.li_m_i[i].inv_act_motion(&a_parent) + data.c[i];
        data.a[i] = match model.joint(i) {
            Joint::FreeFlyer => {
                let rhs = Motion::from_column_slice(&tau[k..k + 6]) - data.bias[i];
                let a = data.inertia[i].cholesky().map(|c| c.solve(&rhs)).unwrap_or_else(|| Motion::repeat(f64::NAN));
                data.ddq.rows_mut(k, 6).copy_from(&(a - a_prime));
                a
            }
            Joint::Fixed => a_prime,
            joint => {
                let s = joint.axis_motion().expect("one-degree-of-freedom joint");
                let qdd = (data.ddq[k] - data.u[i].dot(&a_prime)) / data.d[i];
                data.ddq[k] = qdd;
                a_prime + s * qdd
            }
        };
    }
    &data.ddq
}
