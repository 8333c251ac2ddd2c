//! Free dynamics (no contacts): configuration integration and rollouts.

use legkit_dynamics::algorithms::{self, Method};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::batch::{broadcast, ArrayArg};
use crate::convert::FloatArray;
use crate::model::PyModel;
use crate::workspace::{check_state, finite_result, run, run_packed, unpack};

/// `q ⊕ v dt`: joint coordinates add; a free-flyer base moves along exp(v dt) in its own frame: `(..., nq)`.
#[pyfunction]
pub fn integrate<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>, v: ArrayArg<'_>, dt: f64) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    legkit_dynamics::validate::finite("dt", dt).map_err(crate::convert::kernel_error)?;
    let batch = broadcast(&[("q", &q, &[m.nq()]), ("v", &v, &[m.nv()])])?;
    run(py, &model, &batch, &[m.nq()], |m, _, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        check_state(m, q, Some(v))?;
        algorithms::integrate(m, q, v, dt, out);
        Ok(())
    })
}

/// Rolls the free dynamics (ABA: no contacts, no ground, no joint limits) out for `steps` steps of `dt` from
/// (q, v) under joint forces `tau` (constant (nv,), per step (steps, nv), or None for zero) with "rk4" or
/// "semi_implicit_euler". Returns (qs (..., steps + 1, nq), vs (..., steps + 1, nv)). Leading dimensions of
/// q and v run independent rollouts on all cores. Contact simulation is `Simulation`.
#[pyfunction]
#[pyo3(signature = (model, q, v, dt, steps, tau = None, method = "rk4"))]
#[allow(clippy::too_many_arguments)]
pub fn free_rollout<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    dt: f64,
    steps: usize,
    tau: Option<ArrayArg<'_>>,
    method: &str,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let method = match method {
        "rk4" => Method::Rk4,
        "semi_implicit_euler" => Method::SemiImplicitEuler,
        other => return Err(PyValueError::new_err(format!("method: expected \"rk4\" or \"semi_implicit_euler\", got {other:?}"))),
    };
    let (nq, nv) = (model.model.nq(), model.model.nv());
    let tau: Vec<f64> = match &tau {
        Some(t) => t.get("tau")?.iter().copied().collect(),
        None => vec![0.0; nv],
    };
    if let Some(bad) = tau.iter().find(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!("tau: must be finite, got {bad}")));
    }
    let batch = broadcast(&[("q", &q, &[nq]), ("v", &v, &[nv])])?;
    let width = (steps + 1) * (nq + nv);
    let packed = run_packed(py, &model, &batch, width, |m, w, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        check_state(m, q, Some(v))?;
        let (qs, vs) = out.split_at_mut((steps + 1) * nq);
        algorithms::free_rollout(m, w.data(), q, v, &tau, dt, steps, method, qs, vs)?;
        finite_result(&*out)
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[steps + 1, nq], &[steps + 1, nv]]).into_iter();
    Ok((parts.next().unwrap(), parts.next().unwrap()))
}
