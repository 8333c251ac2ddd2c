//! Kinematic quantities over batches: poses, Jacobians, centre of mass, subtree mass properties and
//! centroidal momentum.

use legkit_dynamics::algorithms::{self, Frame};
use nalgebra::{Dim, Dyn, Matrix, RawStorage, Vector3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::batch::{broadcast, ArrayArg};
use crate::convert::{homogeneous, vector3, FloatArray, Vector};
use crate::model::PyModel;
use crate::workspace::{run, run_packed, unpack};

/// World pose (4x4) of every body: `(..., nbodies, 4, 4)`.
#[pyfunction(crate = "crate::arguments")]
pub fn forward_kinematics<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()])])?;
    run(py, &model, &batch, &[m.nbodies(), 4, 4], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        let data = w.data();
        algorithms::forward_kinematics(m, data, q)?;
        for (pose, chunk) in data.o_m_i.iter().zip(out.chunks_exact_mut(16)) {
            chunk.copy_from_slice(&homogeneous(pose));
        }
        Ok(())
    })
}

fn frame(name: &str) -> PyResult<Frame> {
    match name {
        "local" => Ok(Frame::Local),
        "world" => Ok(Frame::World),
        "local_world_aligned" => Ok(Frame::LocalWorldAligned),
        other => Err(PyValueError::new_err(format!("frame: expected \"local\", \"world\" or \"local_world_aligned\", got {other:?}"))),
    }
}

/// The body index, point (default the origin) and convention of a frame argument.
fn frame_arguments(model: &PyModel, body: &Bound<'_, PyAny>, point: Option<Vector<'_>>, frame: &str) -> PyResult<(usize, Vector3<f64>, Frame)> {
    let (body, convention) = (model.body_index("body", body)?, self::frame(frame)?);
    let point = point.map(|p| vector3("point", &p)).transpose()?.unwrap_or_else(Vector3::zeros);
    legkit_dynamics::validate::finite_vector("point", point).map_err(crate::convert::kernel_error)?;
    Ok((body, point, convention))
}

/// The 6 x nv Jacobian (rows [linear; angular]) of the frame at `point` (body coordinates, default the
/// origin) on `body` (index or name), in Pinocchio's `frame` convention: "local", "world" or
/// "local_world_aligned" (the point's velocity in world axes). `(..., 6, nv)`.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, body, point = None, frame = "local_world_aligned"))]
pub fn jacobian<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<FloatArray<'py>> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    let nv = model.model.nv();
    of_configuration(py, &model, &q, &[6, nv], |m, data, q, out| {
        row_major(algorithms::jacobian(m, data, q, body, &point, convention)?, out);
        Ok(())
    })
}

/// A kernel of the configuration alone over a batch of q: `kernel(model, data, q, out)` writes each row's `shape` numbers.
fn of_configuration<'py>(
    py: Python<'py>,
    model: &PyModel,
    q: &ArrayArg<'_>,
    shape: &[usize],
    kernel: impl Fn(&legkit_dynamics::Model, &mut legkit_dynamics::Data, &[f64], &mut [f64]) -> Result<(), legkit_dynamics::Error> + Sync,
) -> PyResult<FloatArray<'py>> {
    let batch = broadcast(&[("q", q, &[model.model.nq()])])?;
    run(py, model, &batch, shape, |m, w, i, out| kernel(m, w.data(), batch.rows[0].row(i), out))
}

/// d/dq_d of entry [r, a] of `jacobian` at [r, a, d] (Pinocchio's `getJointKinematicHessian`; q on its tangent space,
/// as `rnea_derivatives`), in "world" or "local_world_aligned": `(..., 6, nv, nv)`. Along q_d, the slope of
/// w . J_lin (the gradient of w . position): `np.einsum("r,rad->ad", w, H[..., :3, :, :])`.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, body, point = None, frame = "local_world_aligned"))]
pub fn kinematic_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<FloatArray<'py>> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    if convention == Frame::Local {
        return Err(PyValueError::new_err("frame: kinematic_hessian takes \"world\" or \"local_world_aligned\", got \"local\""));
    }
    let nv = model.model.nv();
    of_configuration(py, &model, &q, &[6, nv, nv], |m, data, q, out| algorithms::kinematic_hessian(m, data, q, body, &point, convention, out))
}

