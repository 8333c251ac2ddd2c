//! Centroidal momentum (Orin & Goswami): the robot's linear momentum and its angular momentum about the
//! centre of mass, in world-aligned axes, and its time derivative.

use nalgebra::{Vector3, Vector6};

use super::{joint_motion, joint_placement};
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_force, cross_motion, linear, spatial, Motion};
use crate::MassProperties;

/// Body velocities, accelerations (without gravity) and poses; returns the spatial momentum and its rate
/// about the world origin in world coordinates, and the centre of mass.
fn world_momentum(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>) -> (Vector6<f64>, Vector6<f64>, Vector3<f64>) {
    let (mut momentum, mut rate) = (Vector6::zeros(), Vector6::zeros());
    let mut total = MassProperties::zero();
    for i in 0..model.nbodies() {
        let li = joint_placement(model, i, q);
        data.li_m_i[i] = li;
        let (v_parent, a_parent, o_parent) = if i == 0 {
            (Motion::zeros(), Motion::zeros(), crate::Transform::identity())
        } else {
            let p = model.parent(i);
            (data.v[p], data.a[p], data.o_m_i[p])
        };
        data.o_m_i[i] = o_parent.compose(&li);
        total = total + model.body(i).transformed_unchecked(&data.o_m_i[i].rotation, &data.o_m_i[i].translation);
        let v_joint = joint_motion(model, i, v);
        data.v[i] = li.inv_act_motion(&v_parent) + v_joint;
        let inertia = model.inertia(i);
        let h = inertia.apply(&data.v[i]);
        momentum += data.o_m_i[i].act_force(&h);
        if let Some(a) = a {
            data.a[i] = li.inv_act_motion(&a_parent) + joint_motion(model, i, a) + cross_motion(&data.v[i], &v_joint);
            rate += data.o_m_i[i].act_force(&(inertia.apply(&data.a[i]) + cross_force(&data.v[i], &h)));
        }
    }
    (momentum, rate, total.com())
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
