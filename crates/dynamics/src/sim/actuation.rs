//! Actuation: per-degree-of-freedom position/velocity servos around direct joint forces, and the
//! application of generalized forces to the Rapier bodies.
//!
//! Every step, before Rapier integrates, each degree of freedom k gets
//! `τ_k = clip(kp_k (q*_k − q_k) + kd_k (v*_k − v_k) + τ_ff,k, ±limit_k)`, held over the step (a servo
//! sampled at 1/dt), then clipped again to the joint's effort bound in the model (`JointLimits::effort`),
//! so the tighter of the two applies. A joint force enters Rapier as an equal and opposite pair on the child and parent
//! bodies (a couple about the axis for a revolute joint, a force along the axis through the joint origin
//! for a prismatic one), whose generalized force is exactly τ_k on that joint and zero on every other.

use nalgebra::Vector3;

use crate::model::{Joint, Model};
use crate::{Error, Result};

/// Servo gains, limits and targets, one entry per velocity coordinate. The free-flyer base is not
/// actuated by servos (its gains must be zero), but `τ_ff` may push it.
#[derive(Debug, Clone, PartialEq)]
pub struct Servo {
    pub kp: Vec<f64>,
    pub kd: Vec<f64>,
    pub limit: Vec<f64>,
    /// Target joint coordinates, indexed by velocity coordinate (base entries unused).
    pub target_q: Vec<f64>,
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
        Ok(Servo { kp, kd, limit, target_q, target_v })
    }

    /// The actuation for state (joint coordinates by velocity index `q_dof`, velocities `v`) and
    /// feed-forward `tau_ff`, written to `out`.
    pub fn torques(&self, q_dof: &[f64], v: &[f64], tau_ff: &[f64], out: &mut [f64]) {
        for k in 0..out.len() {
            let raw = self.kp[k] * (self.target_q[k] - q_dof[k]) + self.kd[k] * (self.target_v[k] - v[k]) + tau_ff[k];
            out[k] = raw.clamp(-self.limit[k], self.limit[k]);
        }
    }
}

/// Joint coordinates indexed by velocity coordinate: q[idx_q] for each one-degree-of-freedom joint, zero
/// on the base (the layout of servo targets).
pub fn dof_coordinates(model: &Model, q: &[f64], out: &mut [f64]) {
    out.fill(0.0);
    for i in 1..model.nbodies() {
        if matches!(model.joint(i), Joint::Revolute(_) | Joint::Prismatic(_)) {
            out[model.idx_v(i)] = q[model.idx_q(i)];
        }
    }
}

/// The world-frame wrench of one generalized force, to apply to Rapier bodies.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Push {
    /// A pure couple on `child` and its opposite on `parent` (Rapier body indices).
    Couple { child: usize, parent: usize, torque: Vector3<f64> },
    /// A force through `point` on `child` and its opposite on `parent`.
    Force { child: usize, parent: usize, force: Vector3<f64>, point: Vector3<f64> },
    /// A wrench on the base: `force` through `point`, plus a couple.
    Base { force: Vector3<f64>, point: Vector3<f64>, torque: Vector3<f64> },
}