/// (Hessian `(..., nv, nv)`, gradient `(..., nv)`) with respect to q (on its tangent space, as `rnea_derivatives`;
/// entry [e, d] the slope along q_d of the gradient's entry e) of `weights` . the world velocity J_lin(q) v of
/// `point` on `body`: the curvature of a load's virtual power F . J(q) v.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, body, point, weights))]
pub fn point_velocity_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    weights: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let (body, point, _) = frame_arguments(&model, body, point, "local_world_aligned")?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("weights", &weights, &[3])])?;
    let packed = run_packed(py, &model, &batch, nv * nv + nv, |m, w, i, out| {
        let (q, v, f) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (hessian, gradient) = out.split_at_mut(nv * nv);
        algorithms::point_velocity_hessian(m, w.data(), q, v, body, &point, &Vector3::from_column_slice(f), hessian, gradient)?;
        Ok(())
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[nv, nv], &[nv]])?.into_iter();
    Ok((parts.next().expect("two"), parts.next().expect("two")))
}

/// (qq, qv, vv, qa, q-gradient) of `weights` . the classical world acceleration of `point` on `body` (as
/// `point_accelerations`), with respect to q (on its tangent space, as `rnea_derivatives`), v and a: each `(..., nv, nv)`
/// (qq `[b, d]` the slope along q_d of the gradient's entry b; qv, qa `[d, e]` = d2/dq_d dv_e, d2/dq_d da_e), the
/// gradient `(..., nv)`; aa and va are zero.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, a, body, point, weights))]
#[allow(clippy::too_many_arguments)]
pub fn point_acceleration_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    weights: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let (body, point, _) = frame_arguments(&model, body, point, "local_world_aligned")?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("a", &a, &[nv]), ("weights", &weights, &[3])])?;
    let packed = run_packed(py, &model, &batch, 4 * nv * nv + nv, |m, w, i, out| {
        let (q, v, a, f) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i), batch.rows[3].row(i));
        algorithms::point_acceleration_hessian(m, w.data(), q, v, a, body, &point, &Vector3::from_column_slice(f), out)?;
        Ok(())
    })?;
    let square: &[usize] = &[nv, nv];
    let mut parts = unpack(py, &batch, &packed, &[square, square, square, square, &[nv]])?.into_iter();
    let mut next = || parts.next().expect("five");
    Ok((next(), next(), next(), next(), next()))
}

/// The model's centre of mass in the world frame: `(..., 3)`.
#[pyfunction(crate = "crate::arguments")]
pub fn center_of_mass<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let batch = broadcast(&[("q", &q, &[model.model.nq()])])?;
    run(py, &model, &batch, &[3], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        out.copy_from_slice(algorithms::center_of_mass(m, w.data(), q)?.as_slice());
        Ok(())
    })
}

/// (Hessian `(..., nv, nv)`, gradient `(..., nv)`) with respect to q (on its tangent space, as `rnea_derivatives`;
/// entry [e, d] the slope along q_d of the gradient's entry e) of `weights` . the world centre of mass.
#[pyfunction(crate = "crate::arguments")]
pub fn center_of_mass_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    weights: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("weights", &weights, &[3])])?;
    let packed = run_packed(py, &model, &batch, nv * nv + nv, |m, w, i, out| {
        let (q, f) = (batch.rows[0].row(i), batch.rows[1].row(i));
        let (hessian, gradient) = out.split_at_mut(nv * nv);
        algorithms::center_of_mass_hessian(m, w.data(), q, &Vector3::from_column_slice(f), hessian, gradient)?;
        Ok(())
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[nv, nv], &[nv]])?.into_iter();
    Ok((parts.next().expect("two"), parts.next().expect("two")))
}

/// (qq, qv, q-gradient) of `weights` (..., 6) . the centroidal momentum h = [linear; angular about the COM]
/// (`centroidal_momentum`): qq `(..., nv, nv)` (entry [e, d] the slope along q_d of the gradient's entry e, q on its
/// tangent space), qv `(..., nv, nv)` (entry [d, e] = d2/dq_d dv_e), the gradient `(..., nv)`; vv is zero.
#[pyfunction(crate = "crate::arguments")]
pub fn centroidal_momentum_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    weights: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("weights", &weights, &[6])])?;
    let packed = run_packed(py, &model, &batch, 2 * nv * nv + nv, |m, w, i, out| {
        let (q, v, f) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let weights: [f64; 6] = f.try_into().expect("six weights, as broadcast");
        let (qq, rest) = out.split_at_mut(nv * nv);
        let (qv, gradient) = rest.split_at_mut(nv * nv);
        algorithms::centroidal_momentum_hessian(m, w.data(), q, v, &weights, qq, qv, gradient)?;
        Ok(())
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[nv, nv], &[nv, nv], &[nv]])?.into_iter();
    let mut next = || parts.next().expect("three");
    Ok((next(), next(), next()))
}

