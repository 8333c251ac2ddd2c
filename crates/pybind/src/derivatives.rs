//! The derivatives of the dynamics over batches of states, as `dynamics.rs` runs the dynamics.

use legkit_dynamics::algorithms;
use legkit_dynamics::{Error, Model};
use numpy::ndarray::Axis;
use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::prelude::*;

use crate::batch::{split, ArrayArg, Batch};
use crate::convert::{Arrays2, Arrays3, Arrays4, FloatArray};
use crate::dynamics::{on_state, state_batch};
use crate::kinematics::row_major;
use crate::model::PyModel;
use crate::workspace::{batched, run, Workspace};

/// Copies `matrices` (column-major, as nalgebra stores them) one after the other into `out`.
pub(crate) fn write_columns(matrices: &[&[f64]], out: &mut [f64]) {
    let mut rest = out;
    for matrix in matrices {
        let (chunk, tail) = rest.split_at_mut(matrix.len());
        chunk.copy_from_slice(matrix);
        rest = tail;
    }
}

/// Runs `kernel(model, workspace, i, out)` over the batch, which writes `COUNT` matrices of `rows` x nv column-major
/// one after the other into `out` (`write_columns`); returns one array per matrix, `(..., rows, nv)`: column-major
/// views of one buffer (as Pinocchio's, which are Eigen's), so that nothing is transposed. (Transposing chain512's two
/// 512 x 512 matrices into row-major arrays took as long as computing them.)
pub(crate) fn run_matrices<'py, const COUNT: usize, K>(
    py: Python<'py>, owner: &PyModel, batch: &Batch, rows: usize, kernel: K,
) -> PyResult<[FloatArray<'py>; COUNT]>
where
    K: Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    let out = run(py, owner, batch, &[COUNT, owner.model.nv(), rows], kernel)?;
    // SAFETY: the array was just filled and nothing else refers to it; the views keep it alive as their base.
    let buffer = unsafe { out.as_array() };
    let axis = Axis(buffer.ndim() - 3);
    Ok(std::array::from_fn(|k| {
        let mut view = buffer.index_axis(axis, k);
        let n = view.ndim();
        view.swap_axes(n - 2, n - 1);
        unsafe { PyArrayDyn::borrow_from_array(&view, out.clone().into_any()) }
    }))
}

model_function! {
    /// ∂τ/∂q and ∂τ/∂v of inverse dynamics (`rnea`), each `(..., nv, nv)`, q on its tangent space (Carpentier &
    /// Mansard, RSS 2018; Pinocchio's `computeRNEADerivatives`). ∂τ/∂a is `crba`.
    #[pyo3(signature = (model, q, v, a, f_ext = None))]
    fn rnea_derivatives(py, model, q: ArrayArg, v: ArrayArg, a: ArrayArg, f_ext: Option<ArrayArg>) -> Arrays2<'py> {
        let nv = model.model.nv();
        let batch = state_batch(&model.model, &q, &v, ("a", &a), f_ext.as_ref())?;
        let [dq, dv] = run_matrices(
            py,
            &model,
            &batch,
            nv,
            on_state(&batch, |m, data, [q, v, a], forces, out| {
                // Straight into the arrays: no nv x nv workspace, no copy.
                let [dq, dv] = split(out, [nv * nv; 2]);
                algorithms::rnea_derivatives_into(m, data, q, v, a, forces, dq, dv)
            }),
        )?;
        Ok((dq, dv))
    }
}

