//! Recursive Newton–Euler inverse dynamics (Featherstone, Table 5.1): τ = M(q) q̈ + C(q, q̇) q̇ + g(q) − Jᵀ f_ext.

use nalgebra::DVector;

use super::checks::{check_forces, check_state, finite_result};
use super::kinematics::body_motions;
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{cross_force, Force};
use crate::Result;

/// Inverse dynamics by the recursive Newton–Euler algorithm [Featherstone 2008, Table 5.1], O(n):
/// τ = M(q) q̈ + C(q, q̇) q̇ + g(q) − Jᵀ f_ext.
///
/// Joint forces for configuration `q`, velocity `v` and acceleration `a`. `f_ext`, when given, holds one
/// external force `[f; n]` per body, acting on that body and expressed in its frame.
pub fn rnea<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>) -> Result<&'d DVector<f64>> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    check_forces(model, f_ext)?;
    rnea_unchecked(model, data, q, v, a, f_ext);
    finite_result(data.tau.as_slice())?;
    Ok(&data.tau)
}

/// [`rnea`] without its checks, for the crate's inner loops.
pub(crate) fn rnea_unchecked<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>) -> &'d DVector<f64> {
    // Forward pass: velocities, accelerations (gravity as a base acceleration) and the net force each body
    // needs (eq. 5.7–5.9).
    body_motions(model, data, q, v, Some(a), model.gravity_bias());
    for i in 0..model.nbodies() {
        let inertia = model.inertia(i);
        data.f[i] = inertia.apply(&data.a[i]) + cross_force(&data.v[i], &inertia.apply(&data.v[i]));
        if let Some(f_ext) = f_ext {
            data.f[i] -= f_ext[i];
        }
    }
    // Backward pass: project onto the joint axes and pass the rest to the parent (eq. 5.10–5.11).
    for i in (0..model.nbodies()).rev() {
        let k = model.idx_v(i);
        let f = data.f[i];
        match model.joint(i).dofs() {
            Dofs::Free => data.tau.rows_mut(k, 6).copy_from(&f),
            Dofs::Zero => {}
            Dofs::One(s) => data.tau[k] = s.dot(&f) + model.armature()[k] * a[k],
            // S = [0; I]: the moment.
            Dofs::Ball => {
                for c in 0..3 {
                    data.tau[k + c] = f[3 + c] + model.armature()[k + c] * a[k + c];
                }
            }
        }
        if i > 0 {
            let p = model.parent(i);
            data.f[p] += data.li_m_i[i].act_force(&f);
        }
    }
    &data.tau
}
