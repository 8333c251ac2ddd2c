//! legkit's contact engine on the kinematic tree, in reduced coordinates. Each (sub)step of length h:
//!
//! 1. Actuation: an unsaturated servo's PD terms and the joint damping are integrated implicitly, as
//!    M̃ = M + diag(armature + h (kd + damping) + h² kp) and τ = servo + feed-forward − h kp v − damping v
//!    (the linearisation of the servo at the end of the step); a saturated servo applies its bound.
//! 2. Dynamics: the articulated-body algorithm on M̃ gives v_free = v + h M̃⁻¹ (τ − C v − g) in O(n), and
//!    leaves its factor, from which every body's apparent inverse inertia follows in O(n) (`delassus`).
//! 3. Contacts from parry at the start-of-step configuration (`collision`), joint limits about to be
//!    crossed, each a constraint whose rows follow the ancestor chain of its bodies.
//! 4. Newton's method on the soft contacts, under Coulomb's law (the default: the normal rows complementary
//!    to the normal velocity alone, friction in the disk |λ_t| ≤ μ λ_n: no lift off a sliding contact) or the
//!    cone law (the convex relaxation), warm-started from the last step's impulses (`solver`),
//!    gives v⁺ = v_free + M̃⁻¹ Jᵀ λ; then q⁺ = q ⊕ h v⁺ (semi-implicit Euler).
//!
//! Why Newton on the tree: its matrix M̃ + Jᵀ H J keeps the tree's sparsity (a contact adds a 6x6
//! stiffness to its body's inertia), so each iteration costs O(n) passes plus O(1) per contact
//! (`articulated`), and the Delassus matrix, dense over all contacts on a floating or deep tree, is never
//! formed. It converges in a few iterations where Gauss–Seidel on the same problem needed hundreds of
//! sweeps on trees lying on the ground.
//!
//! Nothing is allocated per step once the buffers have grown to the largest contact set seen.

mod articulated;
mod collision;
mod constraint;
mod delassus;
mod delassus_derivatives;
mod lu;
mod plane;
mod solver;
#[cfg(test)]
mod tests;
mod transition;

use std::sync::Arc;

use nalgebra::{Vector3, Vector6};

use super::actuation::{dof_coordinates, Actuation};
use super::options::{FrictionLaw, Options, DEFAULT_FRICTION};
use super::{Contact, Engine, Jacobians};
// The unchecked kernels: the engine checks its state once, not per call.
use crate::algorithms::{aba_with_armature_unchecked as aba_with_armature, integrate_unchecked as integrate, joint_placement, world_pose};
use crate::model::{Data, Model};
use crate::spatial::{spatial, Transform};
use crate::{Error, MassProperties, Result};
use collision::{warm_of, Collision, Found, History};
use constraint::{Constraint, Kind, Target, BAUMGARTE, MAX_CORRECTION, TOLERANCE};
use delassus::Delassus;
use solver::Solver;
use transition::Transition;

/// The most steps the solver waits between tries of its first step from v_free (`free_wait`).
const MAX_FREE_WAIT: usize = 64;
/// Joint limits are watched from this far off (rad or m), beyond the step's own travel.
const LIMIT_MARGIN: f64 = 1e-3;

/// A joint with a position range: its body, velocity and configuration coordinates, and bounds.
#[derive(Debug, Clone, Copy)]
struct LimitedJoint {
    body: usize,
    v: usize,
    q: usize,
    lower: f64,
    upper: f64,
}

