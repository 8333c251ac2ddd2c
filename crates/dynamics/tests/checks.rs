//! The checked entry points: each refuses a wrong-size, non-finite or non-unit argument and another model's `Data`
//! with the crate's `Error` naming the argument, before writing anything; and reports a numerical failure (a
//! singular mass matrix, an overflow) on valid arguments as `Error::Numerical`.

use legkit_dynamics::algorithms::{self, ContactDim, ContactPoint, Frame, Method};
use legkit_dynamics::spatial::Force;
use legkit_dynamics::{Data, Error, Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{DMatrix, Matrix3, Vector3};

/// A floating base with a ball joint and two revolute joints below it: nq 7 + 4 + 2, nv 6 + 3 + 2.
fn robot() -> Model {
    let body = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.0, 0.0, 0.1), &Matrix3::identity()).unwrap();
    let mut model = Model::new(true, body, "base");
    let placement = Transform::from_translation(Vector3::new(0.0, 0.0, 0.2));
    model.add_body(0, Joint::Spherical, placement, body, "ball", JointLimits::NONE).unwrap();
    model.add_body(1, Joint::Revolute(Vector3::y()), placement, body, "a", JointLimits::NONE).unwrap();
    model.add_body(2, Joint::Revolute(Vector3::x()), placement, body, "b", JointLimits::NONE).unwrap();
    model
}

/// A valid state: q with unit quaternions, v and a forces vector.
fn state(model: &Model) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut q = model.neutral().as_slice().to_vec();
    q[0] = 0.3;
    q[11] = 0.4;
    let v: Vec<f64> = (0..model.nv()).map(|k| 0.1 * k as f64 - 0.3).collect();
    let tau: Vec<f64> = (0..model.nv()).map(|k| 0.5 - 0.05 * k as f64).collect();
    (q, v, tau)
}

fn invalid(error: Error, argument: &str, needle: &str) {
    assert!(matches!(error, Error::InvalidArgument { .. }), "{error} is not an invalid argument");
    assert_eq!(error.argument(), argument, "{error}");
    assert!(error.to_string().contains(needle), "{error} does not contain {needle:?}");
}

#[test]
fn a_wrong_size_q_is_refused_naming_q_and_data_is_left_as_it_was() {
    let model = robot();
    let mut data = Data::new(&model);
    let (q, v, tau) = state(&model);
    let before = data.ddq.clone();
    invalid(
        algorithms::aba(&model, &mut data, &q[1..], &v, &tau, None).unwrap_err(),
        "q",
        &format!("expected length {}, got {}", model.nq(), model.nq() - 1),
    );
    assert_eq!(data.ddq, before);
    invalid(algorithms::rnea(&model, &mut data, &q, &v[1..], &tau, None).unwrap_err(), "v", "expected length");
    invalid(algorithms::rnea(&model, &mut data, &q, &v, &tau[1..], None).unwrap_err(), "a", "expected length");
    invalid(algorithms::crba(&model, &mut data, &[0.0; 3]).unwrap_err(), "q", "expected length");
    invalid(algorithms::minv(&model, &mut data, &[]).unwrap_err(), "q", "expected length");
}

#[test]
fn a_nan_or_infinite_argument_is_refused_naming_it() {
    let model = robot();
    let mut data = Data::new(&model);
    let (q, mut v, tau) = state(&model);
    v[4] = f64::NAN;
    invalid(algorithms::aba(&model, &mut data, &q, &v, &tau, None).unwrap_err(), "v", "element 4 is not finite (NaN)");
    invalid(algorithms::kinetic_energy(&model, &mut data, &q, &v).unwrap_err(), "v", "element 4 is not finite");
    let (mut q, v, mut tau) = state(&model);
    tau[2] = f64::INFINITY;
    invalid(algorithms::aba(&model, &mut data, &q, &v, &tau, None).unwrap_err(), "tau", "element 2 is not finite (inf)");
    q[12] = f64::NEG_INFINITY;
    invalid(algorithms::forward_kinematics(&model, &mut data, &q).unwrap_err(), "q", "element 12 is not finite");
    let (q, v, tau) = state(&model);
    let mut forces = vec![Force::zeros(); model.nbodies()];
    forces[1][3] = f64::NAN;
    invalid(algorithms::aba(&model, &mut data, &q, &v, &tau, Some(&forces)).unwrap_err(), "f_ext", "element 9 is not finite");
    invalid(algorithms::rnea(&model, &mut data, &q, &v, &tau, Some(&forces[1..])).unwrap_err(), "f_ext", "expected 4 forces");
    invalid(algorithms::jacobian(&model, &mut data, &q, 2, &Vector3::new(0.0, f64::NAN, 0.0), Frame::World).unwrap_err(), "point", "");
    invalid(algorithms::jacobian(&model, &mut data, &q, 4, &Vector3::zeros(), Frame::World).unwrap_err(), "body", "body 4 does not exist");
    invalid(algorithms::integrate(&model, &q, &v, f64::NAN, &mut vec![0.0; model.nq()]).unwrap_err(), "dt", "");
}