/// Mass properties of the subtree rooted at each body, in world coordinates (inertia about the subtree's
/// COM): `(mass (..., nbodies), com (..., nbodies, 3), inertia (..., nbodies, 3, 3))`.
#[pyfunction(crate = "crate::arguments")]
pub fn subtree_mass_properties<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let nb = model.model.nbodies();
    let batch = broadcast(&[("q", &q, &[model.model.nq()])])?;
    let packed = run_packed(py, &model, &batch, 13 * nb, |m, w, i, out| {
        let q = batch.rows[0].row(i);
        let (masses, rest) = out.split_at_mut(nb);
        let (coms, inertias) = rest.split_at_mut(3 * nb);
        for (b, body) in algorithms::subtree_mass_properties(m, w.data(), q)?.iter().enumerate() {
            masses[b] = body.mass();
            coms[3 * b..3 * b + 3].copy_from_slice(body.com().as_slice());
            inertias[9 * b..9 * b + 9].copy_from_slice(body.inertia().transpose().as_slice());
        }
        Ok(())
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[nb], &[nb, 3], &[nb, 3, 3]])?.into_iter();
    Ok((parts.next().unwrap(), parts.next().unwrap(), parts.next().unwrap()))
}

/// Centroidal momentum [h_lin, h_ang about the COM], world-aligned: `(..., 6)`.
#[pyfunction(crate = "crate::arguments")]
pub fn centroidal_momentum<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>, v: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()]), ("v", &v, &[m.nv()])])?;
    run(py, &model, &batch, &[6], |m, w, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        out.copy_from_slice(algorithms::centroidal_momentum(m, w.data(), q, v)?.as_slice());
        Ok(())
    })
}

/// The centroidal momentum matrix A_G, `centroidal_momentum(q, v) = A_G(q) v`: `(..., 6, nv)`.
#[pyfunction(crate = "crate::arguments")]
pub fn centroidal_map<'py>(py: Python<'py>, model: PyRef<'_, PyModel>, q: ArrayArg<'_>) -> PyResult<FloatArray<'py>> {
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()])])?;
    run(py, &model, &batch, &[6, nv], |m, w, i, out| {
        let q = batch.rows[0].row(i);
        row_major(algorithms::centroidal_map(m, w.data(), q)?, out);
        Ok(())
    })
}

/// Time derivative of the centroidal momentum for joint accelerations `a` (gravity excluded): `(..., 6)`.
#[pyfunction(crate = "crate::arguments")]
pub fn centroidal_momentum_rate<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
) -> PyResult<FloatArray<'py>> {
    let m = &model.model;
    let batch = broadcast(&[("q", &q, &[m.nq()]), ("v", &v, &[m.nv()]), ("a", &a, &[m.nv()])])?;
    run(py, &model, &batch, &[6], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        out.copy_from_slice(algorithms::centroidal_momentum_rate(m, w.data(), q, v, a)?.as_slice());
        Ok(())
    })
}

/// A k x nv matrix (column-major, as nalgebra stores it) written row by row, as NumPy reads it.
pub(crate) fn row_major<R: Dim, S: RawStorage<f64, R, Dyn>>(matrix: &Matrix<f64, R, Dyn, S>, out: &mut [f64]) {
    for (r, row) in out.chunks_exact_mut(matrix.ncols()).enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = matrix[(r, c)];
        }
    }
}

/// The velocity `[linear; angular]` of the frame at `point` on `body` in `frame` (Pinocchio's `getFrameVelocity`):
/// `(..., 6)`.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, body, point = None, frame = "local_world_aligned"))]
pub fn frame_velocity<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<FloatArray<'py>> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[model.model.nv()])])?;
    run(py, &model, &batch, &[6], |m, w, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        out.copy_from_slice(algorithms::frame_velocity(m, w.data(), q, v, body, &point, convention)?.as_slice());
        Ok(())
    })
}

