//! Forward kinematics: the pose of every body in the world.

use nalgebra::Vector3;

use super::{joint_placement, world_pose};
use crate::model::{Data, Model};
use crate::spatial::Transform;

/// Writes each body's pose in the world to `data.o_m_i`.
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    poses_from(model, data, q, joint_placement(model, 0, q));
}

/// Writes each body's pose in the world's axes about the base's origin to `data.o_m_i`: the frame of the
/// world-frame recursions (ABA, CRBA, Minv). Their results do not depend on the origin, but the spatial
/// inertias of a floating robot far from the world's origin carry m|p|² terms that swamp its own inertia
/// and cost digits (a 0.2 kg body 3 m out lost five).
pub(crate) fn base_centred_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    poses_from(model, data, q, base_centred_root(model, q));
}

/// The base's pose with its translation dropped.
pub(crate) fn base_centred_root(model: &Model, q: &[f64]) -> Transform {
    Transform::new(joint_placement(model, 0, q).rotation, Vector3::zeros())
}

fn poses_from(model: &Model, data: &mut Data, q: &[f64], root: Transform) {
    data.o_m_i[0] = root;
    for i in 1..model.nbodies() {
        data.o_m_i[i] = world_pose(model, i, &data.o_m_i[model.parent(i)], q);
    }
}
