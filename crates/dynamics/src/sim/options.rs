//! Construction options shared by both backends: step, ground, collision shapes (`geometry::Shape`) and the
//! backend itself (joint damping and armature are the model's: `Model::damping`, `Model::armature`).

use crate::geometry::Shape;
use crate::model::Model;
use crate::spatial::Transform;
use crate::validate::finite;
use crate::{Error, Result};

use super::ground::Ground;

/// Most contact-solver (Newton) iterations per step of the tree engine unless asked otherwise. A cap, not a
/// cost: most steps converge in 1-10. Under Coulomb's law a step whose feet switch between sticking, sliding
/// and lifting off can take more (22 on a quadruped pushed sideways at 0.35 m/s, two feet lifting), and a
/// capped step is unconverged: its impulses, and the transition Jacobians that take it as converged, are off.
pub const DEFAULT_SOLVER_ITERATIONS: usize = 50;
/// Friction coefficient of body-body contacts when there is no ground to take it from.
pub const DEFAULT_FRICTION: f64 = 0.8;

/// Construction options of a simulation (see `Simulation::new`).
#[derive(Debug, Clone)]
pub struct Options {
    /// Step length (s), > 0.
    pub dt: f64,
    /// The terrain, or None for none.
    pub ground: Option<Ground>,
    /// Shapes replacing the listed bodies' own (the model's collision shapes, or the default box); `None`
    /// removes a body's colliders.
    pub shapes: Vec<(usize, Option<Shape>)>,
    /// Contacts between bodies of the robot (never between a body and its parent).
    pub self_collision: bool,
    /// Substeps per step: the tree engine takes `substeps` steps of dt / substeps; Rapier runs that many
    /// solver iterations, each re-evaluating the multibody dynamics. Either way more substeps integrate
    /// more accurately at a proportional cost.
    pub substeps: usize,
    /// The engine that steps the simulation.
    pub backend: Backend,
    /// Most contact-solver (Newton) iterations per (sub)step of the tree engine (it stops earlier once
    /// converged).
    pub solver_iterations: usize,
    /// The tree engine's friction law (Rapier has its own).
    pub friction_law: FrictionLaw,
}

/// How the tree engine bounds friction (`sim::tree::solver`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrictionLaw {
    /// The convex relaxation: impulses in the elliptic cone |λ_t| ≤ μ λ_n, one strictly convex problem
    /// (Anitescu 2006): unique impulses, Newton converging from anywhere. A sliding contact separates at
    /// v_n = μ |v_t|: a sliding body hops.
    Cone,
    /// Coulomb's law: the normal row complementary to the normal velocity alone, friction in the disk
    /// |λ_t| ≤ μ λ_n (non-associated): no lift, μ g deceleration from the first step; not convex. The default.
    Coulomb,
}

impl FrictionLaw {
    /// The law named `name` ("cone" or "coulomb"); another name is an error on `friction_law`.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "cone" => Ok(FrictionLaw::Cone),
            "coulomb" => Ok(FrictionLaw::Coulomb),
            other => Err(Error::invalid("friction_law", format!("must be 'cone' or 'coulomb', got {other:?}"))),
        }
    }

    /// The name `parse` reads.
    pub fn name(&self) -> &'static str {
        match self {
            FrictionLaw::Cone => "cone",
            FrictionLaw::Coulomb => "coulomb",
        }
    }
}

/// The most substeps per step, and solver iterations per substep: a step is the unit a long run can be
/// interrupted at, so it must stay short (a thousand substeps of a large model already take seconds).
pub const MAX_SUBSTEPS: usize = 1000;
/// The most solver iterations per substep (see [`MAX_SUBSTEPS`]).
pub const MAX_SOLVER_ITERATIONS: usize = 1000;

/// Which engine steps the simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// legkit's reduced-coordinate tree engine (`sim::tree`): the default.
    Tree,
    /// Rapier's multibody, kept as the reference.
    Rapier,
}

impl Backend {
    /// The backend named `name` ("tree" or "rapier"); another name is an error on `backend`.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "tree" => Ok(Backend::Tree),
            "rapier" => Ok(Backend::Rapier),
            other => Err(Error::invalid("backend", format!("must be 'tree' or 'rapier', got {other:?}"))),
        }
    }

    /// The name `parse` reads.
    pub fn name(&self) -> &'static str {
        match self {
            Backend::Tree => "tree",
            Backend::Rapier => "rapier",
        }
    }
}

impl Options {
    /// Defaults around step length `dt` (s): no ground, the model's shapes, no self-collision, one substep,
    /// the tree engine with [`DEFAULT_SOLVER_ITERATIONS`] and Coulomb's friction law. Checked by
    /// [`Simulation::new`](super::Simulation::new).
    pub fn new(dt: f64) -> Self {
        Options {
            dt,
            ground: None,
            shapes: Vec::new(),
            self_collision: false,
            substeps: 1,
            backend: Backend::Tree,
            solver_iterations: DEFAULT_SOLVER_ITERATIONS,
            friction_law: FrictionLaw::Coulomb,
        }
    }

    /// Every collider, with the shape frame in the body frame: a body's shape given here (none where it
    /// says None), else the model's own collision shapes if it has any (`Model::collision_shapes`, none
    /// for a body it lists nothing for), else the default box (none for a massless body).
    /// Every collider as (body, shape, shape frame in the body frame): `shapes` overrides, else the model's
    /// collision shapes, else a default box from the body's inertia.
    pub fn colliders<'a>(&'a self, model: &'a Model) -> impl Iterator<Item = (usize, Shape, Transform)> + 'a {
        (0..model.nbodies()).flat_map(move |i| {
            let shapes: Vec<Shape> = match (self.shapes.iter().find(|(b, _)| *b == i), model.collision_shapes()) {
                (Some((_, shape)), _) => shape.iter().cloned().collect(),
                (None, Some(described)) => described.iter().filter(|(b, _)| *b == i).map(|(_, s)| s.clone()).collect(),
                (None, None) => Shape::default_box(model.body(i)).into_iter().collect(),
            };
            shapes.into_iter().map(move |shape| {
                let in_body = shape.placement.unwrap_or_else(|| Transform::from_translation(model.body(i).com()));
                (i, shape, in_body)
            })
        })
    }

    /// Checks every option against `model`.
    pub fn check(&self, model: &Model) -> Result<()> {
        if finite("dt", self.dt)? <= 0.0 {
            return Err(Error::invalid("dt", format!("must be > 0, got {}", self.dt)));
        }
        if !(1..=MAX_SUBSTEPS).contains(&self.substeps) {
            return Err(Error::invalid("substeps", format!("must be in 1..={MAX_SUBSTEPS}, got {}", self.substeps)));
        }
        if !(1..=MAX_SOLVER_ITERATIONS).contains(&self.solver_iterations) {
            return Err(Error::invalid("solver_iterations", format!("must be in 1..={MAX_SOLVER_ITERATIONS}, got {}", self.solver_iterations)));
        }
        let mut seen = vec![false; model.nbodies()];
        for (body, _) in &self.shapes {
            if *body >= model.nbodies() {
                return Err(Error::invalid("shapes", format!("body {body} does not exist (the model has {} bodies)", model.nbodies())));
            }
            if std::mem::replace(&mut seen[*body], true) {
                return Err(Error::invalid("shapes", format!("body {body} is given more than once")));
            }
        }
        Ok(())
    }
}
