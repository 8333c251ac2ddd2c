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
//! differences at fixed v⁺ and fixed Delassus diagonals, no contact solve: per coordinate, the poses of the subtree its
//! joint moves and one pass over the contacts it moves (the others keep their rows, gap and velocity). Every
//! constraint's diagonal changes with the configuration too, through M̃ and its rows; the chain rule carries that: its
//! impulses' slopes by its diagonal (once per substep) times the diagonal's slopes by q, analytic at fixed rows
//! (`delassus_derivatives`) plus the moved rows' own change.
//!
//! What is differentiated: the step from the given state with its contact set, each contact's zone (apart,
//! sticking, sliding), its saturated servos and the joint limits in play held; the Jacobians are the step's
//! away from switches between them, with the contact solve taken as converged. A step of several substeps is the
//! chain of theirs, each substep's contact set and zones held, the warm starts it passes on followed (`Substeps`).

use nalgebra::{DMatrix, Matrix3x2, Matrix4, Matrix4x3, Matrix6, Matrix6x4, Matrix6xX, Vector2, Vector3, Vector4, Vector6};

use super::articulated::Articulated;
use super::collision::{warm_of, Found, Source, Warm};
use super::constraint::{Constraint, Stiffness, Target};
use super::delassus::Delassus;
use super::delassus_derivatives::DiagonalSlopes;
use super::lu::{lu_factor, lu_solve};
use super::solver::generalized_impulses;
use super::{base_origin, contact_constraint, limit_constraint, TreeSimulation};
use crate::algorithms::aba::ball_subspace;
// The unchecked kernels: the engine checks its state once, not per call.
use crate::algorithms::{
    crba_unchecked as crba, integrate_jacobians_unchecked as integrate_jacobians, integrate_unchecked as integrate,
    placement_update_unchecked as placement_update, rnea_derivatives_unchecked as rnea_derivatives,
};
use crate::joint::Dofs;
use crate::model::{Data, Dense, Model};
use crate::sim::actuation::Actuation;
use crate::spatial::{Motion, Transform};
use crate::validate::{array_len, check_cancelled, filled};
use crate::{Error, Result};

/// The step of the central differences of the contacts' impulses (rad or m, m/s; relative for a diagonal or a warm start).
/// Their truncation error, ∝ STEP², is large for contacts that curve sharply in q (5e-6 of the Jacobians of the
/// 21-module tree resting on box corners at 1e-6); the rounding at 1e-7 stays near 1e-9.
const STEP: f64 = 1e-7;

/// Buffers for the Jacobians of one model, grown once.
pub(super) struct Transition {
    /// The poses, collision poses and constraints at a displaced configuration: the poses the step's own but for the
    /// bodies in `written` (`placement_update`), and the body whose joint each coordinate is.
    data: Data,
    written: Vec<usize>,
    body_of: Vec<usize>,
    /// The fused bodies a displacement moves (its coordinate's joint's subtree), and the step's contacts re-evaluated
    /// at its own configuration (`Collision::moved`), which a contact between bodies it does not move keeps.
    moving: Vec<bool>,
    found_at_q: Vec<Found>,
    /// Per contact, whether the displacement moves it; per constraint (contacts, then limits), its constraint built at
    /// the step's configuration, its Delassus diagonal and scale there, and the slopes of its impulses by that diagonal
    /// [normal, tangents] (3 x 2), which carry its change (`DiagonalSlopes`) by the chain rule.
    contact_moves: Vec<bool>,
    held: Vec<Constraint>,
    held_diagonals: Vec<(Vector2<f64>, f64)>,
    by_diagonal: Vec<Matrix3x2<f64>>,
    diagonal_slopes: DiagonalSlopes,
    /// The rows of the moved contacts at the displacement's − side, for their rows' own change.
    rows_minus: Vec<[Vector6<f64>; 3]>,
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
    /// H, then its LU factors in place with their row swaps (`lu_factor`), and H⁻¹ from them: its products with the
    /// 3 nv columns of a substep are one matrix product, not 3 nv triangular solves. No allocation per substep.
    hessian: DMatrix<f64>,
    pivots: Vec<usize>,
    inverse: DMatrix<f64>,
    /// ∂g/∂(q, v, τ_ff), nv x 3 nv; of a lone substep, after the solve, ∂v⁺ by them. Every substep's slopes by the
    /// servo targets are its slopes by τ_ff times kp and kd, so the chain carries τ_ff's columns alone
    /// (`servo_columns`).
    slopes: DMatrix<f64>,
    /// ∂(q ⊕ h v⁺)/∂q and /∂v⁺.
    integrate_q: DMatrix<f64>,
    integrate_v: DMatrix<f64>,
    /// Across substeps (`Substeps`).
    substeps: Substeps,
    /// The state a substep starts from.
    start: [Vec<f64>; 2],
}

