//! The derivative of a frame's Jacobian with respect to q (Pinocchio's `getJointKinematicHessian`): the curvature
//! of a point's position, of which the Jacobian is the slope.
//!
//! A joint's world column S_a (`jacobian`'s `Frame::World`) moves rigidly with every joint before it: a change of
//! coordinate d of an ancestor (or of the same multi-DoF joint, whose coordinates perturb it on the right)
//! turns it as ∂S_a/∂q_d = S_d × S_a (Carpentier & Mansard, RSS 2018, eq. 7); joints after it leave it unchanged.
//! A point's linear column S_a,lin + ω_a × p also changes as the point moves: ω_a × J_lin,d.

use nalgebra::Vector3;

use super::jacobian::{jacobian, Frame};
use super::kinematics_derivatives::{about, support};
use super::rnea_derivatives::column;
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_motion, linear, spatial, Motion};

/// `out` (6 x nv x nv, row-major, entry `[r, a, d]`): the slope along q_d (q on its tangent space, as
/// `rnea_derivatives`) of entry `[r, a]` of the Jacobian `jacobian(model, data, q, body, point, frame)` returns, for
/// `frame` `World` or `LocalWorldAligned` (`Local` is not covered). Runs `jacobian`; zero outside the body's support.
pub fn kinematic_hessian(model: &Model, data: &mut Data, q: &[f64], body: usize, point: &Vector3<f64>, frame: Frame, out: &mut [f64]) {
    debug_assert!(frame != Frame::Local, "kinematic_hessian covers World and LocalWorldAligned");
    let nv = model.nv();
    jacobian(model, data, q, body, point, Frame::World);
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
}

/// Adds `m` to entries `[r, a, d]` of the row-major 6 x nv x nv `out`.
#[inline(always)]
fn add(out: &mut [f64], nv: usize, a: usize, d: usize, m: &Motion) {
    for r in 0..6 {
        out[(r * nv + a) * nv + d] += m[r];
    }
}

/// The Hessian `out` (nv x nv, row-major, `[e, d]`: the slope along q_d of the gradient's entry e, q on its tangent
/// space) and the gradient `slope` (nv) of F · v_p(q), v_p = J_lin(q) u the velocity of `point` on `body` (world axes)
/// for joint velocity `u`, F = `weights`. With W_e = Σ_{a after e} u_a S_a (world columns, a at or after e's joint)
/// the derivative of the world velocity V is D_e V = S_e × W_e, and with J_e the point's linear column and m the later
/// of d and e: D_d(S_e × W_e) = [d ≼ e] (S_d × S_e) × W_e + S_e × (S_d × W_m). Runs `jacobian`; W goes to
/// `data.derivatives.velocity_after`.
#[allow(clippy::too_many_arguments)]
pub fn point_velocity_hessian(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    u: &[f64],
    body: usize,
    point: &Vector3<f64>,
    weights: &Vector3<f64>,
    out: &mut [f64],
    slope: &mut [f64],
) {
    let nv = model.nv();
    data.derivatives.reserve(model);
    jacobian(model, data, q, body, point, Frame::World);
    let origin = data.o_m_i[body].transform_point(point);
    out.fill(0.0);
    slope.fill(0.0);
    // W per coordinate, summed from the body's joint to the root (a joint's coordinates share one W).
    let mut after = Motion::zeros();
    let mut j = body;
    loop {
        let k = model.idx_v(j);
        for (c, rate) in u.iter().enumerate().skip(k).take(model.joint(j).nv()) {
            after += column(&data.jacobian, c) * *rate;
        }
        for c in k..k + model.joint(j).nv() {
            data.derivatives.velocity_after.set_column(c, &after);
        }
        if j == 0 {
            break;
        }
        j = model.parent(j);
    }
    let (columns, sums) = (&data.jacobian, &data.derivatives.velocity_after);
    let velocity = after;
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
}

/// Whether `ancestor` is `joint` or one of its ancestors.
fn is_ancestor(model: &Model, ancestor: usize, joint: usize) -> bool {
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
