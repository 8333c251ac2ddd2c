//! The contact solver: Newton's method on soft, regularised contacts with friction, on the tree, under
//! either of two friction laws (`FrictionLaw`).
//!
//! Each constraint is a contact (normal row n and tangent rows t1, t2, one block) or a joint limit (one
//! row). With A = J M̃⁻¹ Jᵀ its Delassus block, R = ε diag(A) the regularisation and y = J v − b the
//! velocities relative to those asked for (b: for the normal row, the gap closed in one step while apart
//! (speculative contact) or a fraction of the penetration while overlapping (Baumgarte); for the tangent
//! rows R_t λ_t,warm, which regularises friction towards last step's: proximally, no creep at rest), the
//! impulses follow from y contact by contact (Todorov 2014's soft contacts, MuJoCo's R), and the step's
//! velocities solve M̃ (v − v_free) = Jᵀ λ(J v − b).
//!
//! The cone law is the convex (Anitescu 2006) relaxation: λ = R^-½ Π_K̂(−R^-½ y), the projection on the
//! elliptic cone |λ_t| ≤ μ λ_n, of slope μ̂ = μ (R_t / R_n)^½ in the scaled impulses R^½ λ.
//! The velocities minimise one strictly convex primal,
//!   min ½ (v − v_free)ᵀ M̃ (v − v_free) + Σ ½ |Π_K̂(−R^-½ (J v − b))|²,
//! so the impulses are unique even where contacts are redundant (four corners of a box on the ground). Its
//! optimality conditions make a sliding contact separate at v_n = μ |v_t|: a 1 kg box launched at 2 m/s
//! with μ = 0.8 loses 39 % of its speed in its first millisecond and hops 47 mm.
//!
//! Coulomb's law (the default): λ_n = max(0, −y_n / R_n) and λ_t = −y_t / R_t clamped to the disk
//! |λ_t| ≤ μ λ_n. The normal row is complementary to the normal velocity alone and friction bounded by the
//! same solve's normal impulse: the non-associated law, as the per-contact solvers of Bullet, PhysX and Rapier clamp it (normal,
//! then tangent), and as Kaufman et al. 2008 (staggered projections) solve it globally. No lift: that box
//! decelerates at μ g from its first step (`tests/test_friction.py`). What it gives up: the law is no
//! minimum of one convex function, so Newton's global convergence guarantee and the solution's uniqueness
//! are lost. It is the fixed point of convex problems, those with the friction disks' radii frozen; where
//! several exist (stiff contacts coupled through a light, high-μ chain, as in Painlevé's paradox) the step
//! picks one deterministically, from its warm start. Measured, it converges in few iterations (0.7 per step
//! on a sliding box, 2 at most; 1-3 on the bench's robots and trees; a few steps where feet switch between
//! sticking, sliding and lifting off take 20-40, hence the cap of 50), and the
//! transition Jacobians (`transition`) match central differences of its step. The laws can part on a robot's
//! landing, chaotically: a quadruped dropped 7 cm onto ridges of slope 0.4 at μ 0.9 falls over or not as the
//! drop height changes by a centimetre, under either law and in MuJoCo (docs/simulation.md). The cone law
//! stays for what convexity buys: impulses unique and Newton globally convergent (contacts between two bodies
//! converge in fewer iterations under it), and the relaxation that convex solvers (MuJoCo's, Drake's SAP) share.
//!
//! Newton. Each iteration holds the disks' radii at the current normal impulses: that problem is the primal
//!   min ½ (v − v_free)ᵀ M̃ (v − v_free) + Σ ψ(−R^-½ (J v − b)),  ψ(s) = ½ |s|² − ½ dist(s, C)²,
//! with C the cylinder (s_n ≥ 0, |s_t| ≤ ρ) in the scaled impulses (ψ's gradient is the projection on C: a
//! normal half-line and a friction disk), convex, and its gradient at the current v is the law's residual
//! (under the cone law, C is the cone and the problem the same every iteration). The Newton matrix is
//! H = M̃ + Σ Jᵀ H_c J, H_c = ∂λ/∂(−y) in the constraint's zone (apart: 0; sticking: R⁻¹; sliding: the
//! cone's ray and bend, or the disk's bend across the slip plus, under Coulomb's law, the unsymmetric
//! ∂λ_t/∂(−y_n) = μ R_n⁻¹ e by which the bound follows the normal impulse). A contact on body b adds
//! Φ_bᵀ (F H_c Fᵀ) Φ_b, a 6x6 stiffness on b, so H keeps the tree's sparsity and the articulated-body
//! recursion factors it in O(n), unsymmetric or not (`articulated`). Under the cone law every step is line
//! searched exactly, in O(1) per contact. Under Coulomb's law a full step is taken where it keeps every
//! contact in its zone (the law is smooth there: quadratic convergence); a full step that raises the
//! residual is taken back to the exact line search along it on the frozen problem, which it descends (no
//! second factor: undoing it for a fresh symmetric step took 16 % more iterations on a falling ANYmal and
//! a trotting quadruped); otherwise the step is line searched, and where the unsymmetric step does not
//! descend the frozen problem, or leaves a pivot non-positive, the frozen problem's symmetric step, line
//! searched, which descends it.
//! The first step guesses the zones: Newton's step on the law with each constraint's impulses by the formula
//! of the zone its warm-start impulses lie in (last step's solution: pressing, sticking or sliding), wherever
//! that differs from the zone at the warm-start velocities v_free + M̃⁻¹ Jᵀ λ_warm. Those velocities leave a
//! loaded contact within R λ of its zone's boundary, which the change of v_free from one step to the next
//! crosses (on the bench's swaying 21-module tree, 56 of 88 contacts looked sliding there while the solution
//! had every one sticking, and Newton took 3-4 iterations to find its zones again). Where the guess is right
//! and nothing slides, the law is affine in those zones and the step lands on its solution; a guess that
//! raises the law's residual is undone (one factor lost, a few steps in a thousand) and Newton goes on from
//! the warm start as before.
//! Newton converges in a few iterations where Gauss–Seidel needed hundreds of sweeps: contacts along a
//! chain lying on the ground couple through the whole chain. A contact between two bodies couples their
//! chains outside the tree's sparsity; its Hessian is taken on each body alone, which still gives a
//! descent direction, and linear convergence.

use nalgebra::{Cholesky, Matrix6, Vector3, Vector6, U6};

use super::articulated::Articulated;
use crate::model::{Data, Model};

