//! Running a kernel over a batch of states with per-task workspaces, the GIL released.

use legkit_dynamics::model::Dense;
use legkit_dynamics::spatial::Force;
use legkit_dynamics::validate::{array_len, filled, with_capacity, zeros};
use legkit_dynamics::{Data, Error, Model};
use nalgebra::DMatrix;
use numpy::PyArrayMethods;
use pyo3::prelude::*;

use crate::convert::{kernel_error, FloatArray};

use crate::batch::{array, broadcast, map_rows, to_numpy, Argument, Batch};
use crate::interrupt::{in_pieces, Pace};
use crate::model::PyModel;

/// Models with fewer bodies than this run a single state without releasing the GIL.
const SMALL_MODEL: usize = 16;

/// A workspace for one task: the model's cached one when free, handed back when done.
pub struct Workspace<'m> {
    owner: &'m PyModel,
    /// Boxed, so that taking and handing back a workspace moves a pointer.
    data: Option<Box<Data>>,
    forces: Vec<Force>,
    /// Two square matrices for kernels that write a pair of them (`matrix_pair`).
    matrices: (DMatrix<f64>, DMatrix<f64>),
}

impl<'m> Workspace<'m> {
    pub fn new(owner: &'m PyModel) -> Self {
        Self { owner, data: Some(owner.take_workspace()), forces: Vec::new(), matrices: (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0)) }
    }

    pub fn data(&mut self) -> &mut Data {
        self.data.as_mut().expect("present until dropped")
    }

    /// The workspace with its dense `parts` sized fallibly (see `Data::reserve_dense`): for the kernels that
    /// need nv x nv matrices, so that a model too large for them is a MemoryError, not an abort.
    pub fn dense(&mut self, parts: &[Dense]) -> Result<&mut Data, Error> {
        let data = self.data.as_mut().expect("present until dropped");
        data.reserve_dense(&self.owner.model, parts)?;
        Ok(data)
    }

    /// The workspace and the external forces read from a row of `nbodies x 6` numbers (None when the
    /// argument was not given; the kernels check them).
    pub fn with_forces(&mut self, row: Option<&[f64]>) -> (&mut Data, Option<&[Force]>) {
        let data = self.data.as_mut().expect("present until dropped");
        let Some(row) = row else { return (data, None) };
        self.forces.resize(row.len() / 6, Force::zeros());
        for (force, values) in self.forces.iter_mut().zip(row.chunks_exact(6)) {
            force.copy_from_slice(values);
        }
        (data, Some(&self.forces))
    }

    /// Two n x n matrices, allocated (fallibly) by the task's first row and reused by the others.
    pub fn matrix_pair(&mut self, n: usize) -> Result<(&mut DMatrix<f64>, &mut DMatrix<f64>), Error> {
        if self.matrices.0.nrows() != n {
            let len = array_len("model", &[n, n], std::mem::size_of::<f64>())?;
            self.matrices = (DMatrix::from_vec(n, n, filled("model", len, 0.0)?), DMatrix::from_vec(n, n, filled("model", len, 0.0)?));
        }
        Ok((&mut self.matrices.0, &mut self.matrices.1))
    }
}

impl Drop for Workspace<'_> {
    fn drop(&mut self) {
        if let Some(data) = self.data.take() {
            self.owner.put_back(data);
        }
    }
}

/// Runs `kernel(model, workspace, i, out)` over the batch, GIL released; returns `batch + out_core`,
/// written in place into a new NumPy array. The array starts uninitialised: a kernel writes all of `out`
/// or fails (and the array is dropped).
pub fn run<'py, K>(py: Python<'py>, owner: &PyModel, batch: &Batch, out_core: &[usize], kernel: K) -> PyResult<FloatArray<'py>>
where
    K: Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    // Every kernel writes its whole row before the array can be read (see above).
    let array = batch.output(py, out_core)?;
    // SAFETY: the array was just created here and nothing else refers to it yet.
    let out = unsafe { array.as_slice_mut() }.expect("a new array is contiguous");
    fill(py, owner, batch, out, out_core.iter().product(), kernel)?;
    Ok(array)
}

