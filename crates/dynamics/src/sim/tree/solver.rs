//! The contact solver: projected Gauss–Seidel on soft, regularised constraints, warm-started, in the
//! u = D^½ L v coordinates of `factor` (a row update costs the depth of its body, not nv).
//!
//! Each constraint is a contact (normal row n and tangent rows t1, t2, one block) or a joint limit (one
//! row). With A = Yᵀ Y the Delassus block and R = ε diag(A) the regularisation, the impulses λ solve
//!   normal:   λ_n ≥ 0 ⊥ Y_nᵀ u − b + R_n λ_n ≥ 0,
//!   friction: λ_t = argmin over |λ_t| ≤ μ λ_n (the elliptic Coulomb cone) of the tangential block's quadratic,
//! with u = u_free + Σ Y λ, where b is the normal velocity the constraint asks for: the gap closed in one
//! step while apart (speculative contact), a fraction of the penetration beyond the tolerance while
//! overlapping (Baumgarte). The regularisation makes the problem strictly convex, so the impulses are
//! unique even where contacts are redundant (four corners of a box on the ground), and it is what keeps
//! Gauss–Seidel converging on such sets.

use std::ops::Range;

use super::factor::Entry;

/// Regularisation, relative to the Delassus diagonal: R = ε A_ii.
pub(super) const REGULARISATION: f64 = 1e-4;
/// Fraction of the penetration beyond the tolerance removed per step.
pub(super) const BAUMGARTE: f64 = 0.2;
/// Penetration left standing (m).
pub(super) const TOLERANCE: f64 = 2e-4;
/// Sweeps stop once no impulse changed by more than this fraction of the largest.
const CONVERGED: f64 = 1e-10;

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
    pub entries: Range<usize>,
    /// The normal velocity asked for (m/s or rad/s).
    pub bias: f64,
    /// Impulses [λ_n, λ_t1, λ_t2] (N s or N m s); warm start in, solution out.
    pub lambda: [f64; 3],
    /// Yᵀ Y: [nn, 11, 22, n1, n2, 12].
    block: [f64; 6],
}

impl Constraint {
    pub(super) fn new(kind: Kind, entries: Range<usize>, bias: f64, lambda: [f64; 3], all: &[Entry]) -> Self {
        let mut block = [0.0; 6];
        for e in &all[entries.clone()] {
            let [n, t1, t2] = e.value;
            block[0] += n * n;
            block[1] += t1 * t1;
            block[2] += t2 * t2;
            block[3] += n * t1;
            block[4] += n * t2;
            block[5] += t1 * t2;
        }
        let mut lambda = lambda;
        lambda[0] = lambda[0].max(0.0);
        if let Kind::Contact { mu } = kind {
            clamp_to_cone(&mut lambda, mu);
        } else {
            lambda[1] = 0.0;
            lambda[2] = 0.0;
        }
        Constraint { kind, entries, bias, lambda, block }
    }
}

fn clamp_to_cone(lambda: &mut [f64; 3], mu: f64) {
    let bound = mu * lambda[0];
    let norm = lambda[1].hypot(lambda[2]);
    if norm > bound {
        let scale = if norm > 0.0 { bound / norm } else { 0.0 };
        lambda[1] *= scale;
        lambda[2] *= scale;
    }
}

/// Solves for the impulses, updating `u` from u_free (in) to u_free + Σ Y λ (out). Returns the sweeps done.
pub(super) fn solve(constraints: &mut [Constraint], entries: &[Entry], u: &mut [f64], max_sweeps: usize) -> usize {
    for c in constraints.iter() {
        apply(entries, c.entries.clone(), c.lambda, u);
    }
    for sweep in 1..=max_sweeps {
        let (mut change, mut scale) = (0.0f64, 0.0f64);
        for c in constraints.iter_mut() {
            let rows = &entries[c.entries.clone()];
            let mut dots = [0.0; 3];
            for e in rows {
                let x = u[e.index as usize];
                dots[0] += e.value[0] * x;
                dots[1] += e.value[1] * x;
                dots[2] += e.value[2] * x;
            }
            let [nn, t11, t22, n1, n2, t12] = c.block;
            let old = c.lambda;
            let r_n = REGULARISATION * nn;
            let normal = (old[0] - (dots[0] - c.bias + r_n * old[0]) / (nn + r_n)).max(0.0);
            let mut delta = [normal - old[0], 0.0, 0.0];
            if let Kind::Contact { mu } = c.kind {
                // The tangential velocities after the normal update, then the 2x2 block's Newton step
                // projected on the disc |λ_t| ≤ μ λ_n.
                let r_t = REGULARISATION * 0.5 * (t11 + t22);
                let g1 = dots[1] + n1 * delta[0] + r_t * old[1];
                let g2 = dots[2] + n2 * delta[0] + r_t * old[2];
                let (a, b, d) = (t11 + r_t, t12, t22 + r_t);
                let det = a * d - b * b;
                let mut next = [normal, old[1] - (d * g1 - b * g2) / det, old[2] - (a * g2 - b * g1) / det];
                clamp_to_cone(&mut next, mu);
                delta[1] = next[1] - old[1];
                delta[2] = next[2] - old[2];
            }
            if delta != [0.0; 3] {
                c.lambda = [old[0] + delta[0], old[1] + delta[1], old[2] + delta[2]];
                for e in rows {
                    u[e.index as usize] += e.value[0] * delta[0] + e.value[1] * delta[1] + e.value[2] * delta[2];
                }
            }
            change = change.max(delta[0].abs()).max(delta[1].abs()).max(delta[2].abs());
            scale = scale.max(c.lambda[0]);
        }
        if change <= CONVERGED * scale {
            return sweep;
        }
    }
    max_sweeps
}

fn apply(entries: &[Entry], range: Range<usize>, lambda: [f64; 3], u: &mut [f64]) {
    if lambda == [0.0; 3] {
        return;
    }
    for e in &entries[range] {
        u[e.index as usize] += e.value[0] * lambda[0] + e.value[1] * lambda[1] + e.value[2] * lambda[2];
    }
}