/// Regularisation, relative to the Delassus diagonal: R = ε A_ii. It bounds the impulses of contact sets
/// that conflict (a body on one joint pressed into the ground at several points) by the velocity error
/// over ε, and lets a loaded contact creep at ε times the velocity its load would build up in one step
/// (1e-4 m/s under gravity at 1 kHz), which the Baumgarte term stops within a few micrometres.
pub(super) const REGULARISATION: f64 = 1e-2;
/// Fraction of the penetration removed per step.
pub(super) const BAUMGARTE: f64 = 0.2;
/// The fastest the Baumgarte term pushes an overlap apart (m/s): a deep overlap (a robot started inside
/// the ground) is resolved over several steps rather than thrown apart.
pub(super) const MAX_CORRECTION: f64 = 0.5;
/// Penetration a resting contact stays within (m). The Baumgarte term acts on any penetration (no slop:
/// a resting body settles at once, its contact forces summing to its weight), so the regularisation's
/// creep stops a few micrometres in; this bounds what impacts leave behind.
pub(super) const TOLERANCE: f64 = 2e-4;
/// Newton stops once the gradient is at most this fraction of the contacts' generalized impulses
/// M̃ (v − v_free), or the error its steps leave (the step, or where they contract linearly by r, the
/// step r / (1 − r)) at most this fraction of the contacts' whole change of the velocities, both in the
/// mass-matrix norm; it converges quadratically once the zones settle, so the error left is far smaller. Tight enough that the
/// step is differentiable to 1e-8 (central differences of a sliding contact's step match the transition
/// Jacobians, which take the solve as converged), for 3 % more iterations than 1e-7 on a walking quadruped.
pub(super) const CONVERGED: f64 = 1e-10;
/// A row whose Delassus diagonal is below this fraction of its scale (tr Ω |F|², `Delassus`) is immovable:
/// the joints cannot move the contact along it (a normal row: it carries nothing; tangent rows: no friction).
const IMMOVABLE: f64 = 1e-12;
/// The line search's most Newton steps on the slope, and its tolerance relative to the slope at 0.
const LINE_ITERATIONS: usize = 30;
const LINE_TOLERANCE: f64 = 1e-4;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Kind {
    /// A contact with friction coefficient μ at arm r from the origin: its rows are [d; r × d] for its
    /// normal and tangents d (orthonormal); Coulomb's law or the cone (`FrictionLaw`).
    Contact { mu: f64, arm: Vector3<f64>, coulomb: bool },
    /// A one-sided joint-limit row (normal only).
    Limit,
}

/// What a constraint's rows act on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Target {
    /// A body, and opposite, another body: the rows are spatial forces on them.
    Bodies(usize, Option<usize>),
    /// A velocity coordinate: the normal row's first entry is the generalized force on it.
    Coordinate(usize),
}

#[derive(Debug, Clone)]
pub(super) struct Constraint {
    pub kind: Kind,
    target: Target,
    /// Impulses [λ_n, λ_t1, λ_t2] (N s or N m s); warm start in, solution out.
    pub lambda: [f64; 3],
    /// Its rows as forces on its target: n, t1, t2.
    rows: [Vector6<f64>; 3],
    /// The velocities asked for, b: [normal bias, R_t λ_t1,warm, R_t λ_t2,warm].
    asked: [f64; 3],
    /// The warm start's friction impulses.
    held: [f64; 2],
    /// R_n^-½ and R_t^-½, zero where R is: R_n for an immovable constraint (it carries nothing), R_t for one
    /// whose tangent rows move nothing or that has no friction (its friction idles at the warm start, within
    /// the cone).
    inverse_sqrt_r: [f64; 2],
    /// μ (zero for a limit or a contact without friction rows).
    mu: f64,
    /// The cone law's slope μ̂ = μ (R_t / R_n)^½ of the cone in the scaled impulses and 1 / (1 + μ̂²), the
    /// weight of its ray; zero under Coulomb's law (or without friction).
    cone_slope: f64,
    ray_weight: f64,
    /// The friction disk's radius in the scaled impulses, μ λ_n R_t^½, frozen for one Newton iteration.
    radius: f64,
    /// Where the impulses lie at `residual`, kept from the Newton iteration's impulses for its stiffness.
    projection: Projection,
    /// J v − b at the solver's current velocities, and J d along its step.
    residual: [f64; 3],
    slope: [f64; 3],
    /// The zone the warm start's impulses lie in, where they press (None otherwise): the first Newton
    /// step's guess of the solution's zones (`Solver::step_in_warm_zones`).
    warm_zone: Option<Projection>,
}

fn clamp_to_cone(lambda: &mut [f64; 3], mu: f64) {
    let bound = mu * lambda[0];
    let norm = (lambda[1] * lambda[1] + lambda[2] * lambda[2]).sqrt();
    if norm > bound {
        let scale = if norm > 0.0 { bound / norm } else { 0.0 };
        lambda[1] *= scale;
        lambda[2] *= scale;
    }
}

/// Where a constraint's scaled impulse R^½ λ = Π(s), s = −R^-½ (J v − b), lies: the normal row projected on
/// λ_n ≥ 0, the tangent rows on the disk of radius ρ = μ λ_n R_t^½ (the non-associated law, module doc).
#[derive(Debug, Clone, Copy)]
struct Projection {
    /// Π_n = s_n while pressing, None while apart.
    normal: Option<f64>,
    tangent: Tangent,
}

impl Projection {
    /// Whether `other` is in the same zone: pressing or apart; sticking, sliding or free.
    fn same_zone(&self, other: &Projection) -> bool {
        self.normal.is_some() == other.normal.is_some() && std::mem::discriminant(&self.tangent) == std::mem::discriminant(&other.tangent)
    }
}

#[derive(Debug, Clone, Copy)]
enum Tangent {
    /// No friction: a limit, a contact without friction rows, or one whose bound is zero.
    Free,
    /// Inside the disk (sticking): Π_t = s_t.
    Held([f64; 2]),
    /// On its rim (sliding): Π_t = ρ e, e = s_t / |s_t|, with the bend ρ / |s_t| of the projection across e.
    Sliding { radius: f64, e: [f64; 2], bend: f64 },
    /// The cone law's sliding: Π = c (1, μ̂ e) on the cone's surface (`normal` holds c), with the bend
    /// μ̂ c / |s_t| of the projection across e.
    Ray { e: [f64; 2], bend: f64 },
}

