//! The contact solver's constraints and their friction laws (`FrictionLaw`): each constraint's impulses as a
//! function of its rows' velocities, and their derivatives, which Newton's method (`solver`) and the transition
//! Jacobians (`transition`) build on.
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

use nalgebra::{Matrix6, Vector3, Vector6};

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
/// A row whose Delassus diagonal is below this fraction of its scale (tr Ω |F|², `Delassus`) is immovable:
/// the joints cannot move the contact along it (a normal row: it carries nothing; tangent rows: no friction).
const IMMOVABLE: f64 = 1e-12;
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
    pub(super) target: Target,
    /// Impulses [λ_n, λ_t1, λ_t2] (N s or N m s); warm start in, solution out.
    pub lambda: [f64; 3],
    /// Its rows as forces on its target: n, t1, t2.
    pub(super) rows: [Vector6<f64>; 3],
    /// The velocities asked for, b: [normal bias, R_t λ_t1,warm, R_t λ_t2,warm].
    pub(super) asked: [f64; 3],
    /// The warm start's impulses (clamped to the cone).
    warm: [f64; 3],
    /// R_n^-½ and R_t^-½, zero where R is: R_n for an immovable constraint (it carries nothing), R_t for one
    /// whose tangent rows move nothing or that has no friction (its friction idles at the warm start, within
    /// the cone).
    inverse_sqrt_r: [f64; 2],
    /// μ (zero for a limit or a contact without friction rows).
    pub(super) mu: f64,
    /// The cone law's slope μ̂ = μ (R_t / R_n)^½ of the cone in the scaled impulses and 1 / (1 + μ̂²), the
    /// weight of its ray; zero under Coulomb's law (or without friction).
    pub(super) cone_slope: f64,
    ray_weight: f64,
    /// The friction disk's radius in the scaled impulses, μ λ_n R_t^½, frozen for one Newton iteration.
    pub(super) radius: f64,
    /// Where the impulses lie at `residual`, kept from the Newton iteration's impulses for its stiffness.
    pub(super) projection: Projection,
    /// J v − b at the solver's current velocities, and J d along its step.
    pub(super) residual: [f64; 3],
    pub(super) slope: [f64; 3],
    /// The zone the warm start's impulses lie in, where they press (None otherwise): the first Newton
    /// step's guess of the solution's zones (`Solver::step_in_warm_zones`).
    pub(super) warm_zone: Option<Projection>,
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
pub(super) struct Projection {
    /// Π_n = s_n while pressing, None while apart.
    pub(super) normal: Option<f64>,
    tangent: Tangent,
}

impl Projection {
    /// Whether `other` is in the same zone: pressing or apart; sticking, sliding or free.
    pub(super) fn same_zone(&self, other: &Projection) -> bool {
        self.normal.is_some() == other.normal.is_some() && std::mem::discriminant(&self.tangent) == std::mem::discriminant(&other.tangent)
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Tangent {
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
            warm: lambda,
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

    /// The same constraint with another Delassus diagonal and scale (`Delassus::contact`), which set its
    /// regularisation, from its warm start.
    pub(super) fn with_diagonal(&self, diagonal: [f64; 2], scale: f64) -> Constraint {
        Constraint::new(self.kind, self.target, self.rows, self.asked[0], self.warm, diagonal, scale)
    }

    pub(super) fn active(&self) -> bool {
        self.inverse_sqrt_r[0] > 0.0
    }

    /// The disk's radius μ λ_n R_t^½ that the normal impulse at residual `y` gives (in the zone of `zone`).
    pub(super) fn radius_at(&self, y: [f64; 3], zone: Option<&Projection>) -> f64 {
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
    pub(super) fn project_in(&self, y: [f64; 3], radius: f64, zone: Option<&Projection>) -> Projection {
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
    pub(super) fn project(&self, y: [f64; 3]) -> Projection {
        self.project_in(y, self.radius, None)
    }

    /// The projection of the law itself at residual `y`: the radius from the normal impulse at `y`.
    pub(super) fn project_coulomb(&self, y: [f64; 3], zone: Option<&Projection>) -> Projection {
        self.project_in(y, self.radius_at(y, zone), zone)
    }

    /// The impulses λ = R^-½ Π.
    pub(super) fn impulses(&self, projection: &Projection) -> [f64; 3] {
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
    pub(super) fn add_stiffness(&self, projection: &Projection, stiffness: &mut Matrix6<f64>) {
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
    pub(super) fn add_coupling(&self, projection: &Projection, stiffness: &mut Matrix6<f64>) {
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
    pub(super) fn stays_in_zone(&self) -> bool {
        self.projection.same_zone(&self.project_coulomb(std::array::from_fn(|r| self.residual[r] + self.slope[r]), None))
    }

    /// Whether, in the zone of `zone`, the law is affine (pressing or apart, and sticking or without friction)
    /// and its Newton matrix term exact (on one body or coordinate): a full Newton step in that zone lands on
    /// the law's solution.
    pub(super) fn exact_in(&self, zone: &Projection) -> bool {
        matches!(zone.tangent, Tangent::Free | Tangent::Held(_)) && !matches!(self.target, Target::Bodies(_, Some(_)))
    }

    /// Its impulses back to the warm start's.
    pub(super) fn rewarm(&mut self) {
        self.lambda = self.warm;
    }

    /// Whether its law's unsymmetric term is in play: pressing and sliding (`add_coupling`).
    pub(super) fn couples(&self) -> bool {
        matches!((self.projection.normal, self.projection.tangent), (Some(_), Tangent::Sliding { .. }))
    }

    /// The diagonal entry H_c[0, 0] (a joint limit's stiffness on its coordinate, before the row's scale).
    pub(super) fn normal_stiffness(&self, projection: &Projection) -> f64 {
        if projection.normal.is_some() {
            self.inverse_sqrt_r[0] * self.inverse_sqrt_r[0]
        } else {
            0.0
        }
    }

    /// λ · dy and dyᵀ H_c dy at residual `y`, the radius held, without forming H_c (the line search's inner loop).
    pub(super) fn along(&self, y: [f64; 3], dy: [f64; 3]) -> (f64, f64) {
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
    pub(super) fn settle(&mut self) {
        self.settle_in(None);
    }

    /// `settle`, the impulses in the zone of `zone` if given, whichever zone the residual is in.
    /// Its impulses at velocities `v` whose body motions are `motion` (`Articulated::motions`), in the zone of
    /// `solved`, the step's own constraint (`transition`).
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
                lambda[1] = self.warm[1];
                lambda[2] = self.warm[2];
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
pub(super) fn rows_times(c: &Constraint, motion: &[Vector6<f64>], x: &[f64]) -> [f64; 3] {
    match c.target {
        Target::Bodies(a, b) => {
            let relative = b.map_or(motion[a], |b| motion[a] - motion[b]);
            c.rows.map(|f| f.dot(&relative))
        }
        Target::Coordinate(k) => [c.rows[0][0] * x[k], 0.0, 0.0],
    }
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
