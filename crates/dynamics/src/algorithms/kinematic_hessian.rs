//! The derivative of a frame's Jacobian with respect to q (Pinocchio's `getJointKinematicHessian`): the curvature
//! of a point's position, of which the Jacobian is the slope.
//!
//! A joint's world column S_a (`jacobian`'s `Frame::World`) moves rigidly with every joint before it: a change of
//! coordinate d of an ancestor (or of the same multi-DoF joint, whose coordinates perturb it on the right)
//! turns it as ∂S_a/∂q_d = S_d × S_a (Carpentier & Mansard, RSS 2018, eq. 7); joints after it leave it unchanged.
//! A point's linear column S_a,lin + ω_a × p also changes as the point moves: ω_a × J_lin,d.

use nalgebra::{Matrix6xX, Vector3};

use super::checks::{check_frame, check_frame_state, check_output, check_state, finite_result};
use super::jacobian::{jacobian_unchecked, Frame};
use super::kinematics_derivatives::{about, joints_to_root, support};
use super::rnea_derivatives::{column, set_column};
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_motion, linear, spatial, Motion};
use crate::validate::finite_vector;
use crate::{Error, Result};

/// `out` (6 x nv x nv, row-major, entry `[r, a, d]`): the slope along q_d (q on its tangent space, as
/// `rnea_derivatives`) of entry `[r, a]` of the Jacobian `jacobian(model, data, q, body, point, frame)` returns, for
/// `frame` `World` or `LocalWorldAligned` (`Local` is not covered). Runs `jacobian`; zero outside the body's support.
///
/// # Examples
///
/// The kinematic Hessian is the Jacobian's slope along q, entry `[r, a, d]` of `out` (6 x nv x nv, row-major) being
/// ∂J_ra/∂q_d: checked here against central differences of `jacobian` at the tip of a double pendulum (links 0.4 m
/// long, hinged about y; built in the hidden lines).
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
/// let (q, tip, nv, h) = ([0.3, -0.5], Vector3::new(0.0, 0.0, -0.4), 2, 1e-6);
/// let mut hessian = vec![0.0; 6 * nv * nv];
/// algorithms::kinematic_hessian(&model, &mut data, &q, 2, &tip, Frame::World, &mut hessian)?;
/// for d in 0..nv {
///     let plus = algorithms::jacobian(&model, &mut data, &nudge(q, d, h), 2, &tip, Frame::World)?.clone();
///     let slope = (plus - algorithms::jacobian(&model, &mut data, &nudge(q, d, -h), 2, &tip, Frame::World)?) / (2.0 * h);
///     for (r, a) in (0..6).flat_map(|r| (0..nv).map(move |a| (r, a))) {
///         assert!((hessian[(r * nv + a) * nv + d] - slope[(r, a)]).abs() < 1e-8);
///     }
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn kinematic_hessian(model: &Model, data: &mut Data, q: &[f64], body: usize, point: &Vector3<f64>, frame: Frame, out: &mut [f64]) -> Result<()> {
    check_state(model, data, q, &[])?;
    check_frame(model, body, point)?;
    if frame == Frame::Local {
        return Err(Error::invalid("frame", "kinematic_hessian takes World or LocalWorldAligned, got Local"));
    }
    check_output("out", out, 6 * model.nv() * model.nv())?;
    let nv = model.nv();
    jacobian_unchecked(model, data, q, body, point, Frame::World);
    let origin = data.o_m_i[body].transform_point(point);
    let columns = &data.jacobian;
    out.fill(0.0);
    support(model, body, |a, joint| {
        let s_a = column(columns, a);
        // ∂S_a/∂q_d = S_d × S_a for the coordinates d of joint a's joint and its ancestors.
        support(model, joint, |d, _| {
            let turned = cross_motion(&column(columns, d), &s_a);
            match frame {
                Frame::World => add(out, nv, a, d, &turned),
                _ => add(out, nv, a, d, &about(&turned, &origin)),
            }
        });
        if frame == Frame::LocalWorldAligned {
            // The point moves along J_lin,d under the column's angular part.
            support(model, body, |d, _| {
                let moved = angular(&s_a).cross(&linear(&about(&column(columns, d), &origin)));
                add(out, nv, a, d, &spatial(moved, Vector3::zeros()));
            });
        }
    });
    finite_result(out)
}

