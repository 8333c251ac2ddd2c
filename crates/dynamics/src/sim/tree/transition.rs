//! The transition Jacobians of one step: A = ∂x⁺/∂x and B = ∂x⁺/∂u at a state x = (q, v), q on its tangent
//! space (q ⊕ δq), and controls u = (τ_ff, target_q, target_v), as MuJoCo's `mjd_transitionFD` gives them.
//!
//! The step's velocities v⁺ minimise the contact solver's primal (`solver`), so its gradient vanishes there:
//!   g(v⁺; q, v, u) = h RNEA(q, v, (v⁺ − v) / h) + D (v⁺ − v) − h τ(q, v, u) − Σ_c J_cᵀ λ_c(J_c v⁺ − b_c) = 0,
//! with D the armature the actuation adds (implicit servos, damping) and τ its forces (`actuate`). By the
//! implicit-function theorem dv⁺ = −H⁻¹ (∂g/∂x dx + ∂g/∂u du), where H = ∂g/∂v⁺ = M̃ + Σ_c J_cᵀ H_c J_c, with
//! H_c = ∂λ_c/∂(−y_c) of the friction law (unsymmetric for a sliding contact, whose bound μ λ_n follows
//! y_n), formed densely here with the coupling of contacts between two bodies (which the solver's O(n)
//! factor leaves out), and solved by LU; then q⁺ = q ⊕ h v⁺ through `integrate_jacobians`.
//! ∂g/∂v and ∂g/∂u are analytic: the RNEA derivatives and the actuation's slopes. In ∂g/∂q the rigid-body and
//! actuation terms are analytic too; the contacts' Σ J_cᵀ λ_c, whose rows, gaps and regularisation move with
//! the configuration (through the contact geometry and the Delassus diagonals), is differentiated by central
//! differences at fixed v⁺: one ABA factor and one pass over the contacts per coordinate, no contact solve.
//!
//! What is differentiated: the step from the given state with its contact set, each contact's zone (apart,
//! sticking, sliding), its saturated servos and the joint limits in play held; the Jacobians are the step's
//! away from switches between them, with the contact solve taken as converged.

use nalgebra::{DMatrix, Matrix6, Matrix6xX};

use super::articulated::Articulated;
use super::delassus::Delassus;
use super::solver::{impulses_at, Constraint, Stiffness};
use super::{base_origin, contact_constraint, limit_constraint, TreeSimulation};
use crate::algorithms::{aba_with_armature, crba, integrate, integrate_jacobians, rnea_derivatives};
use crate::model::{Data, Model};
use crate::sim::actuation::Actuation;
use crate::sim::Engine;
use crate::spatial::{Motion, Transform};
use crate::{Error, Result};

/// The configuration step of the central differences of the contacts' generalized impulses (rad or m).
const STEP: f64 = 1e-6;

/// Buffers for the Jacobians of one model, grown once.
pub(super) struct Transition {
    /// The factor, Delassus diagonals, collision poses and constraints at a displaced configuration.
    data: Data,
    delassus: Delassus,
    tree: Articulated,
    constraints: Vec<Constraint>,
    poses: Vec<Transform>,
    displaced: Vec<f64>,
    direction: Vec<f64>,
    plus: Vec<f64>,
    minus: Vec<f64>,
    /// CRBA and the RNEA derivatives at the step's start, with its acceleration (v⁺ − v) / h.
    rigid: Data,
    acceleration: Vec<f64>,
    /// A contact's relative Φ_a − Φ_b (6 x nv), the coordinates it touches, and which.
    relative: Matrix6xX<f64>,
    columns: Vec<usize>,
    touched: Vec<bool>,
    hessian: DMatrix<f64>,
    /// ∂g/∂(q, v, τ_ff, target_q, target_v), nv x 5 nv; after the solve, ∂v⁺ with respect to them.
    slopes: DMatrix<f64>,
    /// ∂(q ⊕ h v⁺)/∂q and /∂v⁺.
    integrate_q: DMatrix<f64>,
    integrate_v: DMatrix<f64>,
}

impl Transition {
    pub(super) fn new(fused: &Model, nbodies: usize) -> Self {
        let nv = fused.nv();
        Transition {
            data: Data::new(fused),
            delassus: Delassus::new(fused),
            tree: Articulated::new(fused),
            constraints: Vec::new(),
            poses: vec![Transform::identity(); nbodies],
            displaced: vec![0.0; fused.nq()],
            direction: vec![0.0; nv],
            plus: vec![0.0; nv],
            minus: vec![0.0; nv],
            rigid: Data::new(fused),
            acceleration: vec![0.0; nv],
            relative: Matrix6xX::zeros(nv),
            columns: Vec::with_capacity(nv),
            touched: vec![false; nv],
            hessian: DMatrix::zeros(nv, nv),
            slopes: DMatrix::zeros(nv, 5 * nv),
            integrate_q: DMatrix::zeros(nv, nv),
            integrate_v: DMatrix::zeros(nv, nv),
        }
    }