/// An r x c matrix of zeros, allocated fallibly: `Error::TooLarge` naming the model where it cannot be (the
/// Jacobians' buffers grow with nv², a model too large for them is a MemoryError, not an abort).
fn zeros(rows: usize, columns: usize) -> Result<DMatrix<f64>> {
    let len = array_len("model", &[rows, columns], std::mem::size_of::<f64>())?;
    Ok(DMatrix::from_vec(rows, columns, filled("model", len, 0.0)?))
}

/// `matrix` sized r x c and zeroed, reallocated (fallibly) only if its size changes.
fn zeroed(matrix: &mut DMatrix<f64>, rows: usize, columns: usize) -> Result<()> {
    if matrix.shape() == (rows, columns) {
        matrix.fill(0.0);
    } else {
        *matrix = zeros(rows, columns)?;
    }
    Ok(())
}

/// The chain rule across the substeps of one step. Substep s maps (q_s, v_s) and its contacts' warm starts W_s (each
/// contact's [λ_n, friction in world axes], which it inherits from the last substep's impulses) to (q_s+1, v_s+1) and
/// its impulses, the next W. The warm start is no mere seed: the friction rows ask for R_t λ_t,warm (`solver`), so a
/// substep's solution depends on it, and through it on the state and controls at the step's start.
#[derive(Default)]
struct Substeps {
    /// ∂(q_s, v_s)/∂(x, τ_ff) (2 nv x 3 nv) and ∂W_s/∂(x, τ_ff) (4 k_s x 3 nv).
    state: DMatrix<f64>,
    warm: DMatrix<f64>,
    /// Per contact, the spatial force F ∂λ_c/∂W_c its impulses' slopes by its warm start exert (6 x 4; a contact's
    /// impulses at fixed v⁺ depend on its own warm start alone).
    warm_force: Vec<Matrix6x4<f64>>,
    /// ∂v⁺ and ∂q⁺ by (x, τ_ff) of the substep being folded in (nv x 3 nv each), and ∂W⁺ before it is passed on.
    velocity_by: DMatrix<f64>,
    position_by: DMatrix<f64>,
    /// The right-hand side ∂g d(x_s, τ_ff, W_s) of dv⁺ (nv x 3 nv).
    rhs: DMatrix<f64>,
    warm_by: DMatrix<f64>,
    /// The last substep's contacts (where their impulses went) and impulses, and ∂W⁺/∂(x, τ_ff) (4 k x 3 nv).
    sources: Vec<(Source, usize, Option<usize>, Warm)>,
    next_warm: DMatrix<f64>,
    /// Per contact of this substep: ∂W⁺/∂q at fixed v⁺ (4 k x nv), ∂W_c⁺/∂W_c (4 x 4), and ∂W_c⁺/∂(J_c v⁺) (4 x 3: a
    /// contact's impulses follow v⁺ through its own rows' velocities alone).
    warm_dq: DMatrix<f64>,
    warm_dw: Vec<Matrix4<f64>>,
    warm_dy: Vec<Matrix4x3<f64>>,
    /// Per contact of this substep, the last substep's contact whose impulses it inherits (`inherited_warm`).
    inherits_from: Vec<Option<usize>>,
    /// The impulses at the displaced configurations (4 k each) and the contacts' tangents there.
    warm_plus: Vec<f64>,
    warm_minus: Vec<f64>,
    tangents: Vec<[nalgebra::Vector3<f64>; 2]>,
}

