//! Analytic derivatives of a frame's kinematics (Pinocchio's `getFrameVelocityDerivatives`,
//! `getFrameAccelerationDerivatives` and `getFrameJacobianTimeVariation`): the velocity and spatial acceleration of a
//! frame fixed to a body, differentiated with respect to q (on its tangent space, as `rnea_derivatives`), q̇ and q̈,
//! and the time derivative J̇ of its Jacobian (a contact's acceleration is J q̈ + J̇ q̇ + ω × v). The derivative of
//! the frame's placement on the tangent space is its Jacobian in `Frame::Local` (`jacobian`).
//!
//! From the forward pass the RNEA derivatives share (`motion_derivatives`; Carpentier & Mansard, RSS 2018): a change of
//! joint j's coordinate moves the body's frame rigidly about S_j and changes its world velocity and acceleration, apart
//! from that motion, by the columns ∂v/∂q and ∂a/∂q − v × ∂v/∂q. Each frame's result is the derivative of what
//! `frame_velocity` and `frame_acceleration` return. Pinocchio's `LOCAL_WORLD_ALIGNED` q-derivatives differ from
//! these in the linear rows, by ω × J_lin for the velocity and α × J_lin for the acceleration: they hold the frame's
//! origin still.

use nalgebra::{Matrix6xX, Vector3};

use super::checks::{check_frame_state, finite_result};
use super::jacobian::Frame;
use super::joint_placement;
use super::rnea_derivatives::{column, motion_derivatives, set_column};
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_motion, linear, spatial, Motion, Transform};
use crate::Result;

/// A frame at `point` on a body after `motion_derivatives`: its pose in the centred frame, its origin in the world,
/// and its velocity and acceleration (world axes, about its origin: `Frame::LocalWorldAligned`).
pub(crate) struct FramePoint {
    pub body: usize,
    pub pose: Transform,
    pub origin: Vector3<f64>,
    pub velocity: Motion,
    pub acceleration: Motion,
}

/// A motion about the centred frame's origin, taken about `point` (centred coordinates) instead.
#[inline(always)]
pub(crate) fn about(m: &Motion, point: &Vector3<f64>) -> Motion {
    spatial(linear(m) + angular(m).cross(point), angular(m))
}

impl FramePoint {
    pub(crate) fn new(model: &Model, data: &Data, q: &[f64], body: usize, point: &Vector3<f64>) -> Self {
        let body_pose = data.centred_m_i[body];
        let centred = body_pose.transform_point(point);
        let d = &data.derivatives;
        FramePoint {
            body,
            pose: Transform::new(body_pose.rotation, centred),
            // The centred frame sits at the base's origin, in world axes.
            origin: centred + joint_placement(model, 0, q).translation,
            velocity: about(&d.velocity[body], &centred),
            acceleration: about(&d.acceleration[body], &centred),
        }
    }

    /// The classical acceleration of the frame's origin, world axes: the spatial acceleration's linear part plus ω × v.
    pub(crate) fn classical_acceleration(&self) -> Vector3<f64> {
        linear(&self.acceleration) + angular(&self.velocity).cross(&linear(&self.velocity))
    }

    /// `value` (world axes, about the frame's origin) in `frame`.
    pub(crate) fn express(&self, value: &Motion, frame: Frame) -> Motion {
        match frame {
            Frame::LocalWorldAligned => *value,
            Frame::Local => self.rotated_back(value),
            Frame::World => spatial(linear(value) - angular(value).cross(&self.origin), angular(value)),
        }
    }

    fn rotated_back(&self, m: &Motion) -> Motion {
        let r = &self.pose.rotation;
        spatial(r.tr_mul(&linear(m)), r.tr_mul(&angular(m)))
    }

    /// A derivative column in `frame`: `change` (centred coordinates) is the change of a quantity apart from the rigid
    /// motion of the frame, `value` the quantity (world axes, about the frame's origin), and the change of coordinates
    /// turns the frame at `turn` and moves its origin at `travel` (both zero for a change of q̇ or q̈). World-aligned
    /// axes stay while the frame turns, so the value's turn adds to the change there; the world's origin stays while
    /// the frame's moves, so the moment arm's change adds there too.
    pub(crate) fn derivative(&self, change: &Motion, value: &Motion, turn: &Vector3<f64>, travel: &Vector3<f64>, frame: Frame) -> Motion {
        let shifted = about(change, &self.pose.translation);
        if frame == Frame::Local {
            return self.rotated_back(&shifted);
        }
        let aligned = shifted + spatial(turn.cross(&linear(value)), turn.cross(&angular(value)));
        match frame {
            Frame::World => spatial(linear(&aligned) - angular(value).cross(travel) - angular(&aligned).cross(&self.origin), angular(&aligned)),
            _ => aligned,
        }
    }

