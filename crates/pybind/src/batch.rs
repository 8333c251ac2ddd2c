//! Broadcasting of leading batch dimensions; the batch loops are the core's (`legkit_dynamics::parallel`).
//!
//! Each argument has a core shape (a scalar, or a vector of known length); whatever dimensions lead it
//! form its batch shape, and the batch shapes broadcast as in NumPy. Every argument is copied once, with the
//! GIL held, before the kernels run without it: another Python thread may write the array meanwhile.

use legkit_dynamics::parallel;
use legkit_dynamics::Error;
use numpy::ndarray::{ArrayViewD, Axis, IxDyn};
use numpy::{PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use smallvec::SmallVec;

use crate::convert::{batch_error, kernel_error, new_array, FloatArray};
use legkit_dynamics::validate::{array_len, filled, with_capacity};

pub type ArrayArg<'py> = crate::convert::Floats<'py>;

/// The core shape of one argument (`&[]` for a scalar); the dimensions before it are its batch shape.
pub type Core<'c> = &'c [usize];

/// A batched argument: its name (for errors), its array and its core shape.
pub type Argument<'a, 'py> = (&'static str, &'a ArrayArg<'py>, Core<'a>);

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
    /// The argument with the most batch elements: the one an output too large to allocate is blamed on.
    pub largest: &'static str,
}

impl Batch {
    /// Row `i` of each of the first `N` arguments, in order.
    #[inline]
    pub fn row<const N: usize>(&self, i: usize) -> [&[f64]; N] {
        std::array::from_fn(|k| self.rows[k].row(i))
    }

    /// The shape of an output with the given core dimensions.
    pub fn output_shape(&self, core: &[usize]) -> Shape {
        self.shape.iter().chain(core).copied().collect()
    }

    /// A new output array with the given core dimensions (MemoryError if it cannot be allocated).
    pub fn output<'py>(&self, py: Python<'py>, core: &[usize]) -> PyResult<FloatArray<'py>> {
        new_array(py, self.largest, &self.output_shape(core))
    }
}

fn describe(core: Core) -> String {
    if core.is_empty() {
        return "a scalar or an array of scalars".to_owned();
    }
    let dims: Vec<String> = core.iter().map(|d| d.to_string()).collect();
    format!("(..., {})", dims.join(", "))
}

/// Every argument's rows over the broadcast batch shape. MemoryError, naming the argument, for a batch
/// whose copy cannot be allocated (or whose size does not even fit in a machine word).
pub fn broadcast(arguments: &[Argument<'_, '_>]) -> PyResult<Batch> {
    let mut shape = Shape::new();
    let mut arrays: SmallVec<[_; 4]> = SmallVec::new();
    let (mut largest, mut most) = ("", 0);
    for (name, argument, core) in arguments {
        let array = argument.array(name)?;
        let dims = array.shape();
        if dims.len() < core.len() || &dims[dims.len() - core.len()..] != *core {
            return Err(PyValueError::new_err(format!("{name}: expected shape {}, got {dims:?}", describe(core))));
        }
        let batch = &dims[..dims.len() - core.len()];
        shape = broadcast_shapes(&shape, batch)
            .ok_or_else(|| PyValueError::new_err(format!("{name}: batch shape {batch:?} does not broadcast with {shape:?}")))?;
        let elements = batch.iter().product::<usize>();
        if elements > most || largest.is_empty() {
            (largest, most) = (name, elements);
        }
        arrays.push((*name, array, batch.len(), *core));
    }
    let len = shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d));
    let rows = arrays
        .into_iter()
        .map(|(name, array, batch_ndim, core)| {
            let batch = &array.shape()[..batch_ndim];
            let shared = batch.iter().product::<usize>() == 1;
            // The copy's size, checked before anything is allocated: a product that overflows, or more bytes
            // than an allocation may have, is a MemoryError naming the argument.
            let numbers = len.and_then(|n| n.checked_mul(core.iter().product()));
            if !shared && numbers.is_none_or(|n| n > isize::MAX as usize / std::mem::size_of::<f64>()) {
                let full: Shape = shape.iter().chain(core.iter()).copied().collect();
                array_len(name, &full, std::mem::size_of::<f64>()).map_err(kernel_error)?;
            }
            // SAFETY: read here, with the GIL held, so no Python thread writes the array meanwhile (and no
            // Rust code writes arguments); the kernels then run on this copy with the GIL released. Only a
            // C-ordered array is its rows in order: `as_slice` also takes a Fortran-ordered one (a transpose).
            let contiguous = if array.is_c_contiguous() { unsafe { array.as_slice() }.ok() } else { None };
            let data = match contiguous {
                Some(slice) if shared || batch == shape.as_slice() => copied(name, slice)?,
                _ => {
                    let view: ArrayViewD<'_, f64> = unsafe { array.as_array() };
                    let full: Vec<usize> = shape.iter().chain(core.iter()).copied().collect();
                    let spread = if shared || batch == shape.as_slice() { Some(view) } else { view.broadcast(IxDyn(&full)) };
                    row_major(name, spread.expect("shapes were checked to broadcast"))?
                }
            };
            Ok(Rows { data, width: core.iter().product(), shared })
        })
        .collect::<PyResult<_>>()?;
    // An overflowing batch length was refused above, with the first argument that spans the batch.
    Ok(Batch { shape, len: len.unwrap_or(usize::MAX), rows, largest })
}