pub(crate) struct TreeSimulation {
    /// The model with every body on a fixed joint merged into its carrier (as MuJoCo's `fusestatic`): the
    /// same coordinates, far fewer bodies on robots whose URDFs hang sensors and frames on fixed joints.
    fused: Arc<Model>,
    /// Each body's body in `fused` (the moving body it is carried by: bodies with one carrier share a
    /// chain), and its frame in that body's frame (None where the frames coincide: the body is its carrier).
    fused_body: Vec<usize>,
    offset: Vec<Option<Transform>>,
    /// The bodies carrying a collider, in order: the only ones whose poses collision needs (most of a URDF's
    /// links carry none).
    collider_bodies: Vec<usize>,
    options: Options,
    /// Substep length (s).
    h: f64,
    friction: f64,
    /// Coulomb's law rather than the cone (`FrictionLaw`).
    coulomb: bool,
    data: Data,
    delassus: Delassus,
    collision: Collision,
    /// What the step being taken changed, to undo it if it fails (`Engine::undo`).
    history: History,
    limit_impulses_before: Vec<[f64; 2]>,
    contacts_before: Vec<Contact>,
    iterations_before: usize,
    free_wait_before: [usize; 2],
    /// Joints with a position range.
    limited: Vec<LimitedJoint>,
    /// Last step's limit impulses per velocity coordinate: [at the lower bound, at the upper bound].
    limit_impulses: Vec<[f64; 2]>,
    found: Vec<Found>,
    /// For each limit constraint of this step: (its joint in `limited`, 0 for lower or 1 for upper).
    limit_rows: Vec<(usize, usize)>,
    constraints: Vec<Constraint>,
    solver: Solver,
    /// Newton iterations of the contact solver in the last substep.
    iterations: usize,
    /// Steps to wait before the solver next tries its first step from v_free (`Solver::solve`), and the wait
    /// after the next try that fails: doubled by each failure (a robot whose zones keep switching), reset by a
    /// try that lands (a resting one).
    free_wait: [usize; 2],
    poses: Vec<Transform>,
    q_dof: Vec<f64>,
    tau: Vec<f64>,
    armature: Vec<f64>,
    implicit: Vec<bool>,
    saturated: Vec<bool>,
    v_free: Vec<f64>,
    v_next: Vec<f64>,
    q_start: Vec<f64>,
    contacts: Vec<Contact>,
    /// The transition Jacobians' buffers, once asked for.
    transition: Option<Box<Transition>>,
}

impl TreeSimulation {
    pub(crate) fn new(model: &Model, options: &Options) -> Result<Self> {
        let nv = model.nv();
        let (fused, fused_body, offset) = fuse(model)?;
        let collision = Collision::new(model, options, &fused, &fused_body);
        let limited = (1..model.nbodies())
            .filter(|&i| model.joint(i).nv() == 1 && model.limits(i).has_position_limits())
            .map(|i| LimitedJoint {
                body: fused_body[i],
                v: model.idx_v(i),
                q: model.idx_q(i),
                lower: model.limits(i).lower,
                upper: model.limits(i).upper,
            })
            .collect();
        Ok(TreeSimulation {
            h: options.dt / options.substeps as f64,
            friction: options.ground.as_ref().map_or(DEFAULT_FRICTION, |g| g.friction()),
            coulomb: options.friction_law == FrictionLaw::Coulomb,
            data: Data::new(&fused),
            delassus: Delassus::new(&fused),
            solver: Solver::new(&fused),
            fused: Arc::new(fused),
            fused_body,
            offset: offset.into_iter().map(|o| (o != Transform::identity()).then_some(o)).collect(),
            collider_bodies: collision.bodies(),
            collision,
            history: History::default(),
            limit_impulses_before: vec![[0.0; 2]; nv],
            contacts_before: Vec::new(),
            iterations_before: 0,
            free_wait_before: [0, 1],
            options: options.clone(),
            limited,
            limit_impulses: vec![[0.0; 2]; nv],
            found: Vec::new(),
            limit_rows: Vec::new(),
            constraints: Vec::new(),
            iterations: 0,
            free_wait: [0, 1],
            poses: vec![Transform::identity(); model.nbodies()],
            q_dof: vec![0.0; nv],
            tau: vec![0.0; nv],
            armature: vec![0.0; nv],
            implicit: vec![false; nv],
            saturated: vec![false; nv],
            v_free: vec![0.0; nv],
            v_next: vec![0.0; nv],
            q_start: vec![0.0; model.nq()],
            contacts: Vec::new(),
            transition: None,
        })
    }

    /// The actuation of step 1; `saturated` marks servos treated as saturated whatever their force.
    fn actuate(&mut self, model: &Model, actuation: &Actuation<'_>, v: &[f64]) {
        let h = self.h;
        for k in 0..model.nv() {
            let (damping, armature) = (model.damping()[k], model.armature()[k]);
            let (kp, kd) = (actuation.servo.kp[k], actuation.servo.kd[k]);
            let (raw, bound) = (actuation.raw(k, &self.q_dof, v), actuation.bound(k));
            let implicit = !self.saturated[k] && raw.abs() <= bound && (kp > 0.0 || kd > 0.0);
            if implicit {
                self.tau[k] = raw - h * kp * v[k] - damping * v[k];
                self.armature[k] = armature + h * (kd + damping) + h * h * kp;
            } else {
                self.tau[k] = raw.clamp(-bound, bound) - damping * v[k];
                self.armature[k] = armature + h * damping;
            }
            self.implicit[k] = implicit;
        }
    }

