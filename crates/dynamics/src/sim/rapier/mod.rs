//! Contact simulation of a legkit `Model` on Rapier (reduced-coordinate multibodies, parry collision).
//!
//! The model becomes one Rapier multibody (see `builder`): revolute and prismatic joints become
//! multibody joints, bodies on fixed joints are merged into their parents, and every body gets a collider
//! (a box matching its inertia unless a shape is given). Joint dynamics are exact: the model's damping and
//! armature, no joint friction; gravity is the model's.
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
//! Every method checks its input before touching the state: on error the simulation is unchanged. A step
//! that fails is undone bit for bit by going back to a checkpoint (a copy of the world's state) and replaying
//! the steps taken since, each from the generalized forces it applied: stepping is deterministic, so the
//! replay reproduces them exactly. A checkpoint is taken every `CHECKPOINT_STEPS` steps (and after every
//! change of state from outside), so a step pays a small fraction of a world copy instead of a whole one.

mod builder;
mod state;

use nalgebra::Vector3;
use rapier3d_f64::prelude::{
    BroadPhaseBvh, CCDSolver, ColliderSet, ImpulseJointSet, IslandManager, MultibodyJointSet, NarrowPhase, PhysicsWorld, RigidBodySet,
};

use crate::joint::Dofs;
use crate::model::Model;
use crate::spatial::Transform;
use crate::{Error, Result};
use builder::{Layout, RapierAxis};

use super::actuation::{dof_coordinates, Actuation};
use super::options::Options;
use super::{Contact, Engine, Jacobians};
use crate::geometry::{from_pose, to_vector};

/// The world-frame wrench of one generalized force, to apply to Rapier bodies.
#[derive(Debug, Clone, Copy)]
enum Push {
    /// A pure couple on `child` and its opposite on `parent` (Rapier body indices).
    Couple { child: usize, parent: usize, torque: Vector3<f64> },
    /// A force through `point` on `child` and its opposite on `parent`.
    Force { child: usize, parent: usize, force: Vector3<f64>, point: Vector3<f64> },
    /// A wrench on the base: `force` through `point`, plus a couple.
    Base { force: Vector3<f64>, point: Vector3<f64>, torque: Vector3<f64> },
}

/// Steps replayed at most to undo a failed one; a world copy per this many steps.
const CHECKPOINT_STEPS: usize = 32;

/// How one body's generalized forces reach the Rapier bodies.
#[derive(Debug, Clone, Copy)]
enum Drive {
    /// The floating base: applied[0..6] is a wrench on it.
    Base,
    /// A one-degree-of-freedom joint (velocity index `k`) between Rapier bodies `child` and `parent`.
    Axis { k: usize, axis: RapierAxis, child: usize, parent: usize },
}

pub(crate) struct RapierSimulation {
    options: Options,
    world: PhysicsWorld,
    /// The world at the last checkpoint and the steps taken since; None when the world changed otherwise.
    checkpoint: Option<Checkpoint>,
    /// The generalized forces of each step since the checkpoint (nv per step), the last one the step in
    /// progress; preallocated for `CHECKPOINT_STEPS` steps.
    replay: Vec<f64>,
    layout: Layout,
    drives: Vec<Drive>,
    nv: usize,
    q_dof: Vec<f64>,
    pushes: Vec<Push>,
}

struct Checkpoint {
    world: Saved,
    /// Steps taken (or begun) since the checkpoint.
    steps: usize,
}

/// Every part of a `PhysicsWorld` that carries state from one step to the next.
struct Saved {
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    ccd_solver: CCDSolver,
}

impl Saved {
    fn of(world: &PhysicsWorld) -> Self {
        Saved {
            islands: world.islands.clone(),
            broad_phase: world.broad_phase.clone(),
            narrow_phase: world.narrow_phase.clone(),
            bodies: world.bodies.clone(),
            colliders: world.colliders.clone(),
            impulse_joints: world.impulse_joints.clone(),
            multibody_joints: world.multibody_joints.clone(),
            ccd_solver: world.ccd_solver.clone(),
        }
    }

    fn restore(self, world: &mut PhysicsWorld) {
        world.islands = self.islands;
        world.broad_phase = self.broad_phase;
        world.narrow_phase = self.narrow_phase;
        world.bodies = self.bodies;
        world.colliders = self.colliders;
        world.impulse_joints = self.impulse_joints;
        world.multibody_joints = self.multibody_joints;
        world.ccd_solver = self.ccd_solver;
    }
}

impl RapierSimulation {
    /// The model at its neutral configuration, at rest (options checked by the caller).
    pub(crate) fn new(model: &Model, options: &Options) -> Result<Self> {
        let (world, layout) = builder::build(model, options)?;
        Ok(RapierSimulation {
            options: options.clone(),
            world,
            checkpoint: None,
            replay: Vec::with_capacity(CHECKPOINT_STEPS * model.nv()),
            drives: drives(model, &layout),
            layout,
            nv: model.nv(),
            q_dof: vec![0.0; model.nv()],
            pushes: Vec::with_capacity(model.nbodies()),
        })
    }
}

