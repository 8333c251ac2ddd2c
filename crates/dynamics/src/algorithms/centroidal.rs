//! Centroidal momentum (Orin & Goswami): the robot's linear momentum and its angular momentum about the
//! centre of mass, in world-aligned axes, and its time derivative.

use nalgebra::{Vector3, Vector6};

use super::com::world_com;
use super::kinematics::body_motions;
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_force, linear, spatial, Motion};

/// Body velocities, accelerations (without gravity) and poses; returns the spatial momentum and its rate
/// about the world origin in world coordinates, and the centre of mass.
fn world_momentum(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>) -> (Vector6<f64>, Vector6<f64>, Vector3<f64>) {
    let (mut momentum, mut rate) = (Vector6::zeros(), Vector6::zeros());
    body_motions(model, data, q, v, a, Motion::zeros());
    for i in 0..model.nbodies() {
        let o_parent = if i == 0 { crate::Transform::identity() } else { data.o_m_i[model.parent(i)] };
        data.o_m_i[i] = o_parent.compose(&data.li_m_i[i]);
        let inertia = model.inertia(i);
        let h = inertia.apply(&data.v[i]);
        momentum += data.o_m_i[i].act_force(&h);
        if a.is_some() {
            rate += data.o_m_i[i].act_force(&(inertia.apply(&data.a[i]) + cross_force(&data.v[i], &h)));
        }
    }
    (momentum, rate, world_com(model, data))
}

/// `[h_lin; h_ang]`: linear momentum and angular momentum about the COM, world-aligned.
pub fn centroidal_momentum(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> Vector6<f64> {
    let (momentum, _, com) = world_momentum(model, data, q, v, None);
    // Shift the moment from the world origin to the COM: L_G = L_O − c × p.
    spatial(linear(&momentum), angular(&momentum) - com.cross(&linear(&momentum)))
}

/// d/dt `[h_lin; h_ang]` for joint accelerations `a` (gravity excluded): the net external wrench about the
/// COM. Since ċ × p = ċ × m ċ = 0, the rate about the COM is L̇_O − c × ṗ.
pub fn centroidal_momentum_rate(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64]) -> Vector6<f64> {
    let (_, rate, com) = world_momentum(model, data, q, v, Some(a));
    spatial(linear(&rate), angular(&rate) - com.cross(&linear(&rate)))
}