    /// Step 3: the constraints of this step, contacts first, in the order found; `model` is the fused model.
    fn constrain(&mut self, model: &Model, q: &[f64]) {
        let origin = base_origin(model, q);
        self.constraints.clear();
        for f in &self.found {
            self.constraints.push(self.contact_row(model, &self.data, &self.delassus, f, f.distance, &origin));
        }
        self.limit_rows.clear();
        for (index, joint) in self.limited.iter().enumerate() {
            let travel = self.h * self.v_free[joint.v];
            for (side, gap, sign) in [(0, q[joint.q] - joint.lower, 1.0), (1, joint.upper - q[joint.q], -1.0)] {
                if gap >= LIMIT_MARGIN + (-sign * travel).max(0.0) {
                    continue;
                }
                let warm = self.limit_impulses[joint.v][side];
                self.constraints.push(limit_constraint(model, &self.data, &self.delassus, self.h, joint, side, q, q, warm));
                self.limit_rows.push((index, side));
            }
        }
    }

    /// The world poses of the original model's bodies that carry colliders from the fused model's, which
    /// `data` holds about the base origin of `q`, into `poses` (indexed by body; the others are left as they are), with
    /// `moving` those of the fused bodies it marks alone.
    fn collision_poses(&self, data: &Data, q: &[f64], poses: &mut [Transform], moving: Option<&[bool]>) {
        let origin = base_origin(&self.fused, q);
        for &i in &self.collider_bodies {
            if moving.is_some_and(|moving| !moving[self.fused_body[i]]) {
                continue;
            }
            let centred = &data.centred_m_i[self.fused_body[i]];
            let pose = Transform::new(centred.rotation, centred.translation + origin);
            poses[i] = match &self.offset[i] {
                Some(offset) => pose.compose(offset),
                None => pose,
            };
        }
    }

    fn substep(&mut self, actuation: &Actuation<'_>, q: &mut [f64], v: &mut [f64], applied: &mut [f64]) -> Result<()> {
        let fused = Arc::clone(&self.fused);
        let model = fused.as_ref();
        let (h, nv) = (self.h, model.nv());
        dof_coordinates(model, q, &mut self.q_dof);
        self.saturated.fill(false);
        let mut detected = false;
        loop {
            self.actuate(model, actuation, v);
            let ddq = aba_with_armature(model, &mut self.data, q, v, &self.tau, None, &self.armature);
            for k in 0..nv {
                self.v_free[k] = v[k] + h * ddq[k];
            }
            if !self.delassus.update(model, &self.data, &self.armature) {
                return Err(Error::numerical("step", "the mass matrix stopped being positive definite (a massless body on a joint?)"));
            }
            if !detected {
                let mut poses = std::mem::take(&mut self.poses);
                self.collision_poses(&self.data, q, &mut poses, None);
                self.poses = poses;
                self.found.clear();
                self.collision.detect(&self.poses, &mut self.found, &mut self.history);
                // Bodies fixed to a fixed base cannot move: their contacts carry no constraint.
                if !model.floating_base() {
                    let carrier = &self.fused_body;
                    self.found.retain(|f| carrier[f.body] != 0 || f.other.is_some_and(|o| carrier[o] != 0));
                }
                detected = true;
            }
            self.constrain(model, q);
            let (most, from_free) = (self.options.solver_iterations, self.iterations <= 1 && self.free_wait[0] == 0);
            self.free_wait[0] = self.free_wait[0].saturating_sub(1);
            self.iterations = self
                .solver
                .solve(
                    model,
                    &self.data,
                    self.delassus.base(),
                    &self.armature,
                    &mut self.constraints,
                    &self.v_free,
                    &mut self.v_next,
                    most,
                    from_free,
                )
                .ok_or_else(|| Error::numerical("step", "the contact solver's Newton matrix stopped being positive definite"))?;
            if from_free {
                let [_, next] = self.free_wait;
                self.free_wait = if self.solver.landed { [0, 1] } else { [next, (2 * next).min(MAX_FREE_WAIT)] };
            }
            // An implicit servo whose force at the end of the step exceeds its bound saturates: redo the
            // step with it applying its bound.
            let mut redo = false;
            for k in 0..nv {
                let (raw, bound) = (actuation.raw(k, &self.q_dof, v), actuation.bound(k));
                applied[k] = if self.implicit[k] {
                    let (kp, kd) = (actuation.servo.kp[k], actuation.servo.kd[k]);
                    let force = raw - kp * h * self.v_next[k] - kd * (self.v_next[k] - v[k]);
                    if force.abs() > bound {
                        self.saturated[k] = true;
                        redo = true;
                    }
                    force
                } else {
                    raw.clamp(-bound, bound)
                };
            }
            if !redo {
                break;
            }
        }
        self.report(h);
        v.copy_from_slice(&self.v_next);
        self.q_start.copy_from_slice(q);
        integrate(model, &self.q_start, v, h, q);
        Ok(())
    }

