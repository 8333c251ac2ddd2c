//! The checks of the algorithms' public entry points, as Pinocchio's `PINOCCHIO_CHECK_ARGUMENT_SIZE`: before a kernel
//! runs, its `data` belongs to its model and every argument has its size, is finite and (a configuration) holds unit
//! quaternions; after, its outputs are finite, a failure there being numerical (an overflow, or a singular mass
//! matrix) rather than an argument's. Each error names the argument; nothing has been written when an argument is
//! refused.

use nalgebra::{DMatrix, Vector3};

use crate::model::{check_data, check_vector, Data, Dense, Model};
use crate::spatial::{spd_inverse6, Force};
use crate::validate::finite_vector;
use crate::{Error, Result};

/// `data` built for `model`, `q` a configuration of it, and each named vector (`v`, `a`, `tau`, ...) nv finite numbers.
pub(crate) fn check_state(model: &Model, data: &Data, q: &[f64], vectors: &[(&'static str, &[f64])]) -> Result<()> {
    check_data(model, data)?;
    model.check_configuration(q)?;
    for (argument, x) in vectors {
        check_vector(argument, x, model.nv())?;
    }
    Ok(())
}

/// External forces, if given: one finite force per body (numbered as the `nbodies x 6` numbers they flatten to).
pub(crate) fn check_forces(model: &Model, f_ext: Option<&[Force]>) -> Result<()> {
    let Some(forces) = f_ext else { return Ok(()) };
    if forces.len() != model.nbodies() {
        return Err(Error::invalid("f_ext", format!("expected {} forces (one per body), got {}", model.nbodies(), forces.len())));
    }
    let flat = forces.iter().flat_map(|f| f.iter().copied());
    if let Some((i, x)) = flat.enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(Error::invalid("f_ext", format!("element {i} is not finite ({x})")));
    }
    Ok(())
}

/// A frame: a body of the model and a finite point on it.
pub(crate) fn check_frame(model: &Model, body: usize, point: &Vector3<f64>) -> Result<()> {
    if body >= model.nbodies() {
        return Err(Error::invalid("body", format!("body {body} does not exist (the model has {} bodies)", model.nbodies())));
    }
    finite_vector("point", *point).map(|_| ())
}

/// `check_state` and `check_frame`, and the derivative workspace sized (fallibly): the opening of the frame kernels.
pub(crate) fn check_frame_state(
    model: &Model, data: &mut Data, q: &[f64], vectors: &[(&'static str, &[f64])], body: usize, point: &Vector3<f64>,
) -> Result<()> {
    check_state(model, data, q, vectors)?;
    check_frame(model, body, point)?;
    data.reserve_dense(model, &[Dense::Workspace])
}

/// An output slice of `len` numbers.
pub(crate) fn check_output(argument: &'static str, out: &[f64], len: usize) -> Result<()> {
    if out.len() != len {
        return Err(Error::invalid(argument, format!("expected {len} numbers, got {}", out.len())));
    }
    Ok(())
}

/// An output matrix of n x n.
pub(crate) fn check_square(argument: &'static str, m: &DMatrix<f64>, n: usize) -> Result<()> {
    if m.shape() != (n, n) {
        return Err(Error::invalid(argument, format!("expected a {n} x {n} matrix, got {} x {}", m.nrows(), m.ncols())));
    }
    Ok(())
}

/// Fails on NaN or infinity in a result: with valid (finite) inputs, a number overflowed. A numerical failure, never
/// reported as a singular mass matrix.
///
/// # Examples
///
/// The result checks, for code of one's own around the kernels: a number that overflowed is a numerical failure, not the
/// caller's argument; a singular mass matrix is the model's.
///
/// ```
/// use legkit_dynamics::algorithms;
///
/// assert!(algorithms::finite_result(&[1.0, -2.5]).is_ok());
/// let error = algorithms::finite_result(&[1.0, f64::INFINITY]).unwrap_err();
/// assert!(error.to_string().starts_with("result: not finite"));
/// assert!(algorithms::singular().to_string().starts_with("model: the mass matrix is singular"));
/// ```
pub fn finite_result(values: &[f64]) -> Result<()> {
    if all_finite(values) {
        Ok(())
    } else {
        Err(Error::numerical("result", "not finite: a number overflowed float64 (are the inputs' magnitudes physical?)"))
    }
}

/// Whether every number is finite, without a branch per number: x 0 is 0 for a finite x and NaN otherwise, summed in
/// eight lanes the compiler keeps in vector registers (an early-exit loop took 10 µs of `aba_derivatives`' 95 µs on a
/// 64-joint chain).
fn all_finite(values: &[f64]) -> bool {
    let mut lanes = [0.0f64; 8];
    let chunks = values.chunks_exact(8);
    let tail: f64 = chunks.remainder().iter().map(|x| x * 0.0).sum();
    for chunk in chunks {
        for (lane, x) in lanes.iter_mut().zip(chunk) {
            *lane += x * 0.0;
        }
    }
    lanes.iter().sum::<f64>() + tail == 0.0
}

/// `finite_result` for the outputs of the articulated-body factorisation left in `data` (ABA, Minv, and what runs
/// them), which also fail on a singular mass matrix.
pub fn finite_dynamics(model: &Model, data: &Data, values: &[f64]) -> Result<()> {
    finite_result(values).map_err(|overflow| if singular_factor(model, data) { singular() } else { overflow })
}

/// Whether the articulated-body factor in `data` is singular: a joint's pivot infinite or non-positive, or a floating
/// base's finite articulated inertia not positive definite (an overflowed state leaves NaN instead).
///
/// # Examples
///
/// A link without mass leaves ABA's factor singular: `singular_factor` tells it from an overflow, and
/// `finite_dynamics` reports a non-finite result of it as the model's singular mass matrix.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::Vector3;
/// let mut massless = Model::new(false, MassProperties::zero(), "base");
/// massless.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), MassProperties::zero(), "link", JointLimits::NONE)?;
/// let mut data = Data::new(&massless);
/// assert!(algorithms::aba(&massless, &mut data, &[0.0], &[0.0], &[1.0], None).is_err());
/// assert!(algorithms::singular_factor(&massless, &data));
/// assert_eq!(algorithms::finite_dynamics(&massless, &data, data.ddq.as_slice()), Err(algorithms::singular()));
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn singular_factor(model: &Model, data: &Data) -> bool {
    let base = &data.inertia[0];
    let base_singular = model.floating_base() && base.iter().all(|x| x.is_finite()) && spd_inverse6(base)[(0, 0)].is_nan();
    base_singular || (1..model.nbodies()).any(|i| model.joint(i).nv() == 1 && (data.d_inv[i].is_infinite() || data.d_inv[i] <= 0.0))
}

/// The error of a singular mass matrix: the model's fault (a numerical failure with valid arguments).
pub fn singular() -> Error {
    Error::numerical("model", "the mass matrix is singular at this configuration (a body or joint without inertia?)")
}
