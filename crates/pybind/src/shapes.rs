//! Collision shapes between Python and `legkit_dynamics::geometry`: the `shapes` argument of `Simulation` and
//! `Model.colliders`, and the colliders listed back.

use legkit_dynamics::geometry::{Convex, Shape, ShapeKind};
use legkit_dynamics::sim::Options;
use legkit_dynamics::{Model, Transform};
use pyo3::exceptions::{PyIndexError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

use crate::convert::{homogeneous, kernel_error, number, rows3, to_numpy, transform, vector3, Floats};

/// `error` with its message prefixed by `argument`, its class kept.
fn prefixed(argument: &str, error: &PyErr, py: Python<'_>) -> PyErr {
    let message = format!("{argument}: {}", error.value(py));
    if error.is_instance_of::<PyIndexError>(py) {
        PyIndexError::new_err(message)
    } else if error.is_instance_of::<PyTypeError>(py) {
        PyTypeError::new_err(message)
    } else {
        PyValueError::new_err(message)
    }
}

fn shape_error(reason: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("shapes: {reason}"))
}

fn parse_shape(value: &Bound<'_, PyAny>) -> PyResult<Option<Shape>> {
    if value.is_none() {
        return Ok(None);
    }
    let tuple = value.cast::<PyTuple>().map_err(|_| PyTypeError::new_err("shapes: each value must be a tuple like (\"box\", size) or None"))?;
    let kind: String =
        tuple.get_item(0).and_then(|k| k.extract()).map_err(|_| PyTypeError::new_err("shapes: the first element must be a shape name"))?;
    let count = match kind.as_str() {
        "box" | "sphere" | "convex" => 1,
        "capsule" | "cylinder" => 2,
        other => return Err(shape_error(format!("unknown shape {other:?} (expected box, sphere, capsule, cylinder or convex)"))),
    };
    if tuple.len() != 1 + count && tuple.len() != 2 + count {
        return Err(shape_error(format!("{kind} takes {count} size parameter(s) and an optional placement, got {} values", tuple.len() - 1)));
    }
    let number = |k: usize| -> PyResult<f64> {
        number(&tuple.get_item(k)?).ok_or_else(|| PyTypeError::new_err(format!("shapes: {kind} parameters must be numbers")))
    };
    let shape_kind = match kind.as_str() {
        "box" => {
            let size: Floats<'_> = tuple.get_item(1)?.extract()?;
            let size = vector3("shapes", &size)?;
            ShapeKind::Box(size)
        }
        "sphere" => ShapeKind::Sphere(number(1)?),
        "convex" => {
            let points: Floats<'_> = tuple.get_item(1)?.extract()?;
            ShapeKind::Convex(Convex::hull(&rows3("shapes", &points)?).map_err(kernel_error)?)
        }
        "capsule" => ShapeKind::Capsule { half_height: number(1)?, radius: number(2)? },
        _ => ShapeKind::Cylinder { half_height: number(1)?, radius: number(2)? },
    };
    let placement: Option<Transform> =
        if tuple.len() == 2 + count { Some(transform(&tuple.get_item(1 + count)?).map_err(|e| shape_error(e.to_string()))?) } else { None };
    Shape::new(shape_kind, placement).map(Some).map_err(kernel_error)
}

/// The `shapes` argument: bodies (index or name) to their replacement shape, or None for no collider.
pub fn shape_overrides(
    shapes: Option<&Bound<'_, PyDict>>, body_index: impl Fn(&Bound<'_, PyAny>) -> PyResult<usize>,
) -> PyResult<Vec<(usize, Option<Shape>)>> {
    let Some(shapes) = shapes else { return Ok(Vec::new()) };
    shapes
        .iter()
        .map(|(key, value)| {
            let body = body_index(&key).map_err(|e| prefixed("shapes", &e, key.py()))?;
            Ok((body, parse_shape(&value)?))
        })
        .collect()
}

/// `Model.colliders(shapes=None)`: what a `Simulation(model, shapes=shapes)` collides with, as
/// (body, kind, size, placement (4, 4) in the body frame).
pub fn colliders<'py>(py: Python<'py>, model: &Model, shapes: Vec<(usize, Option<Shape>)>) -> PyResult<Bound<'py, PyList>> {
    let mut options = Options::new(1e-3);
    options.shapes = shapes;
    options.check(model).map_err(kernel_error)?;
    let items = options.colliders(model).map(|(body, shape, placement)| {
        let matrix = to_numpy(py, [4, 4], homogeneous(&placement).to_vec());
        let (kind, size): (&str, Bound<'py, PyAny>) = match shape.kind {
            ShapeKind::Box(size) => ("box", PyTuple::new(py, size.iter())?.into_any()),
            ShapeKind::Sphere(radius) => ("sphere", PyTuple::new(py, [radius])?.into_any()),
            ShapeKind::Capsule { half_height, radius } => ("capsule", PyTuple::new(py, [half_height, radius])?.into_any()),
            ShapeKind::Cylinder { half_height, radius } => ("cylinder", PyTuple::new(py, [half_height, radius])?.into_any()),
            ShapeKind::Convex(hull) => {
                let vertices: Vec<f64> = hull.vertices().iter().flat_map(|v| v.iter().copied()).collect();
                ("convex", to_numpy(py, [hull.vertices().len(), 3], vertices).into_any())
            }
        };
        (body, kind, size, matrix).into_pyobject(py)
    });
    PyList::new(py, items.collect::<PyResult<Vec<_>>>()?)
}
