//! Contact simulation of a legkit `Model`: legkit's own reduced-coordinate tree engine (`tree`, the
//! default) or Rapier's multibody (`rapier`, kept as the reference), behind one `Simulation`.
//!
//! Both take the same options (`Options`): ground, collision shapes (a box matching each body's inertia
//! unless given), self-collision, joint damping and armature, servos (`Servo`) and the model's joint
//! limits (position range enforced as a constraint, effort bound by clipping the actuation; velocity bounds
//! are for controllers). Every method checks its input before touching the state: on error the simulation is
//! unchanged. A step that would leave the state non-finite or exploding (a speed or position beyond
//! `DIVERGENCE_BOUND`) stops with `Error::Numerical`, naming the step and the body, and leaves the
//! simulation exactly as before that step. The same inputs give bit-identical trajectories on either backend.
//!
//! # Examples
//!
//! A 2 kg box on a free-flyer base, dropped onto a plane with friction, comes to rest on its 0.1 m high face, the
//! contacts bearing its weight; a torque of the wrong length is refused and steps nothing.
//!
//! ```
//! use legkit_dynamics::sim::{Ground, Options, Simulation};
//! use legkit_dynamics::{MassProperties, Model};
//! use nalgebra::{Matrix3, Vector3};
//!
//! let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
//! let model = Model::new(true, body, "box");
//! let mut sim = Simulation::new(&model, Options { ground: Some(Ground::plane(0.8)?), ..Options::new(1e-3) })?;
//! sim.set_state(Some(&[0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0]), None)?;
//! sim.step(None, 1000)?;
//! let support: f64 = sim.contacts().iter().map(|contact| contact.normal_force).sum();
//! assert!((sim.q()[2] - 0.05).abs() < 1e-3, "resting at {}", sim.q()[2]);
//! assert!((support - 2.0 * 9.81).abs() < 1e-2, "bearing {support} N");
//! let error = sim.step(Some(&[0.0; 3]), 1).unwrap_err();
//! assert_eq!((error.to_string().as_str(), sim.steps()), ("tau: expected length 6, got 3", 1000));
//! # Ok::<(), legkit_dynamics::Error>(())
//! ```
//!
//! With the `rapier` feature (on by default) the same simulation runs on Rapier's multibody, the reference backend;
//! without it that backend is refused.
//!
//! ```
//! # use legkit_dynamics::sim::{Ground, Options, Simulation};
//! # use legkit_dynamics::{MassProperties, Model};
//! # use nalgebra::{Matrix3, Vector3};
//! # let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
//! # let model = Model::new(true, body, "box");
//! use legkit_dynamics::sim::Backend;
//! let options = Options { ground: Some(Ground::plane(0.8)?), backend: Backend::Rapier, ..Options::new(1e-3) };
//! match Simulation::new(&model, options) {
//!     Ok(mut sim) => {
//!         sim.set_state(Some(&[0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0]), None)?;
//!         sim.step(None, 1000)?;
//!         assert!(cfg!(feature = "rapier") && (sim.q()[2] - 0.05).abs() < 2e-3, "resting at {}", sim.q()[2]);
//!     }
//!     Err(error) => assert!(!cfg!(feature = "rapier"), "{error}"),
//! }
//! # Ok::<(), legkit_dynamics::Error>(())
//! ```

mod actuation;
mod ground;
mod options;
#[cfg(feature = "rapier")]
mod rapier;
#[cfg(test)]
mod tests;
mod tree;

pub use actuation::{dof_coordinates, Servo};
pub use ground::Ground;
pub use options::{Backend, FrictionLaw, Options, DEFAULT_SOLVER_ITERATIONS, MAX_SOLVER_ITERATIONS, MAX_SUBSTEPS};

use std::panic::AssertUnwindSafe;

use nalgebra::{DMatrix, Vector3};

use crate::model::{check_vector, Model};
use crate::spatial::Transform;
use crate::validate::{array_len, check_cancelled, filled, with_capacity};
use crate::{Error, Result};
use actuation::{effort_bounds, Actuation};

