//! The inverse of the joint-space mass matrix by the articulated-body recursion (Carpentier 2018,
//! "Analytical inverse of the joint space inertia matrix"; Pinocchio's `computeMinverse`), never forming
//! or factorising M.
//!
//! Worked in the world's axes about the base (`kinematics::base_centred_kinematics`): articulated inertias, the
//! force sets F_i (τ ↦ bias force of subtree i) and the motion sets P_i (τ ↦ acceleration of body i) pass between
//! bodies without transforms, so each (body, column) pair costs a few 6-vector operations. Row i of the upper
//! triangle is kept in column i (the lower triangle), where it is contiguous.
//!
//! F_i is nonzero only on the columns of i's subtree, and each of those but i's own belongs to exactly one
//! child's subtree: a child writes its part of F_parent outright, so no set is ever cleared.

use nalgebra::{DMatrix, Matrix6xX, Vector3, Vector6};

use super::aba::ball_factors;
use super::kinematics::base_centred_kinematics;
use crate::joint::Dofs;
use crate::model::{reserve_square, Data, Model};
use crate::spatial::{add_reduced_inertia, dot6, spd_inverse6};

/// Body `i`'s set and its parent's (`parent < i`), as 6-vector chunks, one per column.
fn sets(data: &mut [Matrix6xX<f64>], parent: usize, i: usize) -> (&mut [f64], &mut [f64]) {
    let (head, tail) = data.split_at_mut(i);
    (head[parent].as_mut_slice(), tail[0].as_mut_slice())
}

#[inline]
fn chunk(x: &[f64], column: usize) -> &[f64; 6] {
    x[6 * column..6 * column + 6].try_into().expect("a 6-vector chunk")
}

/// `out = base + x m`, 6-vectors.
#[inline]
fn axpy(out: &mut [f64; 6], base: &[f64; 6], x: &Vector6<f64>, m: f64) {
    for r in 0..6 {
        out[r] = base[r] + x[r] * m;
    }
}

/// M(q)⁻¹ by the articulated-body recursion (Carpentier, "Analytical inverse of the joint space inertia matrix",
/// 2018; Pinocchio's `computeMinverse`), without forming or factorising M.
///
/// Fills `data.minv` (both triangles) with M(q)⁻¹ and returns it.
pub fn minv<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    base_centred_kinematics(model, data, q);
    for i in 0..model.nbodies() {
        data.inertia[i] = data.centred_m_i[i].act_rigid_inertia(model.inertia(i)).matrix();
        data.s[i] = model.joint(i).subspace_in(&data.centred_m_i[i]);
    }
    inverse(model, data, false)
}

/// `minv` at the configuration `aba` (or `aba_with_armature` with the model's armature) last ran at, from the
/// poses, subspaces and articulated-body factors (I^A, U, D⁻¹) it left in `data`, into `out` (nv x nv, column-major).
pub(crate) fn minv_after_aba_into(model: &Model, data: &mut Data, out: &mut [f64]) {
    inverse_into(model, data, true, out);
}

/// The passes of `minv` after the kinematics into `data.minv` (`inverse_into`).
fn inverse<'d>(model: &Model, data: &'d mut Data, factored: bool) -> &'d DMatrix<f64> {
    reserve_square(&mut data.minv, model.nv());
    // An empty matrix holds no allocation: M⁻¹ is lent to the passes and put back.
    let mut minv = std::mem::replace(&mut data.minv, DMatrix::zeros(0, 0));
    inverse_into(model, data, factored, minv.as_mut_slice());
    data.minv = minv;
    &data.minv
}