    /// Calls `visit(column, body)` for each velocity coordinate that moves the frame (its body's support), from the
    /// body to the root.
    pub(crate) fn support(&self, model: &Model, visit: impl FnMut(usize, usize)) {
        support(model, self.body, visit);
    }

    /// Column `c` of the frame's Jacobian (world axes, about its origin) from the joints' columns `subspace`.
    pub(crate) fn jacobian_column(&self, subspace: &Matrix6xX<f64>, c: usize) -> Motion {
        about(&column(subspace, c), &self.pose.translation)
    }
}

/// Calls `visit(column, joint)` for each velocity coordinate of `joint` and of its ancestors, from it to the root.
pub(crate) fn support(model: &Model, joint: usize, mut visit: impl FnMut(usize, usize)) {
    joints_to_root(model, joint, |coordinates, j| coordinates.for_each(|c| visit(c, j)));
}

/// Calls `visit(coordinates, joint)` with the velocity coordinates of `joint` and of each of its ancestors, from it to the
/// root.
pub(crate) fn joints_to_root(model: &Model, joint: usize, mut visit: impl FnMut(std::ops::Range<usize>, usize)) {
    let mut j = joint;
    loop {
        let k = model.idx_v(j);
        visit(k..k + model.joint(j).nv(), j);
        if j == 0 {
            break;
        }
        j = model.parent(j);
    }
}

/// The velocity (rows `[linear; angular]`) of the frame at `point` (body coordinates) on `body`, in `frame`, at
/// configuration `q` and velocity `v` (Pinocchio's `getFrameVelocity`).
pub fn frame_velocity(model: &Model, data: &mut Data, q: &[f64], v: &[f64], body: usize, point: &Vector3<f64>, frame: Frame) -> Result<Motion> {
    check_frame_state(model, data, q, &[("v", v)], body, point)?;
    motion_derivatives(model, data, q, v, None, Motion::zeros());
    let at = FramePoint::new(model, data, q, body, point);
    let velocity = at.express(&at.velocity, frame);
    finite_result(velocity.as_slice())?;
    Ok(velocity)
}

/// The spatial acceleration (gravity excluded; rows `[linear; angular]`) of the frame at `point` on `body`, in `frame`,
/// for joint accelerations `a` (Pinocchio's `getFrameAcceleration`). The classical acceleration of the frame's origin
/// is the world-aligned linear part plus ω × v.
#[allow(clippy::too_many_arguments)]
pub fn frame_acceleration(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64], body: usize, point: &Vector3<f64>, frame: Frame,
) -> Result<Motion> {
    check_frame_state(model, data, q, &[("v", v), ("a", a)], body, point)?;
    motion_derivatives(model, data, q, v, Some(a), Motion::zeros());
    let at = FramePoint::new(model, data, q, body, point);
    let acceleration = at.express(&at.acceleration, frame);
    finite_result(acceleration.as_slice())?;
    Ok(acceleration)
}

