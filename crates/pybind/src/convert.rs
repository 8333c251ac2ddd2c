//! Conversions between NumPy arrays and nalgebra values, and the mapping of kernel errors to Python ones.

use legkit_dynamics::validate::with_capacity;
use legkit_dynamics::{Error, Transform};
use nalgebra::{Matrix3, Vector3};
use numpy::ndarray::{Array, ArrayViewD, Dimension, IntoDimension};
use numpy::npyffi::{self, npy_intp};
use numpy::{Element, PyArrayDescrMethods, PY_ARRAY_API};
use numpy::{PyArray, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyMemoryError, PyOverflowError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyComplex, PyFloat, PyInt, PyString, PyTuple};
use smallvec::SmallVec;
use std::ffi::c_int;

/// A NumPy float64 array returned to Python.
pub type FloatArray<'py> = Bound<'py, PyArrayDyn<f64>>;
/// Two to five arrays: what the functions with several outputs return.
pub type Arrays2<'py> = (FloatArray<'py>, FloatArray<'py>);
pub type Arrays3<'py> = (FloatArray<'py>, FloatArray<'py>, FloatArray<'py>);
pub type Arrays4<'py> = (FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>);
pub type Arrays5<'py> = (FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>);

/// A float64 array argument: anything NumPy converts to real numbers (float64 arrays, strided or not, are used in
/// place; anything else goes through `numpy.asarray`). Extraction never fails; `get` raises an argument that is not
/// real numbers as a TypeError naming it, where NumPy would turn it into numbers: complex ones (the imaginary part
/// dropped with only a warning), strings ("1.5"), dates and records. A masked array with masked entries, whose
/// hidden values NumPy would read, and a Python int beyond float64's range are ValueErrors.
///
/// Arrays are read only while the GIL is held (and copied where a kernel then releases it), so another
/// Python thread cannot write them meanwhile; rust-numpy's borrow tracking, which guards Rust borrows
/// only, is not needed.
pub struct Floats<'py>(Result<FloatArray<'py>, Refused>);

/// Why an argument is not an array of real numbers, by the class of the error it raises.
enum Refused {
    Type(String),
    Value(String),
}

impl<'a, 'py> FromPyObject<'a, 'py> for Floats<'py> {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let py = obj.py();
        // SAFETY: a type check of a live object.
        let exact = unsafe { npyffi::PyArray_CheckExact(py, obj.as_ptr()) } != 0;
        let float64 = obj.cast::<PyArrayDyn<f64>>();
        if let (true, Ok(array)) = (exact, &float64) {
            return Ok(Floats(Ok((*array).to_owned())));
        }
        if !exact && obj.cast::<PyUntypedArray>().is_ok() && py.import("numpy.ma")?.call_method1("is_masked", (obj,))?.is_truthy()? {
            return Ok(Floats(Err(Refused::Value("a masked array with masked entries (fill them first: a.filled(value))".into()))));
        }
        if let Ok(array) = float64 {
            return Ok(Floats(Ok(array.to_owned())));
        }
        let refused = |e: PyErr| match e.is_instance_of::<PyOverflowError>(py) {
            true => Refused::Value("a number beyond float64's range".into()),
            false => Refused::Type(format!("expected an array of numbers ({e})")),
        };
        // SAFETY: `numpy.asarray(obj)` through NumPy's C API (no dtype asked: NumPy's own choice), which returns a new
        // array or null with a Python error set.
        let array = unsafe {
            let pointer = PY_ARRAY_API.PyArray_FromAny(py, obj.as_ptr(), std::ptr::null_mut(), 0, 0, 0, std::ptr::null_mut());
            Bound::from_owned_ptr_or_err(py, pointer)
        };
        let array = match array.and_then(|a| Ok(a.cast_into::<PyUntypedArray>()?)) {
            Ok(array) => array,
            Err(e) => return Ok(Floats(Err(refused(e)))),
        };
        if let Ok(array) = array.cast::<PyArrayDyn<f64>>() {
            return Ok(Floats(Ok(array.to_owned())));
        }
        let dtype = array.dtype();
        if !matches!(dtype.kind(), b'b' | b'i' | b'u' | b'f' | b'O') {
            return Ok(Floats(Err(Refused::Type(format!("expected real numbers, got an array of {}", dtype.str()?)))));
        }
        let converted = py.import("numpy")?.call_method1("asarray", (array, "float64"));
        Ok(Floats(converted.and_then(|a| Ok(a.cast_into::<PyArrayDyn<f64>>()?)).map_err(refused)))
    }
}