    /// Keeps the impulses for the next step's warm start and reports the contacts.
    fn report(&mut self, h: f64) {
        self.contacts.clear();
        let per_second = 1.0 / h;
        for (f, c) in self.found.iter().zip(&self.constraints) {
            let warm = warm_of(&f.tangents, &c.lambda);
            let friction = Vector3::new(warm[1], warm[2], warm[3]);
            self.collision.store(f.source, warm);
            self.contacts.push(Contact {
                body: f.body,
                other: f.other,
                point: f.point,
                normal: f.normal,
                normal_force: c.lambda[0] * per_second,
                tangential_force: friction * per_second,
                depth: (-f.distance).max(0.0),
            });
        }
        for impulses in self.limit_impulses.iter_mut() {
            *impulses = [0.0; 2];
        }
        for (&(index, side), c) in self.limit_rows.iter().zip(&self.constraints[self.found.len()..]) {
            self.limit_impulses[self.limited[index].v][side] = c.lambda[0];
        }
    }
}

impl Engine for TreeSimulation {
    fn write_state(&mut self, _model: &Model, _q: &[f64], _v: &[f64]) {}

    fn restart(&mut self, _model: &Model, _q: &[f64], _v: &[f64]) -> Result<()> {
        self.collision.clear();
        self.limit_impulses.iter_mut().for_each(|x| *x = [0.0; 2]);
        self.contacts.clear();
        // As new: no solve yet (which also sets how the next one starts, `Solver::solve`).
        self.iterations = 0;
        self.free_wait = [0, 1];
        Ok(())
    }

    fn step(&mut self, _model: &Model, actuation: &Actuation<'_>, q: &mut [f64], v: &mut [f64], applied: &mut [f64], ab: Jacobians) -> Result<()> {
        if let Some(ab) = ab {
            return self.step_with_jacobians(actuation, q, v, applied, ab);
        }
        for _ in 0..self.options.substeps {
            self.substep(actuation, q, v, applied)?;
        }
        Ok(())
    }

    fn save(&mut self) {
        self.collision.save(&mut self.history);
        self.limit_impulses_before.copy_from_slice(&self.limit_impulses);
        self.contacts_before.clone_from(&self.contacts);
        self.iterations_before = self.iterations;
        self.free_wait_before = self.free_wait;
    }

    fn undo(&mut self) {
        self.collision.undo(&mut self.history);
        self.limit_impulses.copy_from_slice(&self.limit_impulses_before);
        std::mem::swap(&mut self.contacts, &mut self.contacts_before);
        self.iterations = self.iterations_before;
        self.free_wait = self.free_wait_before;
    }

    fn body_poses(&self, model: &Model, q: &[f64]) -> Vec<Transform> {
        let mut poses = vec![joint_placement(model, 0, q)];
        for i in 1..model.nbodies() {
            let parent = poses[model.parent(i)];
            poses.push(world_pose(model, i, &parent, q));
        }
        poses
    }

    fn contacts(&self) -> Vec<Contact> {
        self.contacts.clone()
    }

    fn contact_tolerance(&self) -> f64 {
        TOLERANCE
    }

    fn solver_iterations(&self) -> Option<usize> {
        Some(self.iterations)
    }
}

fn carriers(model: &Model) -> Vec<usize> {
    let mut carrier = vec![0; model.nbodies()];
    for i in 1..model.nbodies() {
        carrier[i] = if model.joint(i).nv() == 0 { carrier[model.parent(i)] } else { i };
    }
    carrier
}