/// Adds `m` to entries `[r, a, d]` of the row-major 6 x nv x nv `out`.
#[inline(always)]
fn add(out: &mut [f64], nv: usize, a: usize, d: usize, m: &Motion) {
    for r in 0..6 {
        out[(r * nv + a) * nv + d] += m[r];
    }
}

/// The Hessian `out` (nv x nv, row-major, `[e, d]`: the slope along q_d of the gradient's entry e, q on its tangent
/// space) and the gradient `slope` (nv) of F · v_p(q), v_p = J_lin(q) v the velocity of `point` on `body` (world axes)
/// for joint velocity `v`, F = `weights`. With W_e = Σ_{a after e} v_a S_a (world columns, a at or after e's joint)
/// the derivative of the world velocity V is D_e V = S_e × W_e, and with J_e the point's linear column and m the later
/// of d and e: D_d(S_e × W_e) = [d ≼ e] (S_d × S_e) × W_e + S_e × (S_d × W_m). Runs `jacobian`; W goes to
/// `data.derivatives.velocity_after`.
///
/// # Examples
///
/// `point_velocity_hessian` and `point_acceleration_hessian` differentiate twice a weighted velocity F · v_p and
/// acceleration F · a_p of a point (world axes); their q-gradients, checked here against central differences of
/// J_lin q̇ and of `point_accelerations` at the tip of `kinematic_hessian`'s double pendulum (built in the hidden
/// lines):
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
/// use legkit_dynamics::algorithms::{ContactDim, ContactPoint, Frame};
/// let (q, v, a, nv, h) = ([0.3, -0.5], [1.0, 2.0], [-3.0, 0.5], 2, 1e-6);
/// let (tip, weights) = (Vector3::new(0.0, 0.0, -0.4), Vector3::new(1.0, -2.0, 0.5));
/// let (mut velocity_hessian, mut velocity_gradient) = (vec![0.0; nv * nv], vec![0.0; nv]);
/// algorithms::point_velocity_hessian(&model, &mut data, &q, &v, 2, &tip, &weights, &mut velocity_hessian, &mut velocity_gradient)?;
/// // qq, qv, vv and qa Hessians (nv x nv each), then the q-gradient.
/// let mut acceleration_hessians = vec![0.0; 4 * nv * nv + nv];
/// algorithms::point_acceleration_hessian(&model, &mut data, &q, &v, &a, 2, &tip, &weights, &mut acceleration_hessians)?;
/// let mut weighted = |q: &[f64]| -> legkit_dynamics::Result<(f64, f64)> {
///     let j = algorithms::jacobian(&model, &mut data, q, 2, &tip, Frame::LocalWorldAligned)?;
///     let velocity = weights.dot(&(j.fixed_rows::<3>(0) * DVector::from_row_slice(&v)));
///     let mut acceleration = [0.0; 3];
///     algorithms::point_accelerations(&model, &mut data, q, &v, Some(&a), &[ContactPoint { body: 2, point: tip }], ContactDim::Point, &mut acceleration)?;
///     Ok((velocity, weights.dot(&Vector3::from(acceleration))))
/// };
/// for d in 0..nv {
///     let ((velocity_plus, acceleration_plus), (velocity_minus, acceleration_minus)) = (weighted(&nudge(q, d, h))?, weighted(&nudge(q, d, -h))?);
///     assert!((velocity_gradient[d] - (velocity_plus - velocity_minus) / (2.0 * h)).abs() < 1e-8);
///     assert!((acceleration_hessians[4 * nv * nv + d] - (acceleration_plus - acceleration_minus) / (2.0 * h)).abs() < 1e-8);
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn point_velocity_hessian(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], body: usize, point: &Vector3<f64>, weights: &Vector3<f64>, out: &mut [f64],
    slope: &mut [f64],
) -> Result<()> {
    check_frame_state(model, data, q, &[("v", v)], body, point)?;
    finite_vector("weights", *weights)?;
    check_output("out", out, model.nv() * model.nv())?;
    check_output("slope", slope, model.nv())?;
    let nv = model.nv();
    data.derivatives.reserve(model);
    jacobian_unchecked(model, data, q, body, point, Frame::World);
    let origin = data.o_m_i[body].transform_point(point);
    out.fill(0.0);
    slope.fill(0.0);
    let velocity = velocities_after(model, body, &data.jacobian, v, &mut data.derivatives.velocity_after);
    let (columns, sums) = (&data.jacobian, &data.derivatives.velocity_after);
    let linear_at = |m: &Motion| linear(m) + angular(m).cross(&origin);
    support(model, body, |e, joint_e| {
        let (s_e, w_e) = (column(columns, e), column(sums, e));
        let turned_e = cross_motion(&s_e, &w_e); // D_e V
        let j_e = linear_at(&s_e);
        slope[e] = weights.dot(&linear_at(&turned_e)) + angular(&velocity).dot(&j_e.cross(weights));
        let spin = angular(&turned_e);
        support(model, body, |d, joint_d| {
            let s_d = column(columns, d);
            let j_d = linear_at(&s_d);
            let d_before_e = is_ancestor(model, joint_d, joint_e);
            // W of the later of d and e on the chain.
            let w_m = if d_before_e { w_e } else { column(sums, d) };
            let mut change = cross_motion(&s_e, &cross_motion(&s_d, &w_m));
            let mut column_change = angular(&s_e).cross(&j_d); // D_d J_e (`kinematic_hessian`'s linear rows)
            if d_before_e {
                let s_de = cross_motion(&s_d, &s_e);
                change += cross_motion(&s_de, &w_e);
                column_change += linear_at(&s_de);
            }
            out[e * nv + d] = weights.dot(&linear_at(&change))
                + weights.dot(&spin.cross(&j_d))
                + angular(&cross_motion(&s_d, &column(sums, d))).dot(&j_e.cross(weights))
                + angular(&velocity).dot(&column_change.cross(weights));
        });
    });
    finite_result(out)?;
    finite_result(slope)
}