/// The passes of `minv` after the kinematics, M⁻¹ into `out` (nv x nv, column-major): from the bodies' rigid inertias
/// in `data.inertia`, or, `factored`, from ABA's articulated inertias and factors there.
fn inverse_into(model: &Model, data: &mut Data, factored: bool, out: &mut [f64]) {
    let (n, nv) = (model.nbodies(), model.nv());
    if data.force_sets.len() != n {
        data.force_sets = vec![Matrix6xX::zeros(nv); n];
    }
    // Backward pass: the rows' subtree parts D⁻¹(e_i − Sᵀ F_i); F_i + U M⁻¹_i goes to the parent together
    // with the articulated inertia I^A − U D⁻¹ Uᵀ.
    for i in (0..n).rev() {
        let k = model.idx_v(i);
        if let Dofs::Free = model.joint(i).dofs() {
            // S = X_0 (the base frame to the world), so D⁻¹ Sᵀ = X_0⁻¹ I^A⁻¹: the base rows of column c are
            // X_0⁻¹ I^A⁻¹ (X_0⁻ᵀ e_c) for the base's own columns and −X_0⁻¹ I^A⁻¹ F_0[c] for the others, and
            // the base's motion set P_0[c] = S M⁻¹_0[c] is the world-frame solve itself.
            let base = data.centred_m_i[0];
            // One inverse, then independent products (the solves would each be a chain of divisions).
            let inverse = spd_inverse6(&data.inertia[0]);
            for col in 0..nv {
                let motion = if col < 6 {
                    inverse * base.act_force(&Vector6::ith(col, 1.0))
                } else {
                    -(inverse * Vector6::from_column_slice(chunk(data.force_sets[0].as_slice(), col)))
                };
                // Row r of the upper triangle lives in column r: entry (col, r), at r nv + col.
                let minv = &mut *out;
                for (r, x) in base.inv_act_motion(&motion).iter().enumerate() {
                    minv[r * nv + col] = *x;
                }
                data.force_sets[0].as_mut_slice()[6 * col..6 * col + 6].copy_from_slice(motion.as_slice());
            }
            continue;
        }
        if model.joint(i).dofs() == Dofs::Ball {
            ball_backward(model, data, i, factored, out);
            continue;
        }
        let one_dof = model.joint(i).nv() == 1;
        let s = data.s[i];
        let (u, dinv) = match (one_dof, factored) {
            (true, true) => (data.u[i], data.d_inv[i]),
            (true, false) => {
                let u = data.inertia[i] * s;
                (u, 1.0 / (s.dot(&u) + model.armature()[k]))
            }
            (false, _) => (Vector6::zeros(), 0.0),
        };
        if one_dof {
            // Beyond the subtree this row is zero until the forward pass.
            out[k * nv + k..(k + 1) * nv].fill(0.0);
            data.u[i] = u;
            data.d_inv[i] = dinv;
        }
        if i == 0 {
            continue;
        }
        let p = model.parent(i);
        let (fp, fi) = sets(&mut data.force_sets, p, i);
        let row: &mut [f64] = if one_dof { &mut out[k * nv..(k + 1) * nv] } else { &mut [] };
        for columns in model.subtree_columns(i) {
            let span = 6 * columns.start..6 * columns.end;
            let pairs = fp[span.clone()].chunks_exact_mut(6).zip(fi[span].chunks_exact(6));
            if !one_dof {
                pairs.for_each(|(to, from)| to.copy_from_slice(from));
                continue;
            }
            let mut pairs = pairs.zip(&mut row[columns.clone()]);
            if columns.start == k {
                // i's own column comes first, where F_i is zero.
                let ((to, _), entry) = pairs.next().expect("i's own column");
                *entry = dinv;
                axpy(to.try_into().expect("6"), &[0.0; 6], &u, dinv);
            }
            for ((to, from), entry) in pairs {
                let (to, from): (&mut [f64; 6], &[f64; 6]) = (to.try_into().expect("6"), from.try_into().expect("6"));
                let m = -dinv * dot6(&s, from);
                *entry = m;
                axpy(to, from, &u, m);
            }
        }
        if !factored {
            let (head, tail) = data.inertia.split_at_mut(i);
            add_reduced_inertia(&mut head[p], &tail[0], &u, &(u * dinv));
        }
    }
    // Forward pass: subtract D⁻¹ Uᵀ P_parent, then P_i = S M⁻¹_i + P_parent (reusing the sets' storage).
    for i in 0..n {
        let k = model.idx_v(i);
        match model.joint(i).dofs() {
            // The backward pass left P_0.
            Dofs::Free => {}
            Dofs::Ball => ball_forward(model, data, i, out),
            Dofs::Zero if i == 0 => data.force_sets[0].fill(0.0),
            dofs => {
                let (p, s, u, dinv) = (model.parent(i), data.s[i], data.u[i], data.d_inv[i]);
                let (pp, pi) = sets(&mut data.force_sets, p, i);
                if dofs == Dofs::Zero {
                    pi[6 * k..].copy_from_slice(&pp[6 * k..]);
                    continue;
                }
                let row = &mut out[k * nv + k..(k + 1) * nv];
                for ((parent, own), entry) in pp[6 * k..].chunks_exact(6).zip(pi[6 * k..].chunks_exact_mut(6)).zip(row) {
                    let (parent, own): (&[f64; 6], &mut [f64; 6]) = (parent.try_into().expect("6"), own.try_into().expect("6"));
                    let m = *entry - dinv * dot6(&u, parent);
                    *entry = m;
                    axpy(own, parent, &s, m);
                }
            }
        }
    }
    // The upper triangle from the lower: entry (r, c), r < c, from (c, r).
    for c in 1..nv {
        for r in 0..c {
            out[c * nv + r] = out[r * nv + c];
        }
    }
}