impl Constraint {
    /// A constraint on `target` whose rows are the forces `rows`, asking for the normal velocity `bias`,
    /// with its warm-start impulses, its Delassus diagonal `diagonal` (A_ii of the normal row, and summed
    /// over the two tangent rows) and the scale below which a row counts as immovable (`Delassus`).
    #[inline]
    pub(super) fn new(kind: Kind, target: Target, rows: [Vector6<f64>; 3], bias: f64, warm: [f64; 3], diagonal: [f64; 2], scale: f64) -> Self {
        let immovable = |a: f64, f: &Vector6<f64>| a <= IMMOVABLE * scale * f.norm_squared();
        let r_n = if immovable(diagonal[0], &rows[0]) { 0.0 } else { REGULARISATION * diagonal[0] };
        let tangents = diagonal[1];
        let mu = match kind {
            Kind::Contact { mu, .. } if r_n > 0.0 && mu > 0.0 && !immovable(tangents, &(rows[1] + rows[2])) => mu,
            _ => 0.0,
        };
        let r_t = if mu > 0.0 { REGULARISATION * 0.5 * tangents } else { 0.0 };
        // R_n^-½, R_t^-½, μ̂ = μ (R_t / R_n)^½ and 1 / (1 + μ̂²) = R_n / (R_n + μ² R_t), through one division.
        let cone = matches!(kind, Kind::Contact { coulomb: false, .. });
        let (sqrt_n, sqrt_t) = (r_n.sqrt(), r_t.sqrt());
        let (inverse_sqrt_r, cone_slope, ray_weight) = match (r_n > 0.0, r_t > 0.0) {
            (true, true) => {
                let sum = r_n + mu * mu * r_t;
                let inverse = 1.0 / (sqrt_n * sqrt_t * sum);
                let (i_n, i_t) = (sqrt_t * sum * inverse, sqrt_n * sum * inverse);
                let (slope, weight) = if cone { (mu * sqrt_t * i_n, r_n * sqrt_n * sqrt_t * inverse) } else { (0.0, 1.0) };
                ([i_n, i_t], slope, weight)
            }
            (true, false) => ([1.0 / sqrt_n, 0.0], 0.0, 1.0),
            _ => ([0.0; 2], 0.0, 1.0),
        };
        let mut lambda = if r_n > 0.0 { warm } else { [0.0; 3] };
        lambda[0] = lambda[0].max(0.0);
        match kind {
            Kind::Contact { mu, .. } => clamp_to_cone(&mut lambda, mu),
            Kind::Limit => {
                lambda[1] = 0.0;
                lambda[2] = 0.0;
            }
        }
        // Friction strictly inside its disk sticks; on its rim (to rounding: the impulses went through the
        // world's axes) it slides.
        let friction = (lambda[1] * lambda[1] + lambda[2] * lambda[2]).sqrt();
        let warm_zone = (lambda[0] > 0.0).then(|| {
            let tangent = if r_t == 0.0 {
                Tangent::Free
            } else if friction < (1.0 - 1e-9) * mu * lambda[0] {
                Tangent::Held([0.0; 2])
            } else {
                Tangent::Sliding { radius: 0.0, e: [0.0; 2], bend: 0.0 }
            };
            Projection { normal: Some(0.0), tangent }
        });
        Constraint {
            kind,
            target,
            lambda,
            rows,
            asked: [bias, r_t * lambda[1], r_t * lambda[2]],
            held: [lambda[1], lambda[2]],
            inverse_sqrt_r,
            mu,
            cone_slope,
            ray_weight,
            radius: 0.0,
            projection: Projection { normal: None, tangent: Tangent::Free },
            residual: [0.0; 3],
            slope: [0.0; 3],
            warm_zone,
        }
    }

    fn active(&self) -> bool {
        self.inverse_sqrt_r[0] > 0.0
    }

    /// The disk's radius μ λ_n R_t^½ that the normal impulse at residual `y` gives (in the zone of `zone`).
    fn radius_at(&self, y: [f64; 3], zone: Option<&Projection>) -> f64 {
        let [i_n, i_t] = self.inverse_sqrt_r;
        if self.mu == 0.0 {
            return 0.0;
        }
        let p = -y[0] * i_n;
        let pressed = zone.map_or(p > 0.0, |z| z.normal.is_some());
        // Pressing, p > 0; in a zone held pressing (`transition`), the same formula continued linearly.
        if pressed {
            self.mu * p * i_n / i_t
        } else {
            0.0
        }
    }

    /// The projection at residual `y` for the disk of `radius`, in the zone it is in, or by the formula of
    /// the zone of `zone`.
    fn project_in(&self, y: [f64; 3], radius: f64, zone: Option<&Projection>) -> Projection {
        let [i_n, i_t] = self.inverse_sqrt_r;
        let p = -y[0] * i_n;
        if self.cone_slope > 0.0 {
            return self.project_on_cone(p, [-y[1] * i_t, -y[2] * i_t], zone);
        }
        let pressed = zone.map_or(p > 0.0, |z| z.normal.is_some());
        let normal = pressed.then_some(p);
        let free = zone.map_or(radius <= 0.0, |z| matches!(z.tangent, Tangent::Free));
        if i_t == 0.0 || free {
            return Projection { normal, tangent: Tangent::Free };
        }
        let q = [-y[1] * i_t, -y[2] * i_t];
        let t = (q[0] * q[0] + q[1] * q[1]).sqrt();
        let sliding = zone.map_or(t > radius, |z| matches!(z.tangent, Tangent::Sliding { .. }));
        let tangent = if !sliding {
            Tangent::Held(q)
        } else if t > 0.0 {
            let inverse_t = 1.0 / t;
            Tangent::Sliding { radius, e: [q[0] * inverse_t, q[1] * inverse_t], bend: radius * inverse_t }
        } else {
            Tangent::Sliding { radius, e: [0.0; 2], bend: 0.0 }
        };
        Projection { normal, tangent }
    }

    /// The cone law's projection of s = (p, q) on the cone |s_t| ≤ μ̂ s_n, in the zone it is in or that of
    /// `zone`: inside (sticking), in the polar cone (apart), or on the surface (sliding).
    fn project_on_cone(&self, p: f64, q: [f64; 2], zone: Option<&Projection>) -> Projection {
        let slope = self.cone_slope;
        let t = (q[0] * q[0] + q[1] * q[1]).sqrt();
        let held = Projection { normal: Some(p), tangent: Tangent::Held(q) };
        let apart = Projection { normal: None, tangent: Tangent::Free };
        let ray = || {
            let c = (p + slope * t) * self.ray_weight;
            let inverse_t = 1.0 / t;
            Projection { normal: Some(c), tangent: Tangent::Ray { e: [q[0] * inverse_t, q[1] * inverse_t], bend: slope * c * inverse_t } }
        };
        match zone.map(|z| z.tangent) {
            Some(Tangent::Held(_)) => held,
            Some(Tangent::Ray { .. }) => ray(),
            Some(_) => apart,
            None if t <= slope * p => held,
            None if slope * t <= -p => apart,
            None => ray(),
        }
    }

