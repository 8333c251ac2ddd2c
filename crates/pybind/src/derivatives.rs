//! The derivatives of the dynamics over batches of states, as `dynamics.rs` runs the dynamics.

use legkit_dynamics::algorithms;
use legkit_dynamics::{Error, Model};
use numpy::ndarray::Axis;
use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::prelude::*;

use crate::batch::{broadcast, ArrayArg, Batch};
use crate::convert::FloatArray;
use crate::dynamics::state_batch;
use crate::kinematics::row_major;
use crate::model::PyModel;
use crate::workspace::{run, Workspace};

/// Copies `matrices` (column-major, as nalgebra stores them) one after the other into `out`.
pub(crate) fn write_columns(matrices: &[&[f64]], out: &mut [f64]) {
    let mut rest = out;
    for matrix in matrices {
        let (chunk, tail) = rest.split_at_mut(matrix.len());
        chunk.copy_from_slice(matrix);
        rest = tail;
    }
}

/// Runs `kernel(model, workspace, i, out)` over the batch, which writes `count` matrices of `rows` x nv column-major
/// one after the other into `out` (`write_columns`); returns one array per matrix, `(..., rows, nv)`: column-major
/// views of one buffer (as Pinocchio's, which are Eigen's), so that nothing is transposed. (Transposing chain512's two
/// 512 x 512 matrices into row-major arrays took as long as computing them.)
pub(crate) fn run_matrices<'py, K>(
    py: Python<'py>,
    owner: &PyModel,
    batch: &Batch,
    count: usize,
    rows: usize,
    kernel: K,
) -> PyResult<Vec<FloatArray<'py>>>
where
    K: Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    let out = run(py, owner, batch, &[count, owner.model.nv(), rows], kernel)?;
    // SAFETY: the array was just filled and nothing else refers to it; the views keep it alive as their base.
    let buffer = unsafe { out.as_array() };
    let axis = Axis(buffer.ndim() - 3);
    Ok((0..count)
        .map(|k| {
            let mut view = buffer.index_axis(axis, k);
            let n = view.ndim();
            view.swap_axes(n - 2, n - 1);
            unsafe { PyArrayDyn::borrow_from_array(&view, out.clone().into_any()) }
        })
        .collect())
}

/// The two arrays of a pair.
pub(crate) fn pair(parts: Vec<FloatArray<'_>>) -> PyResult<(FloatArray<'_>, FloatArray<'_>)> {
    let mut parts = parts.into_iter();
    Ok((parts.next().expect("two"), parts.next().expect("two")))
}

/// ∂τ/∂q and ∂τ/∂v of inverse dynamics (`rnea`), each `(..., nv, nv)`, q on its tangent space (Carpentier &
/// Mansard, RSS 2018; Pinocchio's `computeRNEADerivatives`). ∂τ/∂a is `crba`.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, a, f_ext = None))]
pub fn rnea_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    f_ext: Option<ArrayArg<'_>>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("a", &a), f_ext.as_ref())?;
    let parts = run_matrices(py, &model, &batch, 2, nv, |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)));
        // Straight into the arrays: no nv x nv workspace, no copy.
        let (dq, dv) = out.split_at_mut(m.nv() * m.nv());
        algorithms::rnea_derivatives_into(m, data, q, v, a, forces, dq, dv)?;
        Ok(())
    })?;
    pair(parts)
}

/// The second derivatives of inverse dynamics (`rnea`), each `(..., nv, nv, nv)` with entry [i, j, k] the slope along
/// the third index of a first derivative: ∂/∂q_k of ∂τ_i/∂q_j, ∂/∂v_k of ∂τ_i/∂v_j, ∂/∂v_k of ∂τ_i/∂q_j and ∂/∂q_k of
/// ∂τ_i/∂a_j = M_ij; q on its tangent space (Pinocchio's `ComputeRNEASecondOrderDerivatives`).
#[pyfunction(crate = "crate::arguments")]
pub fn rnea_second_order_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("a", &a), None)?;
    let out = run(py, &model, &batch, &[4, nv, nv, nv], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let second = algorithms::rnea_second_order_derivatives(m, w.data(), q, v, a)?;
        write_columns(&[&second.dqdq, &second.dvdv, &second.dqdv, &second.dadq], out);
        Ok(())
    })?;
    // SAFETY: the array was just filled and nothing else refers to it; the views keep it alive as their base.
    let buffer = unsafe { out.as_array() };
    let axis = Axis(buffer.ndim() - 4);
    let part = |k: usize| unsafe { PyArrayDyn::borrow_from_array(&buffer.index_axis(axis, k), out.clone().into_any()) };
    Ok((part(0), part(1), part(2), part(3)))
}

/// ∂a/∂q, ∂a/∂v and ∂a/∂τ = M⁻¹ of forward dynamics (`aba`), each `(..., nv, nv)`, q on its tangent space
/// (Pinocchio's `computeABADerivatives`).
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, tau, f_ext = None))]
pub fn aba_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    tau: ArrayArg<'_>,
    f_ext: Option<ArrayArg<'_>>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("tau", &tau), f_ext.as_ref())?;
    let parts = run_matrices(py, &model, &batch, 3, nv, |m, w, i, out| {
        let (q, v, tau) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)));
        // Straight into the arrays: no nv x nv workspace for them, no copy.
        let (dq, rest) = out.split_at_mut(m.nv() * m.nv());
        let (dv, minv) = rest.split_at_mut(m.nv() * m.nv());
        algorithms::aba_derivatives_into(m, data, q, v, tau, forces, dq, dv, minv)?;
        Ok(())
    })?;
    let mut parts = parts.into_iter();
    Ok((parts.next().expect("three"), parts.next().expect("three"), parts.next().expect("three")))
}

/// ∂h/∂q, ∂ḣ/∂q, ∂ḣ/∂v and ∂ḣ/∂a = ∂h/∂v = A_G of the centroidal momentum h (`centroidal_momentum`) and its rate ḣ
/// (`centroidal_momentum_rate`, gravity excluded), each `(..., 6, nv)`, q on its tangent space (Pinocchio's
/// `computeCentroidalDynamicsDerivatives`).
#[pyfunction(crate = "crate::arguments")]
pub fn centroidal_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let batch = state_batch(&model.model, &q, &v, ("a", &a), None)?;
    let parts = run_matrices(py, &model, &batch, 4, 6, |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (dh_dq, dhdot_dq, dhdot_dv, dhdot_da) = algorithms::centroidal_derivatives(m, w.data(), q, v, a)?;
        write_columns(&[dh_dq.as_slice(), dhdot_dq.as_slice(), dhdot_dv.as_slice(), dhdot_da.as_slice()], out);
        Ok(())
    })?;
    let mut parts = parts.into_iter();
    Ok((parts.next().expect("four"), parts.next().expect("four"), parts.next().expect("four"), parts.next().expect("four")))
}

/// The centre of mass's Jacobian ∂c/∂q, `(..., 3, nv)`, world axes, q on its tangent space (Pinocchio's
/// `jacobianCenterOfMass`).
#[pyfunction(crate = "crate::arguments")]
pub fn center_of_mass_jacobian<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()])])?;
    run(py, &model, &batch, &[3, nv], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        row_major(algorithms::center_of_mass_jacobian(m, w.data(), q)?, out);
        Ok(())
    })
}
