//! Contact simulation of a legkit `Model` on Rapier (reduced-coordinate multibodies, parry collision).
//!
//! The model becomes one Rapier multibody (see `builder`): revolute and prismatic joints become
//! multibody joints, bodies on fixed joints are merged into their parents, and every body gets a collider
//! (a box matching its inertia unless a shape is given). Joint dynamics are exact: no damping, armature or
//! joint friction unless `joint_damping` asks for it; gravity is the model's.
//!
//! The model's joint limits (`Model::limits`) are enforced: the position range by Rapier joint limits,
//! the effort bound by clipping the actuation (servo plus feed-forward) of that joint. Velocity bounds
//! are not enforced (they are for controllers).
//!
//! Rapier integrates each substep semi-implicitly (velocities first, Coriolis and gyroscopic terms
//! linearly implicit, then positions), so free motion matches legkit's ABA + RK4 to first order in the
//! substep length. Single-threaded and free of hash-order effects, the same inputs give bit-identical
//! trajectories.
//!
//! Every method checks its input before touching the state: on error the simulation is unchanged.

mod actuation;
mod builder;
mod ground;
mod state;
#[cfg(test)]
mod tests;

pub use actuation::{dof_coordinates, Servo};
pub use builder::{Options, Shape, ShapeKind, MIN_DEFAULT_EDGE};
pub use ground::Ground;
pub use state::Contact;

use nalgebra::Vector3;
use rapier3d_f64::prelude::PhysicsWorld;

use crate::model::{check_vector, Joint, Model};
use crate::spatial::Transform;
use crate::{Error, Result};
use actuation::Push;
use builder::{to_vector, Layout};

pub struct Simulation {
    model: Model,
    options: Options,
    world: PhysicsWorld,
    layout: Layout,
    servo: Servo,
    /// The model's effort bound per velocity coordinate (+inf on the base and unbounded joints).
    effort: Vec<f64>,
    steps: u64,
    /// Actuation of the last step, one entry per velocity coordinate.
    applied: Vec<f64>,
    q: Vec<f64>,
    v: Vec<f64>,
    q_dof: Vec<f64>,
    pushes: Vec<Push>,
}

impl Simulation {
    /// A simulation of `model` at its neutral configuration, at rest, at time 0.
    pub fn new(model: &Model, options: Options) -> Result<Self> {
        options.check(model)?;
        let (world, layout) = builder::build(model, &options)?;
        let (nq, nv) = (model.nq(), model.nv());
        let mut sim = Simulation {
            model: model.clone(),
            options,
            world,
            layout,
            servo: Servo::off(nv),
            effort: effort_bounds(model),
            steps: 0,
            applied: vec![0.0; nv],
            q: vec![0.0; nq],
            v: vec![0.0; nv],
            q_dof: vec![0.0; nv],
            pushes: Vec::with_capacity(model.nbodies()),
        };
        sim.refresh();
        Ok(sim)
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    pub fn options(&self) -> &Options {
        &self.options
    }

    /// Simulated time (s): steps taken times dt.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.options.dt
    }

    /// Configuration in legkit's layout (nq).
    pub fn q(&self) -> &[f64] {
        &self.q
    }

    /// Velocity in legkit's layout (nv).
    pub fn v(&self) -> &[f64] {
        &self.v
    }

    /// Generalized forces applied during the last step (servo plus feed-forward, clipped to the tighter of
    /// the servo's limit and the joint's effort bound), per velocity coordinate.
    pub fn applied_torques(&self) -> &[f64] {
        &self.applied
    }

    pub fn servo(&self) -> &Servo {
        &self.servo
    }

    pub fn set_servo(&mut self, servo: Servo) -> Result<()> {
        if servo.kp.len() != self.model.nv() {
            return Err(Error::invalid("kp", format!("expected {} values, got {}", self.model.nv(), servo.kp.len())));
        }
        self.servo = servo;
        Ok(())
    }

    /// Penetration Rapier lets stand without correcting it (m): the contact tolerance.
    pub fn contact_tolerance(&self) -> f64 {
        self.world.integration_parameters.allowed_linear_error()
    }

    /// Moves the robot to (q, v) without touching time, servos or the contact cache. Both are checked
    /// (length, finite, unit base quaternion) before anything changes.
    pub fn set_state(&mut self, q: Option<&[f64]>, v: Option<&[f64]>) -> Result<()> {
        if let Some(q) = q {
            self.model.check_configuration(q)?;
        }
        if let Some(v) = v {
            check_vector("v", v, self.model.nv())?;
        }
        let q = q.map_or_else(|| self.q.clone(), <[f64]>::to_vec);
        let v = v.map_or_else(|| self.v.clone(), <[f64]>::to_vec);
        state::write(&mut self.world, &self.layout, &self.model, &q, &v);
        self.refresh();
        Ok(())
    }

    /// Starts over from (q, v) at time 0: a fresh Rapier world (no contact history), so what follows is
    /// bit-identical to a new simulation set to the same state. Servo settings are kept.
    pub fn reset(&mut self, q: &[f64], v: &[f64]) -> Result<()> {
        self.model.check_configuration(q)?;
        check_vector("v", v, self.model.nv())?;
        let (world, layout) = builder::build(&self.model, &self.options)?;
        self.world = world;
        self.layout = layout;
        self.steps = 0;
        self.applied.fill(0.0);
        state::write(&mut self.world, &self.layout, &self.model, q, v);
        self.refresh();
        Ok(())
    }

