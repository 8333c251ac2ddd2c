//! Broadcasting of leading batch dimensions, and batch loops spread over all cores.
//!
//! Each argument has a core shape (a scalar, or a vector of known length); whatever dimensions lead it
//! form its batch shape, and the batch shapes broadcast as in NumPy. Every argument is copied once, with the
//! GIL held, before the kernels run without it: another Python thread may write the array meanwhile.

use legkit_dynamics::Error;
use numpy::ndarray::{ArrayViewD, IxDyn};
use numpy::{PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use smallvec::SmallVec;

use crate::convert::{batch_error, FloatArray};

pub type ArrayArg<'py> = crate::convert::Floats<'py>;

/// The core shape of one argument (`&[]` for a scalar); the dimensions before it are its batch shape.
pub type Core<'c> = &'c [usize];

/// One argument's rows, one per batch element: a copy of the argument, taken with the GIL held.
pub struct Rows {
    data: Vec<f64>,
    width: usize,
    shared: bool,
}

impl Rows {
    #[inline]
    pub fn row(&self, i: usize) -> &[f64] {
        let start = if self.shared { 0 } else { i * self.width };
        &self.data[start..start + self.width]
    }
}

/// A shape; inline up to four dimensions, as every call's arguments and outputs are, so that a call
/// allocates nothing for its shapes.
pub type Shape = SmallVec<[usize; 4]>;

/// The broadcast batch: its shape, its length, and every argument's rows.
pub struct Batch {
    pub shape: Shape,
    pub len: usize,
    pub rows: SmallVec<[Rows; 4]>,
}

impl Batch {
    /// The shape of an output with the given core dimensions.
    pub fn output_shape(&self, core: &[usize]) -> Shape {
        self.shape.iter().chain(core).copied().collect()
    }
}

fn describe(core: Core) -> String {
    if core.is_empty() {
        return "a scalar or an array of scalars".to_owned();
    }
    let dims: Vec<String> = core.iter().map(|d| d.to_string()).collect();
    format!("(..., {})", dims.join(", "))
}

pub fn broadcast(arguments: &[(&str, &ArrayArg<'_>, Core)]) -> PyResult<Batch> {
    let mut shape = Shape::new();
    let mut arrays: SmallVec<[_; 4]> = SmallVec::new();
    for (name, argument, core) in arguments {
        let array = argument.array(name)?;
        let dims = array.shape();
        if dims.len() < core.len() || &dims[dims.len() - core.len()..] != *core {
            return Err(PyValueError::new_err(format!("{name}: expected shape {}, got {dims:?}", describe(core))));
        }
        let batch = &dims[..dims.len() - core.len()];
        shape = broadcast_shapes(&shape, batch)
            .ok_or_else(|| PyValueError::new_err(format!("{name}: batch shape {batch:?} does not broadcast with {shape:?}")))?;
        arrays.push((array, batch.len(), *core));
    }
    let len = shape.iter().product();
    let rows = arrays
        .into_iter()
        .map(|(array, batch_ndim, core)| {
            let batch = &array.shape()[..batch_ndim];
            let shared = batch.iter().product::<usize>() == 1;
            // SAFETY: read here, with the GIL held, so no Python thread writes the array meanwhile (and no
            // Rust code writes arguments); the kernels then run on this copy with the GIL released. Only a
            // C-ordered array is its rows in order: `as_slice` also takes a Fortran-ordered one (a transpose).
            let contiguous = if array.is_c_contiguous() { unsafe { array.as_slice() }.ok() } else { None };
            let data = match contiguous {
                Some(slice) if shared || batch == shape.as_slice() => copied(slice),
                _ => {
                    let view: ArrayViewD<'_, f64> = unsafe { array.as_array() };
                    let full: Vec<usize> = shape.iter().chain(core.iter()).copied().collect();
                    let spread = if shared || batch == shape.as_slice() { Some(view) } else { view.broadcast(IxDyn(&full)) };
                    spread.expect("shapes were checked to broadcast").iter().copied().collect()
                }
            };
            Rows { data, width: core.iter().product(), shared }
        })
        .collect();
    Ok(Batch { shape, len, rows })
}

/// `slice` copied on every core: large batches of cheap kernels would otherwise wait on a one-core copy.
fn copied(slice: &[f64]) -> Vec<f64> {
    let mut copy = vec![0.0; slice.len()];
    copy.par_chunks_mut(COPY_CHUNK).zip(slice.par_chunks(COPY_CHUNK)).for_each(|(to, from)| to.copy_from_slice(from));
    copy
}

/// Numbers per parallel copy task.
const COPY_CHUNK: usize = 1 << 16;

fn broadcast_shapes(a: &[usize], b: &[usize]) -> Option<Shape> {
    let n = a.len().max(b.len());
    let dim = |s: &[usize], i: usize| if i + s.len() >= n { s[i + s.len() - n] } else { 1 };
    (0..n)
        .map(|i| match (dim(a, i), dim(b, i)) {
            (x, y) if x == y => Some(x),
            (1, y) => Some(y),
            (x, 1) => Some(x),
            _ => None,
        })
        .collect()
}

/// Rows per parallel task: large enough that a task's setup (e.g. a fresh workspace) is amortised.
const MIN_ROWS_PER_TASK: usize = 64;

/// Evaluates `kernel(state, i, row)` for each batch row `i` of `out` (`width` numbers per row), in parallel
/// over the available cores (each task with its own `state` from `init`). A failure names the lowest
/// failing row, so the message does not depend on scheduling.
pub fn map_rows<S, I, K>(out: &mut [f64], width: usize, init: I, kernel: K) -> PyResult<()>
where
    I: Fn() -> S + Sync,
    K: Fn(&mut S, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    if width == 0 {
        return Ok(());
    }
    let len = out.len() / width;
    let failure = if len < 2 * MIN_ROWS_PER_TASK {
        let mut state = init();
        out.chunks_mut(width).enumerate().find_map(|(i, row)| kernel(&mut state, i, row).err().map(|e| (i, e)))
    } else {
        out.par_chunks_mut(width)
            .enumerate()
            .with_min_len(MIN_ROWS_PER_TASK)
            .map_init(&init, |state, (i, row)| kernel(state, i, row).err().map(|e| (i, e)))
            .flatten()
            .min_by_key(|(i, _)| *i)
    };
    match failure {
        Some((_, e)) if len == 1 => Err(crate::convert::kernel_error(e)),
        Some((i, e)) => Err(batch_error(e, i)),
        None => Ok(()),
    }
}

pub fn to_numpy<'py>(py: Python<'py>, shape: Shape, data: Vec<f64>) -> FloatArray<'py> {
    crate::convert::to_numpy(py, IxDyn(&shape), data)
}
