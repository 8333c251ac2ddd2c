//! Kinematic quantities over batches: poses, Jacobians, centre of mass, subtree mass properties and
//! centroidal momentum.

use legkit_dynamics::algorithms::{self, Frame};
use nalgebra::{Dim, Dyn, Matrix, Matrix6xX, RawStorage, Vector3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::batch::{split, ArrayArg};
use crate::convert::{homogeneous, vector3, Arrays2, Arrays3, Arrays4, Arrays5, FloatArray, Vector};
use crate::model::PyModel;
use crate::workspace::{batched, batched_parts};

model_function! {
    /// World pose (4x4) of every body: `(..., nbodies, 4, 4)`.
    fn forward_kinematics(py, model, q: ArrayArg) -> FloatArray<'py> {
        let m = &model.model;
        batched(py, &model, [("q", &q, &[m.nq()])], &[m.nbodies(), 4, 4], |m, w, [q], out| {
            let data = w.data();
            algorithms::forward_kinematics(m, data, q)?;
            for (pose, chunk) in data.o_m_i.iter().zip(out.chunks_exact_mut(16)) {
                chunk.copy_from_slice(&homogeneous(pose));
            }
            Ok(())
        })
    }
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

model_function! {
    /// The 6 x nv Jacobian (rows [linear; angular]) of the frame at `point` (body coordinates, default the
    /// origin) on `body` (index or name), in Pinocchio's `frame` convention: "local", "world" or
    /// "local_world_aligned" (the point's velocity in world axes). `(..., 6, nv)`.
    #[pyo3(signature = (model, q, body, point = None, frame = "local_world_aligned"))]
    fn jacobian(py, model, q: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> FloatArray<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        let nv = model.model.nv();
        of_configuration(py, &model, &q, &[6, nv], |m, data, q, out| {
            row_major(algorithms::jacobian(m, data, q, body, &point, convention)?, out);
            Ok(())
        })
    }
}

/// A kernel of the configuration alone over a batch of q: `kernel(model, data, q, out)` writes each row's `shape` numbers.
fn of_configuration<'py>(
    py: Python<'py>, model: &PyModel, q: &ArrayArg<'_>, shape: &[usize],
    kernel: impl Fn(&legkit_dynamics::Model, &mut legkit_dynamics::Data, &[f64], &mut [f64]) -> Result<(), legkit_dynamics::Error> + Sync,
) -> PyResult<FloatArray<'py>> {
    batched(py, model, [("q", q, &[model.model.nq()])], shape, |m, w, [q], out| kernel(m, w.data(), q, out))
}

model_function! {
    /// d/dq_d of entry [r, a] of `jacobian` at [r, a, d] (Pinocchio's `getJointKinematicHessian`; q on its tangent space,
    /// as `rnea_derivatives`), in "world" or "local_world_aligned": `(..., 6, nv, nv)`. Along q_d, the slope of
    /// w . J_lin (the gradient of w . position): `np.einsum("r,rad->ad", w, H[..., :3, :, :])`.
    #[pyo3(signature = (model, q, body, point = None, frame = "local_world_aligned"))]
    fn kinematic_hessian(py, model, q: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> FloatArray<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        if convention == Frame::Local {
            return Err(PyValueError::new_err("frame: kinematic_hessian takes \"world\" or \"local_world_aligned\", got \"local\""));
        }
        let nv = model.model.nv();
        of_configuration(py, &model, &q, &[6, nv, nv], |m, data, q, out| algorithms::kinematic_hessian(m, data, q, body, &point, convention, out))
    }
}

model_function! {
    /// (Hessian `(..., nv, nv)`, gradient `(..., nv)`) with respect to q (on its tangent space, as `rnea_derivatives`;
    /// entry [e, d] the slope along q_d of the gradient's entry e) of `weights` . the world velocity J_lin(q) v of
    /// `point` on `body`: the curvature of a load's virtual power F . J(q) v.
    #[pyo3(signature = (model, q, v, body, point, weights))]
    fn point_velocity_hessian(py, model, q: ArrayArg, v: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, weights: ArrayArg) -> Arrays2<'py> {
        let (body, point, _) = frame_arguments(&model, body, point, "local_world_aligned")?;
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("weights", &weights, &[3])];
        let [hessian, gradient] = batched_parts(py, &model, arguments, [&[nv, nv], &[nv]], |m, w, [q, v, f], out| {
            let [hessian, gradient] = split(out, [nv * nv, nv]);
            algorithms::point_velocity_hessian(m, w.data(), q, v, body, &point, &Vector3::from_column_slice(f), hessian, gradient)
        })?;
        Ok((hessian, gradient))
    }
}

