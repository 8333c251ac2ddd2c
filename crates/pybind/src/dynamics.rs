//! The dynamics algorithms over batches of states: arguments broadcast over leading dimensions, rows are
//! checked, and the batch is spread over all cores with the GIL released.

use legkit_dynamics::algorithms;
use legkit_dynamics::Model;
use pyo3::prelude::*;

use crate::convert::FloatArray;

use crate::batch::{broadcast, ArrayArg, Batch};
use crate::model::PyModel;
use crate::workspace::run;

/// The batch of (q, v, x[, f_ext]) with cores (nq,), (nv,), (nv,) and (nbodies, 6).
pub(crate) fn state_batch(
    m: &Model,
    q: &ArrayArg<'_>,
    v: &ArrayArg<'_>,
    (name, x): (&'static str, &ArrayArg<'_>),
    f_ext: Option<&ArrayArg<'_>>,
) -> PyResult<Batch> {
    let (q_core, v_core, force_core) = ([m.nq()], [m.nv()], [m.nbodies(), 6]);
    let arguments = [("q", q, &q_core[..]), ("v", v, &v_core[..]), (name, x, &v_core[..])];
    match f_ext {
        Some(f) => broadcast(&[arguments[0], arguments[1], arguments[2], ("f_ext", f, &force_core[..])]),
        None => broadcast(&arguments),
    }
}

/// Inverse dynamics τ = M q̈ + C q̇ + g − Σ Jᵀ f_ext (recursive Newton–Euler). `f_ext`, optional, holds one
/// force `[f, n]` per body, in that body's frame: `(..., nbodies, 6)`.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, a, f_ext = None))]
pub fn rnea<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    f_ext: Option<ArrayArg<'_>>,
) -> PyResult<FloatArray<'py>> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("a", &a), f_ext.as_ref())?;
    run(py, &model, &batch, &[nv], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)));
        out.copy_from_slice(algorithms::rnea(m, data, q, v, a, forces)?.as_slice());
        Ok(())
    })
}

/// Forward dynamics q̈ = M⁻¹ (τ − C q̇ − g + Σ Jᵀ f_ext) by the O(n) articulated-body algorithm.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, tau, f_ext = None))]
pub fn aba<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    tau: ArrayArg<'_>,
    f_ext: Option<ArrayArg<'_>>,
) -> PyResult<FloatArray<'py>> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("tau", &tau), f_ext.as_ref())?;
    run(py, &model, &batch, &[nv], |m, w, i, out| {
        let (q, v, tau) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)));
        out.copy_from_slice(algorithms::aba(m, data, q, v, tau, forces)?.as_slice());
        Ok(())
    })
}

/// The joint-space mass matrix M(q) (composite-rigid-body algorithm): `(..., nv, nv)`.
#[pyfunction(crate = "crate::arguments")]
pub fn crba<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()])])?;
    run(py, &model, &batch, &[m.nv(), m.nv()], |m, w, i, out| {
        // M is symmetric, so its column-major storage is also its row-major layout.
        out.copy_from_slice(algorithms::crba(m, w.data(), batch.rows[0].row(i))?.as_slice());
        Ok(())
    })
}

/// M(q)⁻¹ by the O(n) articulated-body recursion, without forming or factorising M: `(..., nv, nv)`.
#[pyfunction(crate = "crate::arguments")]
pub fn minv<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()])])?;
    run(py, &model, &batch, &[m.nv(), m.nv()], |m, w, i, out| {
        out.copy_from_slice(algorithms::minv(m, w.data(), batch.rows[0].row(i))?.as_slice());
        Ok(())
    })
}

/// Kinetic energy ½ vᵀ M v: `(...)`.
#[pyfunction(crate = "crate::arguments")]
pub fn kinetic_energy<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>, v: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()]), ("v", &v, &[m.nv()])])?;
    run(py, &model, &batch, &[], |m, w, i, out| {
        out[0] = algorithms::kinetic_energy(m, w.data(), batch.rows[0].row(i), batch.rows[1].row(i))?;
        Ok(())
    })
}

/// Potential energy −Σ mᵢ gᵀ cᵢ: `(...)`.
#[pyfunction(crate = "crate::arguments")]
pub fn potential_energy<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let batch = broadcast(&[("q", &q, &[model.model.nq()])])?;
    run(py, &model, &batch, &[], |m, w, i, out| {
        out[0] = algorithms::potential_energy(m, w.data(), batch.rows[0].row(i))?;
        Ok(())
    })
}