/// Each body's `Drive`, parent before child (the order forces are summed in).
fn drives(model: &Model, layout: &Layout) -> Vec<Drive> {
    (0..model.nbodies())
        .filter_map(|i| match model.joint(i).dofs() {
            Dofs::Free => Some(Drive::Base),
            Dofs::One(_) => Some(Drive::Axis {
                k: model.idx_v(i),
                axis: RapierAxis::of(model.joint(i)).expect("the builder takes no other joint"),
                child: layout.carrier[i],
                parent: layout.carrier[model.parent(i)],
            }),
            // The builder refuses ball joints.
            Dofs::Zero | Dofs::Ball => None,
        })
        .collect()
}

impl Engine for RapierSimulation {
    fn write_state(&mut self, model: &Model, q: &[f64], v: &[f64]) {
        // The steps since the checkpoint no longer lead to this world.
        self.checkpoint = None;
        state::write(&mut self.world, &self.layout, model, q, v);
    }

    fn restart(&mut self, model: &Model, q: &[f64], v: &[f64]) -> Result<()> {
        let (world, layout) = builder::build(model, &self.options)?;
        self.checkpoint = None;
        self.world = world;
        self.drives = drives(model, &layout);
        self.layout = layout;
        state::write(&mut self.world, &self.layout, model, q, v);
        Ok(())
    }

    fn step(&mut self, model: &Model, actuation: &Actuation<'_>, q: &mut [f64], v: &mut [f64], applied: &mut [f64], ab: Jacobians) -> Result<()> {
        // Counted before anything can fail, so that `undo` replays exactly the steps before this one.
        let logged = self.checkpoint.as_mut().map(|c| c.steps += 1).is_some();
        if ab.is_some() {
            return Err(Error::invalid(
                "backend",
                "transition Jacobians are those of legkit's tree engine (backend='tree'); Rapier's step is not differentiated",
            ));
        }
        dof_coordinates(model, q, &mut self.q_dof);
        actuation.explicit(&self.q_dof, v, applied);
        if logged {
            self.replay.extend_from_slice(applied);
        }
        self.apply_forces(applied);
        self.world.step();
        state::read(&self.world, &self.layout, model, q, v);
        Ok(())
    }

    fn save(&mut self) {
        if self.checkpoint.as_ref().is_none_or(|c| c.steps >= CHECKPOINT_STEPS) {
            self.replay.clear();
            self.checkpoint = Some(Checkpoint { world: Saved::of(&self.world), steps: 0 });
        }
    }

    fn undo(&mut self) {
        let Some(checkpoint) = self.checkpoint.take() else { return };
        checkpoint.world.restore(&mut self.world);
        // Every step since the checkpoint but the failed last one, as it was taken: the same forces on the
        // same world give the same step, bit for bit.
        let replay = std::mem::take(&mut self.replay);
        for step in 0..checkpoint.steps.saturating_sub(1) {
            self.apply_forces(&replay[step * self.nv..(step + 1) * self.nv]);
            self.world.step();
        }
        self.replay = replay;
        self.replay.clear();
    }

    fn body_poses(&self, _model: &Model, _q: &[f64]) -> Vec<Transform> {
        state::body_poses(&self.world, &self.layout)
    }

    fn contacts(&self) -> Vec<Contact> {
        state::contacts(&self.world, self.options.dt)
    }

    fn contact_tolerance(&self) -> f64 {
        self.world.integration_parameters.allowed_linear_error()
    }

    fn solver_iterations(&self) -> Option<usize> {
        None
    }
}

impl RapierSimulation {
    /// Turns `applied` into forces on the Rapier bodies (replacing those of the previous step).
    fn apply_forces(&mut self, applied: &[f64]) {
        let layout = &self.layout;
        let carrier_pose = |r: usize| from_pose(&state::carrier_pose(&self.world, layout, r));
        self.pushes.clear();
        for drive in &self.drives {
            let (k, axis, child, parent) = match *drive {
                Drive::Base => {
                    let base = carrier_pose(0).compose(&layout.offset[0]);
                    let (f, n) = (Vector3::new(applied[0], applied[1], applied[2]), Vector3::new(applied[3], applied[4], applied[5]));
                    if f != Vector3::zeros() || n != Vector3::zeros() {
                        self.pushes.push(Push::Base { force: base.rotation * f, point: base.translation, torque: base.rotation * n });
                    }
                    continue;
                }
                Drive::Axis { k, axis, child, parent } if applied[k] != 0.0 => (k, axis, child, parent),
                Drive::Axis { .. } => continue,
            };
            let pose = carrier_pose(child);
            self.pushes.push(match axis {
                RapierAxis::Angular(a) => Push::Couple { child, parent, torque: pose.rotation * a * applied[k] },
                RapierAxis::Linear(a) => Push::Force { child, parent, force: pose.rotation * a * applied[k], point: pose.translation },
            });
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
