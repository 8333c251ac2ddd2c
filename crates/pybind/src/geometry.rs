//! Circle–line queries over broadcast batches (the loop is cheap per query, so it stays on one core).

use legkit_dynamics::validate::finite_vector;
use legkit_dynamics::{circle_line as circle_line_query, rotation_toward_line as rotation_query, Circle, Error, Line};
use nalgebra::Vector3;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

use crate::batch::{broadcast, to_numpy, ArrayArg, Batch, Rows};
use crate::convert::{batch_error, value_error};

fn vector(rows: &Rows<'_>, i: usize) -> Vector3<f64> {
    Vector3::from_column_slice(rows.row(i))
}

/// Runs `query` on each row with the GIL released, naming the row of a failing batch element.
fn each_row<T: Send>(py: Python<'_>, batch: &Batch<'_>, query: impl Fn(usize) -> Result<T, Error> + Sync) -> PyResult<Vec<T>> {
    py.detach(|| (0..batch.len).map(|i| query(i).map_err(|e| (e, i))).collect::<Result<Vec<T>, _>>())
        .map_err(|(e, i)| if batch.shape.is_empty() { value_error(e) } else { batch_error(e, i) })
}

type CircleLineArrays<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<i64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<bool>>,
);

/// (distance, count, circle_points (..., 2, 3), line_points (..., 2, 3), equidistant) over the batch.
#[pyfunction]
pub fn circle_line<'py>(
    py: Python<'py>,
    center: ArrayArg<'_>,
    normal: ArrayArg<'_>,
    radius: ArrayArg<'_>,
    line_point: ArrayArg<'_>,
    line_direction: ArrayArg<'_>,
) -> PyResult<CircleLineArrays<'py>> {
    let batch = broadcast(&[
        ("center", &center, &[3]),
        ("normal", &normal, &[3]),
        ("radius", &radius, &[]),
        ("line_point", &line_point, &[3]),
        ("line_direction", &line_direction, &[3]),
    ])?;
    let r = &batch.rows;
    let results = each_row(py, &batch, |i| {
        let circle = Circle::new(vector(&r[0], i), vector(&r[1], i), r[2].row(i)[0])?;
        let line = Line::new(vector(&r[3], i), vector(&r[4], i))?;
        Ok(circle_line_query(&circle, &line))
    })?;
    let points = |pick: fn(&legkit_dynamics::CircleLine) -> &[Vector3<f64>; 2]| {
        let data = results.iter().flat_map(|x| pick(x).iter().flat_map(|p| p.iter().copied())).collect();
        crate::convert::to_numpy(py, numpy::IxDyn(&batch.output_shape(&[2, 3])), data)
    };
    Ok((
        to_numpy(py, batch.shape.clone(), results.iter().map(|x| x.distance).collect()),
        crate::convert::to_numpy(py, numpy::IxDyn(&batch.shape), results.iter().map(|x| x.count as i64).collect()),
        points(|x| &x.circle_points),
        points(|x| &x.line_points),
        crate::convert::to_numpy(py, numpy::IxDyn(&batch.shape), results.iter().map(|x| x.equidistant).collect()),
    ))
}

/// (theta, distance) over the batch.
#[pyfunction]
pub fn rotation_toward_line<'py>(
    py: Python<'py>,
    axis_point: ArrayArg<'_>,
    axis_direction: ArrayArg<'_>,
    point: ArrayArg<'_>,
    line_point: ArrayArg<'_>,
    line_direction: ArrayArg<'_>,
) -> PyResult<(Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<f64>>)> {
    let batch = broadcast(&[
        ("axis_point", &axis_point, &[3]),
        ("axis_direction", &axis_direction, &[3]),
        ("point", &point, &[3]),
        ("line_point", &line_point, &[3]),
        ("line_direction", &line_direction, &[3]),
    ])?;
    let r = &batch.rows;
    let results = each_row(py, &batch, |i| {
        let axis = Line::axis(vector(&r[0], i), vector(&r[1], i))?;
        let point = finite_vector("point", vector(&r[2], i))?;
        let line = Line::new(vector(&r[3], i), vector(&r[4], i))?;
        Ok(rotation_query(&axis, &point, &line))
    })?;
    Ok((
        to_numpy(py, batch.shape.clone(), results.iter().map(|x| x.0).collect()),
        to_numpy(py, batch.shape.clone(), results.iter().map(|x| x.1).collect()),
    ))
}

