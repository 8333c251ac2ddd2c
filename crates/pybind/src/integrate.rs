//! The configuration space (integration, difference and their Jacobians) and free dynamics (no contacts): rollouts.

use legkit_dynamics::algorithms::{self, Method};
use legkit_dynamics::{Error, Model};
use nalgebra::DMatrix;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::batch::{array, broadcast, map_rows, Argument, ArrayArg};
use crate::convert::{kernel_error, shown, Arrays2, FloatArray, Integer};
use crate::derivatives::{run_matrices, write_columns};
use crate::interrupt::{in_pieces, Pace};
use crate::model::PyModel;
use crate::workspace::{batched, unpack, Workspace};
use legkit_dynamics::validate::{array_len, zeros};

model_function! {
    /// `q ⊕ v dt`: joint coordinates add; a free-flyer base moves along exp(v dt) in its own frame: `(..., nq)`.
    /// `dt` defaults to 1, as Pinocchio's `integrate(model, q, v)`.
    #[pyo3(signature = (model, q, v, dt = 1.0))]
    fn integrate(py, model, q: ArrayArg, v: ArrayArg, dt: f64) -> FloatArray<'py> {
        let m = &model.model;
        legkit_dynamics::validate::finite("dt", dt).map_err(crate::convert::kernel_error)?;
        batched(py, &model, [("q", &q, &[m.nq()]), ("v", &v, &[m.nv()])], &[m.nq()], |m, _, [q, v], out| algorithms::integrate(m, q, v, dt, out))
    }
}

model_function! {
    /// Rolls the free dynamics (ABA: no contacts, no ground, no joint limits) out for `steps` steps of `dt` from
    /// (q, v) under joint forces `tau` (constant (nv,), per step (steps, nv), or None for zero) with "rk4" or
    /// "semi_implicit_euler". Returns (qs (..., steps + 1, nq), vs (..., steps + 1, nv)). Leading dimensions of
    /// q and v run independent rollouts on all cores. Contact simulation is `Simulation`. MemoryError if the
    /// output cannot be allocated; Ctrl-C interrupts a long rollout (KeyboardInterrupt).
    #[pyo3(signature = (model, q, v, dt, steps, tau = None, method = "rk4"))]
    fn free_rollout(py, model, q: ArrayArg, v: ArrayArg, dt: f64, steps: Integer, tau: Option<ArrayArg>, method: &str) -> Arrays2<'py> {
        let method = match method {
            "rk4" => Method::Rk4,
            "semi_implicit_euler" => Method::SemiImplicitEuler,
            other => return Err(PyValueError::new_err(format!("method: expected \"rk4\" or \"semi_implicit_euler\", got {other:?}"))),
        };
        let (nq, nv) = (model.model.nq(), model.model.nv());
        let steps = steps.value("steps")?;
        if steps < 0 {
            return Err(PyValueError::new_err(format!("steps: must be >= 0, got {}", shown(steps))));
        }
        // Checked before anything is allocated: the outputs hold steps + 1 rows.
        let rows = usize::try_from(steps).ok().and_then(|s| s.checked_add(1));
        let rows = rows.ok_or_else(|| kernel_error(Error::too_large("steps", format!("{} steps are beyond any memory", shown(steps)))))?;
        let steps = rows - 1;
        array_len("steps", &[rows, nq + nv], std::mem::size_of::<f64>()).map_err(kernel_error)?;
        let tau: Vec<f64> = match &tau {
            Some(t) => {
                let view = t.get("tau")?;
                if view.shape() != [nv] && view.shape() != [steps, nv] {
                    return Err(PyValueError::new_err(format!(
                        "tau: expected shape ({nv},) or ({steps}, {nv}) (one row per step), got {:?}",
                        view.shape()
                    )));
                }
                view.iter().copied().collect()
            }
            None => vec![0.0; nv],
        };
        // Checked whole here, before any step: the pieces below pass the core one step's rows at a time.
        if let Some(bad) = tau.iter().find(|x| !x.is_finite()) {
            return Err(PyValueError::new_err(format!("tau: must be finite, got {bad}")));
        }
        let batch = broadcast(&[("q", &q, &[nq]), ("v", &v, &[nv])])?;
        let width = rows * (nq + nv);
        let len = array_len("steps", &[batch.len, width], std::mem::size_of::<f64>()).map_err(kernel_error)?;
        let mut packed = zeros("steps", len).map_err(kernel_error)?;
        let owner: &PyModel = &model;
        map_rows(
            &mut packed,
            width,
            0,
            batch.len,
            || Workspace::new(owner),
            |w, i, out| {
                // The initial state, checked and written by a rollout of no steps.
                let (qs, vs) = out.split_at_mut(rows * nq);
                let tau = if tau.len() == nv { &tau[..] } else { &[] };
                let [q, v] = batch.row(i);
                algorithms::free_rollout(&owner.model, w.data(), q, v, tau, dt, 0, method, &mut qs[..nq], &mut vs[..nv])
            },
        )?;
        let mut done = 0;
        // In pieces of whole steps, each continuing from the last row written: a step depends only on (q, v).
        in_pieces(py, steps as u64, &Pace::default(), |k| {
            let (from, to) = (done, done + k as usize);
            map_rows(
                &mut packed,
                width,
                0,
                batch.len,
                || Workspace::new(owner),
                |w, _, out| {
                    let (qs, vs) = out.split_at_mut(rows * nq);
                    let (q0, v0) = (qs[from * nq..(from + 1) * nq].to_vec(), vs[from * nv..(from + 1) * nv].to_vec());
                    let tau = if tau.len() == nv { &tau[..] } else { &tau[from * nv..to * nv] };
                    let (qs, vs) = (&mut qs[from * nq..(to + 1) * nq], &mut vs[from * nv..(to + 1) * nv]);
                    algorithms::free_rollout(&owner.model, w.data(), &q0, &v0, tau, dt, to - from, method, qs, vs)
                },
            )?;
            done = to;
            Ok(())
        })?;
        let [qs, vs] = array(unpack(py, &batch, &packed, &[&[rows, nq], &[rows, nv]])?);
        Ok((qs, vs))
    }
}

