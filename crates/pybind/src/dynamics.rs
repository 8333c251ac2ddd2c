//! The dynamics algorithms over batches of states: arguments broadcast over leading dimensions, rows are
//! checked, and the batch is spread over all cores with the GIL released.

use legkit_dynamics::algorithms;
use legkit_dynamics::spatial::Force;
use legkit_dynamics::{Data, Error, Model};
use pyo3::prelude::*;

use crate::convert::FloatArray;

use crate::batch::{broadcast, ArrayArg, Batch};
use crate::model::PyModel;
use crate::workspace::{batched, run, Workspace};

/// The batch of (q, v, x[, f_ext]) with cores (nq,), (nv,), (nv,) and (nbodies, 6).
pub(crate) fn state_batch(
    m: &Model, q: &ArrayArg<'_>, v: &ArrayArg<'_>, (name, x): (&'static str, &ArrayArg<'_>), f_ext: Option<&ArrayArg<'_>>,
) -> PyResult<Batch> {
    let (q_core, v_core, force_core) = ([m.nq()], [m.nv()], [m.nbodies(), 6]);
    let arguments = [("q", q, &q_core[..]), ("v", v, &v_core[..]), (name, x, &v_core[..])];
    match f_ext {
        Some(f) => broadcast(&[arguments[0], arguments[1], arguments[2], ("f_ext", f, &force_core[..])]),
        None => broadcast(&arguments),
    }
}

/// `kernel(model, data, [q, v, x], f_ext, out)` on row `i` of a `state_batch`, as `run` takes kernels.
pub(crate) fn on_state<'b, K>(batch: &'b Batch, kernel: K) -> impl Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync + 'b
where
    K: Fn(&Model, &mut Data, [&[f64]; 3], Option<&[Force]>, &mut [f64]) -> Result<(), Error> + Sync + 'b,
{
    move |m, w, i, out| {
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)));
        kernel(m, data, batch.row(i), forces, out)
    }
}

model_function! {
    /// Inverse dynamics τ = M q̈ + C q̇ + g − Σ Jᵀ f_ext (recursive Newton–Euler). `f_ext`, optional, holds one
    /// force `[f, n]` per body, in that body's frame: `(..., nbodies, 6)`.
    #[pyo3(signature = (model, q, v, a, f_ext = None))]
    fn rnea(py, model, q: ArrayArg, v: ArrayArg, a: ArrayArg, f_ext: Option<ArrayArg>) -> FloatArray<'py> {
        let nv = model.model.nv();
        let batch = state_batch(&model.model, &q, &v, ("a", &a), f_ext.as_ref())?;
        run(
            py,
            &model,
            &batch,
            &[nv],
            on_state(&batch, |m, data, [q, v, a], forces, out| {
                out.copy_from_slice(algorithms::rnea(m, data, q, v, a, forces)?.as_slice());
                Ok(())
            }),
        )
    }
}

model_function! {
    /// Forward dynamics q̈ = M⁻¹ (τ − C q̇ − g + Σ Jᵀ f_ext) by the O(n) articulated-body algorithm.
    #[pyo3(signature = (model, q, v, tau, f_ext = None))]
    fn aba(py, model, q: ArrayArg, v: ArrayArg, tau: ArrayArg, f_ext: Option<ArrayArg>) -> FloatArray<'py> {
        let nv = model.model.nv();
        let batch = state_batch(&model.model, &q, &v, ("tau", &tau), f_ext.as_ref())?;
        run(
            py,
            &model,
            &batch,
            &[nv],
            on_state(&batch, |m, data, [q, v, tau], forces, out| {
                out.copy_from_slice(algorithms::aba(m, data, q, v, tau, forces)?.as_slice());
                Ok(())
            }),
        )
    }
}

model_function! {
    /// The joint-space mass matrix M(q) (composite-rigid-body algorithm): `(..., nv, nv)`.
    fn crba(py, model, q: ArrayArg) -> FloatArray<'py> {
        let m = &model.model;
        batched(py, &model, [("q", &q, &[m.nq()])], &[m.nv(), m.nv()], |m, w, [q], out| {
            // M is symmetric, so its column-major storage is also its row-major layout.
            out.copy_from_slice(algorithms::crba(m, w.data(), q)?.as_slice());
            Ok(())
        })
    }
}

model_function! {
    /// M(q)⁻¹ by the O(n) articulated-body recursion, without forming or factorising M: `(..., nv, nv)`.
    fn minv(py, model, q: ArrayArg) -> FloatArray<'py> {
        let m = &model.model;
        batched(py, &model, [("q", &q, &[m.nq()])], &[m.nv(), m.nv()], |m, w, [q], out| {
            out.copy_from_slice(algorithms::minv(m, w.data(), q)?.as_slice());
            Ok(())
        })
    }
}

model_function! {
    /// Kinetic energy ½ vᵀ M v: `(...)`.
    fn kinetic_energy(py, model, q: ArrayArg, v: ArrayArg) -> FloatArray<'py> {
        let m = &model.model;
        batched(py, &model, [("q", &q, &[m.nq()]), ("v", &v, &[m.nv()])], &[], |m, w, [q, v], out| {
            out[0] = algorithms::kinetic_energy(m, w.data(), q, v)?;
            Ok(())
        })
    }
}

model_function! {
    /// Potential energy −Σ mᵢ gᵀ cᵢ: `(...)`.
    fn potential_energy(py, model, q: ArrayArg) -> FloatArray<'py> {
        batched(py, &model, [("q", &q, &[model.model.nq()])], &[], |m, w, [q], out| {
            out[0] = algorithms::potential_energy(m, w.data(), q)?;
            Ok(())
        })
    }
}
