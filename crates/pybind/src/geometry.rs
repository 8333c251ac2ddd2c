//! Circle–line queries over broadcast batches, written straight into the output arrays in parallel
//! chunks with the GIL released.

use legkit_dynamics::validate::{array_len, filled, finite_vector};
use legkit_dynamics::{circle_line as circle_line_query, rotation_toward_line as rotation_query, Circle, CircleLineColumns, Error, Line};
use nalgebra::Vector3;
use numpy::{IxDyn, PyArrayDyn};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::batch::{broadcast, ArrayArg, Batch, Rows};
use crate::convert::{batch_error, kernel_error, to_numpy, FloatArray};
use crate::interrupt::{in_pieces, Pace};

/// Queries per parallel task.
const CHUNK: usize = 4096;

fn vector(rows: &Rows, i: usize) -> Vector3<f64> {
    Vector3::from_column_slice(rows.row(i))
}

/// The error of the lowest failing row, if any (so that the message does not depend on scheduling).
fn first_error(errors: impl ParallelIterator<Item = Option<(usize, Error)>>) -> Option<(usize, Error)> {
    errors.flatten().min_by_key(|(i, _)| *i)
}

fn raise(batch: &Batch, (i, error): (usize, Error)) -> PyErr {
    if batch.shape.is_empty() {
        kernel_error(error)
    } else {
        batch_error(error, i)
    }
}

type CircleLineArrays<'py> = (FloatArray<'py>, Bound<'py, PyArrayDyn<i64>>, FloatArray<'py>, FloatArray<'py>, Bound<'py, PyArrayDyn<bool>>);

/// (distance, count, circle_points (..., 2, 3), line_points (..., 2, 3), equidistant) over the batch.
#[pyfunction(crate = "crate::arguments")]
pub fn circle_line<'py>(
    py: Python<'py>, center: ArrayArg<'_>, normal: ArrayArg<'_>, radius: ArrayArg<'_>, line_point: ArrayArg<'_>, line_direction: ArrayArg<'_>,
) -> PyResult<CircleLineArrays<'py>> {
    let batch = broadcast(&[
        ("center", &center, &[3]),
        ("normal", &normal, &[3]),
        ("radius", &radius, &[]),
        ("line_point", &line_point, &[3]),
        ("line_direction", &line_direction, &[3]),
    ])?;
    let n = batch.len;
    let points = array_len(batch.largest, &[n, 6], std::mem::size_of::<f64>()).map_err(kernel_error)?;
    let output = |len, value| filled(batch.largest, len, value).map_err(kernel_error);
    let (mut distance, mut count, mut equidistant) =
        (output(n, 0.0)?, filled(batch.largest, n, 0i64).map_err(kernel_error)?, filled(batch.largest, n, false).map_err(kernel_error)?);
    let (mut circle_points, mut line_points) = (output(points, 0.0)?, output(points, 0.0)?);
    let r = &batch.rows;
    let mut done = 0;
    in_pieces(py, n as u64, &Pace::default(), |k| {
        let (first, end) = (done, done + k as usize);
        let chunks = distance[first..end]
            .par_chunks_mut(CHUNK)
            .zip(count[first..end].par_chunks_mut(CHUNK))
            .zip(equidistant[first..end].par_chunks_mut(CHUNK))
            .zip(circle_points[6 * first..6 * end].par_chunks_mut(6 * CHUNK))
            .zip(line_points[6 * first..6 * end].par_chunks_mut(6 * CHUNK))
            .enumerate();
        let failure = first_error(chunks.map(|(c, ((((distance, count), equidistant), circle_points), line_points))| {
            let mut columns = CircleLineColumns { distance, count, circle_points, line_points, equidistant };
            for j in 0..columns.distance.len() {
                let i = first + c * CHUNK + j;
                let query = Circle::new(vector(&r[0], i), vector(&r[1], i), r[2].row(i)[0])
                    .and_then(|circle| Ok((circle, Line::new(vector(&r[3], i), vector(&r[4], i))?)));
                let (circle, line) = match query {
                    Ok(q) => q,
                    Err(e) => return Some((i, e)),
                };
                columns.set(j, &circle_line_query(&circle, &line));
            }
            None
        }));
        done = end;
        failure.map_or(Ok(()), |failure| Err(raise(&batch, failure)))
    })?;
    let points_shape = IxDyn(&batch.output_shape(&[2, 3]));
    Ok((
        to_numpy(py, IxDyn(&batch.shape), distance),
        to_numpy(py, IxDyn(&batch.shape), count),
        to_numpy(py, points_shape.clone(), circle_points),
        to_numpy(py, points_shape, line_points),
        to_numpy(py, IxDyn(&batch.shape), equidistant),
    ))
}

/// (theta, distance) over the batch.
#[pyfunction(crate = "crate::arguments")]
pub fn rotation_toward_line<'py>(
    py: Python<'py>, axis_point: ArrayArg<'_>, axis_direction: ArrayArg<'_>, point: ArrayArg<'_>, line_point: ArrayArg<'_>,
    line_direction: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let batch = broadcast(&[
        ("axis_point", &axis_point, &[3]),
        ("axis_direction", &axis_direction, &[3]),
        ("point", &point, &[3]),
        ("line_point", &line_point, &[3]),
        ("line_direction", &line_direction, &[3]),
    ])?;
    let output = || filled(batch.largest, batch.len, 0.0).map_err(kernel_error);
    let (mut theta, mut distance) = (output()?, output()?);
    let r = &batch.rows;
    let mut done = 0;
    in_pieces(py, batch.len as u64, &Pace::default(), |k| {
        let (first, end) = (done, done + k as usize);
        let chunks = theta[first..end].par_chunks_mut(CHUNK).zip(distance[first..end].par_chunks_mut(CHUNK)).enumerate();
        let failure = first_error(chunks.map(|(c, (theta, distance))| {
            for j in 0..theta.len() {
                let i = first + c * CHUNK + j;
                let query = (|| {
                    let axis = Line::axis(vector(&r[0], i), vector(&r[1], i))?;
                    let point = finite_vector("point", vector(&r[2], i))?;
                    Ok((axis, point, Line::new(vector(&r[3], i), vector(&r[4], i))?))
                })();
                match query {
                    Ok((axis, point, line)) => (theta[j], distance[j]) = rotation_query(&axis, &point, &line),
                    Err(e) => return Some((i, e)),
                }
            }
            None
        }));
        done = end;
        failure.map_or(Ok(()), |failure| Err(raise(&batch, failure)))
    })?;
    Ok((to_numpy(py, IxDyn(&batch.shape), theta), to_numpy(py, IxDyn(&batch.shape), distance)))
}
