//! Joint limits: position range, effort and velocity bounds, checked when built and when a body is added.

use crate::{Error, Result};

/// Limits of a revolute or prismatic joint, in the joint's coordinate: position range `lower..=upper`
/// (rad or m; ±inf where unbounded), and bounds on the magnitude of its generalized force `effort`
/// (N m or N) and of its velocity `velocity` (rad/s or m/s), each +inf where unbounded.
///
/// Build with [`JointLimits::new`] (checked) or start from [`JointLimits::NONE`]; [`Model::add_body`](super::Model::add_body)
/// checks again, so a model never holds invalid limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lowest position (rad or m), −inf if unbounded.
    pub lower: f64,
    /// Highest position (rad or m), +inf if unbounded.
    pub upper: f64,
    /// Largest magnitude of the joint's generalized force (N m or N), +inf if unbounded.
    pub effort: f64,
    /// Largest magnitude of the joint's velocity (rad/s or m/s), +inf if unbounded.
    pub velocity: f64,
}

impl JointLimits {
    /// No limit at all: the only limits a fixed joint or the base can have.
    pub const NONE: JointLimits = JointLimits { lower: f64::NEG_INFINITY, upper: f64::INFINITY, effort: f64::INFINITY, velocity: f64::INFINITY };

    /// Checked limits: `lower` finite or −inf, `upper` finite or +inf, `lower <= upper`, `effort` and
    /// `velocity` > 0 (+inf allowed). Errors name the argument `"limits"`.
    pub fn new(lower: f64, upper: f64, effort: f64, velocity: f64) -> Result<Self> {
        let limits = JointLimits { lower, upper, effort, velocity };
        limits.check()?;
        Ok(limits)
    }

    /// A position range only (no effort or velocity bound).
    pub fn position(lower: f64, upper: f64) -> Result<Self> {
        Self::new(lower, upper, f64::INFINITY, f64::INFINITY)
    }

    /// Whether any of the four bounds is finite.
    pub fn is_limited(&self) -> bool {
        *self != Self::NONE
    }

    /// Whether the position range has a finite end.
    pub fn has_position_limits(&self) -> bool {
        self.lower.is_finite() || self.upper.is_finite()
    }

    pub(crate) fn check(&self) -> Result<()> {
        let bad = |reason: String| Err(Error::invalid("limits", reason));
        if self.lower.is_nan() || self.lower == f64::INFINITY {
            return bad(format!("lower must be finite or -inf, got {}", self.lower));
        }
        if self.upper.is_nan() || self.upper == f64::NEG_INFINITY {
            return bad(format!("upper must be finite or +inf, got {}", self.upper));
        }
        if self.lower > self.upper {
            return bad(format!("lower ({}) must be <= upper ({})", self.lower, self.upper));
        }
        for (name, value) in [("effort", self.effort), ("velocity", self.velocity)] {
            // NaN fails `> 0`.
            if !(value > 0.0) {
                return bad(format!("{name} must be > 0 (+inf for no limit), got {value}"));
            }
        }
        Ok(())
    }
}

impl Default for JointLimits {
    fn default() -> Self {
        Self::NONE
    }
}