    /// The projection at residual `y` with the disk's radius frozen (one Newton iteration's problem).
    fn project(&self, y: [f64; 3]) -> Projection {
        self.project_in(y, self.radius, None)
    }

    /// The projection of the law itself at residual `y`: the radius from the normal impulse at `y`.
    fn project_coulomb(&self, y: [f64; 3], zone: Option<&Projection>) -> Projection {
        self.project_in(y, self.radius_at(y, zone), zone)
    }

    /// The impulses λ = R^-½ Π.
    fn impulses(&self, projection: &Projection) -> [f64; 3] {
        let [i_n, i_t] = self.inverse_sqrt_r;
        let n = projection.normal.unwrap_or(0.0) * i_n;
        match projection.tangent {
            Tangent::Free => [n, 0.0, 0.0],
            Tangent::Held(q) => [n, q[0] * i_t, q[1] * i_t],
            Tangent::Sliding { radius, e, .. } => [n, radius * e[0] * i_t, radius * e[1] * i_t],
            Tangent::Ray { e, .. } => {
                let c = projection.normal.unwrap_or(0.0);
                [n, c * self.cone_slope * e[0] * i_t, c * self.cone_slope * e[1] * i_t]
            }
        }
    }

    /// Adds F H_c Fᵀ, for the rows F and H_c = R^-½ (∂Π / ∂s) R^-½ with the disk's radius held, to
    /// `stiffness`: R_n⁻¹ on the normal row while pressing; R_t⁻¹ on both tangent rows while sticking (with the
    /// normal row, a point's F Fᵀ from its arm); while sliding, the rim's bend ρ / |s_t| across the sliding
    /// direction. Symmetric: the Hessian of one Newton iteration's convex problem.
    fn add_stiffness(&self, projection: &Projection, stiffness: &mut Matrix6<f64>) {
        let [i_n, i_t] = self.inverse_sqrt_r;
        let f = &self.rows;
        let normal = if projection.normal.is_some() { i_n * i_n } else { 0.0 };
        match (projection.tangent, self.kind) {
            (Tangent::Held(_), Kind::Contact { arm, .. }) => {
                add_point(stiffness, i_t * i_t, &arm);
                add_rank_one(stiffness, normal - i_t * i_t, &f[0]);
            }
            (Tangent::Sliding { e, bend, .. }, _) => {
                add_rank_one(stiffness, normal, &f[0]);
                add_rank_one(stiffness, bend * i_t * i_t, &(f[2] * e[0] - f[1] * e[1]));
            }
            // The cone's ray r rᵀ / (1 + μ̂²) plus its bend across the sliding direction.
            (Tangent::Ray { e, bend }, _) => {
                let slope = self.cone_slope;
                add_rank_one(stiffness, self.ray_weight, &(f[0] * i_n + (f[1] * e[0] + f[2] * e[1]) * (slope * i_t)));
                add_rank_one(stiffness, bend, &((f[2] * e[0] - f[1] * e[1]) * i_t));
            }
            _ => add_rank_one(stiffness, normal, &f[0]),
        }
    }

    /// Adds the law's one unsymmetric term, ∂λ_t/∂(−y_n) = μ R_n⁻¹ e of a pressing, sliding contact (its
    /// friction bound follows its normal impulse), as F H_c Fᵀ: μ R_n⁻¹ (f_t e) f_nᵀ.
    fn add_coupling(&self, projection: &Projection, stiffness: &mut Matrix6<f64>) {
        if let (Some(_), Tangent::Sliding { e, .. }) = (projection.normal, projection.tangent) {
            let i_n = self.inverse_sqrt_r[0];
            let along = self.rows[1] * e[0] + self.rows[2] * e[1];
            let n = &self.rows[0];
            let w = self.mu * i_n * i_n;
            for (column, n_c) in stiffness.data.0.iter_mut().zip(n.iter()) {
                *column = std::array::from_fn(|r| column[r] + w * n_c * along[r]);
            }
        }
    }

    /// Whether a full step along `slope` keeps the constraint in the zone of its `projection` (pressing or
    /// apart; sticking, sliding or free), with the disk's radius where it lands.
    fn stays_in_zone(&self) -> bool {
        self.projection.same_zone(&self.project_coulomb(std::array::from_fn(|r| self.residual[r] + self.slope[r]), None))
    }

    /// The diagonal entry H_c[0, 0] (a joint limit's stiffness on its coordinate, before the row's scale).
    fn normal_stiffness(&self, projection: &Projection) -> f64 {
        if projection.normal.is_some() {
            self.inverse_sqrt_r[0] * self.inverse_sqrt_r[0]
        } else {
            0.0
        }
    }

    /// λ · dy and dyᵀ H_c dy at residual `y`, the radius held, without forming H_c (the line search's inner loop).
    fn along(&self, y: [f64; 3], dy: [f64; 3]) -> (f64, f64) {
        let [i_n, i_t] = self.inverse_sqrt_r;
        let ds = [dy[0] * i_n, dy[1] * i_t, dy[2] * i_t];
        let projection = self.project(y);
        if let Tangent::Ray { e, bend } = projection.tangent {
            let c = projection.normal.unwrap_or(0.0);
            let along_ray = ds[0] + self.cone_slope * (e[0] * ds[1] + e[1] * ds[2]);
            let across = e[0] * ds[2] - e[1] * ds[1];
            return (c * along_ray, along_ray * along_ray * self.ray_weight + bend * across * across);
        }
        // Sticking, as one sum (the cone law's exact arithmetic).
        if let (Some(p), Tangent::Held(q)) = (projection.normal, projection.tangent) {
            return (p * ds[0] + q[0] * ds[1] + q[1] * ds[2], ds[0] * ds[0] + ds[1] * ds[1] + ds[2] * ds[2]);
        }
        let (mut push, mut second) = match projection.normal {
            Some(p) => (p * ds[0], ds[0] * ds[0]),
            None => (0.0, 0.0),
        };
        match projection.tangent {
            Tangent::Free | Tangent::Ray { .. } => {}
            Tangent::Held(q) => {
                push += q[0] * ds[1] + q[1] * ds[2];
                second += ds[1] * ds[1] + ds[2] * ds[2];
            }
            Tangent::Sliding { radius, e, bend } => {
                push += radius * (e[0] * ds[1] + e[1] * ds[2]);
                let across = e[0] * ds[2] - e[1] * ds[1];
                second += bend * across * across;
            }
        }
        (push, second)
    }

