//! The derivatives of the dynamics over batches of states, as `dynamics.rs` runs the dynamics.

use legkit_dynamics::algorithms;
use legkit_dynamics::model::check_vector;
use nalgebra::DMatrix;
use numpy::{PyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PySlice;

use crate::batch::{broadcast, ArrayArg};
use crate::convert::FloatArray;
use crate::dynamics::state_batch;
use crate::kinematics::row_major;
use crate::model::PyModel;
use crate::workspace::{check_state, finite_result, run};

/// Writes `matrices` (nv x nv each, column-major) one after the other, row-major, into `out`: transposed in
/// tiles, so that a large matrix is read and written a cache line at a time.
pub(crate) fn write_row_major(matrices: &[&DMatrix<f64>], out: &mut [f64]) {
    const TILE: usize = 16;
    let Some(n) = matrices.first().map(|m| m.nrows()) else { return };
    for (matrix, chunk) in matrices.iter().zip(out.chunks_exact_mut((n * n).max(1))) {
        let from = matrix.as_slice();
        for r0 in (0..n).step_by(TILE) {
            for c0 in (0..n).step_by(TILE) {
                for c in c0..(c0 + TILE).min(n) {
                    for r in r0..(r0 + TILE).min(n) {
                        chunk[r * n + c] = from[c * n + r];
                    }
                }
            }
        }
    }
}

/// The views `out[..., k, :, :]` of an array shaped `(..., count, rows, nv)`: one array per matrix. Without batch
/// dimensions `out[k]`, which NumPy indexes in half the time.
fn split<'py>(out: FloatArray<'py>, count: usize) -> PyResult<Vec<FloatArray<'py>>> {
    let py = out.py();
    let view = |k: usize| if out.ndim() == 3 { out.get_item(k) } else { out.get_item((py.Ellipsis(), k, PySlice::full(py), PySlice::full(py))) };
    (0..count).map(|k| Ok(view(k)?.cast_into::<PyArrayDyn<f64>>()?)).collect()
}

/// `split` of an array shaped `(..., 2, nv, nv)`, as a pair.
pub(crate) fn split_pair(out: FloatArray<'_>) -> PyResult<(FloatArray<'_>, FloatArray<'_>)> {
    let mut parts = split(out, 2)?.into_iter();
    Ok((parts.next().expect("two"), parts.next().expect("two")))
}

/// ∂τ/∂q and ∂τ/∂v of inverse dynamics (`rnea`), each `(..., nv, nv)`, q on its tangent space (Carpentier &
/// Mansard, RSS 2018; Pinocchio's `computeRNEADerivatives`). ∂τ/∂a is `crba`.
#[pyfunction]
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
    let out = run(py, &model, &batch, &[2, nv, nv], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("a", a, m.nv())?;
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)))?;
        let (dq, dv) = algorithms::rnea_derivatives(m, data, q, v, a, forces);
        write_row_major(&[dq, dv], out);
        Ok(())
    })?;
    split_pair(out)
}

/// ∂a/∂q, ∂a/∂v and ∂a/∂τ = M⁻¹ of forward dynamics (`aba`), each `(..., nv, nv)`, q on its tangent space
/// (Pinocchio's `computeABADerivatives`).
#[pyfunction]
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
    let out = run(py, &model, &batch, &[3, nv, nv], |m, w, i, out| {
        let (q, v, tau) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("tau", tau, m.nv())?;
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)))?;
        let (dq, dv, minv) = algorithms::aba_derivatives(m, data, q, v, tau, forces);
        write_row_major(&[dq, dv, minv], out);
        // M⁻¹ is positive definite: a singular M shows on its diagonal, and spreads to the other two.
        finite_result(&*out)
    })?;
    let mut parts = split(out, 3)?.into_iter();
    Ok((parts.next().expect("three"), parts.next().expect("three"), parts.next().expect("three")))
}

/// ∂h/∂q, ∂ḣ/∂q, ∂ḣ/∂v and ∂ḣ/∂a = ∂h/∂v = A_G of the centroidal momentum h (`centroidal_momentum`) and its rate ḣ
/// (`centroidal_momentum_rate`, gravity excluded), each `(..., 6, nv)`, q on its tangent space (Pinocchio's
/// `computeCentroidalDynamicsDerivatives`).
#[pyfunction]
pub fn centroidal_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("a", &a), None)?;
    let out = run(py, &model, &batch, &[4, 6, nv], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("a", a, m.nv())?;
        let (dh_dq, dhdot_dq, dhdot_dv, dhdot_da) = algorithms::centroidal_derivatives(m, w.data(), q, v, a);
        for (matrix, chunk) in [dh_dq, dhdot_dq, dhdot_dv, dhdot_da].into_iter().zip(out.chunks_exact_mut((6 * nv).max(1))) {
            row_major(matrix, chunk);
        }
        Ok(())
    })?;
    let mut parts = split(out, 4)?.into_iter();
    Ok((parts.next().expect("four"), parts.next().expect("four"), parts.next().expect("four"), parts.next().expect("four")))
}

/// The centre of mass's Jacobian ∂c/∂q, `(..., 3, nv)`, world axes, q on its tangent space (Pinocchio's
/// `jacobianCenterOfMass`).
#[pyfunction]
pub fn center_of_mass_jacobian<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()])])?;
    run(py, &model, &batch, &[3, nv], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        check_state(m, q, None)?;
        row_major(algorithms::center_of_mass_jacobian(m, w.data(), q), out);
        Ok(())
    })
}
