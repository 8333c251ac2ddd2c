//! Kinetic and potential energy.

use super::checks::{check_state, finite_result};
use super::forward_kinematics_unchecked;
use super::kinematics::body_motions;
use crate::model::{Data, Model};
use crate::spatial::Motion;
use crate::Result;

/// ½ Σ vᵢᵀ Iᵢ vᵢ over the bodies plus the rotors' ½ Σ armature_k v_k² (equal to ½ q̇ᵀ M q̇ with M from
/// `crba`, as Pinocchio's).
pub fn kinetic_energy(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> Result<f64> {
    check_state(model, data, q, &[("v", v)])?;
    let energy = kinetic_energy_unchecked(model, data, q, v);
    finite_result(&[energy])?;
    Ok(energy)
}

/// [`kinetic_energy`] without its checks, for the crate's inner loops.
pub(crate) fn kinetic_energy_unchecked(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> f64 {
    body_motions(model, data, q, v, None, Motion::zeros());
    let bodies: f64 = (0..model.nbodies()).map(|i| 0.5 * data.v[i].dot(&model.inertia(i).apply(&data.v[i]))).sum();
    bodies + model.armature().iter().zip(v).map(|(a, v)| 0.5 * a * v * v).sum::<f64>()
}

/// −Σ mᵢ gᵀ cᵢ: zero when every COM is at the world origin's height (for the default gravity).
pub fn potential_energy(model: &Model, data: &mut Data, q: &[f64]) -> Result<f64> {
    check_state(model, data, q, &[])?;
    let energy = potential_energy_unchecked(model, data, q);
    finite_result(&[energy])?;
    Ok(energy)
}

/// [`potential_energy`] without its checks, for the crate's inner loops.
pub(crate) fn potential_energy_unchecked(model: &Model, data: &mut Data, q: &[f64]) -> f64 {
    forward_kinematics_unchecked(model, data, q);
    (0..model.nbodies()).map(|i| -model.body(i).mass() * model.gravity.dot(&data.o_m_i[i].transform_point(&model.body(i).com()))).sum()
}