/// A view's numbers in row-major order, a row at a time where its last axis is contiguous (a column slice such
/// as `z[:, a:b]`, which the element iterator copied at a third of the speed: 2 ms of a 3.6 ms RNEA call).
fn row_major(argument: &'static str, view: ArrayViewD<'_, f64>) -> PyResult<Vec<f64>> {
    let mut data = with_capacity(argument, view.len()).map_err(kernel_error)?;
    let Some(last) = view.ndim().checked_sub(1) else {
        data.extend(view.iter().copied());
        return Ok(data);
    };
    for lane in view.lanes(Axis(last)) {
        match lane.as_slice() {
            Some(row) => data.extend_from_slice(row),
            None => data.extend(lane.iter().copied()),
        }
    }
    Ok(data)
}

/// `slice` copied on every core: large batches of cheap kernels would otherwise wait on a one-core copy.
fn copied(argument: &'static str, slice: &[f64]) -> PyResult<Vec<f64>> {
    if slice.len() <= COPY_CHUNK {
        let mut copy = with_capacity(argument, slice.len()).map_err(kernel_error)?;
        copy.extend_from_slice(slice);
        return Ok(copy);
    }
    let mut copy = filled(argument, slice.len(), 0.0).map_err(kernel_error)?;
    copy.par_chunks_mut(COPY_CHUNK).zip(slice.par_chunks(COPY_CHUNK)).for_each(|(to, from)| to.copy_from_slice(from));
    Ok(copy)
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

/// Evaluates `kernel(state, i, row)` for each batch row `i` of `out` on all cores (`parallel::map_rows`: rows
/// `first..` of a batch of `total`, each thread with its own `state` from `init`); the lowest failing row's error,
/// named by its index unless the batch is one row.
pub fn map_rows<S, I, K>(out: &mut [f64], width: usize, first: usize, total: usize, init: I, kernel: K) -> PyResult<()>
where
    I: Fn() -> S + Sync,
    K: Fn(&mut S, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    parallel::map_rows(out, width, first, init, kernel, None).map_err(|failure| match total {
        1 => kernel_error(failure.error),
        _ => batch_error(failure.error, failure.row),
    })
}

/// `parts` (a call's outputs, as many as its kernel writes) as an array, to destructure.
pub fn array<T, const N: usize>(parts: Vec<T>) -> [T; N] {
    match parts.try_into() {
        Ok(array) => array,
        Err(parts) => unreachable!("{N} parts expected, {} made", parts.len()),
    }
}

/// `out` cut into `N` consecutive parts of the given `widths` (their sum is `out`'s length).
#[inline]
pub fn split<const N: usize>(mut out: &mut [f64], widths: [usize; N]) -> [&mut [f64]; N] {
    std::array::from_fn(|k| {
        let (part, rest) = std::mem::take(&mut out).split_at_mut(widths[k]);
        out = rest;
        part
    })
}

pub fn to_numpy<'py>(py: Python<'py>, shape: Shape, data: Vec<f64>) -> FloatArray<'py> {
    crate::convert::to_numpy(py, IxDyn(&shape), data)
}
