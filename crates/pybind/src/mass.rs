//! `legkit.MassProperties`.

use legkit_dynamics::validate::finite_vector;
use legkit_dynamics::MassProperties;
use nalgebra::{Matrix3, Vector3};
use numpy::{PyArray1, PyArray2};
use pyo3::basic::CompareOp;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyInt;

use crate::convert::{homogeneous_matrix, kernel_error, matrix3, matrix_to_numpy, numbers, rows3, vector3, vector_to_numpy, Matrix, Vector};

/// `value` if all its numbers are finite: sums and transforms of valid mass properties can still overflow.
fn finite(value: MassProperties) -> PyResult<PyMassProperties> {
    let (mass, com, inertia) = (value.mass(), value.com(), value.inertia());
    if mass.is_finite() && com.iter().chain(inertia.iter()).all(|x| x.is_finite()) {
        Ok(PyMassProperties(value))
    } else {
        Err(overflow())
    }
}

fn overflow() -> PyErr {
    PyRuntimeError::new_err("result: not finite: a number overflowed float64 (are the inputs' magnitudes physical?)")
}

/// Mass, centre of mass and rotational inertia about the centre of mass, all in one frame.
#[pyclass(name = "MassProperties", module = "legkit", frozen, from_py_object)]
#[derive(Clone, Copy)]
pub struct PyMassProperties(pub MassProperties);

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PyMassProperties {
    #[new]
    fn new(mass: f64, com: Vector<'_>, inertia: Matrix<'_>) -> PyResult<Self> {
        let com = vector3("com", &com)?;
        let inertia = matrix3("inertia", &inertia)?;
        MassProperties::new(mass, com, inertia).map(Self).map_err(kernel_error)
    }

    #[staticmethod]
    fn zero() -> Self {
        Self(MassProperties::zero())
    }

    #[staticmethod]
    fn point(mass: f64, position: Vector<'_>) -> PyResult<Self> {
        MassProperties::point(mass, vector3("position", &position)?).map(Self).map_err(kernel_error)
    }

    #[staticmethod]
    #[pyo3(signature = (mass, size, center = None, rotation = None))]
    fn solid_box(mass: f64, size: Vector<'_>, center: Option<Vector<'_>>, rotation: Option<Matrix<'_>>) -> PyResult<Self> {
        let center = center.map(|c| vector3("center", &c)).transpose()?.unwrap_or_else(Vector3::zeros);
        let rotation = rotation.map(|r| matrix3("rotation", &r)).transpose()?.unwrap_or_else(Matrix3::identity);
        MassProperties::solid_box(mass, vector3("size", &size)?, center, &rotation).map(Self).map_err(kernel_error)
    }

    #[staticmethod]
    fn from_points(masses: Vector<'_>, positions: Matrix<'_>) -> PyResult<Self> {
        let positions = rows3("positions", &positions)?;
        let masses = numbers("masses", &masses)?;
        finite(MassProperties::from_points(&masses, &positions).map_err(kernel_error)?)
    }

    #[getter]
    fn mass(&self) -> f64 {
        self.0.mass()
    }

    #[getter]
    fn com<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_numpy(py, &self.0.com())
    }

    /// Inertia about the centre of mass.
    #[getter]
    fn inertia<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix_to_numpy(py, &self.0.inertia())
    }

    fn inertia_about<'py>(&self, py: Python<'py>, point: Vector<'_>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let point = finite_vector("point", vector3("point", &point)?).map_err(kernel_error)?;
        let inertia = self.0.inertia_about(&point);
        if !inertia.iter().all(|x| x.is_finite()) {
            return Err(overflow());
        }
        Ok(matrix_to_numpy(py, &inertia))
    }

    /// Express in the parent frame of `x_parent = R x + t`: `(R, t)`, or one 4x4 homogeneous matrix.
    #[pyo3(signature = (rotation, translation = None))]
    fn transformed(&self, rotation: Matrix<'_>, translation: Option<Vector<'_>>) -> PyResult<Self> {
        let (r, t) = match translation {
            Some(t) => (matrix3("rotation", &rotation)?, vector3("translation", &t)?),
            None => homogeneous_matrix("rotation", &rotation)?,
        };
        finite(self.0.transformed(&r, &t).map_err(kernel_error)?)
    }

    #[pyo3(signature = (other, rtol = 1e-9, atol = 1e-12))]
    fn isclose(&self, other: &Self, rtol: f64, atol: f64) -> bool {
        self.0.is_close(&other.0, rtol, atol)
    }

    fn __add__(&self, other: &Self) -> PyResult<Self> {
        finite(self.0 + other.0)
    }

    /// Lets `sum(bodies)` start from the integer 0.
    fn __radd__(&self, other: &Bound<'_, PyAny>) -> PyResult<Self> {
        match other.cast::<PyInt>() {
            Ok(i) if i.extract::<i64>()? == 0 => Ok(*self),
            _ => Err(pyo3::exceptions::PyTypeError::new_err("only 0 or a MassProperties can be added")),
        }
    }

    fn __sub__(&self, other: &Self) -> PyResult<Self> {
        finite((self.0 - other.0).map_err(kernel_error)?)
    }

    fn __richcmp__(&self, other: &Bound<'_, PyAny>, op: CompareOp, py: Python<'_>) -> Py<PyAny> {
        let Ok(other) = other.extract::<Self>() else { return py.NotImplemented() };
        let equal = self.0.is_close(&other.0, 1e-9, 1e-12);
        match op {
            CompareOp::Eq => equal.into_pyobject(py).unwrap().to_owned().into_any().unbind(),
            CompareOp::Ne => (!equal).into_pyobject(py).unwrap().to_owned().into_any().unbind(),
            _ => py.NotImplemented(),
        }
    }

    fn __repr__(&self) -> String {
        let (c, i) = (self.0.com(), self.0.inertia());
        format!(
            "MassProperties(mass={}, com=[{}, {}, {}], inertia=[[{}, {}, {}], [{}, {}, {}], [{}, {}, {}]])",
            self.0.mass(),
            c.x,
            c.y,
            c.z,
            i[(0, 0)],
            i[(0, 1)],
            i[(0, 2)],
            i[(1, 0)],
            i[(1, 1)],
            i[(1, 2)],
            i[(2, 0)],
            i[(2, 1)],
            i[(2, 2)]
        )
    }
}