/// ∂v/∂q and ∂v/∂q̇ (6 x nv each; the second is the frame's Jacobian) of `frame_velocity`. Writes
/// `data.derivatives.frame_velocity_dq` and `frame_velocity_dv` and returns them.
///
/// # Examples
///
/// The velocity of a double pendulum's tip (links 0.4 m long, hinged about y; built in the hidden lines) is J q̇; its
/// derivatives are the Jacobian (by q̇) and, checked here against central differences of `frame_velocity`, its slope
/// along q.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
/// # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
/// # let mut model = Model::new(false, MassProperties::zero(), "base");
/// # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
/// # let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
/// # model.add_body(1, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
/// # let mut data = Data::new(&model);
/// # let nudge = |x: [f64; 2], k: usize, step: f64| { let mut x = x; x[k] += step; x };
/// use legkit_dynamics::algorithms::Frame;
/// let (q, v, tip, frame, h) = ([0.3, -0.5], [1.0, 2.0], Vector3::new(0.0, 0.0, -0.4), Frame::LocalWorldAligned, 1e-6);
/// let velocity = algorithms::frame_velocity(&model, &mut data, &q, &v, 2, &tip, frame)?;
/// let j = algorithms::jacobian(&model, &mut data, &q, 2, &tip, frame)?.clone();
/// assert!((velocity - &j * DVector::from_row_slice(&v)).norm() < 1e-12);
/// let (dq, dv) = algorithms::frame_velocity_derivatives(&model, &mut data, &q, &v, 2, &tip, frame)?;
/// let (dq, dv) = (dq.clone(), dv.clone());
/// assert!((dv - &j).amax() < 1e-12);
/// for k in 0..2 {
///     let plus = algorithms::frame_velocity(&model, &mut data, &nudge(q, k, h), &v, 2, &tip, frame)?;
///     let minus = algorithms::frame_velocity(&model, &mut data, &nudge(q, k, -h), &v, 2, &tip, frame)?;
///     assert!((dq.column(k) - (plus - minus) / (2.0 * h)).norm() < 1e-8);
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn frame_velocity_derivatives<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], body: usize, point: &Vector3<f64>, frame: Frame,
) -> Result<(&'d Matrix6xX<f64>, &'d Matrix6xX<f64>)> {
    check_frame_state(model, data, q, &[("v", v)], body, point)?;
    motion_derivatives(model, data, q, v, None, Motion::zeros());
    let at = FramePoint::new(model, data, q, body, point);
    let d = &mut data.derivatives;
    d.frame_velocity_dq.fill(0.0);
    d.frame_velocity_dv.fill(0.0);
    at.support(model, |c, _| {
        let s = at.jacobian_column(&d.subspace, c);
        let (turn, travel) = (angular(&s), linear(&s));
        set_column(&mut d.frame_velocity_dq, c, &at.derivative(&column(&d.dv_dq, c), &at.velocity, &turn, &travel, frame));
        set_column(&mut d.frame_velocity_dv, c, &at.express(&s, frame));
    });
    finite_result(d.frame_velocity_dq.as_slice())?;
    finite_result(d.frame_velocity_dv.as_slice())?;
    Ok((&d.frame_velocity_dq, &d.frame_velocity_dv))
}

/// ∂v/∂q, ∂a/∂q, ∂a/∂q̇ and ∂a/∂q̈ (6 x nv each; the last is the frame's Jacobian) of `frame_velocity` and
/// `frame_acceleration`. Writes them to `data.derivatives` (`frame_velocity_dq`, `frame_acceleration_dq`, `_dv`,
/// `_da`) and returns them.
///
/// # Examples
///
/// In world axes about the world's origin (`Frame::World`) a frame's spatial acceleration is d/dt (J q̇) = J q̈ + J̇ q̇,
/// J̇ from `jacobian_time_variation`. Of the acceleration's derivatives (`frame_acceleration_derivatives`), the one by
/// q̈ is J, and the one by q̇ is checked here against central differences.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
/// # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
/// # let mut model = Model::new(false, MassProperties::zero(), "base");
/// # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
/// # let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
/// # model.add_body(1, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
/// # let mut data = Data::new(&model);
/// # let nudge = |x: [f64; 2], k: usize, step: f64| { let mut x = x; x[k] += step; x };
/// use legkit_dynamics::algorithms::Frame;
/// let (q, v, a, tip, h) = ([0.3, -0.5], [1.0, 2.0], [-3.0, 0.5], Vector3::new(0.0, 0.0, -0.4), 1e-6);
/// let acceleration = algorithms::frame_acceleration(&model, &mut data, &q, &v, &a, 2, &tip, Frame::World)?;
/// let j = algorithms::jacobian(&model, &mut data, &q, 2, &tip, Frame::World)?.clone();
/// let j_rate = algorithms::jacobian_time_variation(&model, &mut data, &q, &v, 2, &tip, Frame::World)?.clone();
/// let (velocity, accelerations) = (DVector::from_row_slice(&v), DVector::from_row_slice(&a));
/// assert!((acceleration - (&j * accelerations + j_rate * velocity)).norm() < 1e-12);
/// let (_, _, by_v, by_a) = algorithms::frame_acceleration_derivatives(&model, &mut data, &q, &v, &a, 2, &tip, Frame::World)?;
/// let (by_v, by_a) = (by_v.clone(), by_a.clone());
/// assert!((by_a - &j).amax() < 1e-12);
/// for k in 0..2 {
///     let plus = algorithms::frame_acceleration(&model, &mut data, &q, &nudge(v, k, h), &a, 2, &tip, Frame::World)?;
///     let minus = algorithms::frame_acceleration(&model, &mut data, &q, &nudge(v, k, -h), &a, 2, &tip, Frame::World)?;
///     assert!((by_v.column(k) - (plus - minus) / (2.0 * h)).norm() < 1e-8);
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn frame_acceleration_derivatives<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], body: usize, point: &Vector3<f64>, frame: Frame,
) -> Result<FrameAccelerationDerivatives<'d>> {
    check_frame_state(model, data, q, &[("v", v), ("a", a)], body, point)?;
    motion_derivatives(model, data, q, v, Some(a), Motion::zeros());
    let at = FramePoint::new(model, data, q, body, point);
    // Out of `data` while the pass's columns are read.
    let d = &mut data.derivatives;
    let mut out =
        [&mut d.frame_velocity_dq, &mut d.frame_acceleration_dq, &mut d.frame_acceleration_dv, &mut d.frame_acceleration_da].map(std::mem::take);
    out.iter_mut().for_each(|m| m.fill(0.0));
    for_each_frame_derivative(model, data, &at, frame, |c, x| {
        for (m, column) in out.iter_mut().zip([x.velocity_dq, x.acceleration_dq, x.acceleration_dv, x.jacobian]) {
            set_column(m, c, &column);
        }
    });
    let d = &mut data.derivatives;
    [d.frame_velocity_dq, d.frame_acceleration_dq, d.frame_acceleration_dv, d.frame_acceleration_da] = out;
    let out = (&d.frame_velocity_dq, &d.frame_acceleration_dq, &d.frame_acceleration_dv, &d.frame_acceleration_da);
    for matrix in [out.0, out.1, out.2, out.3] {
        finite_result(matrix.as_slice())?;
    }
    Ok(out)
}