/// W per coordinate of `body`'s support into `after`: Σ v_a S_a over the joints from the coordinate's to `body`'s
/// (world `columns` S, one W shared by a joint's coordinates), summed from `body`'s joint to the root. Returns the
/// root's W, the body's velocity V.
fn velocities_after(model: &Model, body: usize, columns: &Matrix6xX<f64>, v: &[f64], after: &mut Matrix6xX<f64>) -> Motion {
    let mut sum = Motion::zeros();
    joints_to_root(model, body, |own, _| {
        for c in own.clone() {
            sum += column(columns, c) * v[c];
        }
        for c in own {
            set_column(after, c, &sum);
        }
    });
    sum
}

/// Whether `ancestor` is `joint` or one of its ancestors.
pub(crate) fn is_ancestor(model: &Model, ancestor: usize, joint: usize) -> bool {
    let mut j = joint;
    loop {
        if j == ancestor {
            return true;
        }
        if j == 0 {
            return false;
        }
        j = model.parent(j);
    }
}

/// One support coordinate's quantities for `point_acceleration_hessian` (world axes, about the world origin): its
/// column S, the velocities W (its joint and after), B (before its joint), T = B + its joint's own, the acceleration
/// terms Ā after it, and the slopes along it of the body's velocity Y = S × W, of its acceleration Z and of the
/// point's velocity Q, with X = S × B and the point's column J.
struct Coordinate {
    s: Motion,
    w: Motion,
    before: Motion,
    through: Motion,
    after: Motion,
    x: Motion,
    y: Motion,
    z: Motion,
    j: Vector3<f64>,
    point_rate: Vector3<f64>,
}