/// A state beyond this (a speed in m/s or rad/s, a base or slider position in m) has diverged: no robot
/// gets there, and a physics engine fed such numbers may never return.
pub const DIVERGENCE_BOUND: f64 = 1e6;
/// An actuation beyond this (N m or N) is a units error, whatever the state does with it (Rapier drops
/// forces whose impulses overflow and carries on).
pub const ACTUATION_BOUND: f64 = 1e12;

/// One contact point, seen from `body`.
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    /// The legkit body the force acts on.
    pub body: usize,
    /// The other legkit body, or None for the ground.
    pub other: Option<usize>,
    /// World contact point (midpoint of the two surface points).
    pub point: Vector3<f64>,
    /// Unit contact normal in the world, pointing into `body` (the direction of the normal force on it).
    pub normal: Vector3<f64>,
    /// Normal force on `body` (N, >= 0), averaged over the last step.
    pub normal_force: f64,
    /// Friction force on `body` in the world (N, orthogonal to `normal`), averaged over the last step.
    pub tangential_force: Vector3<f64>,
    /// Penetration depth (m, >= 0) at the start of the last step's contact update.
    pub depth: f64,
}

/// What a backend does; `Simulation` keeps time, servos and the checks.
pub(crate) trait Engine: Send + Sync {
    /// Moves to (q, v), keeping the contact history.
    fn write_state(&mut self, model: &Model, q: &[f64], v: &[f64]);
    /// Starts over from (q, v) with no history.
    fn restart(&mut self, model: &Model, q: &[f64], v: &[f64]) -> Result<()>;
    /// Advances (q, v) by one step; writes the generalized forces the actuation applied; with `ab`, that step's
    /// transition Jacobians A and B at its start too, in one pass (see `Simulation::transition_jacobians`).
    fn step(&mut self, model: &Model, actuation: &Actuation<'_>, q: &mut [f64], v: &mut [f64], applied: &mut [f64], ab: Jacobians) -> Result<()>;
    /// Keeps what a step changes (contact history, warm starts, reported contacts), for `undo`.
    fn save(&mut self);
    /// Returns to the state of the last `save`, bit for bit: the step since then failed.
    fn undo(&mut self);
    fn body_poses(&self, model: &Model, q: &[f64]) -> Vec<Transform>;
    fn contacts(&self) -> Vec<Contact>;
    /// Penetration the engine lets stand without correcting it (m).
    fn contact_tolerance(&self) -> f64;
    /// Contact-solver iterations of the last (sub)step, where the engine stops on convergence.
    fn solver_iterations(&self) -> Option<usize>;
}

/// Where a step writes its transition Jacobians A = ∂x⁺/∂x and B = ∂x⁺/∂u (`Simulation::transition_jacobians`), if
/// they are asked for.
pub(crate) type Jacobians<'a> = Option<(&'a mut DMatrix<f64>, &'a mut DMatrix<f64>)>;

/// What `Simulation::rollout` gives, one row per step, row-major; grown once, reused.
#[derive(Debug, Clone, Default)]
pub struct Rollout {
    /// The configuration after each step (n x nq).
    pub q: Vec<f64>,
    /// The velocity after each step (n x nv).
    pub v: Vec<f64>,
    /// If asked, each step's A = ∂x⁺/∂x at its start (n x 2 nv x 2 nv), as `transition_jacobians`.
    pub a: Vec<f64>,
    /// If asked, each step's B = ∂x⁺/∂u at its start (n x 2 nv x 3 nv).
    pub b: Vec<f64>,
}

/// `buffer` holding `shape`'s numbers (zeroed), reallocated (fallibly, `Error::TooLarge` naming `argument`) only if
/// its size changes.
fn sized(buffer: &mut Vec<f64>, argument: &'static str, shape: &[usize]) -> Result<()> {
    let len = array_len(argument, shape, std::mem::size_of::<f64>())?;
    if buffer.len() == len {
        buffer.fill(0.0);
    } else {
        *buffer = filled(argument, len, 0.0)?;
    }
    Ok(())
}

/// A robot stepped forward in time with contacts, servos and joint limits, on the backend its [`Options`] choose.
/// Every method checks its input before changing anything; a step that diverges returns `Error::Numerical` and
/// leaves the simulation as it was before that step.
pub struct Simulation {
    model: Model,
    options: Options,
    engine: Box<dyn Engine>,
    servo: Servo,
    /// The model's effort bound per velocity coordinate (+inf on the base and unbounded joints).
    effort: Vec<f64>,
    steps: u64,
    /// Actuation of the last step, one entry per velocity coordinate, and before the step being taken.
    applied: Vec<f64>,
    applied_before: Vec<f64>,
    q: Vec<f64>,
    v: Vec<f64>,
    q_next: Vec<f64>,
    v_next: Vec<f64>,
    tau_ff: Vec<f64>,
}

impl Simulation {
    /// A simulation of `model` at its neutral configuration, at rest, at time 0.
    pub fn new(model: &Model, options: Options) -> Result<Self> {
        options.check(model)?;
        let engine: Box<dyn Engine> = match options.backend {
            Backend::Tree => Box::new(tree::TreeSimulation::new(model, &options)?),
            #[cfg(feature = "rapier")]
            Backend::Rapier => Box::new(rapier::RapierSimulation::new(model, &options)?),
            #[cfg(not(feature = "rapier"))]
            Backend::Rapier => {
                return Err(Error::invalid("backend", "'rapier' is not built in: legkit-dynamics was compiled without its `rapier` feature"))
            }
        };
        let (nq, nv) = (model.nq(), model.nv());
        let q = model.neutral().as_slice().to_vec();
        let mut sim = Simulation {
            model: model.clone(),
            options,
            engine,
            servo: Servo::off(nv),
            effort: effort_bounds(model),
            steps: 0,
            applied: vec![0.0; nv],
            applied_before: vec![0.0; nv],
            q_next: vec![0.0; nq],
            v_next: vec![0.0; nv],
            tau_ff: vec![0.0; nv],
            q,
            v: vec![0.0; nv],
        };
        sim.engine.write_state(&sim.model, &sim.q, &sim.v);
        Ok(sim)
    }

