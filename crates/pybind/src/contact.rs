//! Contact-constrained dynamics, the reduced ODE and impacts.

use legkit_dynamics::algorithms::{self, ContactDim, ContactPoint};
use legkit_dynamics::model::Dense;
use legkit_dynamics::{Data, Error, Model};
use nalgebra::DVector;
use numpy::ndarray::{ArrayViewD, IxDyn, ShapeBuilder};
use numpy::{PyArray1, PyArray2, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::batch::{Argument, ArrayArg};
use crate::convert::{kernel_error, numbers, to_numpy, vector3, Arrays2, FloatArray, Integer, Vector};
use crate::model::PyModel;
use crate::workspace::{batched, batched_parts};
use legkit_dynamics::algorithms::finite_result;

/// The `dim` argument: 3 holds each contact's point still, 6 its body's frame at the point.
fn contact_dim(dim: Integer) -> PyResult<ContactDim> {
    let dim = dim.value("dim")?;
    match dim {
        3 => Ok(ContactDim::Point),
        6 => Ok(ContactDim::Frame),
        _ => Err(pyo3::exceptions::PyValueError::new_err(format!("dim: expected 3 (points held still) or 6 (frames held still), got {dim}"))),
    }
}

/// The contact points and their `dim` (see `contact_dim`).
fn contact_arguments(model: &PyModel, contacts: &Bound<'_, PyAny>, dim: Integer) -> PyResult<(Vec<ContactPoint>, ContactDim)> {
    Ok((self::contacts(model, contacts)?, contact_dim(dim)?))
}

/// Contact points from a sequence of (body, point) pairs: body index or name, point in the body's frame.
fn contacts(model: &PyModel, value: &Bound<'_, PyAny>) -> PyResult<Vec<ContactPoint>> {
    let expected = || pyo3::exceptions::PyTypeError::new_err("contacts: expected a sequence of (body, point) pairs");
    let mut out = Vec::new();
    for item in value.try_iter().map_err(|_| expected())? {
        let (body, point): (Bound<'_, PyAny>, Vector<'_>) = item?.extract().map_err(|_| expected())?;
        out.push(ContactPoint { body: model.body_index("body", &body)?, point: vector3("contacts", &point)? });
    }
    algorithms::check_contacts(&model.model, &out).map_err(kernel_error)?;
    Ok(out)
}

/// Broadcasts `arguments` and runs `kernel(model, data, rows)`, which returns (nv numbers, d per contact), over the
/// batch: the arrays `(..., nv)` and `(..., k, d)`.
fn per_state<'py, const N: usize, K>(
    py: Python<'py>, model: &PyModel, arguments: [Argument<'_, '_>; N], (k, d): (usize, usize), kernel: K,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)>
where
    K: Fn(&Model, &mut Data, [&[f64]; N]) -> Result<(DVector<f64>, DVector<f64>), Error> + Sync,
{
    let nv = model.model.nv();
    let [generalized, per_contact] = batched_parts(py, model, arguments, [&[nv], &[k, d]], |m, w, rows, out| {
        let (generalized, per_contact) = kernel(m, w.dense(&[Dense::Inverse, Dense::Workspace])?, rows)?;
        out[..nv].copy_from_slice(generalized.as_slice());
        out[nv..].copy_from_slice(per_contact.as_slice());
        Ok(())
    })?;
    Ok((generalized, per_contact))
}

model_function! {
    /// Forward dynamics with the contacts held still (Hardt & von Stryk eq. 1–3): the points (`dim=3`) or the bodies'
    /// frames at them (`dim=6`). Returns (ddq (..., nv), forces (..., k, dim)), the forces (with dim 6, wrenches [force;
    /// torque about the point]) on the robot at the contacts in world axes; dependent contacts get the minimum-norm forces.
    #[pyo3(signature = (model, q, v, tau, contacts, dim = Integer::new(3)), text_signature = "(model, q, v, tau, contacts, dim=3)")]
    fn contact_dynamics(py, model, q: ArrayArg, v: ArrayArg, tau: ArrayArg, contacts: &Bound<PyAny>, dim: Integer) -> Arrays2<'py> {
        let (contacts, dim) = contact_arguments(&model, contacts, dim)?;
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("tau", &tau, &[nv])];
        per_state(py, &model, arguments, (contacts.len(), dim.rows()), |m, data, [q, v, tau]| {
            let solution = algorithms::contact_dynamics(m, data, q, v, tau, &contacts, dim)?;
            Ok((solution.ddq, solution.forces))
        })
    }
}

