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
///
/// # Examples
///
/// A double pendulum (two 1 kg links 0.4 m long, hinged about y, hanging along −z at q = 0; built in the hidden lines)
/// held straight at angle θ: its centre of mass is 0.4 m from the shoulder along the links, the lower link's 0.6 m, and
/// the subtree below the shoulder holds the whole 2 kg.
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
/// let theta: f64 = 0.3;
/// let along = |r: f64| Vector3::new(-r * theta.sin(), 0.0, -r * theta.cos());
/// let com = algorithms::center_of_mass(&model, &mut data, &[theta, 0.0])?;
/// assert!((com - along(0.4)).norm() < 1e-12);
/// let subtrees = algorithms::subtree_mass_properties(&model, &mut data, &[theta, 0.0])?;
/// assert!((subtrees[1].mass() - 2.0).abs() < 1e-12 && (subtrees[1].com() - along(0.4)).norm() < 1e-12);
/// assert!((subtrees[2].mass() - 1.0).abs() < 1e-12 && (subtrees[2].com() - along(0.6)).norm() < 1e-12);
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
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
