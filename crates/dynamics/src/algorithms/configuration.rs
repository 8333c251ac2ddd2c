//! The configuration space: q ⊕ v dt (`integrate`), q1 ⊖ q0 (`difference`) and their Jacobians on the tangent
//! spaces (Pinocchio's `joint-configuration` algorithms), joint by joint (`Joint::integrate` and the rest). Each
//! joint's coordinates are a group of their own, SE(3) for the free flyer and R for the others, so the Jacobians
//! are block diagonal. A tangent perturbation δ of q means q ⊕ δ, as in the dynamics' derivatives.

use std::ops::Range;

use nalgebra::{Dyn, Matrix, MatrixViewMut, RawStorage, StorageMut};

use crate::joint::Joint;
use crate::model::Model;

/// Each joint with the ranges of its coordinates in q and in v.
fn joints(model: &Model) -> impl Iterator<Item = (&Joint, Range<usize>, Range<usize>)> {
    (0..model.nbodies()).map(move |i| {
        let (joint, kq, kv) = (model.joint(i), model.idx_q(i), model.idx_v(i));
        (joint, kq..kq + joint.nq(), kv..kv + joint.nv())
    })
}

/// `q ⊕ v dt` into `out` (nq).
pub fn integrate(model: &Model, q: &[f64], v: &[f64], dt: f64, out: &mut [f64]) {
    for (joint, cq, cv) in joints(model) {
        joint.integrate(&q[cq.clone()], &v[cv], dt, &mut out[cq]);
    }
}

/// `q1 ⊖ q0` into `out` (nv): the v with `integrate(q0, v, 1) = q1` (Pinocchio's `difference`).
pub fn difference(model: &Model, q0: &[f64], q1: &[f64], out: &mut [f64]) {
    for (joint, cq, cv) in joints(model) {
        joint.difference(&q0[cq.clone()], &q1[cq], &mut out[cv]);
    }
}

/// ∂(q ⊕ v dt)/∂q and ∂(q ⊕ v dt)/∂v into `dq` and `dv` (nv x nv, any storage: a `DMatrix`, or a view such as a
/// row-major one): Pinocchio's `dIntegrate(model, q, v dt, ARG0)` and dt `dIntegrate(model, q, v dt, ARG1)`. They
/// do not depend on q (`Joint::integrate_jacobians`).
pub fn integrate_jacobians<S: StorageMut<f64, Dyn, Dyn>>(
    model: &Model,
    v: &[f64],
    dt: f64,
    dq: &mut Matrix<f64, Dyn, Dyn, S>,
    dv: &mut Matrix<f64, Dyn, Dyn, S>,
) {
    block_diagonal(model, dq, dv, |joint, _, cv, dq, dv| joint.integrate_jacobians(&v[cv], dt, dq, dv));
}

/// ∂(q1 ⊖ q0)/∂q0 and ∂(q1 ⊖ q0)/∂q1 into `d0` and `d1` (nv x nv, any storage): Pinocchio's
/// `dDifference(model, q0, q1, ARG0)` and `(..., ARG1)`.
pub fn difference_jacobians<S: StorageMut<f64, Dyn, Dyn>>(
    model: &Model,
    q0: &[f64],
    q1: &[f64],
    d0: &mut Matrix<f64, Dyn, Dyn, S>,
    d1: &mut Matrix<f64, Dyn, Dyn, S>,
) {
    block_diagonal(model, d0, d1, |joint, cq, _, d0, d1| joint.difference_jacobians(&q0[cq.clone()], &q1[cq], d0, d1));
}

/// One joint's diagonal block of an nv x nv matrix of storage `S`.
type Block<'a, S> = MatrixViewMut<'a, f64, Dyn, Dyn, <S as RawStorage<f64, Dyn, Dyn>>::RStride, <S as RawStorage<f64, Dyn, Dyn>>::CStride>;

/// Zeroes `a` and `b`, then has `write` fill each joint's diagonal blocks of them, given the joint and its ranges in
/// q and v.
fn block_diagonal<S: StorageMut<f64, Dyn, Dyn>>(
    model: &Model,
    a: &mut Matrix<f64, Dyn, Dyn, S>,
    b: &mut Matrix<f64, Dyn, Dyn, S>,
    mut write: impl for<'b> FnMut(&Joint, Range<usize>, Range<usize>, &mut Block<'b, S>, &mut Block<'b, S>),
) {
    a.fill(0.0);
    b.fill(0.0);
    for (joint, cq, cv) in joints(model) {
        let (k, n) = (cv.start, cv.len());
        write(joint, cq, cv, &mut a.view_mut((k, k), (n, n)), &mut b.view_mut((k, k), (n, n)));
    }
}