/// ∂v/∂q, ∂a/∂q, ∂a/∂q̇, ∂a/∂q̈ of a frame.
pub type FrameAccelerationDerivatives<'d> = (&'d Matrix6xX<f64>, &'d Matrix6xX<f64>, &'d Matrix6xX<f64>, &'d Matrix6xX<f64>);

/// One velocity coordinate's column of a frame's derivatives.
pub(crate) struct FrameDerivative {
    pub velocity_dq: Motion,
    pub acceleration_dq: Motion,
    pub acceleration_dv: Motion,
    /// ∂v/∂q̇ = ∂a/∂q̈.
    pub jacobian: Motion,
}

/// Calls `visit(c, derivative)` for each velocity coordinate c that moves the frame, after `motion_derivatives`
/// (their non-rigid parts: the body's own velocity adds v × ∂v/∂q to ∂a/∂q and v × S to ∂a/∂q̇).
pub(crate) fn for_each_frame_derivative(model: &Model, data: &Data, at: &FramePoint, frame: Frame, mut visit: impl FnMut(usize, FrameDerivative)) {
    let d = &data.derivatives;
    let body_velocity = d.velocity[at.body];
    let zero = Vector3::zeros();
    at.support(model, |c, _| {
        let (subspace, dv_dq) = (column(&d.subspace, c), column(&d.dv_dq, c));
        let s = at.jacobian_column(&d.subspace, c);
        let (turn, travel) = (angular(&s), linear(&s));
        let da_dq = column(&d.da_dq, c) - cross_motion(&body_velocity, &dv_dq);
        let da_dv = column(&d.da_dv, c) - cross_motion(&body_velocity, &subspace);
        visit(
            c,
            FrameDerivative {
                velocity_dq: at.derivative(&dv_dq, &at.velocity, &turn, &travel, frame),
                acceleration_dq: at.derivative(&da_dq, &at.acceleration, &turn, &travel, frame),
                acceleration_dv: at.derivative(&da_dv, &at.acceleration, &zero, &zero, frame),
                jacobian: at.express(&s, frame),
            },
        );
    });
}

/// J̇ (6 x nv), the time derivative of the frame's Jacobian (`jacobian`) along q̇ = `v` (Pinocchio's
/// `getFrameJacobianTimeVariation`): column c is joint c's motion S_c carried by its body's velocity v_j × S_c, less the
/// frame's own turn. Writes `data.derivatives.jacobian_rate` and returns it.
pub fn jacobian_time_variation<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], body: usize, point: &Vector3<f64>, frame: Frame,
) -> Result<&'d Matrix6xX<f64>> {
    check_frame_state(model, data, q, &[("v", v)], body, point)?;
    motion_derivatives(model, data, q, v, None, Motion::zeros());
    let at = FramePoint::new(model, data, q, body, point);
    let d = &mut data.derivatives;
    d.jacobian_rate.fill(0.0);
    let (body_velocity, turn, travel) = (d.velocity[at.body], angular(&at.velocity), linear(&at.velocity));
    at.support(model, |c, j| {
        let subspace = column(&d.subspace, c);
        let change = cross_motion(&(d.velocity[j] - body_velocity), &subspace);
        let s = at.jacobian_column(&d.subspace, c);
        set_column(&mut d.jacobian_rate, c, &at.derivative(&change, &s, &turn, &travel, frame));
    });
    finite_result(d.jacobian_rate.as_slice())?;
    Ok(&d.jacobian_rate)
}
