//! Kinetic and potential energy.

use super::{forward_kinematics, joint_motion, joint_placement};
use crate::model::{Data, Model};

/// ½ Σ vᵢᵀ Iᵢ vᵢ over the bodies (equal to ½ q̇ᵀ M q̇).
pub fn kinetic_energy(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> f64 {
    let mut energy = 0.0;
    for i in 0..model.nbodies() {
        let v_parent = if i == 0 { crate::spatial::Motion::zeros() } else { data.v[model.parent(i)] };
        data.v[i] = joint_placement(model, i, q).inv_act_motion(&v_parent) + joint_motion(model, i, v);
        energy += 0.5 * data.v[i].dot(&model.inertia(i).apply(&data.v[i]));
    }
    energy
}

/// −Σ mᵢ gᵀ cᵢ: zero when every COM is at the world origin's height (for the default gravity).
pub fn potential_energy(model: &Model, data: &mut Data, q: &[f64]) -> f64 {
    forward_kinematics(model, data, q);
    (0..model.nbodies()).map(|i| -model.body(i).mass() * model.gravity.dot(&data.o_m_i[i].transform_point(&model.body(i).com()))).sum()
}
