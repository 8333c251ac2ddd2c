//! The contact solver: projected Gauss–Seidel on soft, regularised constraints, warm-started, in the
//! u = D^½ L v coordinates of `factor`, body by body.
//!
//! Each constraint is a contact (normal row n and tangent rows t1, t2, one block) or a joint limit (one
//! row). With A = J M̃⁻¹ Jᵀ its Delassus block and R = ε diag(A) the regularisation, the impulses λ solve
//!   normal:   λ_n ≥ 0 ⊥ J_n v⁺ − b + R_n λ_n ≥ 0,
//!   (friction regularised proximally, R_t (λ_t − λ_t,warm): no creep at rest, and the cone bounds it)
//!   friction: λ_t in the disc |λ_t| ≤ μ λ_n (the elliptic Coulomb cone), sticking or opposing the slip,
//! where b is the normal velocity the constraint asks for: the gap closed in one step while apart
//! (speculative contact), a fraction of the penetration while overlapping
//! (Baumgarte). The regularisation makes the problem strictly convex, so the impulses are unique even
//! where contacts are redundant (four corners of a box on the ground), and keeps Gauss–Seidel converging.
//!
//! Constraints come in groups that share a body (or a pair of bodies, or a joint coordinate): a group
//! holds Φ (`factor::Entry`), its 6x6 W = Φᵀ Φ, and each constraint's rows as spatial forces F. A sweep
//! visits each group once: its velocity w = Φᵀ u (O(depth)), then every constraint of the group in turn,
//! each update moving w by W F Δλ (O(1)), and finally u += Φ Σ F Δλ (O(depth)). So a sweep costs twice the
//! depth per body in contact, however many contacts the body has.

use std::ops::Range;

use nalgebra::{Matrix6, Vector6};

use super::factor::Entry;

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
/// Sweeps stop once the velocities' estimated remaining error is at most this fraction of the contacts'
/// whole change (resting contact forces then sum to the weight within about 1e-7).
pub(super) const CONVERGED: f64 = 1e-7;
/// The largest contraction per sweep the error estimate assumes.
const MAX_CONTRACTION: f64 = 0.999;
/// A constraint whose Delassus diagonal is below this fraction of its group's scale (tr W |F|²) is
/// immovable: the joints cannot move it along its normal.
const IMMOVABLE: f64 = 1e-12;
/// Newton iterations and relative tolerance of a sliding contact's friction on the disc (it converges
/// quadratically: three or four iterations reach the tolerance).
const DISC_ITERATIONS: usize = 8;
const DISC_TOLERANCE: f64 = 1e-12;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Kind {
    /// A contact with friction coefficient μ.
    Contact { mu: f64 },
    /// A one-sided joint-limit row (normal only).
    Limit,
}

#[derive(Debug, Clone)]
pub(super) struct Constraint {
    pub kind: Kind,
    /// The normal velocity asked for (m/s or rad/s).
    pub bias: f64,
    /// Impulses [λ_n, λ_t1, λ_t2] (N s or N m s); warm start in, solution out.
    pub lambda: [f64; 3],
    /// The friction impulses of the warm start: friction is regularised towards them (proximally), so a
    /// sticking contact holds its friction from step to step without creeping.
    warm_friction: [f64; 2],
    /// Its rows as forces on the group's columns: n, t1, t2.
    rows: [Vector6<f64>; 3],
    /// W F of each row: how a unit impulse of the row moves the group's velocity.
    moves: [Vector6<f64>; 3],
    /// The normal row's coupling to the tangent rows, A_n1 and A_n2, and its regularisation R_n.
    coupling: [f64; 2],
    r_n: f64,
    /// 1 / (A_nn + R_n); zero for an immovable contact.
    normal_gain: f64,
    /// The tangent block with its regularisation, Ã = [a b; b d] as [a, b, d], its inverse likewise (None
    /// where the tangent rows move nothing, a contact the tree cannot slide), and R_t.
    tangent: [f64; 3],
    tangent_inverse: Option<[f64; 3]>,
    r_t: f64,
}

#[derive(Debug, Clone)]
pub(super) struct Group {
    pub entries: Range<usize>,
    pub constraints: Range<usize>,
    /// W = Φᵀ Φ.
    w: Matrix6<f64>,
}

impl Group {
    pub(super) fn new(entries: Range<usize>, all: &[Entry]) -> Self {
        let mut w = Matrix6::zeros();
        for e in &all[entries.clone()] {
            for c in 0..6 {
                for r in c..6 {
                    w[(r, c)] += e.value[r] * e.value[c];
                }
            }
        }
        w.fill_upper_triangle_with_lower_triangle();
        Group { entries, constraints: 0..0, w }
    }