model_function! {
    /// Perfectly inelastic impact at the contacts (`dim` as `contact_dynamics`): returns (v_plus (..., nv), impulses
    /// (..., k, dim)).
    #[pyo3(signature = (model, q, v, contacts, dim = Integer::new(3)), text_signature = "(model, q, v, contacts, dim=3)")]
    fn impact(py, model, q: ArrayArg, v: ArrayArg, contacts: &Bound<PyAny>, dim: Integer) -> Arrays2<'py> {
        let (contacts, dim) = contact_arguments(&model, contacts, dim)?;
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[model.model.nv()])];
        per_state(py, &model, arguments, (contacts.len(), dim.rows()), |m, data, [q, v]| algorithms::impact(m, data, q, v, &contacts, dim))
    }
}

model_function! {
    /// World-axes (classical) acceleration of each contact point (body, point in the body's frame) at (q, v, a):
    /// J q̈ + J̇ q̇ per point, `(..., k, 3)`; with `dim=6`, the frame's spatial acceleration [linear; angular] at the point,
    /// world axes, `(..., k, 6)`. Zero for the contacts `contact_dynamics` holds, at its q̈.
    #[pyo3(signature = (model, q, v, a, contacts, dim = Integer::new(3)), text_signature = "(model, q, v, a, contacts, dim=3)")]
    fn point_accelerations(py, model, q: ArrayArg, v: ArrayArg, a: ArrayArg, contacts: &Bound<PyAny>, dim: Integer) -> FloatArray<'py> {
        let (points, dim) = contact_arguments(&model, contacts, dim)?;
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("a", &a, &[nv])];
        batched(py, &model, arguments, &[points.len(), dim.rows()], |m, w, [q, v, a], out| {
            algorithms::point_accelerations(m, w.data(), q, v, Some(a), &points, dim, out)
        })
    }
}

type Reduced<'py> = (
    Bound<'py, PyArray1<f64>>,
    Vec<usize>,
    Vec<usize>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

model_function! {
    /// The reduced ODE on independent velocity coordinates for one state (Hardt & von Stryk eq. 7):
    /// (ddq, independent, dependent, basis N (nv, nI), mass N^T M N, force, offset) with v = N v_I and
    /// q̈ = N v̇_I + offset. `independent` picks the coordinates; by default they are chosen by pivoting.
    #[pyo3(signature = (model, q, v, tau, contacts, independent = None))]
    fn reduced_dynamics(py, model,
        q: Vector<'_>, v: Vector<'_>, tau: Vector<'_>, contacts: &Bound<PyAny>, independent: Option<Vec<usize>>) -> Reduced<'py> {
        let contacts = self::contacts(&model, contacts)?;
        let m = &model.model;
        let (q, v, tau) = (&numbers("q", &q)?[..], &numbers("v", &v)?[..], &numbers("tau", &tau)?[..]);
        let mut data = model.take_workspace();
        let result = data
            .reserve_dense(m, &[Dense::MassMatrix])
            .and_then(|()| algorithms::reduced_dynamics(m, &mut data, q, v, tau, &contacts, independent.as_deref()));
        model.put_back(data);
        let r = result.map_err(kernel_error)?;
        for part in [r.ddq.as_slice(), r.basis.as_slice(), r.mass.as_slice(), r.force.as_slice(), r.offset.as_slice()] {
            finite_result(part).map_err(kernel_error)?;
        }
        let matrix = |x: &nalgebra::DMatrix<f64>| to_numpy(py, (x.nrows(), x.ncols()), x.transpose().as_slice().to_vec());
        Ok((
            to_numpy(py, r.ddq.len(), r.ddq.as_slice().to_vec()),
            r.independent.clone(),
            r.dependent.clone(),
            matrix(&r.basis),
            matrix(&r.mass),
            to_numpy(py, r.force.len(), r.force.as_slice().to_vec()),
            to_numpy(py, r.offset.len(), r.offset.as_slice().to_vec()),
        ))
    }
}

/// Views of `out` (the batch's rows of numbers, `(..., width)`) as arrays `(..., core)`: each `(offset, core, strides)`
/// reads a row's numbers from `offset` with `strides` (in numbers) over `core`, so that the kernels' column-major
/// matrices reach NumPy without a copy or a transpose.
fn views<'py>(out: &FloatArray<'py>, parts: &[(usize, &[usize], &[usize])]) -> Vec<FloatArray<'py>> {
    let batch_shape = &out.shape()[..out.ndim() - 1];
    let batch_strides: Vec<usize> = out.strides()[..out.ndim() - 1].iter().map(|s| *s as usize / std::mem::size_of::<f64>()).collect();
    let pointer = out.data();
    parts
        .iter()
        .map(|(offset, core, strides)| {
            let shape: Vec<usize> = batch_shape.iter().chain(core.iter()).copied().collect();
            let strides: Vec<usize> = batch_strides.iter().chain(strides.iter()).copied().collect();
            // SAFETY: every index of the view falls inside `out`'s buffer (a row's parts lie within its width), which
            // was filled by the kernel and which the view keeps alive as its base.
            unsafe {
                let view = ArrayViewD::from_shape_ptr(IxDyn(&shape).strides(IxDyn(&strides)), pointer.add(*offset));
                PyArrayDyn::borrow_from_array(&view, out.clone().into_any())
            }
        })
        .collect()
}