    /// The simulated model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The options the simulation was built with.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// Simulated time (s): steps taken times dt.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.options.dt
    }

    /// The steps taken since the simulation started (or was last reset).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Configuration in legkit's layout (nq).
    pub fn q(&self) -> &[f64] {
        &self.q
    }

    /// Velocity in legkit's layout (nv).
    pub fn v(&self) -> &[f64] {
        &self.v
    }

    /// Generalized forces applied during the last step (servo plus feed-forward, within the tighter of
    /// the servo's limit and the joint's effort bound), per velocity coordinate. Named `tau` as everywhere
    /// in legkit (Pinocchio's convention), the same name as the Python property `Simulation.applied_tau`.
    pub fn applied_tau(&self) -> &[f64] {
        &self.applied
    }

    /// The servos now driving the joints.
    pub fn servo(&self) -> &Servo {
        &self.servo
    }

    /// Replaces the servos from the next step on. Only the length (nv) is checked here, an error on `kp`: build
    /// `servo` with [`Servo::new`], which checks the rest.
    pub fn set_servo(&mut self, servo: Servo) -> Result<()> {
        if servo.kp.len() != self.model.nv() {
            return Err(Error::invalid("kp", format!("expected {} values, got {}", self.model.nv(), servo.kp.len())));
        }
        self.servo = servo;
        Ok(())
    }

    /// Penetration the engine lets stand without correcting it (m): the contact tolerance.
    pub fn contact_tolerance(&self) -> f64 {
        self.engine.contact_tolerance()
    }

    /// Contact-solver iterations of the last (sub)step (tree engine; None on Rapier, which runs a fixed number).
    pub fn last_solver_iterations(&self) -> Option<usize> {
        self.engine.solver_iterations()
    }

    /// Moves the robot to (q, v) without touching time, servos or the contact history. Both are checked
    /// (length, finite, unit base quaternion) before anything changes.
    pub fn set_state(&mut self, q: Option<&[f64]>, v: Option<&[f64]>) -> Result<()> {
        if let Some(q) = q {
            self.model.check_configuration(q)?;
        }
        if let Some(v) = v {
            check_vector("v", v, self.model.nv())?;
        }
        if let Some(q) = q {
            self.q.copy_from_slice(q);
        }
        if let Some(v) = v {
            self.v.copy_from_slice(v);
        }
        self.engine.write_state(&self.model, &self.q, &self.v);
        Ok(())
    }

