//! Centre of mass and the mass properties of every subtree, in world coordinates.

use nalgebra::Vector3;

use super::checks::{check_state, finite_result};
use super::forward_kinematics_unchecked;
use crate::model::{Data, Model};
use crate::Result;

/// Fills `data.subtree[i]` with the mass properties of the subtree rooted at body `i`, in the world frame
/// (inertia about the subtree's COM): the quantity the distributed agents of Moll et al. compute by
/// message passing. Runs forward kinematics first.
pub fn subtree_mass_properties<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> Result<&'d [crate::MassProperties]> {
    check_state(model, data, q, &[])?;
    forward_kinematics_unchecked(model, data, q);
    for i in 0..model.nbodies() {
        let pose = &data.o_m_i[i];
        data.subtree[i] = model.body(i).transformed_unchecked(&pose.rotation, &pose.translation);
    }
    for i in (1..model.nbodies()).rev() {
        let p = model.parent(i);
        data.subtree[p] = data.subtree[p] + data.subtree[i];
    }
    for body in &data.subtree {
        finite_result(&[body.mass()])?;
        finite_result(body.com().as_slice())?;
        finite_result(body.inertia().as_slice())?;
    }
    Ok(&data.subtree)
}

/// The whole model's centre of mass in the world frame.
pub fn center_of_mass(model: &Model, data: &mut Data, q: &[f64]) -> Result<Vector3<f64>> {
    check_state(model, data, q, &[])?;
    forward_kinematics_unchecked(model, data, q);
    let com = world_com(model, data);
    finite_result(com.as_slice())?;
    Ok(com)
}

/// The centre of mass at the bodies' world poses in `data.o_m_i`: sum m_i c_i / M, without the inertias that
/// `subtree_mass_properties` carries (zeros for a massless model).
pub(crate) fn world_com(model: &Model, data: &Data) -> Vector3<f64> {
    let (mut first, mut mass) = (Vector3::zeros(), 0.0);
    for (i, pose) in data.o_m_i.iter().enumerate().take(model.nbodies()) {
        let body = model.body(i);
        first += (pose.rotation * body.com() + pose.translation) * body.mass();
        mass += body.mass();
    }
    if mass > 0.0 {
        first / mass
    } else {
        Vector3::zeros()
    }
}
