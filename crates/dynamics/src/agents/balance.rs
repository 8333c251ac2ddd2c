//! The per-joint centre-of-mass balancing controller (Moll et al., IROS 2006, §IV–V), every joint from its own
//! agent's estimates; `legkit.control.balance` documents the rule, `legkit.control.gains` the schedules.

use nalgebra::Vector3;

use super::network::Network;
use super::{add, Moments};
use crate::geometry::circle_line::{rotation_toward_line, Line};
use crate::{Error, Result};

/// The gain schedules of §IV: K = (c0 + c1 x) K0 with x = 0, the support distance in module widths, or the
/// mass moment |m2 u x (p2 - q)|.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheme {
    /// x = 0: constant gains c0 K0.
    Constant,
    /// x = the COM's distance from the support line, in module widths.
    Distance,
    /// x = the joint's mass moment |m2 u x (p2 - q)| (kg m).
    Momentum,
}

/// One module's schedule: its scheme, coefficients and base gains (K_P0, K_I0, K_D0).
#[derive(Clone, Copy, Debug)]
pub struct Schedule {
    /// What x is.
    pub scheme: Scheme,
    /// Constant factor of the gains.
    pub c0: f64,
    /// Factor of x in the gains.
    pub c1: f64,
    /// Base proportional gain K_P0.
    pub kp0: f64,
    /// Base integral gain K_I0.
    pub ki0: f64,
    /// Base derivative gain K_D0.
    pub kd0: f64,
}

/// What one module's joints decided from its agent's estimates: each joint's target (rad), the estimated
/// COM–support-line distance (m) and each joint's mass moment |m2 u x (p2 - q)| (kg m).
#[derive(Clone, Copy, Debug, Default)]
struct Decision {
    target: [f64; 3],
    support_distance: f64,
    mass_moment: [f64; 3],
}

/// The controller of every joint of a `Network`, with each joint's PID state.
#[derive(Clone, Debug)]
pub struct Controller {
    schedules: Vec<Schedule>,
    limit: f64,
    width: f64,
    integral: Vec<[f64; 3]>,
    previous_error: Vec<[f64; 3]>,
    stepped: bool,
    decisions: Vec<Decision>,
}

impl Controller {
    /// One schedule per module; joint targets clipped to ±`limit` rad; distances measured in module `width`s.
    pub fn new(schedules: Vec<Schedule>, limit: f64, width: f64) -> Controller {
        let n = schedules.len();
        Controller {
            schedules,
            limit,
            width,
            integral: vec![[0.0; 3]; n],
            previous_error: vec![[0.0; 3]; n],
            stepped: false,
            decisions: vec![Decision::default(); n],
        }
    }

    /// Module m's decision: each joint's target is its angle plus the rotation that brings the COM closest to
    /// the support line, clipped; a module that knows no leader holds its angles.
    fn decide(&self, network: &Network, m: usize) -> Result<Decision> {
        let angles = network.angles(m);
        let Some(fixed) = network.fixed_block(m) else { return Ok(Decision { target: angles, ..Decision::default() }) };
        // Masses and first moments (module frame) beyond each block's connectors, of each part, of the whole.
        let beyond = |block: usize| {
            let mut sum = [0.0; 13];
            (3 * block..3 * block + 3).for_each(|slot| add(&mut sum, network.estimate(m, slot)));
            sum
        };
        let (beyond_a, beyond_b) = (beyond(0), beyond(1));
        let parts = network.part_moments(m);
        let mut total = *network.own(m);
        add(&mut total, &beyond_a);
        add(&mut total, &beyond_b);
        let (rotation, translation) = network.world_pose(m);
        let world = |x: Vector3<f64>| rotation * x + translation;
        let com = world(first_moment(&total) / total[0]);
        let (line_point, line_direction) = network.line(m);
        let line = Line::new(line_point, line_direction).map_err(|e| diverged(m, e))?;
        let offset = com - line_point;
        let mut decision = Decision { support_distance: (offset - line_direction * offset.dot(&line_direction)).norm(), ..Decision::default() };
        let spec = network.spec();
        for (k, angle) in angles.iter().enumerate() {
            // Joint k separates parts 0..=k (A side) from k+1..=3 (B side); the side away from the ground moves.
            let mut moving = if fixed == 1 { beyond_a } else { beyond_b };
            let side = if fixed == 1 { 0..k + 1 } else { k + 1..4 };
            side.for_each(|part| add(&mut moving, &parts[part]));
            let m2 = moving[0];
            let (part_rotation, part_translation) = network.part_pose(m, k + 1);
            let axis_point = world(part_rotation.column(2) * spec.joint_z[k] + part_translation);
            let axis = rotation * part_rotation.column(spec.joint_axes[k]);
            let lever = world(first_moment(&moving) / m2) - axis_point;
            // Turning the moving part turns the COM about the parallel axis through a = c - (m2 / M) lever.
            let pivot = com - lever * (m2 / total[0]);
            let axis_line = Line::axis(pivot, axis).map_err(|e| diverged(m, e))?;
            let (theta, _) = rotation_toward_line(&axis_line, &com, &line);
            let signed = if fixed == 1 { -theta } else { theta };
            decision.target[k] = (angle + signed).clamp(-self.limit, self.limit);
            decision.mass_moment[k] = (axis.cross(&lever) * m2).norm();
        }
        Ok(decision)
    }

    /// Joint torques (N, 3) N m after a control period `dt` s: every module decides, then each joint's error
    /// to its target goes through its PID, the gains scaled by the module's schedule. An error (a module's
    /// estimates not finite) leaves the PID state unchanged.
    pub fn torques(&mut self, network: &Network, dt: f64, out: &mut [[f64; 3]]) -> Result<()> {
        let n = self.schedules.len();
        if network.n_modules() != n || out.len() != n {
            return Err(Error::invalid("network", format!("the controller has {n} modules, the network {}", network.n_modules())));
        }
        for m in 0..n {
            self.decisions[m] = self.decide(network, m)?;
        }
        for (m, decision) in self.decisions.iter().enumerate() {
            let schedule = &self.schedules[m];
            let angles = network.angles(m);
            for k in 0..3 {
                let variable = match schedule.scheme {
                    Scheme::Constant => 0.0,
                    Scheme::Distance => decision.support_distance / self.width,
                    Scheme::Momentum => decision.mass_moment[k],
                };
                let factor = schedule.c0 + schedule.c1 * variable;
                let error = decision.target[k] - angles[k];
                self.integral[m][k] += error * dt;
                // A backward-difference derivative, zero on the first step (`legkit.control.PID`).
                let derivative = if self.stepped { (error - self.previous_error[m][k]) / dt } else { 0.0 };
                self.previous_error[m][k] = error;
                out[m][k] = factor * schedule.kp0 * error + factor * schedule.ki0 * self.integral[m][k] + factor * schedule.kd0 * derivative;
            }
        }
        self.stepped = true;
        Ok(())
    }
}

fn first_moment(x: &Moments) -> Vector3<f64> {
    Vector3::new(x[1], x[2], x[3])
}

fn diverged(module: usize, error: Error) -> Error {
    Error::numerical("torques", format!("module {module}'s estimates are not finite ({error})"))
}