    /// Starts over from (q, v) at time 0 with no contact history, so what follows is bit-identical to a
    /// new simulation set to the same state. Servo settings are kept.
    pub fn reset(&mut self, q: &[f64], v: &[f64]) -> Result<()> {
        self.model.check_configuration(q)?;
        check_vector("v", v, self.model.nv())?;
        self.engine.restart(&self.model, q, v)?;
        self.q.copy_from_slice(q);
        self.v.copy_from_slice(v);
        self.steps = 0;
        self.applied.fill(0.0);
        Ok(())
    }

    /// Advances `n` steps with feed-forward generalized forces `tau` (nv, held over the steps; None for
    /// zero). On a floating base, tau[0..6] is a wrench [f; n] on the base in its frame at its origin, as
    /// in `aba`. Fails before stepping on bad `tau`; stops with `Error::Numerical` at the first step whose
    /// state would diverge, or in which the engine panics (inside a dependency), leaving the simulation
    /// bit-identical to before that step: state, time, contact history and warm starts, applied forces and
    /// reported contacts.
    pub fn step(&mut self, tau: Option<&[f64]>, n: usize) -> Result<()> {
        match tau {
            Some(t) => {
                check_vector("tau", t, self.model.nv())?;
                self.tau_ff.copy_from_slice(t);
            }
            None => self.tau_ff.fill(0.0),
        }
        for _ in 0..n {
            self.advance(None)?;
        }
        Ok(())
    }

    /// One step with the feed-forward in `tau_ff`, as `step` describes it; with `ab`, that step's transition
    /// Jacobians at its start written into them (`Engine::step`).
    fn advance(&mut self, ab: Jacobians) -> Result<()> {
        let outcome =
            self.try_step(ab).and_then(|()| divergence(&self.model, &self.q_next, &self.v_next, &self.applied, self.steps + 1, self.options.dt));
        if let Err(error) = outcome {
            self.undo_step();
            return Err(error);
        }
        std::mem::swap(&mut self.q, &mut self.q_next);
        std::mem::swap(&mut self.v, &mut self.v_next);
        self.steps += 1;
        Ok(())
    }

    /// Takes one step from (q, v) into (q_next, v_next), writing `applied` (and with `ab` its Jacobians), for `advance` to keep or `undo_step` to
    /// take back (the forces before in `applied_before`, the engine's state in its `save`).
    fn try_step(&mut self, ab: Jacobians) -> Result<()> {
        self.q_next.copy_from_slice(&self.q);
        self.v_next.copy_from_slice(&self.v);
        self.applied_before.copy_from_slice(&self.applied);
        self.engine.save();
        let actuation = Actuation { servo: &self.servo, effort: &self.effort, tau_ff: &self.tau_ff };
        let (engine, model) = (&mut self.engine, &self.model);
        let (q_next, v_next, applied) = (&mut self.q_next, &mut self.v_next, &mut self.applied);
        // A panic inside a dependency (parry, Rapier) must not cross into the caller (Python): it fails
        // the step like a divergence.
        std::panic::catch_unwind(AssertUnwindSafe(|| engine.step(model, &actuation, q_next, v_next, applied, ab))).unwrap_or_else(|panic| {
            Err(Error::numerical("step", format!("the physics engine failed at step {}: {}", self.steps + 1, panic_message(&panic))))
        })
    }

    /// Takes back the step `try_step` took: the engine's state and the applied forces as before it.
    fn undo_step(&mut self) {
        self.engine.undo();
        self.applied.copy_from_slice(&self.applied_before);
    }

