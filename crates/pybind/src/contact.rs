//! Contact-constrained dynamics, the reduced ODE and impacts.

use legkit_dynamics::algorithms::{self, ContactPoint};
use legkit_dynamics::model::{check_vector, Dense};
use legkit_dynamics::{Data, Error, Model};
use nalgebra::{DMatrix, DVector};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::batch::{broadcast, ArrayArg, Batch};
use crate::convert::{kernel_error, numbers, to_numpy, vector3, FloatArray, Vector};
use crate::model::PyModel;
use crate::workspace::{check_state, finite_result, run, run_packed, unpack};

/// Contact points from a sequence of (body, point) pairs: body index or name, point in the body's frame.
fn contacts(model: &PyModel, value: &Bound<'_, PyAny>) -> PyResult<Vec<ContactPoint>> {
    let mut out = Vec::new();
    for item in value.try_iter()? {
        let (body, point): (Bound<'_, PyAny>, Vector<'_>) =
            item?.extract().map_err(|_| pyo3::exceptions::PyTypeError::new_err("contacts: expected a sequence of (body, point) pairs"))?;
        out.push(ContactPoint { body: model.body_index(&body)?, point: vector3("contacts", &point)? });
    }
    algorithms::contact::check_contacts(&model.model, &out).map_err(kernel_error)?;
    Ok(out)
}

/// Runs `kernel(model, data, i)`, which returns (nv numbers, 3 per contact), over the batch: the arrays
/// `(..., nv)` and `(..., k, 3)`; a result that is not finite is a ValueError.
fn per_state<'py, K>(py: Python<'py>, model: &PyModel, batch: &Batch, k: usize, kernel: K) -> PyResult<(FloatArray<'py>, FloatArray<'py>)>
where
    K: Fn(&Model, &mut Data, usize) -> Result<(DVector<f64>, DVector<f64>), Error> + Sync,
{
    let nv = model.model.nv();
    let packed = run_packed(py, model, batch, nv + 3 * k, |m, w, i, out| {
        let (generalized, per_contact) = kernel(m, w.dense(&[Dense::Inverse])?, i)?;
        out[..nv].copy_from_slice(generalized.as_slice());
        out[nv..].copy_from_slice(per_contact.as_slice());
        finite_result(out)
    })?;
    let mut parts = unpack(py, batch, &packed, &[&[nv], &[k, 3]])?.into_iter();
    Ok((parts.next().unwrap(), parts.next().unwrap()))
}

/// Forward dynamics with the contact points held still (Hardt & von Stryk eq. 1–3):
/// returns (ddq (..., nv), forces (..., k, 3)), the forces on the robot at the contacts in world axes.
#[pyfunction]
pub fn contact_dynamics<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    tau: ArrayArg<'_>,
    contacts: &Bound<'_, PyAny>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let contacts = self::contacts(&model, contacts)?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("tau", &tau, &[nv])])?;
    per_state(py, &model, &batch, contacts.len(), |m, data, i| {
        let (q, v, tau) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("tau", tau, nv)?;
        let solution = algorithms::contact_dynamics(m, data, q, v, tau, &contacts)?;
        Ok((solution.ddq, solution.forces))
    })
}

/// Perfectly inelastic impact at the contacts: returns (v_plus (..., nv), impulses (..., k, 3)).
#[pyfunction]
pub fn impact<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    contacts: &Bound<'_, PyAny>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let contacts = self::contacts(&model, contacts)?;
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[model.model.nv()])])?;
    per_state(py, &model, &batch, contacts.len(), |m, data, i| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        check_state(m, q, Some(v))?;
        algorithms::impact(m, data, q, v, &contacts)
    })
}

/// World-axes (classical) acceleration of each contact point (body, point in the body's frame) at (q, v, a):
/// J q̈ + J̇ q̇ per point, `(..., k, 3)`; zero for the points `contact_dynamics` holds, at its q̈.
#[pyfunction]
pub fn point_accelerations<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    contacts: &Bound<'_, PyAny>,
) -> PyResult<FloatArray<'py>> {
    let points = self::contacts(&model, contacts)?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("a", &a, &[nv])])?;
    run(py, &model, &batch, &[points.len(), 3], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("a", a, nv)?;
        algorithms::point_accelerations(m, w.data(), q, v, Some(a), &points, out);
        Ok(())
    })
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

