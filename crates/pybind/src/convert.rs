//! Conversions between NumPy arrays and nalgebra values, and the mapping of kernel errors to Python ones.

use legkit_dynamics::Error;
use nalgebra::{Matrix3, Vector3};
use numpy::ndarray::{Array, ArrayViewD, Dimension, IntoDimension};
use numpy::{PyArray, PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;

/// A NumPy float64 array returned to Python.
pub type FloatArray<'py> = Bound<'py, PyArrayDyn<f64>>;

/// A float64 array argument: anything NumPy converts (float64 arrays are used in place, anything else goes
/// through `numpy.asarray`). Extraction never fails; `get` raises a failed conversion as a TypeError
/// naming the argument.
///
/// Arrays are read only while the GIL is held (and copied where a kernel then releases it), so another
/// Python thread cannot write them meanwhile; rust-numpy's borrow tracking, which guards Rust borrows
/// only, is not needed.
pub struct Floats<'py>(Result<FloatArray<'py>, String>);

impl<'a, 'py> FromPyObject<'a, 'py> for Floats<'py> {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        if let Ok(array) = obj.cast::<PyArrayDyn<f64>>() {
            return Ok(Floats(Ok(array.to_owned())));
        }
        let converted =
            numpy::get_array_module(obj.py())?.call_method1("asarray", (obj, "float64")).and_then(|a| Ok(a.cast_into::<PyArrayDyn<f64>>()?));
        Ok(Floats(converted.map_err(|e| e.to_string())))
    }
}

impl<'py> Floats<'py> {
    pub fn array(&self, argument: &str) -> PyResult<&FloatArray<'py>> {
        self.0.as_ref().map_err(|e| PyTypeError::new_err(format!("{argument}: expected an array of numbers ({e})")))
    }

    pub fn get(&self, argument: &str) -> PyResult<ArrayViewD<'_, f64>> {
        // SAFETY: no Rust code mutates these arrays, and the view is used with the GIL held (see above).
        Ok(unsafe { self.array(argument)?.as_array() })
    }
}

pub type Vector<'py> = Floats<'py>;
pub type Matrix<'py> = Floats<'py>;

/// A kernel error as Python's: bad input a ValueError, a numerical failure (a diverging simulation) a
/// RuntimeError.
pub fn kernel_error(error: Error) -> PyErr {
    match error {
        Error::InvalidArgument { .. } => PyValueError::new_err(error.to_string()),
        Error::Numerical { .. } => PyRuntimeError::new_err(error.to_string()),
    }
}

/// A kernel error from row `index` of a batch, e.g. "radius[4]: must be >= 0".
pub fn batch_error(error: Error, index: usize) -> PyErr {
    match error {
        Error::InvalidArgument { argument, reason } => PyValueError::new_err(format!("{argument}[{index}]: {reason}")),
        Error::Numerical { context, reason } => PyRuntimeError::new_err(format!("{context}[{index}]: {reason}")),
    }
}

fn shape_error(argument: &str, expected: &str, shape: &[usize]) -> PyErr {
    PyValueError::new_err(format!("{argument}: expected shape {expected}, got {shape:?}"))
}

pub fn vector3(argument: &str, value: &Vector<'_>) -> PyResult<Vector3<f64>> {
    let view = value.get(argument)?;
    if view.shape() != [3] {
        return Err(shape_error(argument, "(3,)", view.shape()));
    }
    Ok(Vector3::from_iterator(view.iter().copied()))
}

pub fn matrix3(argument: &str, value: &Matrix<'_>) -> PyResult<Matrix3<f64>> {
    matrix3_view(argument, value.get(argument)?)
}

fn matrix3_view(argument: &str, view: ArrayViewD<'_, f64>) -> PyResult<Matrix3<f64>> {
    if view.shape() != [3, 3] {
        return Err(shape_error(argument, "(3, 3)", view.shape()));
    }
    Ok(Matrix3::from_fn(|i, j| view[[i, j]]))
}

/// The rotation and translation of a 4x4 homogeneous transform.
pub fn homogeneous_matrix(argument: &str, value: &Matrix<'_>) -> PyResult<(Matrix3<f64>, Vector3<f64>)> {
    let view = value.get(argument)?;
    if view.shape() != [4, 4] {
        return Err(PyValueError::new_err(format!("{argument}: expected a 4x4 transform or an (R, t) pair, got shape {:?}", view.shape())));
    }
    if (0..4).any(|j| view[[3, j]] != if j == 3 { 1.0 } else { 0.0 }) {
        return Err(PyValueError::new_err(format!("{argument}: the last row of a 4x4 transform must be [0, 0, 0, 1]")));
    }
    Ok((Matrix3::from_fn(|i, j| view[[i, j]]), Vector3::from_fn(|i, _| view[[i, 3]])))
}

/// Rows of an (n, 3) array as vectors.
pub fn rows3(argument: &str, value: &Matrix<'_>) -> PyResult<Vec<Vector3<f64>>> {
    let view = value.get(argument)?;
    if view.ndim() != 2 || view.shape()[1] != 3 {
        return Err(shape_error(argument, "(n, 3)", view.shape()));
    }
    Ok(view.outer_iter().map(|r| Vector3::new(r[0], r[1], r[2])).collect())
}

pub fn to_numpy<'py, D: Dimension, S: IntoDimension<Dim = D>, T: numpy::Element>(
    py: Python<'py>,
    shape: S,
    data: Vec<T>,
) -> Bound<'py, PyArray<T, D>> {
    let array = Array::from_shape_vec(shape, data).expect("output length matches its shape");
    PyArray::from_owned_array(py, array)
}

pub fn vector_to_numpy<'py>(py: Python<'py>, v: &Vector3<f64>) -> Bound<'py, PyArray<f64, numpy::Ix1>> {
    to_numpy(py, 3, v.as_slice().to_vec())
}

pub fn matrix_to_numpy<'py>(py: Python<'py>, m: &Matrix3<f64>) -> Bound<'py, PyArray<f64, numpy::Ix2>> {
    to_numpy(py, (3, 3), m.transpose().as_slice().to_vec())
}