    /// A constraint of this group whose rows are the forces `rows`, with its warm-start impulses.
    pub(super) fn constraint(&self, kind: Kind, rows: [Vector6<f64>; 3], bias: f64, warm: [f64; 3]) -> Constraint {
        let moves = rows.map(|f| self.w * f);
        // A = [W F_i · F_j]
        let (nn, t11, t22) = (rows[0].dot(&moves[0]), rows[1].dot(&moves[1]), rows[2].dot(&moves[2]));
        let (n1, n2, t12) = (rows[0].dot(&moves[1]), rows[0].dot(&moves[2]), rows[1].dot(&moves[2]));
        let mut lambda = warm;
        let r_n = REGULARISATION * nn;
        let immovable = nn <= IMMOVABLE * self.w.trace() * rows[0].norm_squared();
        if immovable {
            // No joint moves the contact along its normal: it carries nothing (and so holds no friction).
            lambda = [0.0; 3];
        }
        lambda[0] = lambda[0].max(0.0);
        match kind {
            Kind::Contact { mu } => clamp_to_cone(&mut lambda, mu),
            Kind::Limit => {
                lambda[1] = 0.0;
                lambda[2] = 0.0;
            }
        }
        let r_t = REGULARISATION * 0.5 * (t11 + t22);
        let (a, b, d) = (t11 + r_t, t12, t22 + r_t);
        let det = a * d - b * b;
        Constraint {
            kind,
            bias,
            lambda,
            warm_friction: [lambda[1], lambda[2]],
            rows,
            moves,
            coupling: [n1, n2],
            r_n,
            normal_gain: if immovable { 0.0 } else { 1.0 / (nn + r_n) },
            tangent: [a, b, d],
            tangent_inverse: (det > 0.0).then(|| [d / det, -b / det, a / det]),
            r_t,
        }
    }
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

/// The new impulses of one constraint given its rows' current velocities `dots`.
#[inline]
fn update(c: &Constraint, dots: [f64; 3]) -> [f64; 3] {
    let old = c.lambda;
    let normal = (old[0] - (dots[0] - c.bias + c.r_n * old[0]) * c.normal_gain).max(0.0);
    let Kind::Contact { mu } = c.kind else { return [normal, 0.0, 0.0] };
    // The tangential velocities after the normal update; then the exact minimiser of the 2x2 block's
    // quadratic on the disc |λ_t| ≤ μ λ_n: the Newton step if it sticks, otherwise the point of the circle
    // where friction opposes the (regularised) slip, maximal dissipation.
    let dn = normal - old[0];
    let g1 = dots[1] + c.coupling[0] * dn + c.r_t * (old[1] - c.warm_friction[0]);
    let g2 = dots[2] + c.coupling[1] * dn + c.r_t * (old[2] - c.warm_friction[1]);
    let Some([i11, i12, i22]) = c.tangent_inverse else {
        // Friction idles where it can move nothing.
        let mut held = [normal, old[1], old[2]];
        clamp_to_cone(&mut held, mu);
        return held;
    };
    let stick = [old[1] - (i11 * g1 + i12 * g2), old[2] - (i12 * g1 + i22 * g2)];
    let radius = mu * normal;
    if stick[0] * stick[0] + stick[1] * stick[1] <= radius * radius {
        return [normal, stick[0], stick[1]];
    }
    let [a, b, d] = c.tangent;
    let [x1, x2] = on_disc(a, b, d, [g1 - a * old[1] - b * old[2], g2 - b * old[1] - d * old[2]], radius);
    [normal, x1, x2]
}

/// argmin ½ xᵀ [a b; b d] x + cᵀ x over |x| = r, for a minimiser of the unconstrained quadratic outside
/// the disc: x = −(A + ν I)⁻¹ c with ν ≥ 0 such that |x| = r (the trust-region subproblem), ν by Newton
/// on 1/|x(ν)| − 1/r, which rises monotonically to its root from ν = 0 (Moré and Sorensen 1983).
fn on_disc(a: f64, b: f64, d: f64, c: [f64; 2], r: f64) -> [f64; 2] {
    if r <= 0.0 {
        return [0.0, 0.0];
    }
    let mut nu = 0.0;
    let mut x = [0.0; 2];
    for _ in 0..DISC_ITERATIONS {
        let (p, s) = (a + nu, d + nu);
        let det = p * s - b * b;
        x = [-(s * c[0] - b * c[1]) / det, -(p * c[1] - b * c[0]) / det];
        let norm2 = x[0] * x[0] + x[1] * x[1];
        let norm = norm2.sqrt();
        if norm - r <= DISC_TOLERANCE * r {
            break;
        }
        // xᵀ (A + ν I)⁻¹ x
        let curvature = (s * x[0] * x[0] - 2.0 * b * x[0] * x[1] + p * x[1] * x[1]) / det;
        nu += (norm / r - 1.0) * norm2 / curvature;
    }
    let scale = r / (x[0] * x[0] + x[1] * x[1]).sqrt();
    [x[0] * scale, x[1] * scale]
}

/// Solves for the impulses, updating `u` from u_free (in) to u_free + Σ Φ F λ (out); `free` and `before`
/// are scratch of u's length. Returns the sweeps done.
///
/// Sweeps stop when the error left in u, estimated from the last sweep's change and contraction, is at
/// most `CONVERGED` times the change all the impulses make (max |u − u_free|): the motion has converged. The impulses themselves may still be shifting inside
/// the null space of statically indeterminate contact sets (a box's four corners, a tree lying on the
/// ground), where regularisation lets them settle only slowly and the motion does not depend on them.
pub(super) fn solve(
    groups: &[Group],
    constraints: &mut [Constraint],
    entries: &[Entry],
    u: &mut [f64],
    free: &mut [f64],
    before: &mut [f64],
    max_sweeps: usize,
) -> usize {
    free.copy_from_slice(u);
    for g in groups {
        let force: Vector6<f64> = constraints[g.constraints.clone()].iter().map(|c| c.rows[0] * c.lambda[0] + c.rows[1] * c.lambda[1] + c.rows[2] * c.lambda[2]).sum();
        scatter(&entries[g.entries.clone()], &force, u);
    }
    let mut last = f64::INFINITY;
    for sweep in 1..=max_sweeps {
        before.copy_from_slice(u);
        for g in groups {
            let columns = &entries[g.entries.clone()];
            let mut velocity = gather(columns, u);
            let mut force = Vector6::zeros();
            for c in &mut constraints[g.constraints.clone()] {
                let dots = [c.rows[0].dot(&velocity), c.rows[1].dot(&velocity), c.rows[2].dot(&velocity)];
                let next = update(c, dots);
                if next != c.lambda {
                    let delta = [next[0] - c.lambda[0], next[1] - c.lambda[1], next[2] - c.lambda[2]];
                    velocity += c.moves[0] * delta[0] + c.moves[1] * delta[1] + c.moves[2] * delta[2];
                    force += c.rows[0] * delta[0] + c.rows[1] * delta[1] + c.rows[2] * delta[2];
                    c.lambda = next;
                }
            }
            if force != Vector6::zeros() {
                scatter(columns, &force, u);
            }
        }
        let (mut change, mut scale) = (0.0f64, 0.0f64);
        for ((x, b), f) in u.iter().zip(before.iter()).zip(free.iter()) {
            change = change.max((x - b).abs());
            scale = scale.max((x - f).abs());
        }
        // Gauss–Seidel converges linearly: with the contraction ρ of the last sweep, the error left is
        // about change ρ / (1 − ρ), which may well exceed the change itself.
        let rho = (change / last).min(MAX_CONTRACTION);
        last = change;
        if change * (rho / (1.0 - rho)).max(1.0) <= CONVERGED * scale {
            return sweep;
        }
    }
    max_sweeps
}

/// Φᵀ u.
#[inline]
fn gather(columns: &[Entry], u: &[f64]) -> Vector6<f64> {
    let mut sum = [0.0; 6];
    for e in columns {
        let x = u[e.index as usize];
        for r in 0..6 {
            sum[r] += e.value[r] * x;
        }
    }
    Vector6::from(sum)
}

/// u += Φ f.
#[inline]
fn scatter(columns: &[Entry], force: &Vector6<f64>, u: &mut [f64]) {
    for e in columns {
        let v = &e.value;
        u[e.index as usize] += (v[0] * force[0] + v[1] * force[1]) + (v[2] * force[2] + v[3] * force[3]) + (v[4] * force[4] + v[5] * force[5]);
    }
}

#[cfg(test)]
mod tests {
    use super::on_disc;