    /// Advances `n` steps with feed-forward generalized forces `tau` (nv, held over the steps; None for
    /// zero). On a floating base, tau[0..6] is a wrench [f; n] on the base in its frame at its origin, as
    /// in `aba`. Fails before stepping on bad `tau`, and stops with an error if the state stops being
    /// finite.
    pub fn step(&mut self, tau: Option<&[f64]>, n: usize) -> Result<()> {
        let nv = self.model.nv();
        let tau_ff = match tau {
            Some(t) => {
                check_vector("tau", t, nv)?;
                t.to_vec()
            }
            None => vec![0.0; nv],
        };
        for _ in 0..n {
            dof_coordinates(&self.model, &self.q, &mut self.q_dof);
            self.servo.torques(&self.q_dof, &self.v, &tau_ff, &mut self.applied);
            for (tau, bound) in self.applied.iter_mut().zip(&self.effort) {
                *tau = tau.clamp(-bound, *bound);
            }
            self.apply_forces();
            self.world.step();
            self.steps += 1;
            self.refresh();
            if self.q.iter().chain(&self.v).any(|x| !x.is_finite()) {
                return Err(Error::invalid(
                    "step",
                    format!("the simulation diverged (non-finite state) at t = {:.6} s; reduce dt or the servo gains", self.time()),
                ));
            }
        }
        Ok(())
    }

    /// World pose of every body.
    pub fn body_poses(&self) -> Vec<Transform> {
        state::body_poses(&self.world, &self.layout)
    }

    /// Contacts of the last step.
    pub fn contacts(&self) -> Vec<Contact> {
        state::contacts(&self.world, self.options.dt)
    }

    fn refresh(&mut self) {
        state::read(&self.world, &self.layout, &self.model, &mut self.q, &mut self.v);
    }

    /// Turns `self.applied` into forces on the Rapier bodies (replacing those of the previous step).
    fn apply_forces(&mut self) {
        let layout = &self.layout;
        let carrier_pose = |r: usize| builder::from_pose(&state::carrier_pose(&self.world, layout, r));
        self.pushes.clear();
        for i in 0..self.model.nbodies() {
            let k = self.model.idx_v(i);
            match *self.model.joint(i) {
                Joint::FreeFlyer => {
                    let base = carrier_pose(0).compose(&layout.offset[0]);
                    let (f, n) = (Vector3::new(self.applied[0], self.applied[1], self.applied[2]), Vector3::new(self.applied[3], self.applied[4], self.applied[5]));
                    if f != Vector3::zeros() || n != Vector3::zeros() {
                        self.pushes.push(Push::Base { force: base.rotation * f, point: base.translation, torque: base.rotation * n });
                    }
                }
                Joint::Fixed => {}
                Joint::Revolute(axis) | Joint::Prismatic(axis) if self.applied[k] != 0.0 => {
                    let (child, parent) = (layout.carrier[i], layout.carrier[self.model.parent(i)]);
                    let pose = carrier_pose(child);
                    let direction = pose.rotation * axis * self.applied[k];
                    self.pushes.push(if matches!(self.model.joint(i), Joint::Revolute(_)) {
                        Push::Couple { child, parent, torque: direction }
                    } else {
                        Push::Force { child, parent, force: direction, point: pose.translation }
                    });
                }
                Joint::Revolute(_) | Joint::Prismatic(_) => {}
            }
        }
        let coms: Vec<Vector3<f64>> = (0..layout.handles.len()).map(|r| carrier_pose(r).transform_point(&layout.local_com[r])).collect();
        for handle in &layout.handles {
            let rb = &mut self.world.bodies[*handle];
            rb.reset_forces(false);
            rb.reset_torques(false);
        }
        let bodies = &mut self.world.bodies;
        let mut push = |r: usize, force: Vector3<f64>, point: Vector3<f64>, torque: Vector3<f64>| {
            let rb = &mut bodies[layout.handles[r]];
            rb.add_force(to_vector(&force), false);
            rb.add_torque(to_vector(&(torque + (point - coms[r]).cross(&force))), false);
        };
        for p in &self.pushes {
            match *p {
                Push::Couple { child, parent, torque } => {
                    push(child, Vector3::zeros(), Vector3::zeros(), torque);
                    push(parent, Vector3::zeros(), Vector3::zeros(), -torque);
                }
                Push::Force { child, parent, force, point } => {
                    push(child, force, point, Vector3::zeros());
                    push(parent, -force, point, Vector3::zeros());
                }
                Push::Base { force, point, torque } => push(0, force, point, torque),
            }
        }
    }
}

/// The effort bound of each velocity coordinate: the joint's `effort` limit, +inf on the base.
fn effort_bounds(model: &Model) -> Vec<f64> {
    let mut bounds = vec![f64::INFINITY; model.nv()];
    for i in 1..model.nbodies() {
        if model.joint(i).nv() == 1 {
            bounds[model.idx_v(i)] = model.limits(i).effort;
        }
    }
    bounds
}