model_function! {
    /// The second derivatives of inverse dynamics (`rnea`), each `(..., nv, nv, nv)` with entry [i, j, k] the slope
    /// along the third index of a first derivative: ∂/∂q_k of ∂τ_i/∂q_j, ∂/∂v_k of ∂τ_i/∂v_j, ∂/∂v_k of ∂τ_i/∂q_j and
    /// ∂/∂q_k of ∂τ_i/∂a_j = M_ij; q on its tangent space (Pinocchio's `ComputeRNEASecondOrderDerivatives`).
    fn rnea_second_order_derivatives(py, model, q: ArrayArg, v: ArrayArg, a: ArrayArg) -> Arrays4<'py> {
        let nv = model.model.nv();
        let batch = state_batch(&model.model, &q, &v, ("a", &a), None)?;
        let out = run(
            py,
            &model,
            &batch,
            &[4, nv, nv, nv],
            on_state(&batch, |m, data, [q, v, a], _, out| {
                let second = algorithms::rnea_second_order_derivatives(m, data, q, v, a)?;
                write_columns(&[&second.dqdq, &second.dvdv, &second.dqdv, &second.dadq], out);
                Ok(())
            }),
        )?;
        // SAFETY: the array was just filled and nothing else refers to it; the views keep it alive as their base.
        let buffer = unsafe { out.as_array() };
        let axis = Axis(buffer.ndim() - 4);
        let part = |k: usize| unsafe { PyArrayDyn::borrow_from_array(&buffer.index_axis(axis, k), out.clone().into_any()) };
        Ok((part(0), part(1), part(2), part(3)))
    }
}

model_function! {
    /// ∂a/∂q, ∂a/∂v and ∂a/∂τ = M⁻¹ of forward dynamics (`aba`), each `(..., nv, nv)`, q on its tangent space
    /// (Pinocchio's `computeABADerivatives`).
    #[pyo3(signature = (model, q, v, tau, f_ext = None))]
    fn aba_derivatives(py, model, q: ArrayArg, v: ArrayArg, tau: ArrayArg, f_ext: Option<ArrayArg>) -> Arrays3<'py> {
        let nv = model.model.nv();
        let batch = state_batch(&model.model, &q, &v, ("tau", &tau), f_ext.as_ref())?;
        let [dq, dv, minv] = run_matrices(
            py,
            &model,
            &batch,
            nv,
            on_state(&batch, |m, data, [q, v, tau], forces, out| {
                // Straight into the arrays: no nv x nv workspace for them, no copy.
                let [dq, dv, minv] = split(out, [nv * nv; 3]);
                algorithms::aba_derivatives_into(m, data, q, v, tau, forces, dq, dv, minv)
            }),
        )?;
        Ok((dq, dv, minv))
    }
}

model_function! {
    /// ∂h/∂q, ∂ḣ/∂q, ∂ḣ/∂v and ∂ḣ/∂a = ∂h/∂v = A_G of the centroidal momentum h (`centroidal_momentum`) and its rate ḣ
    /// (`centroidal_momentum_rate`, gravity excluded), each `(..., 6, nv)`, q on its tangent space (Pinocchio's
    /// `computeCentroidalDynamicsDerivatives`).
    fn centroidal_derivatives(py, model, q: ArrayArg, v: ArrayArg, a: ArrayArg) -> Arrays4<'py> {
        let batch = state_batch(&model.model, &q, &v, ("a", &a), None)?;
        let [dh_dq, dhdot_dq, dhdot_dv, dhdot_da] = run_matrices(
            py,
            &model,
            &batch,
            6,
            on_state(&batch, |m, data, [q, v, a], _, out| {
                let (dh_dq, dhdot_dq, dhdot_dv, dhdot_da) = algorithms::centroidal_derivatives(m, data, q, v, a)?;
                write_columns(&[dh_dq.as_slice(), dhdot_dq.as_slice(), dhdot_dv.as_slice(), dhdot_da.as_slice()], out);
                Ok(())
            }),
        )?;
        Ok((dh_dq, dhdot_dq, dhdot_dv, dhdot_da))
    }
}

model_function! {
    /// The centre of mass's Jacobian ∂c/∂q, `(..., 3, nv)`, world axes, q on its tangent space (Pinocchio's
    /// `jacobianCenterOfMass`).
    fn center_of_mass_jacobian(py, model, q: ArrayArg) -> FloatArray<'py> {
        let nv = model.model.nv();
        batched(py, &model, [("q", &q, &[model.model.nq()])], &[3, nv], |m, w, [q], out| {
            row_major(algorithms::center_of_mass_jacobian(m, w.data(), q)?, out);
            Ok(())
        })
    }
}
