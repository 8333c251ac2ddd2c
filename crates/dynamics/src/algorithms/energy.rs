//! Kinetic and potential energy.

use super::checks::{check_state, finite_result};
use super::forward_kinematics_unchecked;
use super::kinematics::body_motions;
use crate::model::{Data, Model};
use crate::spatial::Motion;
use crate::Result;

/// ½ Σ vᵢᵀ Iᵢ vᵢ over the bodies plus the rotors' ½ Σ armature_k v_k² (equal to ½ q̇ᵀ M q̇ with M from
/// `crba`, as Pinocchio's).
///
/// # Examples
///
/// A double pendulum (two 1 kg links, 0.1 x 0.1 x 0.4 m, hinged about y, hanging along −z at q = 0; built in the hidden
/// lines) swinging straight at angle θ and rate ω: V = −m g (0.2 + 0.6) cos θ, its centres of mass 0.2 and 0.6 m from
/// the shoulder, and T = ½ I ω², I the two links' inertia about the shoulder.
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
/// let (theta, omega): (f64, f64) = (0.3, 2.0);
/// let potential = algorithms::potential_energy(&model, &mut data, &[theta, 0.0])?;
/// assert!((potential + 9.81 * (0.2 + 0.6) * theta.cos()).abs() < 1e-12);
/// let about_centre = (0.1f64.powi(2) + 0.4f64.powi(2)) / 12.0;
/// let about_shoulder = 2.0 * about_centre + 0.2f64.powi(2) + 0.6f64.powi(2);
/// let kinetic = algorithms::kinetic_energy(&model, &mut data, &[theta, 0.0], &[omega, 0.0])?;
/// assert!((kinetic - 0.5 * about_shoulder * omega * omega).abs() < 1e-12);
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
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
