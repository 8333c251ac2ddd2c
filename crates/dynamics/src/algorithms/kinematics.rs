//! Forward kinematics: the pose of every body in the world.

use nalgebra::Vector3;

use super::checks::{check_state, finite_result};
use super::{joint_motion, joint_placement, world_pose};
use crate::model::{Data, Model};
use crate::spatial::{cross_motion, Motion, Transform};
use crate::Result;

/// Writes each body's pose in the world to `data.o_m_i`.
///
/// # Examples
///
/// A double pendulum (links 0.4 m long, hinged about y, hanging along −z at q = 0; built in the hidden lines): the
/// elbow, the lower link's origin, is 0.4 m from the shoulder along the upper link, and the lower link is turned by
/// both angles.
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
/// let q: [f64; 2] = [0.3, -0.8];
/// algorithms::forward_kinematics(&model, &mut data, &q)?;
/// let lower = data.o_m_i[2];
/// assert!((lower.translation - Vector3::new(-0.4 * q[0].sin(), 0.0, -0.4 * q[0].cos())).norm() < 1e-12);
/// assert!((lower.rotation - Transform::rotation_about(&Vector3::y(), q[0] + q[1])).amax() < 1e-12);
/// let error = algorithms::forward_kinematics(&model, &mut data, &[0.3, f64::NAN]).unwrap_err();
/// assert_eq!(error.to_string(), "q: element 1 is not finite (NaN)");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) -> Result<()> {
    check_state(model, data, q, &[])?;
    forward_kinematics_unchecked(model, data, q);
    if data.o_m_i.iter().all(|pose| pose.rotation.iter().chain(pose.translation.iter()).all(|x| x.is_finite())) {
        Ok(())
    } else {
        finite_result(&[f64::NAN])
    }
}

/// [`forward_kinematics`] without its checks, for the crate's inner loops.
pub(crate) fn forward_kinematics_unchecked(model: &Model, data: &mut Data, q: &[f64]) {
    poses_from(model, &mut data.o_m_i, q, joint_placement(model, 0, q));
}

/// Writes each body's pose in the world's axes about the base's origin to `data.centred_m_i`: the frame of the
/// world-frame recursions (ABA, CRBA, Minv). Their results do not depend on the origin, but the spatial
/// inertias of a floating robot far from the world's origin carry m|p|² terms that swamp its own inertia
/// and cost digits (a 0.2 kg body 3 m out lost five).
pub(crate) fn base_centred_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    poses_from(model, &mut data.centred_m_i, q, base_centred_root(model, q));
}

/// The base's pose with its translation dropped.
pub(crate) fn base_centred_root(model: &Model, q: &[f64]) -> Transform {
    Transform::new(joint_placement(model, 0, q).rotation, Vector3::zeros())
}

/// The body-frame forward pass (Featherstone eq. 5.7–5.8) shared by RNEA, the centroidal momentum, the
/// kinetic energy and the contact constraints: each body's pose in its parent (`data.li_m_i`) and its
/// velocity and acceleration in its own frame (`data.v`, `data.a`) under joint velocities `v` and
/// accelerations `a` (None: zero), the base accelerating with `base_acceleration`.
pub(crate) fn body_motions(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>, base_acceleration: Motion) {
    for i in 0..model.nbodies() {
        let li = joint_placement(model, i, q);
        let (v_parent, a_parent) = if i == 0 {
            (Motion::zeros(), base_acceleration)
        } else {
            let p = model.parent(i);
            (data.v[p], data.a[p])
        };
        let v_joint = joint_motion(model, i, v);
        let a_joint = a.map_or_else(Motion::zeros, |a| joint_motion(model, i, a));
        data.li_m_i[i] = li;
        data.v[i] = li.inv_act_motion(&v_parent) + v_joint;
        data.a[i] = li.inv_act_motion(&a_parent) + a_joint + cross_motion(&data.v[i], &v_joint);
    }
}

fn poses_from(model: &Model, poses: &mut [Transform], q: &[f64], root: Transform) {
    poses[0] = root;
    for i in 1..model.nbodies() {
        poses[i] = world_pose(model, i, &poses[model.parent(i)], q);
    }
}