    /// H += (Φ_a − Φ_b)ᵀ K (Φ_a − Φ_b) for a stiffness K on body `a` against body `b` (the ground if None).
    fn add_stiffness(&mut self, model: &Model, data: &Data, a: usize, b: Option<usize>, k: &Matrix6<f64>) {
        let Transition { relative, columns, touched, hessian, .. } = self;
        for (body, sign) in [(Some(a), 1.0), (b, -1.0)] {
            if let Some(body) = body {
                for_each_column(model, data, body, |column, s| {
                    let mut target = relative.column_mut(column);
                    target += s * sign;
                    if !touched[column] {
                        touched[column] = true;
                        columns.push(column);
                    }
                });
            }
        }
        for &j in columns.iter() {
            let stiffened = k * relative.column(j);
            for &i in columns.iter() {
                hessian[(i, j)] += relative.column(i).dot(&stiffened);
            }
        }
        for &j in columns.iter() {
            relative.column_mut(j).fill(0.0);
            touched[j] = false;
        }
        columns.clear();
    }
}

/// Calls `f` with each velocity coordinate moving `body` and its column of Φ_body (world axes about the base
/// origin, as `data` holds the factor).
fn for_each_column(model: &Model, data: &Data, body: usize, mut f: impl FnMut(usize, Motion)) {
    let mut i = body;
    while i > 0 {
        if model.joint(i).nv() == 1 {
            f(model.idx_v(i), data.s[i]);
        }
        i = model.parent(i);
    }
    if model.floating_base() {
        for c in 0..6 {
            f(c, data.centred_m_i[0].act_motion(&Motion::from_fn(|r, _| if r == c { 1.0 } else { 0.0 })));
        }
    }
}