    /// Advances one step per row of `targets` (row-major, nv per row: the servos' position targets per
    /// velocity coordinate, base entries unused), each step's servo target the row's, with feed-forward `tau`
    /// held (None for zero): a servo tracking a trajectory at the simulation's rate without a call per
    /// step. Every target is checked (finite, whole rows) before anything moves. After it, the servos keep
    /// the last row's targets; a step that fails leaves the simulation as `step` does, its servos aiming at
    /// the last completed step's row (or as before the call).
    pub fn step_targets(&mut self, tau: Option<&[f64]>, targets: &[f64]) -> Result<()> {
        let nv = self.model.nv();
        if nv == 0 || !targets.len().is_multiple_of(nv) {
            return Err(Error::invalid(
                "targets",
                format!("expected rows of {nv} values (one per velocity coordinate), got {} values", targets.len()),
            ));
        }
        if let Some(k) = targets.iter().position(|x| !x.is_finite()) {
            return Err(Error::invalid("targets", format!("row {}, element {} is not finite ({})", k / nv, k % nv, targets[k])));
        }
        if let Some(t) = tau {
            check_vector("tau", t, nv)?;
        }
        let before = self.servo.target_q.clone();
        for (k, row) in targets.chunks_exact(nv).enumerate() {
            self.servo.target_q.copy_from_slice(row);
            if let Err(error) = self.step(tau, 1) {
                match k {
                    0 => self.servo.target_q.copy_from_slice(&before),
                    _ => self.servo.target_q.copy_from_slice(&targets[(k - 1) * nv..k * nv]),
                }
                return Err(error);
            }
        }
        Ok(())
    }

    /// The transition Jacobians of one step from the current state with feed-forward `tau` (None for zero)
    /// and the current servos: A = ∂x⁺/∂x (2 nv x 2 nv) and B = ∂x⁺/∂u (2 nv x 3 nv) into `a` and `b`, for the
    /// state x = (q on its tangent space, as q ⊕ δq; v) and the controls u = (τ_ff, target_q, target_v), as
    /// MuJoCo's `mjd_transitionFD`. Nothing changes: not the state, time, contact history nor what
    /// `contacts` reports. The step's contact set and each contact's zone (apart, sticking, sliding), its
    /// saturated servos and active joint limits are held: the Jacobians are the step's away from switches
    /// between them; a step of several substeps is the chain of theirs. Tree engine only (`Error::Invalid` otherwise).
    pub fn transition_jacobians(&mut self, tau: Option<&[f64]>, a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) -> Result<()> {
        self.reserve_jacobians()?;
        match tau {
            Some(t) => {
                check_vector("tau", t, self.model.nv())?;
                self.tau_ff.copy_from_slice(t);
            }
            None => self.tau_ff.fill(0.0),
        }
        // The step is taken and taken back, as a failed step is.
        let outcome = self.try_step(Some((a, b)));
        self.undo_step();
        outcome
    }

    /// Steps once per row of `tau` (row-major, nv per row: each step's feed-forward generalized forces), from the
    /// current state under the current servos, as MuJoCo's `rollout` does: the state after each step into `out.q` and
    /// `out.v` and, with `jacobians`, each step's transition Jacobians at its start (`transition_jacobians`, the state
    /// and control the step takes) into `out.a` and `out.b` (`Rollout`). The rows are checked (at least one, whole,
    /// finite) before anything moves, and the simulation advances as `step` does: one that fails (diverges, or is
    /// cancelled) stops at its last good state, the steps before it taken and written.
    pub fn rollout(&mut self, tau: &[f64], jacobians: bool, out: &mut Rollout) -> Result<()> {
        let (nq, nv) = (self.model.nq(), self.model.nv());
        if nv == 0 || tau.is_empty() || !tau.len().is_multiple_of(nv) {
            return Err(Error::invalid(
                "controls",
                format!("expected one or more rows of {nv} values (one per velocity coordinate), got {} values", tau.len()),
            ));
        }
        if let Some(k) = tau.iter().position(|x| !x.is_finite()) {
            return Err(Error::invalid("controls", format!("row {}, element {} is not finite ({})", k / nv, k % nv, tau[k])));
        }
        let n = tau.len() / nv;
        sized(&mut out.q, "controls", &[n, nq])?;
        sized(&mut out.v, "controls", &[n, nv])?;
        let (na, nb) = if jacobians { (4 * nv * nv, 6 * nv * nv) } else { (0, 0) };
        sized(&mut out.a, "controls", &[n, na])?;
        sized(&mut out.b, "controls", &[n, nb])?;
        if jacobians {
            self.reserve_jacobians()?;
        }
        let (mut a, mut b) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
        for (k, row) in tau.chunks_exact(nv).enumerate() {
            check_cancelled("rollout")?;
            self.tau_ff.copy_from_slice(row);
            // The step and its Jacobians in one pass (`Engine::step`).
            self.advance(jacobians.then_some((&mut a, &mut b)))?;
            if jacobians {
                // Row-major, as NumPy reads them.
                for (m, into) in [(&a, &mut out.a[k * na..(k + 1) * na]), (&b, &mut out.b[k * nb..(k + 1) * nb])] {
                    for (i, out_row) in into.chunks_exact_mut(m.ncols()).enumerate() {
                        out_row.iter_mut().zip(m.row(i).iter()).for_each(|(o, x)| *o = *x);
                    }
                }
            }
            out.q[k * nq..(k + 1) * nq].copy_from_slice(&self.q);
            out.v[k * nv..(k + 1) * nv].copy_from_slice(&self.v);
        }
        Ok(())
    }