/// The reduced ODE on independent velocity coordinates for one state (Hardt & von Stryk eq. 7):
/// (ddq, independent, dependent, basis N (nv, nI), mass N^T M N, force, offset) with v = N v_I and
/// q̈ = N v̇_I + offset. `independent` picks the coordinates; by default they are chosen by pivoting.
#[pyfunction]
#[pyo3(signature = (model, q, v, tau, contacts, independent = None))]
pub fn reduced_dynamics<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: Vector<'_>,
    v: Vector<'_>,
    tau: Vector<'_>,
    contacts: &Bound<'_, PyAny>,
    independent: Option<Vec<usize>>,
) -> PyResult<Reduced<'py>> {
    let contacts = self::contacts(&model, contacts)?;
    let m = &model.model;
    let (q, v, tau) = (&numbers("q", &q)?[..], &numbers("v", &v)?[..], &numbers("tau", &tau)?[..]);
    check_state(m, q, Some(v)).map_err(kernel_error)?;
    check_vector("tau", tau, m.nv()).map_err(kernel_error)?;
    let mut data = model.take_workspace();
    let result = data
        .reserve_dense(m, &[Dense::MassMatrix])
        .and_then(|()| algorithms::reduced_dynamics(m, &mut data, q, v, tau, &contacts, independent.as_deref()));
    model.put_back(data);
    let r = result.map_err(kernel_error)?;
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

/// `matrices` one after the other, each row by row (as NumPy reads them), into `out`.
fn write_rows(matrices: &[&DMatrix<f64>], out: &mut [f64]) {
    let mut rest = out;
    for matrix in matrices {
        let (rows, columns) = matrix.shape();
        let (chunk, tail) = rest.split_at_mut(rows * columns);
        for (c, column) in matrix.as_slice().chunks_exact(rows.max(1)).enumerate() {
            for (r, x) in column.iter().enumerate() {
                chunk[r * columns + c] = *x;
            }
        }
        rest = tail;
    }
}

/// The derivatives of `contact_dynamics` with respect to q (its tangent space), v and tau: (ddq_dq, ddq_dv, ddq_dtau)
/// each `(..., nv, nv)` and (forces_dq, forces_dv, forces_dtau) each `(..., k, 3, nv)`, the forces in world axes
/// (Pinocchio's `computeConstraintDynamicsDerivatives` for 3-D contacts in `LOCAL_WORLD_ALIGNED`). The contacts must be
/// independent (a ValueError otherwise: their forces, and so the derivatives, would not be unique).
#[pyfunction]
pub fn contact_dynamics_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    tau: ArrayArg<'_>,
    contacts: &Bound<'_, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let contacts = self::contacts(&model, contacts)?;
    let (nv, k) = (model.model.nv(), contacts.len());
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("tau", &tau, &[nv])])?;
    let packed = run_packed(py, &model, &batch, 3 * nv * (nv + 3 * k), |m, w, i, out| {
        let (q, v, tau) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("tau", tau, nv)?;
        let d = algorithms::contact_dynamics_derivatives(m, w.dense(&[Dense::Inverse, Dense::RneaDerivatives])?, q, v, tau, &contacts)?;
        write_rows(&[&d.ddq_dq, &d.ddq_dv, &d.ddq_dtau, &d.forces_dq, &d.forces_dv, &d.forces_dtau], out);
        finite_result(out)
    })?;
    let (square, per_contact): (&[usize], &[usize]) = (&[nv, nv], &[k, 3, nv]);
    PyTuple::new(py, unpack(py, &batch, &packed, &[square, square, square, per_contact, per_contact, per_contact])?)
}

/// The derivatives of `impact` with respect to q (its tangent space) and the velocity before it: (v_plus_dq,
/// v_plus_dv) each `(..., nv, nv)` and (impulses_dq, impulses_dv) each `(..., k, 3, nv)` (Pinocchio's
/// `computeImpulseDynamicsDerivatives` with no restitution). The contacts must be independent.
#[pyfunction]
pub fn impact_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    contacts: &Bound<'_, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let contacts = self::contacts(&model, contacts)?;
    let (nv, k) = (model.model.nv(), contacts.len());
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv])])?;
    let packed = run_packed(py, &model, &batch, 2 * nv * (nv + 3 * k), |m, w, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        check_state(m, q, Some(v))?;
        let d = algorithms::impact_derivatives(m, w.dense(&[Dense::Inverse, Dense::RneaDerivatives])?, q, v, &contacts)?;
        write_rows(&[&d.velocity_dq, &d.velocity_dv, &d.impulses_dq, &d.impulses_dv], out);
        finite_result(out)
    })?;
    let (square, per_contact): (&[usize], &[usize]) = (&[nv, nv], &[k, 3, nv]);
    PyTuple::new(py, unpack(py, &batch, &packed, &[square, square, per_contact, per_contact])?)
}