model_function! {
    /// (qq, qv, vv, qa, q-gradient) of `weights` . the classical world acceleration of `point` on `body` (as
    /// `point_accelerations`), with respect to q (on its tangent space, as `rnea_derivatives`), v and a: each `(..., nv, nv)`
    /// (qq `[b, d]` the slope along q_d of the gradient's entry b; qv, qa `[d, e]` = d2/dq_d dv_e, d2/dq_d da_e), the
    /// gradient `(..., nv)`; aa and va are zero.
    #[pyo3(signature = (model, q, v, a, body, point, weights))]
    fn point_acceleration_hessian(py, model,
        q: ArrayArg, v: ArrayArg, a: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, weights: ArrayArg) -> Arrays5<'py> {
        let (body, point, _) = frame_arguments(&model, body, point, "local_world_aligned")?;
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("a", &a, &[nv]), ("weights", &weights, &[3])];
        let square: &[usize] = &[nv, nv];
        let [qq, qv, vv, qa, gradient] = batched_parts(py, &model, arguments, [square, square, square, square, &[nv]], |m, w, [q, v, a, f], out| {
            algorithms::point_acceleration_hessian(m, w.data(), q, v, a, body, &point, &Vector3::from_column_slice(f), out)
        })?;
        Ok((qq, qv, vv, qa, gradient))
    }
}

model_function! {
    /// The model's centre of mass in the world frame: `(..., 3)`.
    fn center_of_mass(py, model, q: ArrayArg) -> FloatArray<'py> {
        batched(py, &model, [("q", &q, &[model.model.nq()])], &[3], |m, w, [q], out| {
            out.copy_from_slice(algorithms::center_of_mass(m, w.data(), q)?.as_slice());
            Ok(())
        })
    }
}

model_function! {
    /// (Hessian `(..., nv, nv)`, gradient `(..., nv)`) with respect to q (on its tangent space, as `rnea_derivatives`;
    /// entry [e, d] the slope along q_d of the gradient's entry e) of `weights` . the world centre of mass.
    fn center_of_mass_hessian(py, model, q: ArrayArg, weights: ArrayArg) -> Arrays2<'py> {
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("weights", &weights, &[3])];
        let [hessian, gradient] = batched_parts(py, &model, arguments, [&[nv, nv], &[nv]], |m, w, [q, f], out| {
            let [hessian, gradient] = split(out, [nv * nv, nv]);
            algorithms::center_of_mass_hessian(m, w.data(), q, &Vector3::from_column_slice(f), hessian, gradient)
        })?;
        Ok((hessian, gradient))
    }
}

model_function! {
    /// (qq, qv, q-gradient) of `weights` (..., 6) . the centroidal momentum h = [linear; angular about the COM]
    /// (`centroidal_momentum`): qq `(..., nv, nv)` (entry [e, d] the slope along q_d of the gradient's entry e, q on its
    /// tangent space), qv `(..., nv, nv)` (entry [d, e] = d2/dq_d dv_e), the gradient `(..., nv)`; vv is zero.
    fn centroidal_momentum_hessian(py, model, q: ArrayArg, v: ArrayArg, weights: ArrayArg) -> Arrays3<'py> {
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("weights", &weights, &[6])];
        let [qq, qv, gradient] = batched_parts(py, &model, arguments, [&[nv, nv], &[nv, nv], &[nv]], |m, w, [q, v, f], out| {
            let weights: [f64; 6] = f.try_into().expect("six weights, as broadcast");
            let [qq, qv, gradient] = split(out, [nv * nv, nv * nv, nv]);
            algorithms::centroidal_momentum_hessian(m, w.data(), q, v, &weights, qq, qv, gradient)
        })?;
        Ok((qq, qv, gradient))
    }
}