/// Broadcasts `arguments` and `run`s `kernel(model, workspace, rows, out)` over the batch, `rows` the arguments'
/// rows in order: the array `batch + out_core`.
pub fn batched<'py, const N: usize, K>(
    py: Python<'py>, owner: &PyModel, arguments: [Argument<'_, '_>; N], out_core: &[usize], kernel: K,
) -> PyResult<FloatArray<'py>>
where
    K: Fn(&Model, &mut Workspace<'_>, [&[f64]; N], &mut [f64]) -> Result<(), Error> + Sync,
{
    let batch = broadcast(&arguments)?;
    run(py, owner, &batch, out_core, |m, w, i, out| kernel(m, w, batch.row(i), out))
}

/// `batched` for a kernel with `P` outputs, which writes each row's one after the other into `out` (`split` cuts it):
/// an array `batch + core` for each of `cores`.
pub fn batched_parts<'py, const N: usize, const P: usize, K>(
    py: Python<'py>, owner: &PyModel, arguments: [Argument<'_, '_>; N], cores: [&[usize]; P], kernel: K,
) -> PyResult<[FloatArray<'py>; P]>
where
    K: Fn(&Model, &mut Workspace<'_>, [&[f64]; N], &mut [f64]) -> Result<(), Error> + Sync,
{
    let batch = broadcast(&arguments)?;
    let width = cores.iter().map(|core| core.iter().product::<usize>()).sum();
    let packed = run_packed(py, owner, &batch, width, |m, w, i, out| kernel(m, w, batch.row(i), out))?;
    Ok(array(unpack(py, &batch, &packed, &cores)?))
}

/// `run` with `width` numbers per row, left packed (see `unpack`).
pub fn run_packed<K>(py: Python<'_>, owner: &PyModel, batch: &Batch, width: usize, kernel: K) -> PyResult<Vec<f64>>
where
    K: Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    let len = array_len(batch.largest, &[batch.len, width], std::mem::size_of::<f64>()).map_err(kernel_error)?;
    let mut out = zeros(batch.largest, len).map_err(kernel_error)?;
    fill(py, owner, batch, &mut out, width, kernel)?;
    Ok(out)
}

fn fill<K>(py: Python<'_>, owner: &PyModel, batch: &Batch, out: &mut [f64], width: usize, kernel: K) -> PyResult<()>
where
    K: Fn(&Model, &mut Workspace<'_>, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    let (model, kernel, total) = (&owner.model, &kernel, batch.len);
    let rows = |first: usize, out: &mut [f64]| map_rows(out, width, first, total, || Workspace::new(owner), |w, i, row| kernel(model, w, i, row));
    // Releasing and retaking the GIL costs about as much as one small model's kernel: keep it for those.
    if total == 1 {
        return if model.nbodies() < SMALL_MODEL { rows(0, out) } else { py.detach(|| rows(0, out)) };
    }
    // Batches in pieces of rows, so that Ctrl-C is answered between them.
    let mut done = 0;
    in_pieces(py, total as u64, &Pace::default(), |k| {
        let next = done + k as usize;
        rows(done, &mut out[done * width..next * width])?;
        done = next;
        Ok(())
    })
}

/// Splits rows packed as `[part 0 | part 1 | ...]` into one array per part, shaped `batch + core`; a copy of
/// `packed` allocated fallibly (MemoryError naming the batch where it cannot be held twice).
pub fn unpack<'py>(py: Python<'py>, batch: &Batch, packed: &[f64], cores: &[&[usize]]) -> PyResult<Vec<FloatArray<'py>>> {
    let widths: Vec<usize> = cores.iter().map(|c| c.iter().product()).collect();
    let width: usize = widths.iter().sum();
    let mut start = 0;
    cores
        .iter()
        .zip(&widths)
        .map(|(core, &w)| {
            let mut part = with_capacity("batch", batch.len.saturating_mul(w)).map_err(kernel_error)?;
            for row in packed.chunks_exact(width.max(1)) {
                part.extend_from_slice(&row[start..start + w]);
            }
            start += w;
            Ok(to_numpy(py, batch.output_shape(core), part))
        })
        .collect()
}