    /// What the constraint adds to the derivative of its impulses' generalized force Jᵀ λ with respect to the
    /// velocities at its final residual, the law's coupling included (`transition`).
    pub(super) fn stiffness(&self) -> Stiffness {
        if !self.active() {
            return Stiffness::Nothing;
        }
        let projection = self.project_coulomb(self.residual, None);
        match self.target {
            Target::Bodies(a, b) => {
                let mut k = Matrix6::zeros();
                self.add_stiffness(&projection, &mut k);
                self.add_coupling(&projection, &mut k);
                Stiffness::Bodies(a, b, k)
            }
            Target::Coordinate(k) => Stiffness::Coordinate(k, self.normal_stiffness(&projection) * self.rows[0][0] * self.rows[0][0]),
        }
    }

    /// The impulses at the solver's final residual; an immovable constraint carries nothing, and friction
    /// that moves nothing keeps its warm start within the cone.
    fn settle(&mut self) {
        self.settle_in(None);
    }

    /// `settle`, the impulses in the zone of `zone` if given, whichever zone the residual is in.
    /// Its impulses at velocities `v` whose body motions are `motion` (`Articulated::motions`), in the zone of
    /// `solved`, the step's own constraint (`impulses_at`).
    pub(super) fn settle_at(&mut self, solved: &Constraint, motion: &[Vector6<f64>], v: &[f64]) {
        self.settle_with(solved, rows_times(self, motion, v));
    }

    /// Its impulses at its rows' velocities J v = `velocity`, in the zone of `solved` (as `settle_at`).
    pub(super) fn settle_with(&mut self, solved: &Constraint, velocity: [f64; 3]) {
        if self.active() {
            self.residual = std::array::from_fn(|r| velocity[r] - self.asked[r]);
        }
        self.settle_in(solved.active().then(|| solved.project_coulomb(solved.residual, None)).as_ref());
    }

    /// Its rows' velocities J x for the body motions `motion` of x.
    pub(super) fn velocity(&self, motion: &[Vector6<f64>], x: &[f64]) -> [f64; 3] {
        rows_times(self, motion, x)
    }

    /// The spatial force F λ its rows exert for impulses `lambda`.
    pub(super) fn force(&self, lambda: &[f64; 3]) -> Vector6<f64> {
        self.rows[0] * lambda[0] + self.rows[1] * lambda[1] + self.rows[2] * lambda[2]
    }

    /// The bodies its rows act on (None for a joint limit).
    pub(super) fn bodies(&self) -> Option<(usize, Option<usize>)> {
        match self.target {
            Target::Bodies(a, b) => Some((a, b)),
            Target::Coordinate(_) => None,
        }
    }

    fn settle_in(&mut self, zone: Option<&Projection>) {
        if !self.active() {
            self.lambda = [0.0; 3];
            return;
        }
        let mut lambda = self.impulses(&self.project_coulomb(self.residual, zone));
        if let Kind::Contact { mu, .. } = self.kind {
            if self.inverse_sqrt_r[1] == 0.0 {
                lambda[1] = self.held[0];
                lambda[2] = self.held[1];
                clamp_to_cone(&mut lambda, mu);
            }
        }
        self.lambda = lambda;
    }
}

/// A constraint's F H_c Fᵀ on its body (with −F H_c Fᵀ coupling it to the other body, if any: the rows act
/// on the two bodies' relative motion), or H_c on its coordinate. Built and matched once per constraint: boxing
/// the 6x6 would only add an allocation.
#[allow(clippy::large_enum_variant)]
pub(super) enum Stiffness {
    Nothing,
    Bodies(usize, Option<usize>, Matrix6<f64>),
    Coordinate(usize, f64),
}

/// out = Jᵀ λ for the impulses the constraints give at velocities `v`, without solving: λ(J v − b) of each,
/// from the poses in `data`, each in the zone (apart, sticking, sliding) the same constraint of `solved` ended
/// in (the primal's gradient term with the zones held, `transition`).
pub(super) fn impulses_at(
    tree: &mut Articulated,
    model: &Model,
    data: &Data,
    constraints: &mut [Constraint],
    solved: &[Constraint],
    v: &[f64],
    out: &mut [f64],
) {
    tree.motions(model, data, v);
    for (c, solved) in constraints.iter_mut().zip(solved) {
        c.settle_at(solved, &tree.motion, v);
    }
    generalized_impulses(tree, model, data, constraints, out);
}

/// The Newton solver's buffers, sized for one model.
pub(super) struct Solver {
    tree: Articulated,
    /// v − v_free and M̃ (v − v_free).
    change: Vec<f64>,
    mass_change: Vec<f64>,
    /// The descent direction's right-hand side, Jᵀ λ − M̃ (v − v_free) (minus the gradient).
    descent: Vec<f64>,
    /// The Newton step d and M̃ d.
    step: Vec<f64>,
    mass_step: Vec<f64>,
}

impl Solver {
    pub(super) fn new(model: &Model) -> Self {
        let nv = model.nv();
        Solver {
            tree: Articulated::new(model),
            change: vec![0.0; nv],
            mass_change: vec![0.0; nv],
            descent: vec![0.0; nv],
            step: vec![0.0; nv],
            mass_step: vec![0.0; nv],
        }
    }