impl Transition {
    pub(super) fn new(fused: &Model, nbodies: usize) -> Result<Self> {
        let nv = fused.nv();
        Ok(Transition {
            data: Data::new(fused),
            written: Vec::with_capacity(nbodies),
            body_of: (0..fused.nbodies()).flat_map(|i| std::iter::repeat_n(i, fused.joint(i).nv())).collect(),
            moving: vec![false; fused.nbodies()],
            found_at_q: Vec::new(),
            contact_moves: Vec::new(),
            held: Vec::new(),
            held_diagonals: Vec::new(),
            by_diagonal: Vec::new(),
            diagonal_slopes: DiagonalSlopes::default(),
            rows_minus: Vec::new(),
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
            hessian: zeros(nv, nv)?,
            pivots: Vec::with_capacity(nv),
            inverse: zeros(nv, nv)?,
            slopes: zeros(nv, 3 * nv)?,
            integrate_q: zeros(nv, nv)?,
            integrate_v: zeros(nv, nv)?,
            substeps: Substeps::default(),
            start: [vec![0.0; fused.nq()], vec![0.0; nv]],
        })
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
        match model.joint(i).dofs() {
            Dofs::One(_) => f(model.idx_v(i), data.s[i]),
            Dofs::Ball => {
                let subspace = ball_subspace(&data.centred_m_i[i]);
                for c in 0..3 {
                    f(model.idx_v(i) + c, Motion::from(subspace.column(c).into_owned()));
                }
            }
            Dofs::Zero | Dofs::Free => {}
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
    /// `contact_constraint` of contact `f` with this simulation's law, friction, step and body map, on the factor in
    /// `data` and `delassus` (the step's own, or one at a displaced configuration), its gap law's piece `piece`.
    pub(super) fn contact_row(&self, model: &Model, data: &Data, delassus: &Delassus, f: &Found, piece: f64, origin: &Vector3<f64>) -> Constraint {
        let diagonal = |body, other, rows: &_, arm: &_| delassus.contact(model, data, body, other, rows, arm);
        contact_constraint(self.coulomb, &self.fused_body, self.friction, self.h, f, piece, origin, diagonal)
    }

    /// `contact_row` with the Delassus diagonal and scale given.
    fn contact_row_with(&self, f: &Found, piece: f64, origin: &Vector3<f64>, (diagonal, scale): (Vector2<f64>, f64)) -> Constraint {
        contact_constraint(self.coulomb, &self.fused_body, self.friction, self.h, f, piece, origin, |_, _, _, _| (diagonal.into(), scale))
    }

    /// The Jacobians' buffers, taken out of `self` while they are in use.
    fn take_transition(&mut self) -> Result<Box<Transition>> {
        match self.transition.take() {
            Some(t) => Ok(t),
            None => Ok(Box::new(Transition::new(&self.fused, self.fused_body.len())?)),
        }
    }

    /// One step from (q, v), as `Engine::step` takes it (the same substeps, bit for bit), with its Jacobians at its
    /// start into `a` and `b`, A = ∂x⁺/∂x (2 nv square) and B = ∂x⁺/∂u (2 nv x 3 nv, u = (τ_ff, target_q, target_v)): a
    /// rollout's step and its linearisation in one pass.
    pub(super) fn step_with_jacobians(
        &mut self, actuation: &Actuation<'_>, q: &mut [f64], v: &mut [f64], applied: &mut [f64], (a, b): (&mut DMatrix<f64>, &mut DMatrix<f64>),
    ) -> Result<()> {
        let mut transition = self.take_transition()?;
        let mut start = std::mem::take(&mut transition.start);
        let outcome = self.chain(&mut transition, &mut start, actuation, q, v, applied, a, b);
        transition.start = start;
        self.transition = Some(transition);
        outcome
    }

    /// Takes the step's substeps from (q, v), in place, each linearised at its start (from `q_start`, `v_start`), and
    /// composes their Jacobians into `a` and `b` (`Substeps`): A = A_k ⋯ A_1 and B = Σ_s A_k ⋯ A_s+1 B_s, with each
    /// substep's warm starts followed from the impulses of the substep before it.
    #[allow(clippy::too_many_arguments)]
    fn chain(
        &mut self, t: &mut Transition, [q_start, v_start]: &mut [Vec<f64>; 2], actuation: &Actuation<'_>, q_s: &mut [f64], v_s: &mut [f64],
        applied: &mut [f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>,
    ) -> Result<()> {
        let (nv, substeps) = (self.fused.nv(), self.options.substeps);
        zeroed(a, 2 * nv, 2 * nv)?;
        zeroed(b, 2 * nv, 3 * nv)?;
        for s in 0..substeps {
            // A thousand substeps of a large model take seconds: a caller that was interrupted stops them here, and
            // `transition_jacobians` undoes what was taken.
            check_cancelled("transition_jacobians")?;
            q_start.copy_from_slice(q_s);
            v_start.copy_from_slice(v_s);
            self.substep(actuation, q_s, v_s, applied)?;
            // The first substep's warm starts are the last step's impulses: constant.
            let inherits = s > 0;
            let passes_on = s + 1 < substeps;
            if inherits {
                self.inherited_warm(t)?;
            }
            self.linearise(t, actuation, q_start, v_start, inherits, passes_on)?;
            if substeps == 1 {
                // ∂v⁺ = −H⁻¹ ∂g.
                let solved = &mut t.substeps.velocity_by;
                zeroed(solved, nv, 3 * nv)?;
                solved.gemm(-1.0, &t.inverse, &t.slopes, 0.0);
                std::mem::swap(&mut t.slopes, solved);
                self.write_jacobians(t, a, b);
                servo_columns(actuation, b);
                return Ok(());
            }
            self.compose(t, s == 0, passes_on)?;
        }
        let state = &t.substeps.state;
        a.copy_from(&state.columns(0, 2 * nv));
        b.columns_mut(0, nv).copy_from(&state.columns(2 * nv, nv));
        servo_columns(actuation, b);
        Ok(())
    }

    /// A and B's feed-forward columns of a lone substep from its slopes.
    fn write_jacobians(&self, t: &Transition, a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        let nv = self.fused.nv();
        let (by_state, by_control) = (t.slopes.columns(0, 2 * nv), t.slopes.columns(2 * nv, nv));
        a.view_mut((0, 0), (nv, 2 * nv)).gemm(1.0, &t.integrate_v, &by_state, 0.0);
        a.view_mut((0, 0), (nv, nv)).zip_apply(&t.integrate_q, |x, d| *x += d);
        a.view_mut((nv, 0), (nv, 2 * nv)).copy_from(&by_state);
        b.view_mut((0, 0), (nv, nv)).gemm(1.0, &t.integrate_v, &by_control, 0.0);
        b.view_mut((nv, 0), (nv, nv)).copy_from(&by_control);
    }

    /// ∂W_s/∂(x, u) of this substep's contacts from the last substep's impulses: a contact inherits the impulses of
    /// the last substep's contact at the same place (`Source`) on the same bodies, exactly as stored (`report`);
    /// any other warm start is the last step's, constant.
    fn inherited_warm(&self, t: &mut Transition) -> Result<()> {
        let columns = 3 * self.fused.nv();
        let Substeps { warm, next_warm, sources, inherits_from, .. } = &mut t.substeps;
        zeroed(warm, 4 * self.found.len(), columns)?;
        inherits_from.clear();
        for f in &self.found {
            let same = |(source, body, other, warm): &(Source, usize, Option<usize>, Warm)| {
                let place = match (source, &f.source) {
                    (Source::Plane(a, b), Source::Plane(c, d)) => a == c && b == d,
                    (Source::Manifold(a, b, c), Source::Manifold(d, e, g)) => a == d && b == e && c == g,
                    _ => false,
                };
                place && *body == f.body && *other == f.other && *warm == f.warm
            };
            inherits_from.push(sources.iter().position(same));
        }
        // Column by column, each contact's four rows contiguous.
        let (rows, from_rows) = (warm.nrows(), next_warm.nrows());
        if rows == 0 || from_rows == 0 {
            return Ok(());
        }
        for (column, from) in warm.as_mut_slice().chunks_exact_mut(rows).zip(next_warm.as_slice().chunks_exact(from_rows)) {
            for (c, k) in inherits_from.iter().enumerate() {
                if let Some(k) = k {
                    column[4 * c..4 * c + 4].copy_from_slice(&from[4 * k..4 * k + 4]);
                }
            }
        }
        Ok(())
    }

    /// Folds this substep's Jacobians (its slopes by (q_s, v_s, τ_ff, W_s), `linearise`) into ∂(q, v)/∂(x, τ_ff) and,
    /// if `passes_on`, its impulses' into ∂W⁺/∂(x, τ_ff). The slopes are applied to the running block before the solve, so
    /// H⁻¹ (from its factor) multiplies 3 nv columns once, and the warm starts' act as forces on their bodies.
    fn compose(&self, t: &mut Transition, first: bool, passes_on: bool) -> Result<()> {
        let model = self.fused.as_ref();
        let (nv, k) = (model.nv(), self.found.len());
        let (columns, k4) = (3 * nv, 4 * k);
        let ss = &mut t.substeps;
        if first {
            zeroed(&mut ss.state, 2 * nv, columns)?;
            ss.state.view_mut((0, 0), (2 * nv, 2 * nv)).fill_with_identity();
            zeroed(&mut ss.warm, k4, columns)?;
        }
        // dv⁺ = −H⁻¹ (∂g/∂(q_s, v_s) d(q_s, v_s) + ∂g/∂τ_ff dτ_ff + ∂g/∂W dW_s), ∂g/∂W_c = −J_cᵀ F ∂λ_c/∂W_c. The
        // first substep's d(q_s, v_s) is the identity on the state's columns: its products are copies.
        zeroed(&mut ss.rhs, nv, columns)?;
        let rhs = &mut ss.rhs;
        if first {
            rhs.columns_mut(0, 2 * nv).copy_from(&t.slopes.columns(0, 2 * nv));
        } else {
            rhs.gemm(1.0, &t.slopes.columns(0, 2 * nv), &ss.state, 0.0);
        }
        rhs.columns_mut(2 * nv, nv).zip_apply(&t.slopes.columns(2 * nv, nv), |x, p| *x += p);
        if !first && ss.warm.nrows() == k4 && ss.warm_force.len() == k {
            // Column by column: the contacts' forces on their bodies, then one pass down the tree (`generalized`),
            // O(n + k) a column where a product with Σ_c J_cᵀ F ∂λ_c/∂W_c would be O(nv k).
            for (j, mut column) in rhs.column_iter_mut().enumerate() {
                t.tree.force.fill(Vector6::zeros());
                for (c, force) in ss.warm_force.iter().enumerate() {
                    let Some((body, other)) = self.constraints[c].bodies() else { continue };
                    let f = force * ss.warm.fixed_view::<4, 1>(4 * c, j);
                    t.tree.force[body] += f;
                    if let Some(other) = other {
                        t.tree.force[other] -= f;
                    }
                }
                t.tree.generalized(model, &self.data, &mut t.plus);
                column.iter_mut().zip(&t.plus).for_each(|(x, g)| *x -= g);
            }
        }
        zeroed(&mut ss.velocity_by, nv, columns)?;
        ss.velocity_by.gemm(-1.0, &t.inverse, &ss.rhs, 0.0);
        // dq⁺ = ∂(q ⊕ h v⁺)/∂q dq_s + ∂(q ⊕ h v⁺)/∂v⁺ dv⁺.
        zeroed(&mut ss.position_by, nv, columns)?;
        if first {
            ss.position_by.columns_mut(0, nv).copy_from(&t.integrate_q);
        } else {
            ss.position_by.gemm(1.0, &t.integrate_q, &ss.state.rows(0, nv), 0.0);
        }
        ss.position_by.gemm(1.0, &t.integrate_v, &ss.velocity_by, 1.0);
        if passes_on {
            // dW⁺ = ∂W⁺/∂q dq_s + ∂W⁺/∂W dW_s + ∂W_c⁺/∂y_c J_c dv⁺ (each contact's own warm start and rows alone).
            zeroed(&mut ss.warm_by, k4, columns)?;
            if first {
                ss.warm_by.columns_mut(0, nv).copy_from(&ss.warm_dq);
            } else {
                ss.warm_by.gemm(1.0, &ss.warm_dq, &ss.state.rows(0, nv), 0.0);
            }
            // Column by column, one pass over the tree each for the bodies' motions: O(n + k), not a 3 k x nv product.
            let inherited = ss.warm.nrows() == k4;
            for (j, column) in ss.velocity_by.column_iter().enumerate() {
                t.tree.motions(model, &self.data, column.as_slice());
                for (c, (by_velocity, by_warm)) in ss.warm_dy.iter().zip(&ss.warm_dw).enumerate() {
                    let y = self.constraints[c].velocity(&t.tree.motion, column.as_slice());
                    let mut change = by_velocity * Vector3::from(y);
                    if inherited {
                        change += by_warm * ss.warm.fixed_view::<4, 1>(4 * c, j);
                    }
                    let mut target = ss.warm_by.fixed_view_mut::<4, 1>(4 * c, j);
                    target += change;
                }
            }
            std::mem::swap(&mut ss.next_warm, &mut ss.warm_by);
            ss.sources.clear();
            for (f, c) in self.found.iter().zip(&self.constraints) {
                ss.sources.push((f.source, f.body, f.other, warm_of(&f.tangents, &c.lambda)));
            }
        }
        ss.state.rows_mut(0, nv).copy_from(&ss.position_by);
        ss.state.rows_mut(nv, nv).copy_from(&ss.velocity_by);
        Ok(())
    }

    /// The Jacobians of the substep just taken from (q, v), whose solution `self` holds: ∂g/∂(q, v, τ_ff) in
    /// `t.slopes` and H factored in `t.hessian`, and with `inherits` the warm starts' forces (`Substeps::warm_force`);
    /// with `passes_on`, the derivatives of its impulses (the next substep's warm starts) in `t.substeps`.
    fn linearise(&self, t: &mut Transition, actuation: &Actuation<'_>, q: &[f64], v: &[f64], inherits: bool, passes_on: bool) -> Result<()> {
        let model = self.fused.as_ref();
        let (nv, h) = (model.nv(), self.h);
        let k4 = 4 * self.found.len();
        let v_next = &self.v_next;
        // CRBA's M and the RNEA derivatives' two squares, reserved fallibly (`Data::reserve_dense`).
        t.rigid.reserve_dense(model, &[Dense::MassMatrix, Dense::RneaDerivatives])?;
        t.hessian.copy_from(crba(model, &mut t.rigid, q));
        zeroed(&mut t.slopes, nv, 3 * nv)?;
        if passes_on {
            let ss = &mut t.substeps;
            zeroed(&mut ss.warm_dq, k4, nv)?;
            ss.warm_dw.clear();
            ss.warm_dw.resize(self.found.len(), Matrix4::zeros());
        }
        t.slopes.columns_mut(nv, nv).zip_apply(&t.hessian, |s, m| *s = -m);
        // The free flyer's coordinates have no armature (`aba_with_armature`).
        let first_joint = if model.floating_base() { 6 } else { 0 };
        for (k, (acceleration, (after, before))) in t.acceleration.iter_mut().zip(v_next.iter().zip(v)).enumerate() {
            *acceleration = (after - before) / h;
            // The actuation's forces and their slopes by (q_k, v_k, τ_ff): an implicit servo acts at the step's end
            // (`actuate`), an unsaturated explicit one at its start, a saturated one not. Its slopes by target_q and
            // target_v are −h gain kp and −h gain kd, kp and kd times τ_ff's (`servo_columns`).
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
        // − ∂(Σ J_cᵀ λ_c)/∂q at fixed v⁺: central differences of the moved contacts and the limits at fixed diagonals, on
        // displaced poses updated from the step's, which `t.data` is to hold first; then every diagonal's change.
        t.written.clear();
        t.written.extend(0..model.nbodies());
        t.found_at_q.clear();
        t.found_at_q.extend(self.found.iter().map(|f| self.collision.moved(f, &self.poses)));
        self.held_constraints(t, q);
        if !t.diagonal_slopes.compute(model, &self.data, &self.armature, self.delassus.base(), &mut t.tree, &t.held)? {
            return Err(Error::numerical("transition_jacobians", "the mass matrix stopped being positive definite near the state"));
        }
        let contacts = self.found.len();
        for k in 0..nv {
            // One coordinate's pair of contact passes: on a model of a thousand links the loop takes seconds.
            check_cancelled("transition_jacobians")?;
            t.direction[k] = 1.0;
            let joint_body = t.body_of[k];
            for i in 0..model.nbodies() {
                t.moving[i] = i == joint_body || (i > joint_body && t.moving[model.parent(i)]);
            }
            t.contact_moves.clear();
            t.contact_moves.extend(self.found.iter().map(|f| {
                let moves = |body: usize| t.moving[self.fused_body[body]];
                moves(f.body) || f.other.is_some_and(moves)
            }));
            // The poses of the bodies this coordinate does not move stay the step's (`collision_poses`).
            t.poses.copy_from_slice(&self.poses);
            integrate(model, q, &t.direction, -STEP, &mut t.displaced);
            self.contact_impulses(t, q, k, 0);
            std::mem::swap(&mut t.plus, &mut t.minus);
            std::mem::swap(&mut t.substeps.warm_plus, &mut t.substeps.warm_minus);
            integrate(model, q, &t.direction, STEP, &mut t.displaced);
            self.contact_impulses(t, q, k, 1);
            t.direction[k] = 0.0;
            for (r, (plus, minus)) in t.plus.iter().zip(&t.minus).enumerate() {
                t.slopes[(r, k)] -= (plus - minus) / (2.0 * STEP);
            }
            let ss = &mut t.substeps;
            let moved = t.contact_moves.iter().enumerate().filter(|(_, moves)| **moves).map(|(c, _)| c);
            if passes_on {
                for (i, c) in moved.enumerate() {
                    for j in 0..4 {
                        ss.warm_dq[(4 * c + j, k)] = (ss.warm_plus[4 * i + j] - ss.warm_minus[4 * i + j]) / (2.0 * STEP);
                    }
                }
            }
            // Each constraint's diagonal change: its slope at fixed rows, and a moved contact's rows' own change.
            let ds = &t.diagonal_slopes;
            t.tree.force.fill(Vector6::zeros());
            let mut moved = 0;
            for (c, held) in t.held.iter().enumerate() {
                let mut change = Vector2::new(ds.slopes[(2 * c, k)], ds.slopes[(2 * c + 1, k)]);
                if c < contacts && t.contact_moves[c] {
                    let (minus, plus, motions) = (&t.rows_minus[moved], &t.constraints[moved].rows, &ds.motions[c]);
                    let along = |r: usize| (plus[r] - minus[r]).dot(&motions[r]) / STEP;
                    change += Vector2::new(along(0), along(1) + along(2));
                    moved += 1;
                }
                let slope = t.by_diagonal[c] * change;
                if slope == Vector3::zeros() {
                    continue;
                }
                match held.bodies() {
                    Some((body, other)) => {
                        let force = held.force(&slope.into());
                        t.tree.force[body] += force;
                        if let Some(other) = other {
                            t.tree.force[other] -= force;
                        }
                    }
                    None => {
                        if let Target::Coordinate(j) = held.target {
                            t.slopes[(j, k)] -= held.rows[0][0] * slope[0];
                        }
                    }
                }
                if passes_on && c < contacts {
                    for (j, x) in warm_of(&t.found_at_q[c].tangents, &slope.into()).into_iter().enumerate() {
                        ss.warm_dq[(4 * c + j, k)] += x;
                    }
                }
            }
            t.tree.generalized(model, &self.data, &mut t.minus);
            for (r, held) in t.minus.iter().enumerate() {
                t.slopes[(r, k)] -= held;
            }
        }
        if passes_on {
            self.impulses_by_velocity(t);
        }
        if inherits {
            self.by_warm_start(t, q, passes_on);
        }
        // ∂g/∂v⁺ is unsymmetric where a sliding contact's friction bound follows its normal impulse (`solver`).
        if !lu_factor(&mut t.hessian, &mut t.pivots) {
            return Err(Error::numerical("transition_jacobians", "the step's Jacobian M̃ + Jᵀ H J is singular"));
        }
        t.inverse.fill_with_identity();
        lu_solve(&t.hessian, &t.pivots, &mut t.inverse);
        integrate_jacobians(model, v_next, h, &mut t.integrate_q, &mut t.integrate_v);
        Ok(())
    }

    /// ∂W_c⁺/∂(J_c v⁺) of each of this substep's contacts, by central differences of its own rows' velocities at v⁺
    /// (no solve, no pass over the tree), into `t.substeps.warm_dy`.
    fn impulses_by_velocity(&self, t: &mut Transition) {
        let model = self.fused.as_ref();
        t.tree.motions(model, &self.data, &self.v_next);
        t.substeps.warm_dy.clear();
        for (f, solved) in self.found.iter().zip(&self.constraints) {
            let at = solved.velocity(&t.tree.motion, &self.v_next);
            let mut slope = Matrix4x3::zeros();
            for r in 0..3 {
                let mut impulses = [Vector4::zeros(); 2];
                for (side, sign) in [(0, 1.0), (1, -1.0)] {
                    let mut velocity = at;
                    velocity[r] += sign * STEP;
                    let mut constraint = solved.clone();
                    constraint.settle_with(solved, velocity);
                    impulses[side] = Vector4::from(warm_of(&f.tangents, &constraint.lambda));
                }
                slope.set_column(r, &((impulses[0] - impulses[1]) / (2.0 * STEP)));
            }
            t.substeps.warm_dy.push(slope);
        }
    }

    /// The slopes by this substep's warm starts W_s: each contact's F ∂λ_c/∂W_c into `t.substeps.warm_force` and,
    /// with `passes_on`, ∂W⁺/∂W, by central differences of each contact's impulses alone at the substep's start
    /// configuration `q` and v⁺ (a contact's impulses depend on its own warm start only: no pass over the tree).
    fn by_warm_start(&self, t: &mut Transition, q: &[f64], passes_on: bool) {
        let model = self.fused.as_ref();
        let origin = base_origin(model, q);
        t.tree.motions(model, &self.data, &self.v_next);
        t.substeps.warm_force.clear();
        for (c, f) in self.found.iter().enumerate() {
            let mut force = Matrix6x4::zeros();
            for j in 0..4 {
                let step = STEP * f.warm.iter().fold(1e-3_f64, |m, x| m.max(x.abs()));
                let mut lambda = [[0.0; 3]; 2];
                for (side, sign) in [(0, 1.0), (1, -1.0)] {
                    let mut displaced: Found = *f;
                    displaced.warm[j] += sign * step;
                    let mut constraint = self.contact_row(model, &self.data, &self.delassus, &displaced, f.distance, &origin);
                    constraint.settle_at(&self.constraints[c], &t.tree.motion, &self.v_next);
                    lambda[side] = constraint.lambda;
                }
                let slope: [f64; 3] = std::array::from_fn(|r| (lambda[0][r] - lambda[1][r]) / (2.0 * step));
                force.set_column(j, &self.constraints[c].force(&slope));
                if passes_on {
                    for (r, x) in warm_of(&f.tangents, &slope).into_iter().enumerate() {
                        t.substeps.warm_dw[c][(r, j)] = x;
                    }
                }
            }
            t.substeps.warm_force.push(force);
        }
    }

    /// Σ J_cᵀ λ_c at v⁺ = `self.v_next` with the configuration at `t.displaced`, of the contacts the displacement moves
    /// (`t.contact_moves`) and the limits: the step's (at `q`) moved there at their diagonals at `q`, each its impulses at
    /// J_c v⁺ − b_c in its zone (no solve, b_c on its piece at `q`), into `t.plus`, and their impulses into
    /// `t.substeps.warm_plus`. The displacement is along coordinate `k`; `side` 0 keeps the moved contacts' rows.
    fn contact_impulses(&self, t: &mut Transition, q: &[f64], k: usize, side: usize) {
        self.constraints_at(t, q, k, side);
        let model = self.fused.as_ref();
        t.tree.motions(model, &t.data, &self.v_next);
        let moved = t.contact_moves.iter().enumerate().filter(|(_, moves)| **moves).map(|(c, _)| c);
        let solved = moved.chain(self.found.len()..self.constraints.len());
        for (constraint, c) in t.constraints.iter_mut().zip(solved) {
            constraint.settle_at(&self.constraints[c], &t.tree.motion, &self.v_next);
        }
        generalized_impulses(&mut t.tree, model, &t.data, &t.constraints, &mut t.plus);
        warm_starts(&t.constraints, &t.substeps.tangents, &mut t.substeps.warm_plus);
    }

    /// The contacts the displacement moves and the limits (at `q`) moved to the configuration at `t.displaced`, at their
    /// diagonals at `q`, into `t.constraints` (and those contacts' tangents there into `t.substeps.tangents`, their rows
    /// into `t.rows_minus` on `side` 0), with the poses there in `t.data`; the displacement is along coordinate `k`,
    /// which moves its joint's subtree alone.
    fn constraints_at(&self, t: &mut Transition, q: &[f64], k: usize, side: usize) {
        let model = self.fused.as_ref();
        let displaced = &t.displaced;
        // The poses are in the base's frame at its origin: the base's position moves none of them.
        let moved_body = match t.body_of[k] {
            0 if displaced[3..] == q[3..] => None,
            body => Some(body),
        };
        placement_update(model, &mut t.data, &self.data, displaced, moved_body, &mut t.written);
        self.collision_poses(&t.data, displaced, &mut t.poses, Some(&t.moving));
        let origin = base_origin(model, displaced);
        t.constraints.clear();
        t.substeps.tangents.clear();
        if side == 0 {
            t.rows_minus.clear();
        }
        for (c, f) in self.found.iter().enumerate() {
            if t.contact_moves[c] {
                let moved = self.collision.moved(f, &t.poses);
                t.substeps.tangents.push(moved.tangents);
                let constraint = self.contact_row_with(&moved, f.distance, &origin, t.held_diagonals[c]);
                if side == 0 {
                    t.rows_minus.push(constraint.rows);
                }
                t.constraints.push(constraint);
            }
        }
        for &(index, side) in &self.limit_rows {
            // A limit's warm start only seeds the solver: its impulse at a given v⁺ does not depend on it.
            t.constraints.push(limit_constraint(model, &self.data, &self.delassus, self.h, &self.limited[index], side, displaced, q, 0.0));
        }
    }

    /// Each contact rebuilt at the step's configuration `q` from `t.found_at_q`, then each limit, into `t.held` with
    /// their diagonals into `t.held_diagonals`, and the slopes of their impulses at v⁺ (in the zone each ended in) by
    /// their diagonals into `t.by_diagonal`, by central differences in the diagonal (relative steps; no pass over the tree).
    fn held_constraints(&self, t: &mut Transition, q: &[f64]) {
        let model = self.fused.as_ref();
        let origin = base_origin(model, q);
        t.tree.motions(model, &self.data, &self.v_next);
        t.held.clear();
        t.held_diagonals.clear();
        t.by_diagonal.clear();
        for (c, solved) in self.constraints.iter().enumerate() {
            let (held, diagonal, scale) = match self.found.get(c) {
                Some(f) => {
                    // The diagonal its rows are built with, kept.
                    let mut at_q = (Vector2::zeros(), 0.0);
                    let diagonal = |body, other, rows: &_, arm: &_| {
                        let (diagonal, scale) = self.delassus.contact(model, &self.data, body, other, rows, arm);
                        at_q = (diagonal.into(), scale);
                        (diagonal, scale)
                    };
                    let held =
                        contact_constraint(self.coulomb, &self.fused_body, self.friction, self.h, &t.found_at_q[c], f.distance, &origin, diagonal);
                    (held, at_q.0, at_q.1)
                }
                None => {
                    let Target::Coordinate(k) = solved.target else { unreachable!("contacts come first") };
                    let diagonal = self.delassus.coordinate(model, &self.data, t.body_of[k]);
                    (solved.clone(), Vector2::new(diagonal, 0.0), diagonal)
                }
            };
            let mut slopes = Matrix3x2::zeros();
            for j in 0..2 {
                let step = STEP * diagonal[j].abs();
                if step == 0.0 {
                    continue;
                }
                let mut lambda = [[0.0; 3]; 2];
                for (side, sign) in [(0, 1.0), (1, -1.0)] {
                    let mut displaced = diagonal;
                    displaced[j] += sign * step;
                    let mut constraint = held.with_diagonal(displaced.into(), scale);
                    constraint.settle_at(solved, &t.tree.motion, &self.v_next);
                    lambda[side] = constraint.lambda;
                }
                for r in 0..3 {
                    slopes[(r, j)] = (lambda[0][r] - lambda[1][r]) / (2.0 * step);
                }
            }
            t.held.push(held);
            t.held_diagonals.push((diagonal, scale));
            t.by_diagonal.push(slopes);
        }
    }
}

/// B's servo-target columns from its feed-forward ones (the first nv): a servo's force on coordinate k follows
/// target_q,k and target_v,k as kp_k and kd_k times it follows τ_ff,k, in every substep, saturated or not.
fn servo_columns(actuation: &Actuation<'_>, b: &mut DMatrix<f64>) {
    let nv = actuation.servo.kp.len();
    for (k, (kp, kd)) in actuation.servo.kp.iter().zip(&actuation.servo.kd).enumerate() {
        for (offset, gain) in [(nv, kp), (2 * nv, kd)] {
            for r in 0..b.nrows() {
                b[(r, offset + k)] = gain * b[(r, k)];
            }
        }
    }
}

/// Each contact's impulses [λ_n, friction in world axes] (what `report` stores as the next warm start) from
/// `constraints` (contacts first) with their `tangents`, into `out` (4 per contact).
fn warm_starts(constraints: &[Constraint], tangents: &[[nalgebra::Vector3<f64>; 2]], out: &mut Vec<f64>) {
    out.clear();
    for (c, tangents) in constraints.iter().zip(tangents) {
        out.extend_from_slice(&warm_of(tangents, &c.lambda));
    }
}