/// The spatial acceleration `[linear; angular]` of the frame at `point` on `body` in `frame` for joint accelerations
/// `a`, gravity excluded (Pinocchio's `getFrameAcceleration`; the classical acceleration of the point is the
/// "local_world_aligned" linear part plus ω × v): `(..., 6)`.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, a, body, point = None, frame = "local_world_aligned"))]
#[allow(clippy::too_many_arguments)]
pub fn frame_acceleration<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<FloatArray<'py>> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("a", &a, &[nv])])?;
    run(py, &model, &batch, &[6], |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        out.copy_from_slice(algorithms::frame_acceleration(m, w.data(), q, v, a, body, &point, convention)?.as_slice());
        Ok(())
    })
}

/// ∂v/∂q and ∂v/∂v (the Jacobian) of `frame_velocity`, q on its tangent space: each `(..., 6, nv)`. Pinocchio's
/// `getFrameVelocityDerivatives`, except in "local_world_aligned", where Pinocchio holds the frame's origin still and
/// its ∂v/∂q lacks ω × J_lin in the linear rows.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, body, point = None, frame = "local_world_aligned"))]
pub fn frame_velocity_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>)> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv])])?;
    let packed = run_packed(py, &model, &batch, 12 * nv, |m, w, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        let (dq, dv) = algorithms::frame_velocity_derivatives(m, w.data(), q, v, body, &point, convention)?;
        for (matrix, chunk) in [dq, dv].into_iter().zip(out.chunks_exact_mut(6 * nv)) {
            row_major(matrix, chunk);
        }
        Ok(())
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[6, nv], &[6, nv]])?.into_iter();
    Ok((parts.next().expect("two"), parts.next().expect("two")))
}

/// ∂v/∂q, ∂a/∂q, ∂a/∂v and ∂a/∂a (the Jacobian) of `frame_velocity` and `frame_acceleration`, q on its tangent space:
/// each `(..., 6, nv)` (Pinocchio's `getFrameAccelerationDerivatives`, except as `frame_velocity_derivatives` says in
/// "local_world_aligned", where Pinocchio's ∂a/∂q also lacks α × J_lin).
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, a, body, point = None, frame = "local_world_aligned"))]
#[allow(clippy::too_many_arguments)]
pub fn frame_acceleration_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    a: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<(FloatArray<'py>, FloatArray<'py>, FloatArray<'py>, FloatArray<'py>)> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("a", &a, &[nv])])?;
    let packed = run_packed(py, &model, &batch, 24 * nv, |m, w, i, out| {
        let (q, v, a) = (batch.rows[0].row(i), batch.rows[1].row(i), batch.rows[2].row(i));
        let (v_dq, a_dq, a_dv, a_da) = algorithms::frame_acceleration_derivatives(m, w.data(), q, v, a, body, &point, convention)?;
        for (matrix, chunk) in [v_dq, a_dq, a_dv, a_da].into_iter().zip(out.chunks_exact_mut(6 * nv)) {
            row_major(matrix, chunk);
        }
        Ok(())
    })?;
    let mut parts = unpack(py, &batch, &packed, &[&[6, nv], &[6, nv], &[6, nv], &[6, nv]])?.into_iter();
    let mut next = || parts.next().expect("four");
    Ok((next(), next(), next(), next()))
}

/// The time derivative of the frame's Jacobian along the velocity `v` (Pinocchio's `getFrameJacobianTimeVariation`):
/// `(..., 6, nv)`. In "local_world_aligned", the point's classical acceleration is J a + J̇ v + ω × v_point.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (model, q, v, body, point = None, frame = "local_world_aligned"))]
pub fn jacobian_time_variation<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyModel>,
    q: ArrayArg<'_>,
    v: ArrayArg<'_>,
    body: &Bound<'_, PyAny>,
    point: Option<Vector<'_>>,
    frame: &str,
) -> PyResult<FloatArray<'py>> {
    let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
    let nv = model.model.nv();
    let batch = broadcast(&[("q", &q, &[model.model.nq()]), ("v", &v, &[nv])])?;
    run(py, &model, &batch, &[6, nv], |m, w, i, out| {
        let (q, v) = (batch.rows[0].row(i), batch.rows[1].row(i));
        row_major(algorithms::jacobian_time_variation(m, w.data(), q, v, body, &point, convention)?, out);
        Ok(())
    })
}