model_function! {
    /// `q1 ⊖ q0`: the velocity v with `integrate(q0, v, 1) = q1` (Pinocchio's `difference`); a free-flyer base's part is
    /// the SE(3) log of its relative pose, in the base frame at q0: `(..., nv)`.
    fn difference(py, model, q0: ArrayArg, q1: ArrayArg) -> FloatArray<'py> {
        let nq = model.model.nq();
        let arguments = [("q0", &q0, &[nq][..]), ("q1", &q1, &[nq])];
        batched(py, &model, arguments, &[model.model.nv()], |m, _, [q0, q1], out| algorithms::difference(m, q0, q1, out))
    }
}

model_function! {
    /// (∂(q ⊕ v dt)/∂q, ∂(q ⊕ v dt)/∂v), each `(..., nv, nv)`, on the tangent spaces: Pinocchio's `dIntegrate` at v dt,
    /// ARG0 and dt times ARG1. Block diagonal; they do not depend on q, which is checked as in `integrate`.
    #[pyo3(signature = (model, q, v, dt = 1.0))]
    fn integrate_jacobians(py, model, q: ArrayArg, v: ArrayArg, dt: f64) -> Arrays2<'py> {
        let (nq, nv) = (model.model.nq(), model.model.nv());
        legkit_dynamics::validate::finite("dt", dt).map_err(crate::convert::kernel_error)?;
        run_matrix_pair(py, &model, [("q", &q, &[nq]), ("v", &v, &[nv])], |m, [q, v], dq, dv| {
            // The Jacobians do not depend on q, which is checked as `integrate` checks it.
            m.check_configuration(q)?;
            algorithms::integrate_jacobians(m, v, dt, dq, dv)
        })
    }
}

model_function! {
    /// (∂(q1 ⊖ q0)/∂q0, ∂(q1 ⊖ q0)/∂q1), each `(..., nv, nv)`, on the tangent spaces: Pinocchio's `dDifference`, ARG0
    /// and ARG1. Block diagonal.
    fn difference_jacobians(py, model, q0: ArrayArg, q1: ArrayArg) -> Arrays2<'py> {
        let nq = model.model.nq();
        let arguments = [("q0", &q0, &[nq][..]), ("q1", &q1, &[nq])];
        run_matrix_pair(py, &model, arguments, |m, [q0, q1], d0, d1| algorithms::difference_jacobians(m, q0, q1, d0, d1))
    }
}

/// Broadcasts the two `arguments` and runs `kernel(model, rows, a, b)`, which writes two nv x nv matrices, over the
/// batch: `(..., nv, nv)` each.
fn run_matrix_pair<'py, K>(
    py: Python<'py>, owner: &PyModel, arguments: [Argument<'_, '_>; 2], kernel: K,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)>
where
    K: Fn(&Model, [&[f64]; 2], &mut DMatrix<f64>, &mut DMatrix<f64>) -> Result<(), Error> + Sync,
{
    let (nv, batch) = (owner.model.nv(), broadcast(&arguments)?);
    let [a, b] = run_matrices(py, owner, &batch, nv, |m, w, i, out| {
        let (a, b) = w.matrix_pair(nv)?;
        kernel(m, batch.row(i), a, b)?;
        write_columns(&[a.as_slice(), b.as_slice()], out);
        Ok(())
    })?;
    Ok((a, b))
}
