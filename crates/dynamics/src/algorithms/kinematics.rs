//! Forward kinematics: the pose of every body in its parent and in the world.

use super::joint_placement;
use crate::model::{Data, Model};

pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    for i in 0..model.nbodies() {
        data.li_m_i[i] = joint_placement(model, i, q);
        data.o_m_i[i] = if i == 0 { data.li_m_i[0] } else { data.o_m_i[model.parent(i)].compose(&data.li_m_i[i]) };
    }
}