/// `model` with every body on a fixed joint merged into its carrier (its mass properties moved into the
/// carrier's frame), moving bodies kept in order so coordinates are unchanged; and for each body of
/// `model`, its body in the fused model and its frame there.
fn fuse(model: &Model) -> Result<(Model, Vec<usize>, Vec<Transform>)> {
    let n = model.nbodies();
    let carrier = carriers(model);
    let mut offset = vec![Transform::identity(); n];
    let mut mass = vec![MassProperties::zero(); n];
    for i in 0..n {
        if i > 0 && carrier[i] != i {
            offset[i] = offset[model.parent(i)].compose(model.placement(i));
        }
        mass[carrier[i]] = mass[carrier[i]] + model.body(i).transformed_unchecked(&offset[i].rotation, &offset[i].translation);
    }
    let mut fused = Model::new(model.floating_base(), mass[0], model.name(0));
    fused.gravity = model.gravity;
    let mut fused_body = vec![0; n];
    for i in 1..n {
        fused_body[i] = if carrier[i] == i {
            let parent = model.parent(i);
            let placement = offset[parent].compose(model.placement(i));
            fused.add_body(fused_body[parent], *model.joint(i), placement, mass[i], model.name(i), *model.limits(i))?
        } else {
            fused_body[carrier[i]]
        };
    }
    fused.set_armature(model.armature())?;
    fused.set_damping(model.damping())?;
    Ok((fused, fused_body, offset))
}

/// The constraint of contact `f` (on the original model's bodies, `fused_body` mapping them to the fused model's) for a
/// step of `h` with friction `mu`, its normal velocity asked on the piece of gap `piece` (`asked_normal_velocity`), its
/// Delassus diagonal and scale from `diagonal` of its bodies, rows and arm (`Delassus::contact`).
#[allow(clippy::too_many_arguments)]
fn contact_constraint(
    coulomb: bool, fused_body: &[usize], mu: f64, h: f64, f: &Found, piece: f64, origin: &Vector3<f64>,
    diagonal: impl FnOnce(usize, Option<usize>, &[Vector6<f64>; 3], &Vector3<f64>) -> ([f64; 2], f64),
) -> Constraint {
    let (body, other) = (fused_body[f.body], f.other.map(|o| fused_body[o]));
    let [t1, t2] = f.tangents;
    let r = f.point - origin;
    let rows = [f.normal, t1, t2].map(|d| spatial(d, r.cross(&d)));
    let (diagonal, scale) = diagonal(body, other, &rows, &r);
    let warm_t = Vector3::new(f.warm[1], f.warm[2], f.warm[3]);
    let warm = [f.warm[0], warm_t.dot(&t1), warm_t.dot(&t2)];
    Constraint::new(
        Kind::Contact { mu, arm: r, coulomb },
        Target::Bodies(body, other),
        rows,
        asked_normal_velocity(f.distance, h, piece),
        warm,
        diagonal,
        scale,
    )
}

/// The constraint of `joint`'s lower (`side` 0) or upper (1) bound at configuration `q`, its normal velocity asked
/// on the piece of the gap at configuration `piece`, with its warm-start impulse, on the fused `model` whose
/// factor `data` and `delassus` hold.
#[allow(clippy::too_many_arguments)]
fn limit_constraint(
    model: &Model, data: &Data, delassus: &Delassus, h: f64, joint: &LimitedJoint, side: usize, q: &[f64], piece: &[f64], warm: f64,
) -> Constraint {
    let gap = |q: &[f64]| if side == 0 { q[joint.q] - joint.lower } else { joint.upper - q[joint.q] };
    let sign = if side == 0 { 1.0 } else { -1.0 };
    let a = delassus.coordinate(model, data, joint.body);
    let unit = Vector6::new(sign, 0.0, 0.0, 0.0, 0.0, 0.0);
    let zero = Vector6::zeros();
    Constraint::new(
        Kind::Limit,
        Target::Coordinate(joint.v),
        [unit, zero, zero],
        asked_normal_velocity(gap(q), h, gap(piece)),
        [warm, 0.0, 0.0],
        [a, 0.0],
        a,
    )
}

/// The normal velocity a constraint at `gap` asks for in a step of `h`: the gap closed while apart
/// (speculative contact), a fraction of the penetration while overlapping (Baumgarte).
/// `piece` is the gap whose piece of this piecewise-linear law applies (`gap` itself in a step; the step's own
/// gap when differentiating it, which holds the piece).
fn asked_normal_velocity(gap: f64, h: f64, piece: f64) -> f64 {
    if piece > 0.0 {
        -gap / h
    } else if -BAUMGARTE * piece / h < MAX_CORRECTION {
        -BAUMGARTE * gap / h
    } else {
        MAX_CORRECTION
    }
}

/// The base's origin in the world: the origin of the frame `aba` works about.
fn base_origin(model: &Model, q: &[f64]) -> Vector3<f64> {
    if model.floating_base() {
        Vector3::new(q[0], q[1], q[2])
    } else {
        Vector3::zeros()
    }
}
