//! The contact solver: Newton's method on soft, regularised contacts with friction, on the tree, under
//! either of two friction laws (`FrictionLaw`).
//! The constraints and their laws are in `constraint`.
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

use nalgebra::{Cholesky, Vector6, U6};

use super::articulated::Articulated;
use super::constraint::{rows_times, Constraint, Target};
use crate::model::{Data, Model};

/// Newton stops once the gradient is at most this fraction of the contacts' generalized impulses
/// M̃ (v − v_free), or the error its steps leave (the step, or where they contract linearly by r, the
/// step r / (1 − r)) at most this fraction of the contacts' whole change of the velocities, both in the
/// mass-matrix norm; it converges quadratically once the zones settle, so the error left is far smaller. Tight enough that the
/// step is differentiable to 1e-8 (central differences of a sliding contact's step match the transition
/// Jacobians, which take the solve as converged), for 3 % more iterations than 1e-7 on a walking quadruped.
pub(super) const CONVERGED: f64 = 1e-10;
/// The line search's most Newton steps on the slope, and its tolerance relative to the slope at 0.
const LINE_ITERATIONS: usize = 30;
const LINE_TOLERANCE: f64 = 1e-4;

/// M̃ on the tree: the model, the poses and factor `aba_with_armature` left in `data`, and the armature it added.
#[derive(Clone, Copy)]
struct Mass<'a> {
    model: &'a Model,
    data: &'a Data,
    armature: &'a [f64],
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
    /// Whether the last solve's first step from v_free landed on its solution (`step_from_free`; true where
    /// nothing is active).
    pub landed: bool,
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
            landed: false,
        }
    }

    /// Solves for the impulses (warm start in `constraints`, solution out) and the velocities `v` they
    /// leave from `v_free`, on the tree whose poses `aba_with_armature` left in `data` (with `armature`; a
    /// free-flyer base's articulated inertia factored as `base`, `Delassus::base`); `from_free`: try the first
    /// step from v_free (`step_from_free`), worth it where the zones hold from step to step (the caller's sign:
    /// its last solve took at most one iteration; where they switch, a failed try costs a factor).
    /// Returns the Newton iterations done, or None if the Newton matrix is not positive definite.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn solve(
        &mut self, model: &Model, data: &Data, base: Option<&Cholesky<f64, U6>>, armature: &[f64], constraints: &mut [Constraint], v_free: &[f64],
        v: &mut [f64], max_iterations: usize, from_free: bool,
    ) -> Option<usize> {
        let mass = Mass { model, data, armature };
        v.copy_from_slice(v_free);
        if !constraints.iter().any(Constraint::active) {
            constraints.iter_mut().for_each(Constraint::settle);
            // v_free is the solution, as a first step from it would find.
            self.landed = true;
            return Some(0);
        }
        // Under the cone law the problem is one convex minimisation: symmetric steps, each line-searched.
        let coulomb = constraints.iter().any(|c| c.mu > 0.0 && c.cone_slope == 0.0);
        self.landed = coulomb && from_free && self.step_from_free(mass, constraints, v_free, v);
        if self.landed {
            constraints.iter_mut().for_each(Constraint::settle);
            return Some(1);
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
                if coulomb && iterations == 1 && self.step_in_warm_zones(mass, constraints, v_free, v) {
                    guessed = true;
                    continue;
                }
                // The law's Jacobian, the friction bounds' dependence on the normal impulses included: Newton
                // on the law itself, quadratic once the zones settle. Unless it leaves a pivot of the tree's
                // elimination non-positive, or its step does not descend this iteration's convex problem: then
                // that problem's symmetric Hessian, whose step does.
                let mut coupled = coulomb;
                (start, initial, curvature) = loop {
                    if !self.assemble(mass, constraints, coupled) {
                        if coupled {
                            coupled = false;
                            continue;
                        }
                        return None;
                    }
                    self.direction(mass, constraints);
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
            // A full step in zones where the law is affine, its Jacobian exact (no sliding; no contact between
            // two bodies, whose coupling the factor leaves out), lands on the solution: nothing left to check.
            if full && constraints.iter().filter(|c| c.active()).all(|c| c.exact_in(&c.projection)) {
                break;
            }
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
    fn direction(&mut self, Mass { model, data, armature }: Mass<'_>, constraints: &mut [Constraint]) {
        let tree = &mut self.tree;
        tree.solve(model, data, &self.descent, &mut self.step);
        tree.motions(model, data, &self.step);
        for c in constraints.iter_mut().filter(|c| c.active()) {
            c.slope = rows_times(c, &tree.motion, &self.step);
        }
        tree.mass_times_motions(model, data, armature, &self.step, &mut self.mass_step);
    }

    /// The first Newton step taken from v_free itself, where every active constraint's zone (its warm start's
    /// where that presses: last step's solution; else the one at v_free) is one where the law is affine and the
    /// factor exact (`Constraint::exact_in`): in those zones the step lands on the solution from wherever it
    /// starts, so the warm start's own solve is saved (a resting robot's step: one factor, one solve). True if
    /// it landed in the zones it assumed, the solution; otherwise false, with `v` at v_free and the warm-start
    /// impulses back, for the warm start (one factor lost).
    fn step_from_free(&mut self, mass: Mass<'_>, constraints: &mut [Constraint], v_free: &[f64], v: &mut [f64]) -> bool {
        let Mass { model, data, .. } = mass;
        self.change.fill(0.0);
        self.mass_change.fill(0.0);
        self.tree.motions(model, data, v_free);
        let (mut affine, mut pressing) = (true, false);
        for c in constraints.iter_mut().filter(|c| c.active()) {
            let velocity = rows_times(c, &self.tree.motion, v_free);
            c.residual = std::array::from_fn(|r| velocity[r] - c.asked[r]);
            let zone = c.warm_zone.unwrap_or_else(|| c.project_coulomb(c.residual, None));
            if !c.exact_in(&zone) {
                affine = false;
                break;
            }
            pressing |= zone.normal.is_some();
            c.radius = c.radius_at(c.residual, Some(&zone));
            c.projection = c.project_in(c.residual, c.radius, Some(&zone));
            c.lambda = c.impulses(&c.projection);
        }
        // Nothing pressing: the warm start is v_free itself, and optimal if nothing presses there either.
        let landed = affine && pressing && {
            self.descend(model, data, constraints);
            self.assemble(mass, constraints, false) && {
                self.direction(mass, constraints);
                self.move_along(constraints, v_free, v, 1.0);
                constraints.iter().filter(|c| c.active()).all(|c| c.projection.same_zone(&c.project_coulomb(c.residual, None)))
            }
        };
        if !landed {
            v.copy_from_slice(v_free);
            constraints.iter_mut().for_each(Constraint::rewarm);
        }
        landed
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
    fn step_in_warm_zones(&mut self, mass: Mass<'_>, constraints: &mut [Constraint], v_free: &[f64], v: &mut [f64]) -> bool {
        let Mass { model, data, .. } = mass;
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
        if self.assemble(mass, constraints, true) {
            self.direction(mass, constraints);
            self.move_along(constraints, v_free, v, 1.0);
            return true;
        }
        project(constraints);
        self.descend(model, data, constraints);
        false
    }

    /// Assembles and factors the Newton matrix M̃ + Σ Jᵀ H_c J at the constraints' projections, with the
    /// law's unsymmetric coupling if `coupled`; false if the factor fails. Symmetric where no constraint
    /// couples (nothing presses and slides): Cholesky for the base, no left factors.
    fn assemble(&mut self, Mass { model, data, armature }: Mass<'_>, constraints: &[Constraint], coupled: bool) -> bool {
        let coupled = coupled && constraints.iter().any(|c| c.active() && c.couples());
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
pub(super) fn generalized_impulses(tree: &mut Articulated, model: &Model, data: &Data, constraints: &[Constraint], out: &mut [f64]) {
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