model_function! {
    /// Mass properties of the subtree rooted at each body, in world coordinates (inertia about the subtree's
    /// COM): `(mass (..., nbodies), com (..., nbodies, 3), inertia (..., nbodies, 3, 3))`.
    fn subtree_mass_properties(py, model, q: ArrayArg) -> Arrays3<'py> {
        let nb = model.model.nbodies();
        let [mass, com, inertia] = batched_parts(py, &model, [("q", &q, &[model.model.nq()])], [&[nb], &[nb, 3], &[nb, 3, 3]], |m, w, [q], out| {
            let [masses, coms, inertias] = split(out, [nb, 3 * nb, 9 * nb]);
            for (b, body) in algorithms::subtree_mass_properties(m, w.data(), q)?.iter().enumerate() {
                masses[b] = body.mass();
                coms[3 * b..3 * b + 3].copy_from_slice(body.com().as_slice());
                inertias[9 * b..9 * b + 9].copy_from_slice(body.inertia().transpose().as_slice());
            }
            Ok(())
        })?;
        Ok((mass, com, inertia))
    }
}

model_function! {
    /// Centroidal momentum [h_lin, h_ang about the COM], world-aligned: `(..., 6)`.
    fn centroidal_momentum(py, model, q: ArrayArg, v: ArrayArg) -> FloatArray<'py> {
        let m = &model.model;
        batched(py, &model, [("q", &q, &[m.nq()]), ("v", &v, &[m.nv()])], &[6], |m, w, [q, v], out| {
            out.copy_from_slice(algorithms::centroidal_momentum(m, w.data(), q, v)?.as_slice());
            Ok(())
        })
    }
}

model_function! {
    /// The centroidal momentum matrix A_G, `centroidal_momentum(q, v) = A_G(q) v`: `(..., 6, nv)`.
    fn centroidal_map(py, model, q: ArrayArg) -> FloatArray<'py> {
        let nv = model.model.nv();
        of_configuration(py, &model, &q, &[6, nv], |m, data, q, out| {
            row_major(algorithms::centroidal_map(m, data, q)?, out);
            Ok(())
        })
    }
}

model_function! {
    /// Time derivative of the centroidal momentum for joint accelerations `a` (gravity excluded): `(..., 6)`.
    fn centroidal_momentum_rate(py, model, q: ArrayArg, v: ArrayArg, a: ArrayArg) -> FloatArray<'py> {
        let m = &model.model;
        batched(py, &model, [("q", &q, &[m.nq()]), ("v", &v, &[m.nv()]), ("a", &a, &[m.nv()])], &[6], |m, w, [q, v, a], out| {
            out.copy_from_slice(algorithms::centroidal_momentum_rate(m, w.data(), q, v, a)?.as_slice());
            Ok(())
        })
    }
}

/// A k x nv matrix (column-major, as nalgebra stores it) written row by row, as NumPy reads it.
pub(crate) fn row_major<R: Dim, S: RawStorage<f64, R, Dyn>>(matrix: &Matrix<f64, R, Dyn, S>, out: &mut [f64]) {
    let columns = matrix.ncols();
    for r in 0..matrix.nrows() {
        for c in 0..columns {
            out[r * columns + c] = matrix[(r, c)];
        }
    }
}

/// `matrices` written row-major (`row_major`) one after the other into `out`.
fn row_major_each<const N: usize>(matrices: [&Matrix6xX<f64>; N], mut out: &mut [f64]) {
    for matrix in matrices {
        let (chunk, rest) = std::mem::take(&mut out).split_at_mut(matrix.len());
        row_major(matrix, chunk);
        out = rest;
    }
}

model_function! {
    /// The velocity `[linear; angular]` of the frame at `point` on `body` in `frame` (Pinocchio's `getFrameVelocity`):
    /// `(..., 6)`.
    #[pyo3(signature = (model, q, v, body, point = None, frame = "local_world_aligned"))]
    fn frame_velocity(py, model, q: ArrayArg, v: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> FloatArray<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        batched(py, &model, [("q", &q, &[model.model.nq()]), ("v", &v, &[model.model.nv()])], &[6], |m, w, [q, v], out| {
            out.copy_from_slice(algorithms::frame_velocity(m, w.data(), q, v, body, &point, convention)?.as_slice());
            Ok(())
        })
    }
}

