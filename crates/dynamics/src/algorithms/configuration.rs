//! The configuration space: q ⊕ v dt (`integrate`), q1 ⊖ q0 (`difference`) and their Jacobians on the tangent
//! spaces (Pinocchio's `joint-configuration` algorithms), joint by joint (`Joint::integrate` and the rest). Each
//! joint's coordinates are a group of their own, SE(3) for the free flyer and R for the others, so the Jacobians
//! are block diagonal. A tangent perturbation δ of q means q ⊕ δ, as in the dynamics' derivatives.

use std::ops::Range;

use nalgebra::{DMatrix, DMatrixViewMut};

use super::checks::{check_output, check_square, finite_result};
use crate::joint::Joint;
use crate::model::check_vector;
use crate::model::Model;
use crate::validate::finite;
use crate::Result;

/// Each joint with the ranges of its coordinates in q and in v.
fn joints(model: &Model) -> impl Iterator<Item = (&Joint, Range<usize>, Range<usize>)> {
    (0..model.nbodies()).map(move |i| {
        let (joint, kq, kv) = (model.joint(i), model.idx_q(i), model.idx_v(i));
        (joint, kq..kq + joint.nq(), kv..kv + joint.nv())
    })
}

/// `q ⊕ v dt` into `out` (nq).
///
/// # Examples
///
/// On a floating box (q = [x, y, z, qx, qy, qz, qw], v = [v; ω] in the box's frame): q1 ⊖ q0 undoes q0 ⊕ v dt, a
/// difference's Jacobians at q1 = q0 are −I and I, and a base quaternion off the unit sphere is refused.
///
/// ```
/// use legkit_dynamics::{algorithms, MassProperties, Model};
/// use nalgebra::{DMatrix, Matrix3, Vector3};
///
/// let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
/// let model = Model::new(true, body, "box");
/// let half: f64 = 0.2; // turned 0.4 rad about x
/// let (q0, v, dt) = ([0.1, 0.0, 0.5, half.sin(), 0.0, 0.0, half.cos()], [1.0, 0.0, -0.5, 0.3, -0.2, 1.0], 0.1);
/// let (mut q1, mut back) = ([0.0; 7], [0.0; 6]);
/// algorithms::integrate(&model, &q0, &v, dt, &mut q1)?;
/// algorithms::difference(&model, &q0, &q1, &mut back)?;
/// assert!(back.iter().zip(&v).all(|(d, v)| (d - v * dt).abs() < 1e-12));
/// let (mut d0, mut d1) = (DMatrix::zeros(6, 6), DMatrix::zeros(6, 6));
/// algorithms::difference_jacobians(&model, &q0, &q0, &mut d0, &mut d1)?;
/// assert!((d0 + DMatrix::identity(6, 6)).amax() < 1e-12 && (d1 - DMatrix::identity(6, 6)).amax() < 1e-12);
/// let error = algorithms::integrate(&model, &[0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 2.0], &v, dt, &mut q1).unwrap_err();
/// assert_eq!(error.to_string(), "q: the base quaternion q[3:7] must have unit norm, got 2.000000000");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn integrate(model: &Model, q: &[f64], v: &[f64], dt: f64, out: &mut [f64]) -> Result<()> {
    model.check_configuration(q)?;
    check_vector("v", v, model.nv())?;
    finite("dt", dt)?;
    check_output("out", out, model.nq())?;
    integrate_unchecked(model, q, v, dt, out);
    finite_result(out)
}

/// [`integrate`] without its checks, for the crate's inner loops.
pub(crate) fn integrate_unchecked(model: &Model, q: &[f64], v: &[f64], dt: f64, out: &mut [f64]) {
    for (joint, cq, cv) in joints(model) {
        joint.integrate(&q[cq.clone()], &v[cv], dt, &mut out[cq]);
    }
}

/// `q1 ⊖ q0` into `out` (nv): the v with `integrate(q0, v, 1) = q1` (Pinocchio's `difference`).
pub fn difference(model: &Model, q0: &[f64], q1: &[f64], out: &mut [f64]) -> Result<()> {
    model.check_configuration_named("q0", q0)?;
    model.check_configuration_named("q1", q1)?;
    check_output("out", out, model.nv())?;
    for (joint, cq, cv) in joints(model) {
        joint.difference(&q0[cq.clone()], &q1[cq], &mut out[cv]);
    }
    finite_result(out)
}