/// The views of `count` square (nv x nv) column-major matrices, then `count` (k·d x nv) ones as `(..., k, d, nv)`.
fn matrix_views<'py>(out: &FloatArray<'py>, count: usize, nv: usize, (k, d): (usize, usize)) -> Vec<FloatArray<'py>> {
    let (square, per_row) = (nv * nv, k * d * nv);
    let (square_core, row_core) = ([nv, nv], [k, d, nv]);
    let (square_strides, row_strides) = ([1, nv], [d, 1, k * d]);
    let parts: Vec<(usize, &[usize], &[usize])> = (0..count)
        .map(|i| (i * square, &square_core[..], &square_strides[..]))
        .chain((0..count).map(|i| (count * square + i * per_row, &row_core[..], &row_strides[..])))
        .collect();
    views(out, &parts)
}

model_function! {
    /// The derivatives of `contact_dynamics` with respect to q (its tangent space), v and tau: (ddq_dq, ddq_dv, ddq_dtau)
    /// each `(..., nv, nv)` and (forces_dq, forces_dv, forces_dtau) each `(..., k, dim, nv)`, the forces in world axes
    /// (Pinocchio's `computeConstraintDynamicsDerivatives` for CONTACT_3D or, with `dim=6`, CONTACT_6D contacts in
    /// `LOCAL_WORLD_ALIGNED`). The contacts must be independent (a ValueError otherwise: their forces, and so the
    /// derivatives, would not be unique).
    #[pyo3(signature = (model, q, v, tau, contacts, dim = Integer::new(3)), text_signature = "(model, q, v, tau, contacts, dim=3)")]
    fn contact_dynamics_derivatives(py, model,
        q: ArrayArg, v: ArrayArg, tau: ArrayArg, contacts: &Bound<PyAny>, dim: Integer) -> Bound<'py, PyTuple> {
        let (contacts, dim) = contact_arguments(&model, contacts, dim)?;
        let (nv, k, d) = (model.model.nv(), contacts.len(), dim.rows());
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("tau", &tau, &[nv])];
        let out = batched(py, &model, arguments, &[3 * nv * (nv + k * d)], |m, w, [q, v, tau], out| {
            // Straight into the array, column-major.
            let (ddq_d, forces_d) = out.split_at_mut(3 * nv * nv);
            let dense = w.dense(&[Dense::Inverse, Dense::Workspace])?;
            algorithms::contact_dynamics_derivatives_into(m, dense, q, v, tau, &contacts, dim, ddq_d, forces_d)?;
            Ok(())
        })?;
        PyTuple::new(py, matrix_views(&out, 3, nv, (k, d)))
    }
}

model_function! {
    /// The derivatives of `impact` with respect to q (its tangent space) and the velocity before it: (v_plus_dq,
    /// v_plus_dv) each `(..., nv, nv)` and (impulses_dq, impulses_dv) each `(..., k, dim, nv)` (Pinocchio's
    /// `computeImpulseDynamicsDerivatives` with no restitution). The contacts must be independent.
    #[pyo3(signature = (model, q, v, contacts, dim = Integer::new(3)), text_signature = "(model, q, v, contacts, dim=3)")]
    fn impact_derivatives(py, model, q: ArrayArg, v: ArrayArg, contacts: &Bound<PyAny>, dim: Integer) -> Bound<'py, PyTuple> {
        let (contacts, dim) = contact_arguments(&model, contacts, dim)?;
        let (nv, k, d) = (model.model.nv(), contacts.len(), dim.rows());
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv])];
        let out = batched(py, &model, arguments, &[2 * nv * (nv + k * d)], |m, w, [q, v], out| {
            let (velocity_d, impulses_d) = out.split_at_mut(2 * nv * nv);
            algorithms::impact_derivatives_into(m, w.dense(&[Dense::Inverse, Dense::Workspace])?, q, v, &contacts, dim, velocity_d, impulses_d)?;
            Ok(())
        })?;
        PyTuple::new(py, matrix_views(&out, 2, nv, (k, d)))
    }
}
