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
    body_motions(model, data, q, v, None, Motion::zeros());
    let bodies: f64 = (0..model.nbodies()).map(|i| 0.5 * data.v[i].dot(&model.inertia(i).apply(&data.v[i]))).sum();
    let energy = bodies + model.armature().iter().zip(v).map(|(a, v)| 0.5 * a * v * v).sum::<f64>();
    finite_result(&[energy])?;
    Ok(energy)
}

/// −Σ mᵢ gᵀ cᵢ: zero when every COM is at the world origin's height (for the default gravity).
pub fn potential_energy(model: &Model, data: &mut Data, q: &[f64]) -> Result<f64> {
    check_state(model, data, q, &[])?;
    forward_kinematics_unchecked(model, data, q);
    let energy: f64 =
        (0..model.nbodies()).map(|i| -model.body(i).mass() * model.gravity.dot(&data.o_m_i[i].transform_point(&model.body(i).com()))).sum();
    finite_result(&[energy])?;
    Ok(energy)
}