    /// Solves for the impulses (warm start in `constraints`, solution out) and the velocities `v` they
    /// leave from `v_free`, on the tree whose poses `aba_with_armature` left in `data` (with `armature`; a
    /// free-flyer base's articulated inertia factored as `base`, `Delassus::base`).
    /// Returns the Newton iterations done, or None if the Newton matrix is not positive definite.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn solve(
        &mut self,
        model: &Model,
        data: &Data,
        base: Option<&Cholesky<f64, U6>>,
        armature: &[f64],
        constraints: &mut [Constraint],
        v_free: &[f64],
        v: &mut [f64],
        max_iterations: usize,
    ) -> Option<usize> {
        v.copy_from_slice(v_free);
        if !constraints.iter().any(Constraint::active) {
            constraints.iter_mut().for_each(Constraint::settle);
            return Some(0);
        }
        let tree = &mut self.tree;
        // Warm start: v = v_free + M̃⁻¹ Jᵀ λ_warm, so M̃ (v − v_free) = Jᵀ λ_warm, through ABA's own factor of M̃.
        generalized_impulses(tree, model, data, constraints, &mut self.mass_change);
        if !tree.factor_of_aba(model, data, armature, base) {
            return None;
        }
        tree.solve(model, data, &self.mass_change, &mut self.change);
        for ((v, free), change) in v.iter_mut().zip(v_free).zip(&self.change) {
            *v = free + change;
        }
        tree.motions(model, data, v);
        for c in constraints.iter_mut().filter(|c| c.active()) {
            let velocity = rows_times(c, &tree.motion, v);
            c.residual = std::array::from_fn(|r| velocity[r] - c.asked[r]);
        }
        let (mut iterations, mut last_gradient, mut steps) = (0, f64::INFINITY, [f64::INFINITY; 2]);
        // Under the cone law the problem is one convex minimisation: symmetric steps, each line-searched.
        let coulomb = constraints.iter().any(|c| c.mu > 0.0 && c.cone_slope == 0.0);
        // Whether the last step was a full unsymmetric one (to take back if it raised the gradient), and
        // the last direction's φ'(0) terms (`line_search`).
        let mut full = false;
        // Whether the last step was the guess in the warm start's zones (to take back if it raised the residual).
        let mut guessed = false;
        let (mut start, mut initial, mut curvature) = (0.0, 0.0, 0.0);
        loop {
            // The friction bounds from the normal impulses at the current velocities, held for this
            // iteration: its problem is convex, and its gradient at the start is the law's residual.
            project(constraints);
            let (gradient, scale) = self.descend(model, data, constraints);
            // A guess that raised the law's residual is undone: Newton goes on from the warm start.
            if std::mem::take(&mut guessed) && gradient >= last_gradient {
                self.move_along(constraints, v_free, v, -1.0);
                continue;
            }
            // A full unsymmetric step that raised the law's residual (its zones' linearisation overshot: a
            // lightly loaded foot whose bound swings with its normal impulse) is taken back to the exact line
            // search along it on the frozen problem it started from, which it descends: no new factor.
            if full && gradient >= last_gradient {
                self.move_along(constraints, v_free, v, -1.0);
                for c in constraints.iter_mut().filter(|c| c.active()) {
                    c.radius = c.radius_at(c.residual, None);
                }
                full = false;
            } else {
                // Optimal already (a warm start that still holds, or a step that stayed within its zones,
                // where the cost is quadratic and Newton's step exact): no step to take.
                if gradient <= CONVERGED * scale || iterations == max_iterations {
                    break;
                }
                iterations += 1;
                last_gradient = gradient;
                if coulomb && iterations == 1 && self.step_in_warm_zones(model, data, armature, constraints, v_free, v) {
                    guessed = true;
                    continue;
                }
                // The law's Jacobian, the friction bounds' dependence on the normal impulses included: Newton
                // on the law itself, quadratic once the zones settle. Unless it leaves a pivot of the tree's
                // elimination non-positive, or its step does not descend this iteration's convex problem: then
                // that problem's symmetric Hessian, whose step does.
                let mut coupled = coulomb;
                (start, initial, curvature) = loop {
                    if !self.assemble(model, data, armature, constraints, coupled) {
                        if coupled {
                            coupled = false;
                            continue;
                        }
                        return None;
                    }
                    self.direction(model, data, armature, constraints);
                    let start = dot(&self.mass_change, &self.step);
                    let initial = start - constraints.iter().filter(|c| c.active()).map(|c| dot(&c.lambda, &c.slope)).sum::<f64>();
                    if coupled && !(initial < 0.0) {
                        coupled = false;
                        continue;
                    }
                    break (start, initial, dot(&self.step, &self.mass_step));
                };
                // A full Newton step where it keeps every contact in its zone (the law is smooth there);
                // otherwise the exact line search on this iteration's convex problem.
                full = coupled && constraints.iter().filter(|c| c.active()).all(Constraint::stays_in_zone);
            }
            let alpha = if full { 1.0 } else { line_search(constraints, start, initial, curvature) };
            self.move_along(constraints, v_free, v, alpha);
            // The error left after a step, from the steps' contraction over two iterations r (linear where
            // contacts couple two bodies' chains, which the factor leaves out): step r / (1 − r), or a
            // thousand steps where they do not contract (the rounding floor).
            let step = (alpha * alpha * curvature).sqrt();
            let ratio = (step / steps[0]).sqrt();
            steps = [steps[1], step];
            let left = if !coulomb {
                step
            } else if ratio < 1.0 {
                step * ratio / (1.0 - ratio)
            } else {
                1e3 * step
            };
            if alpha == 0.0 || left.max(step) <= CONVERGED * dot(&self.change, &self.mass_change).sqrt() {
                break;
            }
        }
        constraints.iter_mut().for_each(Constraint::settle);
        Some(iterations)
    }
}

impl Solver {
    /// out = Jᵀ λ − M̃ (v − v_free), the descent's right-hand side, into `descent`; returns its largest entry
    /// (the law's residual) and that of M̃ (v − v_free) (its scale).
    fn descend(&mut self, model: &Model, data: &Data, constraints: &[Constraint]) -> (f64, f64) {
        generalized_impulses(&mut self.tree, model, data, constraints, &mut self.descent);
        let (mut gradient, mut scale) = (0.0f64, 0.0f64);
        for (descent, mass_change) in self.descent.iter_mut().zip(&self.mass_change) {
            *descent -= mass_change;
            gradient = gradient.max(descent.abs());
            scale = scale.max(mass_change.abs());
        }
        (gradient, scale)
    }

    /// The step d = H⁻¹ `descent` through the factor of the last `assemble`, M̃ d and each constraint's J d.
    fn direction(&mut self, model: &Model, data: &Data, armature: &[f64], constraints: &mut [Constraint]) {
        let tree = &mut self.tree;
        tree.solve(model, data, &self.descent, &mut self.step);
        tree.motions(model, data, &self.step);
        for c in constraints.iter_mut().filter(|c| c.active()) {
            c.slope = rows_times(c, &tree.motion, &self.step);
        }
        tree.mass_times_motions(model, data, armature, &self.step, &mut self.mass_step);
    }