model_function! {
    /// The spatial acceleration `[linear; angular]` of the frame at `point` on `body` in `frame` for joint accelerations
    /// `a`, gravity excluded (Pinocchio's `getFrameAcceleration`; the classical acceleration of the point is the
    /// "local_world_aligned" linear part plus ω × v): `(..., 6)`.
    #[pyo3(signature = (model, q, v, a, body, point = None, frame = "local_world_aligned"))]
    fn frame_acceleration(py, model,
        q: ArrayArg, v: ArrayArg, a: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> FloatArray<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        let nv = model.model.nv();
        batched(py, &model, [("q", &q, &[model.model.nq()]), ("v", &v, &[nv]), ("a", &a, &[nv])], &[6], |m, w, [q, v, a], out| {
            out.copy_from_slice(algorithms::frame_acceleration(m, w.data(), q, v, a, body, &point, convention)?.as_slice());
            Ok(())
        })
    }
}

model_function! {
    /// ∂v/∂q and ∂v/∂v (the Jacobian) of `frame_velocity`, q on its tangent space: each `(..., 6, nv)`. Pinocchio's
    /// `getFrameVelocityDerivatives`, except in "local_world_aligned", where Pinocchio holds the frame's origin still and
    /// its ∂v/∂q lacks ω × J_lin in the linear rows.
    #[pyo3(signature = (model, q, v, body, point = None, frame = "local_world_aligned"))]
    fn frame_velocity_derivatives(py, model, q: ArrayArg, v: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> Arrays2<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv])];
        let [dq, dv] = batched_parts(py, &model, arguments, [&[6, nv]; 2], |m, w, [q, v], out| {
            let (dq, dv) = algorithms::frame_velocity_derivatives(m, w.data(), q, v, body, &point, convention)?;
            row_major_each([dq, dv], out);
            Ok(())
        })?;
        Ok((dq, dv))
    }
}

model_function! {
    /// ∂v/∂q, ∂a/∂q, ∂a/∂v and ∂a/∂a (the Jacobian) of `frame_velocity` and `frame_acceleration`, q on its tangent space:
    /// each `(..., 6, nv)` (Pinocchio's `getFrameAccelerationDerivatives`, except as `frame_velocity_derivatives` says in
    /// "local_world_aligned", where Pinocchio's ∂a/∂q also lacks α × J_lin).
    #[pyo3(signature = (model, q, v, a, body, point = None, frame = "local_world_aligned"))]
    fn frame_acceleration_derivatives(py, model,
        q: ArrayArg, v: ArrayArg, a: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> Arrays4<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        let nv = model.model.nv();
        let arguments = [("q", &q, &[model.model.nq()][..]), ("v", &v, &[nv]), ("a", &a, &[nv])];
        let [v_dq, a_dq, a_dv, a_da] = batched_parts(py, &model, arguments, [&[6, nv]; 4], |m, w, [q, v, a], out| {
            let (v_dq, a_dq, a_dv, a_da) = algorithms::frame_acceleration_derivatives(m, w.data(), q, v, a, body, &point, convention)?;
            row_major_each([v_dq, a_dq, a_dv, a_da], out);
            Ok(())
        })?;
        Ok((v_dq, a_dq, a_dv, a_da))
    }
}

model_function! {
    /// The time derivative of the frame's Jacobian along the velocity `v` (Pinocchio's `getFrameJacobianTimeVariation`):
    /// `(..., 6, nv)`. In "local_world_aligned", the point's classical acceleration is J a + J̇ v + ω × v_point.
    #[pyo3(signature = (model, q, v, body, point = None, frame = "local_world_aligned"))]
    fn jacobian_time_variation(py, model, q: ArrayArg, v: ArrayArg, body: &Bound<PyAny>, point: Option<Vector>, frame: &str) -> FloatArray<'py> {
        let (body, point, convention) = frame_arguments(&model, body, point, frame)?;
        let nv = model.model.nv();
        batched(py, &model, [("q", &q, &[model.model.nq()]), ("v", &v, &[nv])], &[6, nv], |m, w, [q, v], out| {
            row_major(algorithms::jacobian_time_variation(m, w.data(), q, v, body, &point, convention)?, out);
            Ok(())
        })
    }
}