#[test]
fn a_non_unit_quaternion_is_refused_naming_q_and_its_joint() {
    let model = robot();
    let mut data = Data::new(&model);
    let (mut q, v, tau) = state(&model);
    q[6] = 0.5;
    invalid(algorithms::aba(&model, &mut data, &q, &v, &tau, None).unwrap_err(), "q", "the base quaternion q[3:7] must have unit norm");
    let (mut q, _, _) = state(&model);
    q[7] = 0.1;
    invalid(algorithms::crba(&model, &mut data, &q).unwrap_err(), "q", "the quaternion of ball joint 'ball' q[7:11] must have unit norm");
    invalid(algorithms::difference(&model, &state(&model).0, &q, &mut vec![0.0; model.nv()]).unwrap_err(), "q1", "unit norm");
}

#[test]
fn another_models_data_is_refused_naming_data() {
    let model = robot();
    let other = robot();
    let mut foreign = Data::new(&other);
    let (q, v, tau) = state(&model);
    let refused = |error: Error| invalid(error, "data", "was built for another model");
    refused(algorithms::aba(&model, &mut foreign, &q, &v, &tau, None).unwrap_err());
    refused(algorithms::rnea_derivatives(&model, &mut foreign, &q, &v, &tau, None).unwrap_err());
    refused(algorithms::center_of_mass(&model, &mut foreign, &q).unwrap_err());
    // A clone is the same model, and its Data serves both; a model grown by a body is another.
    let clone = model.clone();
    let mut data = Data::new(&clone);
    assert!(algorithms::aba(&model, &mut data, &q, &v, &tau, None).is_ok());
    let mut grown = model.clone();
    let body = *grown.body(1);
    grown.add_body(3, Joint::Revolute(Vector3::z()), Transform::identity(), body, "c", JointLimits::NONE).unwrap();
    let mut q_grown = q.clone();
    q_grown.push(0.0);
    let (v_grown, tau_grown) = ([&v[..], &[0.0]].concat(), [&tau[..], &[0.0]].concat());
    refused(algorithms::aba(&grown, &mut data, &q_grown, &v_grown, &tau_grown, None).unwrap_err());
    assert!(algorithms::aba(&grown, &mut Data::new(&grown), &q_grown, &v_grown, &tau_grown, None).is_ok());
}

#[test]
fn checked_and_valid_calls_agree_with_each_other() {
    // M ABA(q, v, tau) + h = tau, with M from CRBA and h from RNEA at zero acceleration.
    let model = robot();
    let mut data = Data::new(&model);
    let (q, v, tau) = state(&model);
    let ddq = algorithms::aba(&model, &mut data, &q, &v, &tau, None).unwrap().clone();
    let bias = algorithms::rnea(&model, &mut data, &q, &v, &vec![0.0; model.nv()], None).unwrap().clone();
    let mass = algorithms::crba(&model, &mut data, &q).unwrap().clone();
    let residual = &mass * &ddq + bias - nalgebra::DVector::from_column_slice(&tau);
    assert!(residual.amax() < 1e-10, "{residual}");
    let minv = algorithms::minv(&model, &mut data, &q).unwrap().clone();
    assert!((&minv * &mass - DMatrix::identity(model.nv(), model.nv())).amax() < 1e-10);
}

#[test]
fn a_singular_mass_matrix_is_a_numerical_error() {
    // A revolute joint carrying no inertia at the end of a fixed-base chain: M is singular.
    let mut model = Model::new(false, MassProperties::zero(), "base");
    model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), MassProperties::zero(), "massless", JointLimits::NONE).unwrap();
    let mut data = Data::new(&model);
    let error = algorithms::aba(&model, &mut data, &[0.0], &[0.0], &[1.0], None).unwrap_err();
    assert!(matches!(error, Error::Numerical { .. }), "{error}");
    assert!(error.to_string().contains("the mass matrix is singular"), "{error}");
    let error = algorithms::minv(&model, &mut data, &[0.0]).unwrap_err();
    assert!(error.to_string().contains("singular"), "{error}");
    let (mut qs, mut vs) = (vec![0.0; 3], vec![0.0; 3]);
    let error = algorithms::free_rollout(&model, &mut data, &[0.0], &[0.0], &[1.0], 0.01, 2, Method::Rk4, &mut qs, &mut vs).unwrap_err();
    assert!(error.to_string().contains("singular"), "{error}");
}

#[test]
fn outputs_of_the_wrong_size_are_refused_naming_them() {
    let model = robot();
    let mut data = Data::new(&model);
    let (q, v, _) = state(&model);
    let nv = model.nv();
    let (mut dq, mut dv) = (vec![0.0; nv * nv], vec![0.0; nv]);
    invalid(algorithms::rnea_derivatives_into(&model, &mut data, &q, &v, &v, None, &mut dq, &mut dv).unwrap_err(), "dtau_dv", "expected");
    let (mut a, mut b) = (DMatrix::zeros(nv, nv), DMatrix::zeros(nv, nv - 1));
    invalid(algorithms::integrate_jacobians(&model, &v, 0.1, &mut a, &mut b).unwrap_err(), "dv", &format!("expected a {nv} x {nv} matrix"));
    let contact = [ContactPoint { body: 3, point: Vector3::zeros() }];
    invalid(
        algorithms::point_accelerations(&model, &mut data, &q, &v, None, &contact, ContactDim::Point, &mut [0.0; 2]).unwrap_err(),
        "out",
        "expected 3",
    );
    let (mut qs, mut vs) = (vec![0.0; 2 * model.nq()], vec![0.0; nv]);
    invalid(algorithms::free_rollout(&model, &mut data, &q, &v, &v, 0.01, 1, Method::Rk4, &mut qs, &mut vs).unwrap_err(), "vs", "expected");
}