    /// Moves the velocities `v` (and the constraints' residuals) by `alpha` times the last step.
    fn move_along(&mut self, constraints: &mut [Constraint], v_free: &[f64], v: &mut [f64], alpha: f64) {
        for k in 0..v.len() {
            self.change[k] += alpha * self.step[k];
            self.mass_change[k] += alpha * self.mass_step[k];
            v[k] = v_free[k] + self.change[k];
        }
        for c in constraints.iter_mut().filter(|c| c.active()) {
            c.residual = std::array::from_fn(|r| c.residual[r] + alpha * c.slope[r]);
        }
    }

    /// The first Newton step, taken in full in the zones the warm start's impulses lie in (`Constraint::warm_zone`)
    /// wherever they differ from those at the warm start's velocities: Newton's step on the law with each such
    /// constraint's impulses by the formula of its warm zone. Where the zones guessed are the solution's, and
    /// none slides, the law is affine there and the step lands on its solution. Returns false, with the
    /// constraints and the descent as they were, where every zone agrees or the factor fails.
    fn step_in_warm_zones(
        &mut self,
        model: &Model,
        data: &Data,
        armature: &[f64],
        constraints: &mut [Constraint],
        v_free: &[f64],
        v: &mut [f64],
    ) -> bool {
        let mut differs = false;
        for c in constraints.iter_mut().filter(|c| c.active()) {
            if let Some(zone) = c.warm_zone.filter(|zone| !zone.same_zone(&c.projection)) {
                c.radius = c.radius_at(c.residual, Some(&zone));
                c.projection = c.project_in(c.residual, c.radius, Some(&zone));
                c.lambda = c.impulses(&c.projection);
                differs = true;
            }
        }
        if !differs {
            return false;
        }
        self.descend(model, data, constraints);
        if self.assemble(model, data, armature, constraints, true) {
            self.direction(model, data, armature, constraints);
            self.move_along(constraints, v_free, v, 1.0);
            return true;
        }
        project(constraints);
        self.descend(model, data, constraints);
        false
    }

    /// Assembles and factors the Newton matrix M̃ + Σ Jᵀ H_c J at the constraints' projections, with the
    /// law's unsymmetric coupling if `coupled`; false if the factor fails.
    fn assemble(&mut self, model: &Model, data: &Data, armature: &[f64], constraints: &[Constraint], coupled: bool) -> bool {
        let tree = &mut self.tree;
        tree.clear_stiffness();
        for c in constraints.iter().filter(|c| c.active()) {
            let projection = &c.projection;
            match c.target {
                // Φ_aᵀ (F H_c Fᵀ) Φ_a, and likewise on b without the two chains' coupling.
                Target::Bodies(a, b) => {
                    for body in std::iter::once(a).chain(b) {
                        c.add_stiffness(projection, &mut tree.stiffness[body]);
                        if coupled {
                            c.add_coupling(projection, &mut tree.stiffness[body]);
                        }
                    }
                }
                Target::Coordinate(k) => tree.coordinate_stiffness[k] += c.normal_stiffness(projection) * c.rows[0][0] * c.rows[0][0],
            }
        }
        tree.factor(model, data, armature, !coupled)
    }
}

/// Each active constraint's projection and impulses at its residual, the disk's radius from the normal impulse
/// there, held for the Newton iteration.
fn project(constraints: &mut [Constraint]) {
    for c in constraints.iter_mut().filter(|c| c.active()) {
        c.radius = c.radius_at(c.residual, None);
        c.projection = c.project(c.residual);
        c.lambda = c.impulses(&c.projection);
    }
}

/// out = Jᵀ λ for the constraints' impulses.
fn generalized_impulses(tree: &mut Articulated, model: &Model, data: &Data, constraints: &[Constraint], out: &mut [f64]) {
    tree.force.fill(Vector6::zeros());
    for c in constraints.iter().filter(|c| c.lambda != [0.0; 3]) {
        if let Target::Bodies(a, b) = c.target {
            let f = c.force(&c.lambda);
            tree.force[a] += f;
            if let Some(b) = b {
                tree.force[b] -= f;
            }
        }
    }
    tree.generalized(model, data, out);
    for c in constraints.iter().filter(|c| c.active()) {
        if let Target::Coordinate(k) = c.target {
            out[k] += c.rows[0][0] * c.lambda[0];
        }
    }
}

/// stiffness += w [[I, [r]×ᵀ], [[r]×, |r|² I − r rᵀ]], which is w F Fᵀ for the rows F = [d; r × d] of a
/// point at arm r along any orthonormal directions d.
fn add_point(stiffness: &mut Matrix6<f64>, w: f64, r: &Vector3<f64>) {
    let k = &mut stiffness.data.0; // k[column][row]
    let (x, y, z) = (w * r.x, w * r.y, w * r.z);
    // [r]× below the linear block, its transpose above.
    for (column, row, value) in [(0, 4, z), (0, 5, -y), (1, 3, -z), (1, 5, x), (2, 3, y), (2, 4, -x)] {
        k[column][row] += value;
        k[row][column] += value;
    }
    let squared = w * r.norm_squared();
    for (j, column) in k.iter_mut().enumerate().take(3) {
        column[j] += w;
    }
    for (j, column) in k[3..].iter_mut().enumerate() {
        for (i, entry) in column[3..].iter_mut().enumerate() {
            *entry += if i == j { squared } else { 0.0 } - w * r[i] * r[j];
        }
    }
}

/// stiffness += w g gᵀ.
fn add_rank_one(stiffness: &mut Matrix6<f64>, w: f64, g: &Vector6<f64>) {
    let g = &g.data.0[0];
    for (column, g_c) in stiffness.data.0.iter_mut().zip(g) {
        let scale = w * g_c;
        *column = std::array::from_fn(|r| column[r] + scale * g[r]);
    }
}