/// ∂(q ⊕ v dt)/∂q and ∂(q ⊕ v dt)/∂v into `dq` and `dv` (nv x nv): Pinocchio's `dIntegrate(model, q, v dt, ARG0)`
/// and dt `dIntegrate(model, q, v dt, ARG1)`. They do not depend on q (`Joint::integrate_jacobians`).
///
/// # Examples
///
/// ∂(q ⊕ v dt)/∂v (`integrate_jacobians`' second matrix) against central differences, each taken in the tangent
/// space at q ⊕ v dt by `difference`:
///
/// ```
/// # use legkit_dynamics::{algorithms, MassProperties, Model};
/// # use nalgebra::{DMatrix, Matrix3, Vector3};
/// # let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
/// # let model = Model::new(true, body, "box");
/// # let half: f64 = 0.2;
/// let (q0, v, dt, h) = ([0.1, 0.0, 0.5, half.sin(), 0.0, 0.0, half.cos()], [1.0, 0.0, -0.5, 0.3, -0.2, 1.0], 0.1, 1e-6);
/// let (mut by_q, mut by_v) = (DMatrix::zeros(6, 6), DMatrix::zeros(6, 6));
/// algorithms::integrate_jacobians(&model, &v, dt, &mut by_q, &mut by_v)?;
/// let (mut q1, mut moved, mut sides) = ([0.0; 7], [0.0; 7], [[0.0; 6]; 2]);
/// algorithms::integrate(&model, &q0, &v, dt, &mut q1)?;
/// for k in 0..6 {
///     for (side, step) in sides.iter_mut().zip([h, -h]) {
///         let mut nudged = v;
///         nudged[k] += step;
///         algorithms::integrate(&model, &q0, &nudged, dt, &mut moved)?;
///         algorithms::difference(&model, &q1, &moved, side)?;
///     }
///     (0..6).for_each(|r| assert!((by_v[(r, k)] - (sides[0][r] - sides[1][r]) / (2.0 * h)).abs() < 1e-7));
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn integrate_jacobians(model: &Model, v: &[f64], dt: f64, dq: &mut DMatrix<f64>, dv: &mut DMatrix<f64>) -> Result<()> {
    check_vector("v", v, model.nv())?;
    finite("dt", dt)?;
    check_square("dq", dq, model.nv())?;
    check_square("dv", dv, model.nv())?;
    integrate_jacobians_unchecked(model, v, dt, dq, dv);
    finite_result(dq.as_slice())?;
    finite_result(dv.as_slice())
}

/// [`integrate_jacobians`] without its checks, for the crate's inner loops.
pub(crate) fn integrate_jacobians_unchecked(model: &Model, v: &[f64], dt: f64, dq: &mut DMatrix<f64>, dv: &mut DMatrix<f64>) {
    block_diagonal(model, dq, dv, |joint, _, cv, dq, dv| joint.integrate_jacobians(&v[cv], dt, dq, dv));
}

/// ∂(q1 ⊖ q0)/∂q0 and ∂(q1 ⊖ q0)/∂q1 into `d0` and `d1` (nv x nv): Pinocchio's `dDifference(model, q0, q1, ARG0)`
/// and `(..., ARG1)`.
pub fn difference_jacobians(model: &Model, q0: &[f64], q1: &[f64], d0: &mut DMatrix<f64>, d1: &mut DMatrix<f64>) -> Result<()> {
    model.check_configuration_named("q0", q0)?;
    model.check_configuration_named("q1", q1)?;
    check_square("d0", d0, model.nv())?;
    check_square("d1", d1, model.nv())?;
    block_diagonal(model, d0, d1, |joint, cq, _, d0, d1| joint.difference_jacobians(&q0[cq.clone()], &q1[cq], d0, d1));
    finite_result(d0.as_slice())?;
    finite_result(d1.as_slice())
}

/// Zeroes `a` and `b` (nv x nv), then has `write` fill each joint's diagonal blocks of them, given the joint and its
/// ranges in q and v.
fn block_diagonal(
    model: &Model, a: &mut DMatrix<f64>, b: &mut DMatrix<f64>,
    mut write: impl FnMut(&Joint, Range<usize>, Range<usize>, &mut DMatrixViewMut<'_, f64>, &mut DMatrixViewMut<'_, f64>),
) {
    // As slices, a memset: nalgebra's element-wise `fill` took 0.8 µs of 1.2 µs on an 18-DoF free-flying tree.
    a.as_mut_slice().fill(0.0);
    b.as_mut_slice().fill(0.0);
    for (joint, cq, cv) in joints(model) {
        let (k, n) = (cv.start, cv.len());
        write(joint, cq, cv, &mut a.view_mut((k, k), (n, n)), &mut b.view_mut((k, k), (n, n)));
    }
}