impl<'py> Floats<'py> {
    pub fn array(&self, argument: &str) -> PyResult<&FloatArray<'py>> {
        self.0.as_ref().map_err(|refused| match refused {
            Refused::Type(why) => PyTypeError::new_err(format!("{argument}: {why}")),
            Refused::Value(why) => PyValueError::new_err(format!("{argument}: {why}")),
        })
    }

    pub fn get(&self, argument: &str) -> PyResult<ArrayViewD<'_, f64>> {
        // SAFETY: no Rust code mutates these arrays, and the view is used with the GIL held (see above).
        Ok(unsafe { self.array(argument)?.as_array() })
    }
}

pub type Vector<'py> = Floats<'py>;
pub type Matrix<'py> = Floats<'py>;

/// A loader's `path_or_xml` argument as text: a `str` as given (a path or the document itself, the loader tells
/// which), or any path-like object through `os.fspath`.
pub fn source_text(py: Python<'_>, value: &Bound<'_, PyAny>) -> PyResult<String> {
    match value.cast::<PyString>() {
        Ok(s) => Ok(s.to_str()?.to_owned()),
        Err(_) => py
            .import("os")?
            .call_method1("fspath", (value,))
            .and_then(|path| path.extract())
            .map_err(|_| PyTypeError::new_err("path_or_xml: expected a path or an XML string")),
    }
}

/// A kernel error as Python's: bad input a ValueError, a numerical failure (a diverging simulation) a
/// RuntimeError, a size that cannot be allocated a MemoryError.
pub fn kernel_error(error: Error) -> PyErr {
    python_error(&error, error.to_string())
}

/// A kernel error from row `index` of a batch, e.g. "radius[4]: must be >= 0".
pub fn batch_error(error: Error, index: usize) -> PyErr {
    batch_error_noting(error, index, "")
}

/// As `batch_error`, with `note` after the reason.
pub fn batch_error_noting(error: Error, index: usize, note: &str) -> PyErr {
    python_error(&error, format!("{}[{index}]: {}{note}", error.argument(), error.reason()))
}

fn python_error(error: &Error, message: String) -> PyErr {
    match error {
        Error::InvalidArgument { .. } => PyValueError::new_err(message),
        Error::Numerical { .. } => PyRuntimeError::new_err(message),
        Error::TooLarge { .. } => PyMemoryError::new_err(message),
    }
}

/// A new, uninitialised, C-ordered float64 array of `shape`: MemoryError naming `argument` (the argument that
/// asks for that size) if it cannot be allocated, where rust-numpy's constructor would panic.
pub fn new_array<'py>(py: Python<'py>, argument: &'static str, shape: &[usize]) -> PyResult<FloatArray<'py>> {
    let len = legkit_dynamics::validate::array_len(argument, shape, std::mem::size_of::<f64>()).map_err(kernel_error)?;
    let mut dims: SmallVec<[npy_intp; 4]> = shape.iter().map(|&d| d as npy_intp).collect();
    // SAFETY: NumPy's array constructor with a fresh float64 descriptor (whose reference it takes), no data and
    // no strides: it allocates the array, or returns null with a Python error set.
    let array = unsafe {
        let pointer = PY_ARRAY_API.PyArray_NewFromDescr(
            py,
            npyffi::get_type_object(py, npyffi::NpyTypes::PyArray_Type),
            f64::get_dtype(py).into_dtype_ptr(),
            dims.len() as c_int,
            dims.as_mut_ptr(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            0,
            std::ptr::null_mut(),
        );
        Bound::from_owned_ptr_or_err(py, pointer)
    };
    match array {
        // SAFETY: NumPy made a float64 array.
        Ok(array) => Ok(unsafe { array.cast_into_unchecked() }),
        Err(e) if e.is_instance_of::<PyMemoryError>(py) => {
            Err(PyMemoryError::new_err(format!("{argument}: cannot allocate {} bytes for an array of shape {shape:?}", len * 8)))
        }
        Err(e) => Err(e),
    }
}

/// An integer argument of any size (a Python or NumPy integer), saturated to the range of i128: 2**200 reads
/// as i128::MAX, beyond every bound a caller checks. Taken where an i64 or usize parameter would make an
/// integer out of its range an OverflowError instead of the ValueError, IndexError or MemoryError it is.
/// Extraction never fails, as for `Floats`: `value` raises anything but an integer as a TypeError naming the
/// argument.
#[derive(Debug, Clone)]
pub struct Integer(Result<i128, String>);

impl<'a, 'py> FromPyObject<'a, 'py> for Integer {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        // pyo3 reads True as 1; the Python layers refuse a bool for a count, and so do the bindings.
        if obj.is_instance_of::<PyBool>() {
            return Ok(Integer(Err("bool".into())));
        }
        // i64 first: its conversion is the fast one, and nearly every count fits.
        if let Ok(n) = obj.extract::<i64>() {
            return Ok(Integer(Ok(n.into())));
        }
        Ok(Integer(match obj.extract::<i128>() {
            Ok(n) => Ok(n),
            Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => Ok(if obj.gt(0)? { i128::MAX } else { i128::MIN }),
            Err(_) => Err(obj.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string())),
        }))
    }
}

