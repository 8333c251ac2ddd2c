//! Conversions between NumPy arrays and nalgebra values, and the mapping of kernel errors to Python ones.

use legkit_dynamics::Error;
use nalgebra::{Matrix3, Vector3};
use numpy::ndarray::{Array, ArrayView2, Dimension, IntoDimension};
use numpy::{AllowTypeChange, PyArray, PyArrayLike, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// A float64 array argument: anything NumPy converts. A failed conversion becomes a TypeError, which
/// pyo3 prefixes with the argument's name.
pub struct Floats<'py, D: Dimension>(PyArrayLike<'py, f64, D, AllowTypeChange>);

impl<'a, 'py, D: Dimension + 'py> FromPyObject<'a, 'py> for Floats<'py, D> {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        <PyArrayLike<'py, f64, D, AllowTypeChange> as FromPyObject<'a, 'py>>::extract(obj)
            .map(Floats)
            .map_err(|e| PyTypeError::new_err(format!("expected an array of numbers ({e})")))
    }
}

impl<'py, D: Dimension> std::ops::Deref for Floats<'py, D> {
    type Target = PyArrayLike<'py, f64, D, AllowTypeChange>;

    fn deref(&self) -> &Self::Target {
        &self.0
    }
}

pub type Vector<'py> = Floats<'py, numpy::Ix1>;
pub type Matrix<'py> = Floats<'py, numpy::Ix2>;

pub fn value_error(error: Error) -> PyErr {
    PyValueError::new_err(error.to_string())
}

/// A kernel error from row `index` of a batch, e.g. "radius[4]: must be >= 0".
pub fn batch_error(error: Error, index: usize) -> PyErr {
    let Error::InvalidArgument { argument, reason } = error;
    PyValueError::new_err(format!("{argument}[{index}]: {reason}"))
}

fn shape_error(argument: &str, expected: &str, shape: &[usize]) -> PyErr {
    PyValueError::new_err(format!("{argument}: expected shape {expected}, got {shape:?}"))
}

pub fn vector3(argument: &str, value: &Vector<'_>) -> PyResult<Vector3<f64>> {
    match value.as_slice() {
        Ok(&[x, y, z]) => Ok(Vector3::new(x, y, z)),
        _ => Err(shape_error(argument, "(3,)", value.shape())),
    }
}

pub fn matrix3(argument: &str, value: &Matrix<'_>) -> PyResult<Matrix3<f64>> {
    matrix3_view(argument, value.as_array())
}

fn matrix3_view(argument: &str, view: ArrayView2<'_, f64>) -> PyResult<Matrix3<f64>> {
    if view.shape() != [3, 3] {
        return Err(shape_error(argument, "(3, 3)", view.shape()));
    }
    Ok(Matrix3::from_fn(|i, j| view[[i, j]]))
}

/// Rows of an (n, 3) array as vectors.
pub fn rows3(argument: &str, value: &Matrix<'_>) -> PyResult<Vec<Vector3<f64>>> {
    let view = value.as_array();
    if view.ncols() != 3 {
        return Err(shape_error(argument, "(n, 3)", view.shape()));
    }
    Ok(view.rows().into_iter().map(|r| Vector3::new(r[0], r[1], r[2])).collect())
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
