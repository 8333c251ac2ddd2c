//! Recursive Newton–Euler inverse dynamics (Featherstone, Table 5.1): τ = M(q) q̈ + C(q, q̇) q̇ + g(q) − Jᵀ f_ext.

use nalgebra::DVector;

use super::checks::{check_forces, check_state, finite_result};
use super::kinematics::body_motions;
use crate::joint::Dofs;
use crate::model::{Data, Model};
use crate::spatial::{cross_force, Force};
use crate::Result;

/// Inverse dynamics by the recursive Newton–Euler algorithm [Featherstone 2008, Table 5.1], O(n):
/// τ = M(q) q̈ + C(q, q̇) q̇ + g(q) − Jᵀ f_ext.
///
/// Joint forces for configuration `q`, velocity `v` and acceleration `a`. `f_ext`, when given, holds one
/// external force `[f; n]` per body, acting on that body and expressed in its frame.
///
/// # Examples
///
/// Holding still the double pendulum of these examples (two 1 kg links, 0.1 x 0.1 x 0.4 m, hinged about y at the base
/// and at the upper link's end, hanging along −z at q = 0; built in the hidden lines) takes the torques of the links'
/// weights about the hinges: at q = (θ, 0), m g sin θ times the lever arms 0.2 + 0.6 m at the shoulder and 0.2 m at
/// the elbow.
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
/// let tau = algorithms::rnea(&model, &mut data, &[theta, 0.0], &[0.0; 2], &[0.0; 2], None)?;
/// let weight_torque = |lever: f64| 9.81 * lever * theta.sin();
/// assert!((tau[0] - weight_torque(0.2 + 0.6)).abs() < 1e-12);
/// assert!((tau[1] - weight_torque(0.2)).abs() < 1e-12);
/// // A velocity of the wrong length is refused, naming it.
/// let error = algorithms::rnea(&model, &mut data, &[theta, 0.0], &[0.0], &[0.0; 2], None).unwrap_err();
/// assert_eq!(error.to_string(), "v: expected length 2, got 1");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
///
/// External forces are one `[f; n]` per body, in its frame: lifting each link by its weight at its centre of mass
/// leaves the joints nothing to hold, in any pose.
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
/// use legkit_dynamics::spatial::Force;
/// let q = [0.3, -0.8];
/// algorithms::forward_kinematics(&model, &mut data, &q)?;
/// let lift: Vec<Force> = (0..model.nbodies())
///     .map(|i| {
///         let body = model.body(i);
///         let f = data.o_m_i[i].rotation.transpose() * Vector3::new(0.0, 0.0, 9.81 * body.mass());
///         let n = body.com().cross(&f);
///         Force::new(f.x, f.y, f.z, n.x, n.y, n.z)
///     })
///     .collect();
/// let tau = algorithms::rnea(&model, &mut data, &q, &[0.0; 2], &[0.0; 2], Some(&lift))?;
/// assert!(tau.amax() < 1e-12);
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn rnea<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>) -> Result<&'d DVector<f64>> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    check_forces(model, f_ext)?;
    rnea_unchecked(model, data, q, v, a, f_ext);
    finite_result(data.tau.as_slice())?;
    Ok(&data.tau)
}

/// [`rnea`] without its checks, for the crate's inner loops.
pub(crate) fn rnea_unchecked<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>) -> &'d DVector<f64> {
    // Forward pass: velocities, accelerations (gravity as a base acceleration) and the net force each body
    // needs (eq. 5.7–5.9).
    body_motions(model, data, q, v, Some(a), model.gravity_bias());
    for i in 0..model.nbodies() {
        let inertia = model.inertia(i);
        data.f[i] = inertia.apply(&data.a[i]) + cross_force(&data.v[i], &inertia.apply(&data.v[i]));
        if let Some(f_ext) = f_ext {
            data.f[i] -= f_ext[i];
        }
    }
    // Backward pass: project onto the joint axes and pass the rest to the parent (eq. 5.10–5.11).
    for i in (0..model.nbodies()).rev() {
        let k = model.idx_v(i);
        let f = data.f[i];
        match model.joint(i).dofs() {
            Dofs::Free => data.tau.rows_mut(k, 6).copy_from(&f),
            Dofs::Zero => {}
            Dofs::One(s) => data.tau[k] = s.dot(&f) + model.armature()[k] * a[k],
            // S = [0; I]: the moment.
            Dofs::Ball => {
                for c in 0..3 {
                    data.tau[k + c] = f[3 + c] + model.armature()[k + c] * a[k + c];
                }
            }
        }
        if i > 0 {
            let p = model.parent(i);
            data.f[p] += data.li_m_i[i].act_force(&f);
        }
    }
    &data.tau
}
