//! The dynamics algorithms over batches of states: arguments broadcast over leading dimensions, rows are
//! checked, and the batch is spread over all cores with the GIL released.

use legkit_dynamics::algorithms;
use legkit_dynamics::model::check_vector;
use legkit_dynamics::spatial::Force;
use legkit_dynamics::{Data, Error, Model};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

use crate::batch::{broadcast, map_rows, to_numpy, ArrayArg, Batch};
use crate::model::{homogeneous, PyModel};

/// A workspace for one task: the model's cached one when free, handed back when done.
struct Workspace<'m> {
    owner: &'m PyModel,
    data: Option<Data>,
    forces: Vec<Force>,
}

impl<'m> Workspace<'m> {
    fn new(owner: &'m PyModel) -> Self {
        Self { owner, data: Some(owner.take_workspace()), forces: vec![Force::zeros(); owner.model.nbodies()] }
    }

    fn data(&mut self) -> &mut Data {
        self.data.as_mut().expect("present until dropped")
    }

    /// The workspace and the external forces read from a row of `nbodies x 6` numbers (None when the
    /// argument was not given).
    fn with_forces(&mut self, row: Option<&[f64]>) -> Result<(&mut Data, Option<&[Force]>), Error> {
        let data = self.data.as_mut().expect("present until dropped");
        let Some(row) = row else { return Ok((data, None)) };
        check_vector("f_ext", row, 6 * self.forces.len())?;
        for (force, values) in self.forces.iter_mut().zip(row.chunks_exact(6)) {
            force.copy_from_slice(values);
        }
        Ok((data, Some(&self.forces)))
    }
}

impl Drop for Workspace<'_> {
    fn drop(&mut self) {
        if let Some(data) = self.data.take() {
            self.owner.put_back(data);
        }
    }
}

/// Runs `kernel(model, workspace, i, out)` over the batch, GIL released; returns `batch + out_core`.
fn run<'py, K>(py: Python<'py>, owner: &PyModel, batch: &Batch<'_>, out_core: &[usize], kernel: K) -> PyResult<Bound<'py, PyArrayDyn<f64>>>
where
    K: Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    let width = out_core.iter().product();
    let model = &owner.model;
    let out = py.detach(|| map_rows(batch.len, width, || Workspace::new(owner), |w, i, out| kernel(model, w, i, out)))?;
    Ok(to_numpy(py, batch.output_shape(out_core), out))
}

/// Fails on NaN or infinity in a result: a singular model or state rather than silent garbage.
fn finite_result(values: &[f64]) -> Result<(), Error> {
    if values.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(Error::invalid("model", "the result is not finite: the mass matrix is singular at this configuration"))
    }
}

fn check_state(model: &Model, q: &[f64], v: Option<&[f64]>) -> Result<(), Error> {
    model.check_configuration(q)?;
    if let Some(v) = v {
        check_vector("v", v, model.nv())?;
    }
    Ok(())
}

/// The batch of (q, v, x[, f_ext]) with cores (nq,), (nv,), (nv,) and (nbodies, 6).
fn state_batch<'a>(
    m: &Model,
    q: &'a ArrayArg<'_>,
    v: &'a ArrayArg<'_>,
    (name, x): (&'static str, &'a ArrayArg<'_>),
    f_ext: Option<&'a ArrayArg<'_>>,
) -> PyResult<Batch<'a>> {
    let (q_core, v_core, force_core) = ([m.nq()], [m.nv()], [m.nbodies(), 6]);
    let mut arguments = vec![("q", q, &q_core[..]), ("v", v, &v_core[..]), (name, x, &v_core[..])];
    if let Some(f) = f_ext {
        arguments.push(("f_ext", f, &force_core[..]));
    }
    broadcast(&arguments)
}

/// World pose (4x4) of every body: `(..., nbodies, 4, 4)`.
#[pyfunction]
pub fn forward_kinematics<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()])])?;
    run(py, &model, &batch, &[m.nbodies(), 4, 4], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        m.check_configuration(q)?;
        let data = w.data();
        algorithms::forward_kinematics(m, data, q);
        for (pose, chunk) in data.o_m_i.iter().zip(out.chunks_exact_mut(16)) {
            chunk.copy_from_slice(&homogeneous(pose));
        }
        Ok(())
    })
}

/// Inverse dynamics τ = M q̈ + C q̇ + g − Σ Jᵀ f_ext (recursive Newton–Euler). `f_ext`, optional, holds one
/// force `[f, n]` per body, in that body's frame: `(..., nbodies, 6)`.
#[pyfunction]
#[pyo3(signature = (model, q, v, a, f_ext = None))]
pub fn rnea<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    f_ext: Option<ArrayArg<'_>>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("a", &a), f_ext.as_ref())?;
    run(py, &model, &batch, &[nv], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("a", a, m.nv())?;
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)))?;
        out.copy_from_slice(algorithms::rnea(m, data, q, v, a, forces).as_slice());
        Ok(())
    })
}

/// Forward dynamics q̈ = M⁻¹ (τ − C q̇ − g + Σ Jᵀ f_ext) by the O(n) articulated-body algorithm.
#[pyfunction]
#[pyo3(signature = (model, q, v, tau, f_ext = None))]
pub fn aba<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    tau: ArrayArg<'_>,
    f_ext: Option<ArrayArg<'_>>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let nv = model.model.nv();
    let batch = state_batch(&model.model, &q, &v, ("tau", &tau), f_ext.as_ref())?;
    run(py, &model, &batch, &[nv], |m, w, i, out| {
        let (q, v, tau) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        check_state(m, q, Some(v))?;
        check_vector("tau", tau, m.nv())?;
        let (data, forces) = w.with_forces(batch.rows.get(3).map(|r| r.row(i)))?;
        out.copy_from_slice(algorithms::aba(m, data, q, v, tau, forces).as_slice());
        finite_result(out)
    })
}

/// The joint-space mass matrix M(q) (composite-rigid-body algorithm): `(..., nv, nv)`.
#[pyfunction]
pub fn crba<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()])])?;
    run(py, &model, &batch, &[m.nv(), m.nv()], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        m.check_configuration(q)?;
        // M is symmetric, so its column-major storage is also its row-major layout.
        out.copy_from_slice(algorithms::crba(m, w.data(), q).as_slice());
        Ok(())
    })
}

/// M(q)⁻¹ by the O(n) articulated-body recursion, without forming or factorising M: `(..., nv, nv)`.
#[pyfunction]
pub fn minv<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()])])?;
    run(py, &model, &batch, &[m.nv(), m.nv()], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        m.check_configuration(q)?;
        out.copy_from_slice(algorithms::minv(m, w.data(), q).as_slice());
        finite_result(out)
    })
}