/// The second derivatives of F · a_p(q, v, a), a_p the classical world acceleration of `point` on `body` (as
/// `point_accelerations`) and F = `weights`, on q's tangent space as `point_velocity_hessian`: `out` holds, row-major
/// nv x nv each, qq (`[b, d]` the slope along q_d of the q-gradient's entry b), qv (`[d, e]` = ∂²/∂q_d ∂v_e), vv, qa
/// (`[d, e]` = ∂²/∂q_d ∂a_e), then the q-gradient (nv); aa and va are zero. With the world columns S and the force
/// F = [w; p × w] at the origin, a_p = F-paired: F · A + w · (ω × v_p), A = Σ S_a a_a + v_a T_a × S_a the body's
/// spatial acceleration (T_a the velocity of joint a's body). A change of q_d turns the columns at and after its joint
/// (∂S_a/∂q_d = S_d × S_a, Carpentier & Mansard, RSS 2018, eq. 7) and moves p along J_d, so ∂V/∂q_d = S_d × W_d and,
/// by the Jacobi identity, ∂A/∂q_d = S_d × Ā_d - (S_d × B_d) × W_d; differentiating these once more gives each entry
/// from a few cross products of per-coordinate sums: O(n²) for a support of n coordinates. Runs `jacobian`.
#[allow(clippy::too_many_arguments)]
pub fn point_acceleration_hessian(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64], body: usize, point: &Vector3<f64>, weights: &Vector3<f64>, out: &mut [f64],
) -> Result<()> {
    check_frame_state(model, data, q, &[("v", v), ("a", a)], body, point)?;
    finite_vector("weights", *weights)?;
    check_output("out", out, (4 * model.nv() + 1) * model.nv())?;
    let nv = model.nv();
    data.derivatives.reserve(model);
    jacobian_unchecked(model, data, q, body, point, Frame::World);
    let p = data.o_m_i[body].transform_point(point);
    let Data { jacobian: columns, derivatives: sums, .. } = data;
    // W per coordinate; then B = V - W, T and Ā (suffix sums of S a + v T × S).
    let velocity = velocities_after(model, body, columns, v, &mut sums.velocity_after);
    let mut acceleration = Motion::zeros();
    joints_to_root(model, body, |own, _| {
        let before = velocity - column(&sums.velocity_after, own.start);
        let through = own.clone().fold(before, |t, c| t + column(columns, c) * v[c]);
        for c in own.clone() {
            let s = column(columns, c);
            acceleration += s * a[c] + cross_motion(&through, &s) * v[c];
        }
        for c in own {
            set_column(&mut sums.velocity_before, c, &before);
            set_column(&mut sums.velocity_through, c, &through);
            set_column(&mut sums.acceleration_after, c, &acceleration);
        }
    });
    let force = spatial(*weights, p.cross(weights));
    let (omega, point_velocity) = (angular(&velocity), linear_at(&velocity, &p));
    let coordinate = |c: usize| {
        let (s, w, before) = (column(columns, c), column(&sums.velocity_after, c), column(&sums.velocity_before, c));
        let (x, y, after) = (cross_motion(&s, &before), cross_motion(&s, &w), column(&sums.acceleration_after, c));
        let j = linear_at(&s, &p);
        Coordinate {
            s,
            w,
            before,
            through: column(&sums.velocity_through, c),
            after,
            x,
            y,
            z: cross_motion(&s, &after) - cross_motion(&x, &w),
            j,
            point_rate: linear_at(&y, &p) + omega.cross(&j),
        }
    };
    let wrench = |m: &Motion| force.dot(m); // F · m = w · (the velocity m gives p)
    let turning = |j: &Vector3<f64>, m: &Motion| j.cross(weights).dot(&angular(m)); // (∂F/∂q along j) · m
    let (qq, rest) = out.split_at_mut(nv * nv);
    let (qv, rest) = rest.split_at_mut(nv * nv);
    let (vv, rest) = rest.split_at_mut(nv * nv);
    let (qa, gradient) = rest.split_at_mut(nv * nv);
    support(model, body, |b, joint_b| {
        let cb = coordinate(b);
        let spin_b = angular(&cb.s);
        // ∂A/∂v_b = S_b × (W_b - T_b).
        let by_v = cross_motion(&cb.s, &(cb.w - cb.through));
        gradient[b] = turning(&cb.j, &acceleration)
            + wrench(&cb.z)
            + weights.dot(&angular(&cb.y).cross(&point_velocity))
            + weights.dot(&omega.cross(&cb.point_rate));
        support(model, body, |d, joint_d| {
            let cd = coordinate(d);
            let (d_before_b, b_before_d) = (is_ancestor(model, joint_d, joint_b), is_ancestor(model, joint_b, joint_d));
            let later = if d_before_b { &cb } else { &cd };
            // The slopes along q_d of b's quantities.
            let ds = if d_before_b { cross_motion(&cd.s, &cb.s) } else { Motion::zeros() };
            let d_before = if d_before_b && joint_d != joint_b { cross_motion(&cd.s, &(cb.before - cd.before)) } else { Motion::zeros() };
            let d_through = if d_before_b { cross_motion(&cd.s, &(cb.through - cd.before)) } else { Motion::zeros() };
            let dw = cross_motion(&cd.s, &later.w);
            let d_after = cross_motion(&cd.s, &later.after) - cross_motion(&cd.x, &later.w);
            let dj = linear_at(&ds, &p) + spin_b.cross(&cd.j);
            let dx = cross_motion(&ds, &cb.before) + cross_motion(&cb.s, &d_before);
            let dy = cross_motion(&ds, &cb.w) + cross_motion(&cb.s, &dw);
            let dz = cross_motion(&ds, &cb.after) + cross_motion(&cb.s, &d_after) - cross_motion(&dx, &cb.w) - cross_motion(&cb.x, &dw);
            let d_rate = linear_at(&dy, &p) + angular(&cb.y).cross(&cd.j) + angular(&cd.y).cross(&cb.j) + omega.cross(&dj);
            qq[b * nv + d] = dj.cross(weights).dot(&angular(&acceleration))
                + turning(&cb.j, &cd.z)
                + turning(&cd.j, &cb.z)
                + wrench(&dz)
                + weights.dot(&angular(&dy).cross(&point_velocity))
                + weights.dot(&angular(&cb.y).cross(&cd.point_rate))
                + weights.dot(&angular(&cd.y).cross(&cb.point_rate))
                + weights.dot(&omega.cross(&d_rate));
            let d_by_v = cross_motion(&ds, &(cb.w - cb.through)) + cross_motion(&cb.s, &(dw - d_through));
            qv[d * nv + b] = turning(&cd.j, &by_v)
                + wrench(&d_by_v)
                + weights.dot(&angular(&ds).cross(&point_velocity))
                + weights.dot(&spin_b.cross(&cd.point_rate))
                + weights.dot(&angular(&cd.y).cross(&cb.j))
                + weights.dot(&omega.cross(&dj));
            qa[d * nv + b] = turning(&cd.j, &cb.s) + wrench(&ds);
            // ∂²A/∂v_b ∂v_d = S_earlier × S_later (zero within a joint).
            let mut joint_rates = Motion::zeros();
            if d_before_b {
                joint_rates += cross_motion(&cd.s, &cb.s);
            }
            if b_before_d {
                joint_rates += cross_motion(&cb.s, &cd.s);
            }
            vv[b * nv + d] = wrench(&joint_rates) + weights.dot(&spin_b.cross(&cd.j)) + weights.dot(&angular(&cd.s).cross(&cb.j));
        });
    });
    finite_result(out)
}

/// The velocity motion `m` gives the point `p` (world coordinates).
#[inline(always)]
fn linear_at(m: &Motion, p: &Vector3<f64>) -> Vector3<f64> {
    linear(m) + angular(m).cross(p)
}