/// The backward pass at ball joint `i`, its three rows at once: as a one-coordinate joint's with S (6 x 3), U and D⁻¹
/// (3 x 3) from `aba::ball_factors`.
fn ball_backward(model: &Model, data: &mut Data, i: usize, factored: bool, out: &mut [f64]) {
    let (k, nv, p) = (model.idx_v(i), model.nv(), model.parent(i));
    let own = k..k + 3;
    let (s, u, d_inv) = ball_factors(&data.centred_m_i[i], &data.inertia[i], &model.armature()[own.clone()]);
    for r in own.clone() {
        out[r * nv + k..(r + 1) * nv].fill(0.0);
    }
    let (fp, fi) = sets(&mut data.force_sets, p, i);
    for columns in model.subtree_columns(i) {
        for c in columns.clone() {
            // F_i is zero on i's own columns (its storage may hold the last forward pass's P_i).
            let (m, passed) = if own.contains(&c) {
                let m = d_inv.column(c - k).into_owned();
                (m, u * m)
            } else {
                let from = Vector6::from_column_slice(chunk(fi, c));
                let m = -(d_inv * s.tr_mul(&from));
                (m, from + u * m)
            };
            for r in 0..3 {
                out[(k + r) * nv + c] = m[r];
            }
            fp[6 * c..6 * c + 6].copy_from_slice(passed.as_slice());
        }
    }
    if !factored {
        let (head, tail) = data.inertia.split_at_mut(i);
        head[p] += tail[0] - u * d_inv * u.transpose();
    }
}

/// The forward pass at ball joint `i`: its rows less D⁻¹ Uᵀ P_parent, then P_i = S M⁻¹_i + P_parent.
fn ball_forward(model: &Model, data: &mut Data, i: usize, out: &mut [f64]) {
    let (k, nv, p) = (model.idx_v(i), model.nv(), model.parent(i));
    let (s, u, d_inv) = ball_factors(&data.centred_m_i[i], &data.inertia[i], &model.armature()[k..k + 3]);
    let (pp, pi) = sets(&mut data.force_sets, p, i);
    for c in k..nv {
        let parent = Vector6::from_column_slice(chunk(pp, c));
        let m = Vector3::from_fn(|r, _| out[(k + r) * nv + c]) - d_inv * u.tr_mul(&parent);
        for r in 0..3 {
            out[(k + r) * nv + c] = m[r];
        }
        pi[6 * c..6 * c + 6].copy_from_slice((parent + s * m).as_slice());
    }
}