    /// Against brute force: the quadratic's minimum over 100 000 points of the circle |x| = r.
    #[test]
    fn friction_on_the_disc_is_the_quadratics_minimum_on_the_circle() {
        let cases = [(2.0, 0.3, 0.5, [1.0, -2.0], 0.1), (1.0, 0.0, 1.0, [0.3, 0.4], 0.2), (10.0, -2.9, 1.0, [-4.0, 1.0], 0.05), (0.01, 0.0, 5.0, [0.2, 0.2], 1.0)];
        for (a, b, d, c, r) in cases {
            let f = |x: [f64; 2]| 0.5 * (a * x[0] * x[0] + 2.0 * b * x[0] * x[1] + d * x[1] * x[1]) + c[0] * x[0] + c[1] * x[1];
            let x = on_disc(a, b, d, c, r);
            assert!(((x[0] * x[0] + x[1] * x[1]).sqrt() - r).abs() < 1e-12 * r);
            let best = (0..100_000).map(|k| {
                let t = k as f64 * std::f64::consts::TAU / 100_000.0;
                f([r * t.cos(), r * t.sin()])
            });
            let best = best.fold(f64::INFINITY, f64::min);
            assert!(f(x) <= best + 1e-12, "on_disc gives {} > brute force {best}", f(x));
            assert!(f(x) >= best - 1e-6 * r * r * (a + d), "the circle's sampled minimum {best} is far below on_disc's {}", f(x));
        }
    }
}
