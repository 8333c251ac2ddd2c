//! Composite-rigid-body algorithm (Featherstone, Table 6.2): the joint-space mass matrix M(q).

use nalgebra::DMatrix;

use super::joint_placement;
use crate::model::{Data, Joint, Model};

/// Fills `data.mass_matrix` (both triangles) and returns it. Works for any parent-before-child order.
pub fn crba<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    let n = model.nbodies();
    for i in 0..n {
        data.li_m_i[i] = joint_placement(model, i, q);
        data.inertia[i] = *model.inertia(i);
    }
    for i in (0..n).rev() {
        let ic = data.inertia[i];
        if i > 0 {
            let p = model.parent(i);
            let shifted = data.li_m_i[i].act_inertia(&ic);
            data.inertia[p] += shifted;
        }
        let k = model.idx_v(i);
        match model.joint(i) {
            Joint::FreeFlyer => data.mass_matrix.view_mut((k, k), (6, 6)).copy_from(&ic),
            Joint::Fixed => {}
            joint => {
                // F = I^c S, then carried up the ancestors: M_ji = S_jᵀ F (eq. 6.17–6.18).
                let mut force = ic * joint.axis_motion().expect("one-degree-of-freedom joint");
                data.mass_matrix[(k, k)] = joint.axis_motion().unwrap().dot(&force);
                let mut j = i;
                while j != 0 {
                    force = data.li_m_i[j].act_force(&force);
                    j = model.parent(j);
                    let kj = model.idx_v(j);
                    match model.joint(j) {
                        Joint::FreeFlyer => data.mass_matrix.view_mut((kj, k), (6, 1)).copy_from(&force),
                        Joint::Fixed => {}
                        parent_joint => {
                            data.mass_matrix[(kj, k)] = parent_joint.axis_motion().unwrap().dot(&force);
                        }
                    }
                }
            }
        }
    }
    data.mass_matrix.fill_lower_triangle_with_upper_triangle();
    &data.mass_matrix
}