/// J x for one constraint, given the bodies' spatial velocities `motion` under x.
fn rows_times(c: &Constraint, motion: &[Vector6<f64>], x: &[f64]) -> [f64; 3] {
    match c.target {
        Target::Bodies(a, b) => {
            let relative = b.map_or(motion[a], |b| motion[a] - motion[b]);
            c.rows.map(|f| f.dot(&relative))
        }
        Target::Coordinate(k) => [c.rows[0][0] * x[k], 0.0, 0.0],
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The step length α minimising the primal along the Newton step: φ'(α) = 0, by Newton on φ' kept
/// inside a bracket of its sign change (φ is convex and piecewise smooth):
/// φ'(α) = `start` + α `curvature` − Σ λ_c(α) · dy_c, φ''(α) = `curvature` + Σ dy_cᵀ H_c(α) dy_c, with
/// `start` = (v − v_free)ᵀ M̃ d, `curvature` = dᵀ M̃ d, and φ'(0) = `initial` (from the impulses at v).
fn line_search(constraints: &[Constraint], start: f64, initial: f64, curvature: f64) -> f64 {
    if !(initial < 0.0) {
        return 0.0;
    }
    let derivatives = |alpha: f64| {
        let (mut slope, mut second) = (start + alpha * curvature, curvature);
        for c in constraints.iter().filter(|c| c.active()) {
            let (push, stiffness) = c.along(std::array::from_fn(|r| c.residual[r] + alpha * c.slope[r]), c.slope);
            slope -= push;
            second += stiffness;
        }
        (slope, second)
    };
    let (mut low, mut high, mut alpha) = (0.0, f64::INFINITY, 1.0);
    for _ in 0..LINE_ITERATIONS {
        let (slope, second) = derivatives(alpha);
        if slope.abs() <= LINE_TOLERANCE * -initial {
            break;
        }
        if slope < 0.0 {
            low = alpha;
        } else {
            high = alpha;
        }
        let newton = alpha - slope / second;
        alpha = if newton > low && newton < high {
            newton
        } else if high.is_finite() {
            0.5 * (low + high)
        } else {
            2.0 * alpha
        };
    }
    alpha
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, Matrix6x3};

    use super::*;
    use crate::spatial::spatial;

    /// A contact at arm r along an orthonormal frame, with Delassus diagonal 2 (normal) and 3 + 5 (tangents) and friction `mu`,
    /// under Coulomb's law.
    fn contact(mu: f64) -> Constraint {
        contact_under(mu, true)
    }

    fn contact_under(mu: f64, coulomb: bool) -> Constraint {
        let normal = Vector3::new(0.1, 0.2, 1.0).normalize();
        let t1 = normal.cross(&Vector3::x()).normalize();
        let t2 = normal.cross(&t1);
        let r = Vector3::new(0.3, -0.2, 0.5);
        let rows = [normal, t1, t2].map(|d| spatial(d, r.cross(&d)));
        Constraint::new(Kind::Contact { mu, arm: r, coulomb }, Target::Bodies(1, None), rows, 0.0, [0.0; 3], [2.0, 8.0], 1.0)
    }

    /// ∂λ / ∂(−y) by central differences, of the impulses `law` gives at a residual.
    fn impulses_derivative(law: &dyn Fn([f64; 3]) -> [f64; 3], y: [f64; 3]) -> Matrix3<f64> {
        let h = 1e-6;
        Matrix3::from_fn(|r, j| {
            let at = |sign: f64| {
                let mut moved = y;
                moved[j] -= sign * h;
                law(moved)[r]
            };
            (at(1.0) - at(-1.0)) / (2.0 * h)
        })
    }

    fn assert_close(label: &str, got: &Matrix6<f64>, expected: &Matrix6<f64>) {
        let error = (got - expected).abs().max();
        assert!(error <= 1e-6 * expected.abs().max().max(1.0), "{label}: F H Fᵀ off by {error}\n{got}\n{expected}");
    }

    #[test]
    fn stiffness_and_line_search_terms_are_the_impulses_derivatives_in_every_zone() {
        // (friction, residual y, the zone it is in)
        let cases = [
            (0.8, [1.0, 0.1, 0.0], "apart"),
            (0.8, [-1.0, 0.1, -0.05], "sticking"),
            (0.8, [-0.1, 2.0, 1.0], "sliding"),
            (0.8, [-1.0, 2.0, 1.0], "sliding, bound from the normal"),
            (0.0, [-1.0, 0.3, 0.2], "pressing without friction"),
        ];
        for ((mu, y, zone), coulomb) in cases.into_iter().flat_map(|case| [(case, true), (case, false)]) {
            let mut c = contact_under(mu, coulomb);
            let rows = Matrix6x3::from_columns(&c.rows);
            // One Newton iteration's problem: the disk's radius held at the law's.
            c.radius = c.radius_at(y, None);
            let projection = c.project(y);
            let mut stiffness = Matrix6::zeros();
            c.add_stiffness(&projection, &mut stiffness);
            let frozen = impulses_derivative(&|y| c.impulses(&c.project(y)), y);
            assert_close(zone, &stiffness, &(rows * frozen * rows.transpose()));
            // The line search's λ · dy and dyᵀ H dy, without H.
            let dy = [0.3, -0.7, 0.2];
            let (push, second) = c.along(y, dy);
            let lambda = c.impulses(&projection);
            let dy = Vector3::from(dy);
            assert!((push - Vector3::from(lambda).dot(&dy)).abs() <= 1e-12 * push.abs().max(1.0), "{zone}: λ · dy");
            let curvature = dy.dot(&(frozen * dy));
            assert!((second - curvature).abs() <= 1e-6 * curvature.abs().max(1.0), "{zone}: dyᵀ H dy {second} vs {curvature}");
            // The law's derivative, the bound following the normal impulse (`transition`).
            c.residual = y;
            let Stiffness::Bodies(_, _, law) = c.stiffness() else { panic!("{zone}: a contact's stiffness is on its body") };
            let exact = impulses_derivative(&|y| c.impulses(&c.project_coulomb(y, None)), y);
            assert_close(zone, &law, &(rows * exact * rows.transpose()));
        }
    }

    #[test]
    fn a_sliding_contact_asks_for_no_separating_velocity() {
        // Pressing and sliding: the normal impulse is −y_n / R_n whatever the slip (no v_n = μ |v_t| of the
        // cone), and the friction μ λ_n exactly, against the slip.
        let c = contact(0.8);
        let y = [-1.0, 2.0, 1.0];
        let lambda = c.impulses(&c.project_coulomb(y, None));
        let r_n = 1.0 / (c.inverse_sqrt_r[0] * c.inverse_sqrt_r[0]);
        assert!((lambda[0] - 1.0 / r_n).abs() <= 1e-12 * lambda[0]);
        let friction = (lambda[1] * lambda[1] + lambda[2] * lambda[2]).sqrt();
        assert!((friction - 0.8 * lambda[0]).abs() <= 1e-12 * friction);
        assert!(lambda[1] * y[1] + lambda[2] * y[2] < 0.0, "friction opposes the slip");
    }
}