impl TreeSimulation {
    /// A = ∂x⁺/∂x (2 nv square) and B = ∂x⁺/∂u (2 nv x 3 nv, u = (τ_ff, target_q, target_v)) of one step from
    /// (q, v) under `actuation`, leaving the simulation as it was.
    pub(super) fn transition_jacobians(
        &mut self,
        actuation: &Actuation<'_>,
        q: &[f64],
        v: &[f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) -> Result<()> {
        if self.options.substeps != 1 {
            return Err(Error::invalid(
                "substeps",
                format!(
                    "transition Jacobians are of a step of one substep; this simulation takes {} (use dt / substeps as dt instead)",
                    self.options.substeps
                ),
            ));
        }
        // The step is taken and undone, as a failed step is (`Engine::save`, `Engine::undo`).
        self.save();
        let (mut q_next, mut v_next, mut applied) = (q.to_vec(), v.to_vec(), vec![0.0; v.len()]);
        let mut transition = self.transition.take().unwrap_or_else(|| Box::new(Transition::new(&self.fused, self.fused_body.len())));
        let outcome =
            self.substep(actuation, &mut q_next, &mut v_next, &mut applied).and_then(|()| self.linearise(&mut transition, actuation, q, v, a, b));
        self.transition = Some(transition);
        self.undo();
        outcome
    }

    /// The Jacobians of the substep just taken from (q, v), whose solution `self` holds.
    fn linearise(
        &self,
        t: &mut Transition,
        actuation: &Actuation<'_>,
        q: &[f64],
        v: &[f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) -> Result<()> {
        let model = self.fused.as_ref();
        let (nv, h) = (model.nv(), self.h);
        let v_next = &self.v_next;
        t.hessian.copy_from(crba(model, &mut t.rigid, q));
        t.slopes.fill(0.0);
        t.slopes.columns_mut(nv, nv).zip_apply(&t.hessian, |s, m| *s = -m);
        // The free flyer's coordinates have no armature (`aba_with_armature`).
        let first_joint = if model.floating_base() { 6 } else { 0 };
        for (k, (acceleration, (after, before))) in t.acceleration.iter_mut().zip(v_next.iter().zip(v)).enumerate() {
            *acceleration = (after - before) / h;
            // The actuation's forces and their slopes by (q_k, v_k, τ_ff, target_q, target_v): an implicit servo
            // acts at the step's end (`actuate`), an unsaturated explicit one at its start, a saturated one not.
            let s = &actuation.servo;
            let (kp, kd, damping) = (s.kp[k], s.kd[k], model.damping()[k]);
            let active = self.implicit[k] || actuation.raw(k, &self.q_dof, v).abs() < actuation.bound(k);
            let gain = if active { 1.0 } else { 0.0 };
            let by_velocity = -gain * kd - damping - if self.implicit[k] { h * kp } else { 0.0 };
            let added = if k >= first_joint { self.armature[k] - model.armature()[k] } else { 0.0 };
            t.hessian[(k, k)] += added;
            t.slopes[(k, k)] += h * gain * kp;
            t.slopes[(k, nv + k)] += -added - h * by_velocity;
            t.slopes[(k, 2 * nv + k)] = -h * gain;
            t.slopes[(k, 3 * nv + k)] = -h * gain * kp;
            t.slopes[(k, 4 * nv + k)] = -h * gain * kd;
        }
        for c in &self.constraints {
            match c.stiffness() {
                Stiffness::Nothing => {}
                Stiffness::Bodies(body, other, k) => t.add_stiffness(model, &self.data, body, other, &k),
                Stiffness::Coordinate(k, stiffness) => t.hessian[(k, k)] += stiffness,
            }
        }
        let (dtau_dq, dtau_dv) = rnea_derivatives(model, &mut t.rigid, q, v, &t.acceleration, None);
        t.slopes.columns_mut(0, nv).zip_apply(dtau_dq, |s, d| *s += h * d);
        t.slopes.columns_mut(nv, nv).zip_apply(dtau_dv, |s, d| *s += h * d);
        // − ∂(Σ J_cᵀ λ_c)/∂q at fixed v⁺, by central differences.
        for k in 0..nv {
            t.direction[k] = 1.0;
            integrate(model, q, &t.direction, -STEP, &mut t.displaced);
            self.contact_impulses(t, q, v)?;
            std::mem::swap(&mut t.plus, &mut t.minus);
            integrate(model, q, &t.direction, STEP, &mut t.displaced);
            self.contact_impulses(t, q, v)?;
            t.direction[k] = 0.0;
            for (r, (plus, minus)) in t.plus.iter().zip(&t.minus).enumerate() {
                t.slopes[(r, k)] -= (plus - minus) / (2.0 * STEP);
            }
        }
        let hessian = std::mem::replace(&mut t.hessian, DMatrix::zeros(0, 0));
        // ∂g/∂v⁺ is unsymmetric where a sliding contact's friction bound follows its normal impulse (`solver`).
        let factor = hessian.lu();
        if !factor.solve_mut(&mut t.slopes) {
            return Err(Error::numerical("transition_jacobians", "the step's Jacobian M̃ + Jᵀ H J is singular"));
        }
        t.hessian = DMatrix::zeros(nv, nv);
        t.slopes.neg_mut();
        integrate_jacobians(model, v_next, h, &mut t.integrate_q, &mut t.integrate_v);
        a.resize_mut(2 * nv, 2 * nv, 0.0);
        b.resize_mut(2 * nv, 3 * nv, 0.0);
        let (by_state, by_control) = (t.slopes.columns(0, 2 * nv), t.slopes.columns(2 * nv, 3 * nv));
        a.view_mut((0, 0), (nv, 2 * nv)).gemm(1.0, &t.integrate_v, &by_state, 0.0);
        a.view_mut((0, 0), (nv, nv)).zip_apply(&t.integrate_q, |x, d| *x += d);
        a.view_mut((nv, 0), (nv, 2 * nv)).copy_from(&by_state);
        b.view_mut((0, 0), (nv, 3 * nv)).gemm(1.0, &t.integrate_v, &by_control, 0.0);
        b.view_mut((nv, 0), (nv, 3 * nv)).copy_from(&by_control);
        Ok(())
    }

    /// Σ J_cᵀ λ_c at v⁺ = `self.v_next` with the configuration at `t.displaced`: the step's contacts and
    /// limits (at `q`) moved there, each its impulses at J_c v⁺ − b_c (no solve, b_c on its piece at `q`), into
    /// `t.plus`.
    fn contact_impulses(&self, t: &mut Transition, q: &[f64], v: &[f64]) -> Result<()> {
        let model = self.fused.as_ref();
        let displaced = &t.displaced;
        aba_with_armature(model, &mut t.data, displaced, v, &self.tau, None, &self.armature);
        if !t.delassus.update(model, &t.data) {
            return Err(Error::numerical("transition_jacobians", "the mass matrix stopped being positive definite near the state"));
        }
        self.collision_poses(&t.data, displaced, &mut t.poses);
        let origin = base_origin(model, displaced);
        t.constraints.clear();
        for f in &self.found {
            let moved = self.collision.moved(f, &t.poses);
            t.constraints.push(contact_constraint(
                self.coulomb,
                model,
                &t.data,
                &t.delassus,
                &self.fused_body,
                self.friction,
                self.h,
                &moved,
                f.distance,
                &origin,
            ));
        }
        for &(index, side) in &self.limit_rows {
            // A limit's warm start only seeds the solver: its impulse at a given v⁺ does not depend on it.
            t.constraints.push(limit_constraint(model, &t.data, &t.delassus, self.h, &self.limited[index], side, displaced, q, 0.0));
        }
        impulses_at(&mut t.tree, model, &t.data, &mut t.constraints, &self.constraints, &self.v_next, &mut t.plus);
        Ok(())
    }
}
