//! Composite-rigid-body algorithm (Featherstone, Table 6.2): the joint-space mass matrix M(q).
//!
//! Worked in the world's axes about the base (`kinematics::base_centred_kinematics`), as Pinocchio works in world
//! coordinates: composite inertias, in their 10-parameter rigid form, then add without transforms, and each entry
//! M_ji = S_jᵀ F_i is one dot product, whatever the depth of the tree.

use nalgebra::DMatrix;

use super::checks::{check_state, finite_result};
use super::kinematics::base_centred_kinematics;
use crate::joint::Dofs;
use crate::model::Dense;
use crate::model::{reserve_square, Data, Model};
use crate::spatial::{Force, RigidInertia};
use crate::Result;

/// The joint-space mass matrix M(q) by the composite-rigid-body algorithm [Featherstone 2008, Table 6.2].
///
/// Fills `data.mass_matrix` (both triangles, each entry as it is found) and returns it. Works for any parent-before-child order.
///
/// # Examples
///
/// The mass matrix of a double pendulum (two 1 kg links, 0.1 x 0.1 x 0.4 m, hinged about y; built in the hidden lines)
/// is symmetric, ½ q̇ᵀ M q̇ is its kinetic energy, and the elbow's entry is the lower link's inertia about its own
/// hinge, m (w² + l²)/12 + m (l/2)², in any pose.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
/// # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
/// # let mut model = Model::new(false, MassProperties::zero(), "base");
/// # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
/// # let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
/// # model.add_body(1, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
/// # let mut data = Data::new(&model);
/// let q = [0.3, -0.5];
/// let mass = algorithms::crba(&model, &mut data, &q)?.clone();
/// assert_eq!(mass, mass.transpose());
/// assert!((mass[(1, 1)] - ((0.1f64.powi(2) + 0.4f64.powi(2)) / 12.0 + 0.2f64.powi(2))).abs() < 1e-12);
/// let v = DVector::from_vec(vec![1.0, 2.0]);
/// let energy = algorithms::kinetic_energy(&model, &mut data, &q, v.as_slice())?;
/// assert!((0.5 * v.dot(&(&mass * &v)) - energy).abs() < 1e-12);
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn crba<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> Result<&'d DMatrix<f64>> {
    check_state(model, data, q, &[])?;
    data.reserve_dense(model, &[Dense::MassMatrix])?;
    let m = crba_unchecked(model, data, q);
    // M is positive definite, |M_ij| <= sqrt(M_ii M_jj): an overflow shows on its diagonal, checked alone (the whole
    // nv x nv matrix took a quarter of CRBA's time on a 512-link chain).
    let overflowed = m.as_slice().iter().step_by(m.nrows() + 1).any(|x| !x.is_finite());
    finite_result(if overflowed { &[f64::NAN] } else { &[] })?;
    Ok(&data.mass_matrix)
}

/// [`crba`] without its checks, for the crate's inner loops.
pub(crate) fn crba_unchecked<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    let n = model.nbodies();
    reserve_square(&mut data.mass_matrix, model.nv());
    base_centred_kinematics(model, data, q);
    // A fixed base's composite inertia is not needed.
    data.composite[0] = if model.floating_base() { data.centred_m_i[0].act_rigid_inertia(model.inertia(0)) } else { RigidInertia::zeros() };
    for i in 1..n {
        data.composite[i] = data.centred_m_i[i].act_rigid_inertia(model.inertia(i));
        data.s[i] = model.joint(i).subspace_in(&data.centred_m_i[i]);
    }
    for i in (0..n).rev() {
        let composite = data.composite[i];
        if i > 0 {
            data.composite[model.parent(i)] += composite;
        }
        let k = model.idx_v(i);
        match model.joint(i).dofs() {
            // The base's subspace is its own frame: M_00 is the composite inertia expressed there.
            Dofs::Free => {
                let local = data.centred_m_i[0].inverse().act_rigid_inertia(&composite).matrix();
                data.mass_matrix.view_mut((k, k), (6, 6)).copy_from(&local);
            }
            Dofs::Zero => {}
            Dofs::One(_) => {
                // F = I^c S (eq. 6.17), then M_ji = S_jᵀ F up the ancestors (eq. 6.18).
                let force = composite.apply(&data.s[i]);
                data.mass_matrix[(k, k)] = data.s[i].dot(&force) + model.armature()[k];
                ancestor_entries(model, data, i, k, &force);
            }
            Dofs::Ball => {
                let joint = model.joint(i);
                for c in 0..3 {
                    let force = composite.apply(&joint.subspace_column_in(&data.centred_m_i[i], c));
                    // The block's upper triangle, mirrored: M exactly symmetric.
                    for r in 0..=c {
                        let entry = joint.subspace_column_in(&data.centred_m_i[i], r).dot(&force);
                        data.mass_matrix[(k + r, k + c)] = entry;
                        data.mass_matrix[(k + c, k + r)] = entry;
                    }
                    data.mass_matrix[(k + c, k + c)] += model.armature()[k + c];
                    ancestor_entries(model, data, i, k + c, &force);
                }
            }
        }
    }
    &data.mass_matrix
}

/// M_jk = S_jᵀ F (eq. 6.18) and its transpose for every ancestor j of body `i`, F = I^c S's column `k`.
fn ancestor_entries(model: &Model, data: &mut Data, i: usize, k: usize, force: &Force) {
    let mut j = i;
    while j != 0 {
        j = model.parent(j);
        let kj = model.idx_v(j);
        match model.joint(j).dofs() {
            Dofs::Free => {
                let local = data.centred_m_i[0].inv_act_force(force);
                data.mass_matrix.view_mut((kj, k), (6, 1)).copy_from(&local);
                data.mass_matrix.view_mut((k, kj), (1, 6)).copy_from(&local.transpose());
            }
            Dofs::Zero => {}
            Dofs::One(_) => {
                let entry = data.s[j].dot(force);
                data.mass_matrix[(kj, k)] = entry;
                data.mass_matrix[(k, kj)] = entry;
            }
            Dofs::Ball => {
                for r in 0..3 {
                    let entry = model.joint(j).subspace_column_in(&data.centred_m_i[j], r).dot(force);
                    data.mass_matrix[(kj + r, k)] = entry;
                    data.mass_matrix[(k, kj + r)] = entry;
                }
            }
        }
    }
}
