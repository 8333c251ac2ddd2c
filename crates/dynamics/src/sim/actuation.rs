//! Actuation: per-degree-of-freedom position/velocity servos around direct joint forces.
//!
//! Every step each degree of freedom k gets `τ_k = clip(kp_k (q*_k − q_k) + kd_k (v*_k − v_k) + τ_ff,k, ±b_k)`
//! with `b_k` the tighter of the servo's limit and the joint's effort bound in the model
//! (`JointLimits::effort`). Rapier holds it over the step (a servo sampled at 1/dt); the tree engine
//! integrates the PD terms of an unsaturated servo implicitly (`sim::tree`).

use crate::joint::Dofs;
use crate::model::Model;
use crate::{Error, Result};

/// Servo gains, limits and targets, one entry per velocity coordinate: the servo force on coordinate k is
/// `kp (target_q − q) + kd (target_v − v)` plus the feed-forward τ_ff, clipped to the tighter of `limit` and the
/// joint's effort bound. The free-flyer base is not actuated by servos (its gains must be zero), but `τ_ff` may
/// push it.
#[derive(Debug, Clone, PartialEq)]
pub struct Servo {
    /// Position gains (N m/rad or N/m), >= 0.
    pub kp: Vec<f64>,
    /// Velocity gains (N m s/rad or N s/m), >= 0.
    pub kd: Vec<f64>,
    /// Bound on the magnitude of each coordinate's force (N m or N), >= 0, +inf for none.
    pub limit: Vec<f64>,
    /// Target joint coordinates, indexed by velocity coordinate (base entries unused).
    pub target_q: Vec<f64>,
    /// Target velocities (rad/s or m/s).
    pub target_v: Vec<f64>,
}

impl Servo {
    /// No servo: zero gains, no limit.
    pub fn off(nv: usize) -> Self {
        Servo { kp: vec![0.0; nv], kd: vec![0.0; nv], limit: vec![f64::INFINITY; nv], target_q: vec![0.0; nv], target_v: vec![0.0; nv] }
    }

    /// Checks lengths (nv), gains finite and >= 0, limits >= 0 (infinity allowed), targets finite, and
    /// zero gains on a free-flyer base.
    pub fn new(model: &Model, kp: Vec<f64>, kd: Vec<f64>, limit: Vec<f64>, target_q: Vec<f64>, target_v: Vec<f64>) -> Result<Self> {
        let nv = model.nv();
        for (name, values) in [("kp", &kp), ("kd", &kd), ("torque_limit", &limit), ("target_q", &target_q), ("target_v", &target_v)] {
            if values.len() != nv {
                return Err(Error::invalid(name, format!("expected {nv} values (one per velocity coordinate), got {}", values.len())));
            }
        }
        for (name, values) in [("kp", &kp), ("kd", &kd), ("target_q", &target_q), ("target_v", &target_v)] {
            if let Some(k) = values.iter().position(|x| !x.is_finite()) {
                return Err(Error::invalid(name, format!("element {k} is not finite ({})", values[k])));
            }
        }
        for (name, values) in [("kp", &kp), ("kd", &kd), ("torque_limit", &limit)] {
            if let Some(k) = values.iter().position(|x| x.is_nan() || *x < 0.0) {
                return Err(Error::invalid(name, format!("element {k} must be >= 0, got {}", values[k])));
            }
        }
        if model.floating_base() {
            if let Some(k) = (0..6).find(|&k| kp[k] != 0.0 || kd[k] != 0.0) {
                return Err(Error::invalid(
                    if kp[k] != 0.0 { "kp" } else { "kd" },
                    format!("element {k} belongs to the free-flyer base, which servos cannot actuate; it must be 0"),
                ));
            }
        }
        // A ball joint's coordinates are a quaternion: no per-axis angle for a position servo to hold. Its
        // velocity servo (per axis of the body's angular velocity) and feed-forward torques are well defined.
        if let Some(i) = (1..model.nbodies()).find(|&i| model.joint(i).dofs() == Dofs::Ball && kp[model.idx_v(i)..][..3].iter().any(|x| *x != 0.0)) {
            let (name, k) = (model.name(i), model.idx_v(i));
            return Err(Error::invalid(
                "kp",
                format!("elements {k}..{} belong to the ball joint of body '{name}', which position servos cannot actuate; they must be 0 (kd and feed-forward torques act per axis)", k + 3),
            ));
        }
        Ok(Servo { kp, kd, limit, target_q, target_v })
    }
}

/// Joint coordinates indexed by velocity coordinate: `q[idx_q]` for each one-degree-of-freedom joint, zero
/// on the base and on ball joints (the layout of servo targets).
pub fn dof_coordinates(model: &Model, q: &[f64], out: &mut [f64]) {
    out.fill(0.0);
    for i in 1..model.nbodies() {
        if model.joint(i).nv() == 1 {
            out[model.idx_v(i)] = q[model.idx_q(i)];
        }
    }
}

/// The effort bound of each velocity coordinate: the joint's `effort` limit, +inf on the base.
pub(crate) fn effort_bounds(model: &Model) -> Vec<f64> {
    let mut bounds = vec![f64::INFINITY; model.nv()];
    for i in 1..model.nbodies() {
        if model.joint(i).nv() == 1 {
            bounds[model.idx_v(i)] = model.limits(i).effort;
        }
    }
    bounds
}

/// What drives the joints during one step: servos, the model's effort bounds, feed-forward forces.
pub(crate) struct Actuation<'a> {
    pub servo: &'a Servo,
    pub effort: &'a [f64],
    pub tau_ff: &'a [f64],
}

impl Actuation<'_> {
    /// The bound on |τ_k|: the tighter of the servo's limit and the joint's effort bound.
    #[inline]
    pub fn bound(&self, k: usize) -> f64 {
        self.servo.limit[k].min(self.effort[k])
    }

    /// The servo plus feed-forward force on coordinate k before clipping.
    #[inline]
    pub fn raw(&self, k: usize, q_dof: &[f64], v: &[f64]) -> f64 {
        let s = self.servo;
        s.kp[k] * (s.target_q[k] - q_dof[k]) + s.kd[k] * (s.target_v[k] - v[k]) + self.tau_ff[k]
    }

    /// The clipped forces, held over the step, written to `out` (Rapier's explicit actuation).
    #[cfg(feature = "rapier")]
    pub fn explicit(&self, q_dof: &[f64], v: &[f64], out: &mut [f64]) {
        for (k, tau) in out.iter_mut().enumerate() {
            let bound = self.bound(k);
            *tau = self.raw(k, q_dof, v).clamp(-bound, bound);
        }
    }
}