impl Integer {
    pub const fn new(n: i128) -> Self {
        Integer(Ok(n))
    }

    /// The value (saturated), or a TypeError naming `argument` if it is not an integer.
    pub fn value(&self, argument: &str) -> PyResult<i128> {
        self.0.clone().map_err(|kind| PyTypeError::new_err(format!("{argument}: expected an integer, got {kind}")))
    }

    /// The value if it is in `lower..=upper`; a ValueError naming `argument` otherwise.
    pub fn within(&self, argument: &str, lower: u64, upper: u64) -> PyResult<u64> {
        let n = self.value(argument)?;
        if n < lower as i128 || n > upper as i128 {
            return Err(PyValueError::new_err(format!("{argument}: must be in {lower}..={upper}, got {}", shown(n))));
        }
        Ok(n as u64)
    }
}

/// Why `value`, given for a real number, is not one though pyo3 would read it as one: a bool (True as 1.0) or a
/// complex NumPy scalar (its real part, with only a warning). Plain floats and ints are checked first, at no cost.
pub fn not_real(value: &Bound<'_, PyAny>) -> Option<&'static str> {
    if value.is_exact_instance_of::<PyFloat>() || value.is_exact_instance_of::<PyInt>() {
        return None;
    }
    if value.is_instance_of::<PyBool>() {
        return Some("bool");
    }
    let kind = value.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<char>());
    (value.is_instance_of::<PyComplex>() || kind.is_ok_and(|k| k == 'c')).then_some("a complex number")
}

/// A number inside a container argument (a shape's size, a limit), as the argument wrappers read one: None for
/// anything `not_real` or that pyo3 cannot read as an f64.
pub fn number(value: &Bound<'_, PyAny>) -> Option<f64> {
    not_real(value).map_or_else(|| value.extract().ok(), |_| None)
}

/// A saturated integer as a message shows it.
pub fn shown(n: i128) -> String {
    match n {
        i128::MAX => "an integer beyond 2**127".to_owned(),
        i128::MIN => "an integer below -2**127".to_owned(),
        n => n.to_string(),
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

/// A placement from a 4x4 homogeneous matrix or an (R, t) pair.
pub fn transform(value: &Bound<'_, PyAny>) -> PyResult<Transform> {
    if let Ok(pair) = value.cast::<PyTuple>() {
        if pair.len() != 2 {
            return Err(PyValueError::new_err("placement: expected a 4x4 matrix or an (R, t) pair"));
        }
        let rotation: Matrix<'_> = pair.get_item(0)?.extract()?;
        let translation: Vector<'_> = pair.get_item(1)?.extract()?;
        return Ok(Transform::new(matrix3("placement", &rotation)?, vector3("placement", &translation)?));
    }
    let matrix: Matrix<'_> = value.extract()?;
    let (rotation, translation) = homogeneous_matrix("placement", &matrix)?;
    Ok(Transform::new(rotation, translation))
}

/// A placement as a row-major 4x4 homogeneous matrix.
pub fn homogeneous(x: &Transform) -> [f64; 16] {
    let mut out = [0.0; 16];
    for i in 0..3 {
        for j in 0..3 {
            out[4 * i + j] = x.rotation[(i, j)];
        }
        out[4 * i + 3] = x.translation[i];
    }
    out[15] = 1.0;
    out
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

/// Rows of an (n, 3) array as vectors, allocated fallibly (a broadcast view may stand for more rows than
/// memory holds).
pub fn rows3(argument: &'static str, value: &Matrix<'_>) -> PyResult<Vec<Vector3<f64>>> {
    let view = value.get(argument)?;
    if view.ndim() != 2 || view.shape()[1] != 3 {
        return Err(shape_error(argument, "(n, 3)", view.shape()));
    }
    let mut rows = with_capacity(argument, view.shape()[0]).map_err(kernel_error)?;
    rows.extend(view.outer_iter().map(|r| Vector3::new(r[0], r[1], r[2])));
    Ok(rows)
}

/// An array's numbers in order, allocated fallibly.
pub fn numbers(argument: &'static str, value: &Floats<'_>) -> PyResult<Vec<f64>> {
    let view = value.get(argument)?;
    let mut numbers = with_capacity(argument, view.len()).map_err(kernel_error)?;
    numbers.extend(view.iter().copied());
    Ok(numbers)
}

pub fn to_numpy<'py, D: Dimension, S: IntoDimension<Dim = D>, T: numpy::Element>(
    py: Python<'py>, shape: S, data: Vec<T>,
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
