//! The inverse of the joint-space mass matrix by the articulated-body recursion (Carpentier 2018,
//! "Analytical inverse of the joint space inertia matrix"; Pinocchio's `computeMinverse`): O(n) per
//! entry of the result, never forming or factorising M.

use nalgebra::{DMatrix, Matrix6xX};

use super::joint_placement;
use crate::model::{Data, Joint, Model};
use crate::spatial::Inertia;

/// Fills `data.minv` (both triangles) with M(q)⁻¹ and returns it.
pub fn minv<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    let (n, nv) = (model.nbodies(), model.nv());
    if data.force_sets.len() != n {
        data.force_sets = vec![Matrix6xX::zeros(nv); n];
    }
    for i in 0..n {
        data.li_m_i[i] = joint_placement(model, i, q);
        data.inertia[i] = *model.inertia(i);
        data.force_sets[i].fill(0.0);
    }
    // Backward pass: articulated inertias and the rows' subtree parts D⁻¹(e_i − Sᵀ F_i), where F_i maps τ to
    // the articulated bias force of subtree i; then F_i += U M⁻¹_i is carried to the parent.
    for i in (0..n).rev() {
        let k = model.idx_v(i);
        let mut ia = data.inertia[i];
        match model.joint(i) {
            Joint::FreeFlyer => {
                let dinv = ia.try_inverse().unwrap_or_else(|| Inertia::repeat(f64::NAN));
                data.minv.view_mut((0, 0), (6, 6)).copy_from(&dinv);
                let below = -dinv * data.force_sets[0].columns(6, nv - 6);
                data.minv.view_mut((0, 6), (6, nv - 6)).copy_from(&below);
            }
            Joint::Fixed => {}
            joint => {
                let s = joint.axis_motion().expect("one-degree-of-freedom joint");
                let u = ia * s;
                let d = s.dot(&u);
                data.minv[(k, k)] = 1.0 / d;
                for col in k + 1..nv {
                    data.minv[(k, col)] = -s.dot(&data.force_sets[i].column(col)) / d;
                }
                for col in k..nv {
                    let m = data.minv[(k, col)];
                    let mut f = data.force_sets[i].column_mut(col);
                    f += u * m;
                }
                ia -= u * u.transpose() / d;
                data.u[i] = u;
                data.d[i] = d;
            }
        }
        if i > 0 {
            let (p, li) = (model.parent(i), data.li_m_i[i]);
            data.inertia[p] += li.act_inertia(&ia);
            for col in k..nv {
                let f = li.act_force(&data.force_sets[i].column(col).into_owned());
                let mut fp = data.force_sets[p].column_mut(col);
                fp += f;
            }
        }
    }
    // Forward pass: subtract D⁻¹ Uᵀ X⁻¹ P_parent, where the motion set P_i = S_i M⁻¹_i + X⁻¹ P_parent maps τ
    // to body i's acceleration.
    for i in 0..n {
        let k = model.idx_v(i);
        match model.joint(i) {
            Joint::FreeFlyer => {
                let rows = data.minv.rows(0, 6).into_owned();
                data.force_sets[0].copy_from(&rows);
            }
            Joint::Fixed if i == 0 => data.force_sets[0].fill(0.0),
            joint => {
                let (p, li) = (model.parent(i), data.li_m_i[i]);
                let axis = joint.axis_motion();
                for col in k..nv {
                    let carried = li.inv_act_motion(&data.force_sets[p].column(col).into_owned());
                    let mut motion = carried;
                    if let Some(s) = axis {
                        data.minv[(k, col)] -= data.u[i].dot(&carried) / data.d[i];
                        motion += s * data.minv[(k, col)];
                    }
                    data.force_sets[i].set_column(col, &motion);
                }
            }
        }
    }
    data.minv.fill_lower_triangle_with_upper_triangle();
    &data.minv
}