    /// The Jacobians and the buffers behind them hold about 20 nv² numbers: a MemoryError where that cannot be
    /// allocated (asked for as one block first, as `Data::reserve_dense`), not an abort.
    fn reserve_jacobians(&self) -> Result<()> {
        let nv = self.model.nv();
        drop(with_capacity::<f64>("model", array_len("model", &[20, nv, nv], std::mem::size_of::<f64>())?)?);
        Ok(())
    }

    /// World pose of every body.
    pub fn body_poses(&self) -> Vec<Transform> {
        self.engine.body_poses(&self.model, &self.q)
    }

    /// Contacts of the last step.
    pub fn contacts(&self) -> Vec<Contact> {
        self.engine.contacts()
    }
}

/// What a caught panic says (its message if it has one).
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    match (panic.downcast_ref::<&str>(), panic.downcast_ref::<String>()) {
        (Some(message), _) => (*message).to_owned(),
        (None, Some(message)) => message.clone(),
        (None, None) => "a panic".to_owned(),
    }
}

/// `Error::Numerical` naming `step` and the first body whose coordinates are non-finite or beyond
/// `DIVERGENCE_BOUND` (speeds; the base's position and prismatic joints' coordinates), or whose actuation
/// is beyond `ACTUATION_BOUND`.
fn divergence(model: &Model, q: &[f64], v: &[f64], applied: &[f64], step: u64, dt: f64) -> Result<()> {
    // Nearly every step: every number within its bound (NaN is not), so no body's can be beyond it. Checked over the
    // whole vectors first, and body by body only to name one that is: a URDF's many fixed links made that walk a
    // tenth of a standing ANYmal's step.
    let within = |x: &[f64], bound: f64| x.iter().all(|x| x.abs() <= bound);
    if within(q, DIVERGENCE_BOUND) && within(v, DIVERGENCE_BOUND) && within(applied, ACTUATION_BOUND) {
        return Ok(());
    }
    for i in 0..model.nbodies() {
        let (kq, kv, joint) = (model.idx_q(i), model.idx_v(i), model.joint(i));
        let speeds = &v[kv..kv + joint.nv()];
        let actuation = &applied[kv..kv + joint.nv()];
        let coordinates = &q[kq..kq + joint.nq()];
        let positions = &coordinates[joint.length_coordinates()];
        let exploded = |x: &f64| !(x.abs() <= DIVERGENCE_BOUND);
        let what = if coordinates.iter().chain(speeds).any(|x| !x.is_finite()) {
            "its state is not finite"
        } else if speeds.iter().any(exploded) {
            "its speed exceeds 1e6"
        } else if positions.iter().any(exploded) {
            "its position exceeds 1e6 m"
        } else if actuation.iter().any(|x| !(x.abs() <= ACTUATION_BOUND)) {
            "its actuation exceeds 1e12 (N m or N)"
        } else {
            continue;
        };
        return Err(Error::numerical(
            "step",
            format!(
                "the simulation diverged at step {step} (t = {:.6} s): body {i} ({:?}) {what}; the state before that step is kept. \
                 Check the units of tau and the servo gains, or reduce dt",
                step as f64 * dt,
                model.name(i)
            ),
        ));
    }
    Ok(())
}
