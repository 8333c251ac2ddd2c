//! The inverse of the joint-space mass matrix by the articulated-body recursion (Carpentier 2018,
//! "Analytical inverse of the joint space inertia matrix"; Pinocchio's `computeMinverse`), never forming
//! or factorising M.
//!
//! Worked in world coordinates: articulated inertias, the force sets F_i (τ ↦ bias force of subtree i) and
//! the motion sets P_i (τ ↦ acceleration of body i) pass between bodies without transforms, so each
//! (body, column) pair costs a few 6-vector operations. Row i of the upper triangle is kept in column i
//! (the lower triangle), where it is contiguous.

use nalgebra::{DMatrix, Matrix6xX, Vector6};

use super::forward_kinematics;
use crate::model::{Data, Joint, Model};
use crate::spatial::Inertia;

/// Columns `from..` of body `i`'s set and its parent's, as 6-vector chunks (`parent < i`).
fn sets(data: &mut [Matrix6xX<f64>], parent: usize, i: usize, from: usize) -> (&mut [f64], &mut [f64]) {
    let (head, tail) = data.split_at_mut(i);
    (&mut head[parent].as_mut_slice()[6 * from..], &mut tail[0].as_mut_slice()[6 * from..])
}

#[inline]
fn dot(a: &Vector6<f64>, b: &[f64]) -> f64 {
    let b: &[f64; 6] = b.try_into().expect("a 6-vector chunk");
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

/// `out = base + x m`, 6-vectors.
#[inline]
fn axpy(out: &mut [f64], base: &[f64], x: &Vector6<f64>, m: f64) {
    let (out, base): (&mut [f64; 6], &[f64; 6]) = (out.try_into().expect("6"), base.try_into().expect("6"));
    for r in 0..6 {
        out[r] = base[r] + x[r] * m;
    }
}

/// Fills `data.minv` (both triangles) with M(q)⁻¹ and returns it.
pub fn minv<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    let (n, nv) = (model.nbodies(), model.nv());
    if data.force_sets.len() != n {
        data.force_sets = vec![Matrix6xX::zeros(nv); n];
    }
    forward_kinematics(model, data, q);
    for i in 0..n {
        data.inertia[i] = data.o_m_i[i].act_rigid_inertia(model.inertia(i)).matrix();
        if let Some(s) = model.joint(i).axis_motion() {
            data.s[i] = data.o_m_i[i].act_motion(&s);
        }
        let (k, end) = (model.idx_v(i), model.subtree_v_end(i));
        data.force_sets[i].as_mut_slice()[6 * k..6 * end].fill(0.0);
    }
    // Backward pass: the rows' subtree parts D⁻¹(e_i − Sᵀ F_i), then F_i += U M⁻¹_i goes to the parent
    // together with the articulated inertia I^A − U D⁻¹ Uᵀ.
    for i in (0..n).rev() {
        let (k, end) = (model.idx_v(i), model.subtree_v_end(i));
        match model.joint(i) {
            Joint::FreeFlyer => {
                // S = X_0 (the base frame), so D = X_0ᵀ I^A X_0 is the inertia in the base frame.
                let base = data.o_m_i[0];
                let dinv = base.inverse().act_inertia(&data.inertia[0]).try_inverse().unwrap_or_else(|| Inertia::repeat(f64::NAN));
                data.minv.view_mut((0, 0), (6, 6)).copy_from(&dinv);
                for col in 6..nv {
                    let f = Vector6::from_column_slice(&data.force_sets[0].as_slice()[6 * col..6 * col + 6]);
                    data.minv.view_mut((col, 0), (1, 6)).copy_from(&(-dinv * base.inv_act_force(&f)).transpose());
                }
            }
            Joint::Fixed => {}
            Joint::Revolute(_) | Joint::Prismatic(_) => {
                let (s, ia) = (data.s[i], data.inertia[i]);
                let u = ia * s;
                let dinv = 1.0 / s.dot(&u);
                let row = &mut data.minv.as_mut_slice()[k * nv + k..(k + 1) * nv];
                // Beyond the subtree F_i is zero, and so is this part of the row until the forward pass.
                row[end - k..].fill(0.0);
                let f = &mut data.force_sets[i].as_mut_slice()[6 * k..6 * end];
                for (c, (column, entry)) in f.chunks_exact_mut(6).zip(row.iter_mut()).enumerate() {
                    let m = if c == 0 { dinv } else { -dinv * dot(&s, column) };
                    *entry = m;
                    let before: [f64; 6] = (&*column).try_into().expect("6");
                    axpy(column, &before, &u, m);
                }
                data.inertia[i] = ia - u * u.transpose() * dinv;
                data.u[i] = u;
                data.d[i] = 1.0 / dinv;
            }
        }
        if i > 0 {
            let p = model.parent(i);
            let ia = data.inertia[i];
            data.inertia[p] += ia;
            let (fp, fi) = sets(&mut data.force_sets, p, i, k);
            let span = 6 * (end - k);
            fp[..span].iter_mut().zip(fi[..span].iter()).for_each(|(a, b)| *a += b);
        }
    }
    // Forward pass: subtract D⁻¹ Uᵀ P_parent, then P_i = S M⁻¹_i + P_parent (reusing the sets' storage).
    for i in 0..n {
        let k = model.idx_v(i);
        match model.joint(i) {
            Joint::FreeFlyer => {
                let base = data.o_m_i[0];
                for col in 0..nv {
                    let m = Vector6::from_fn(|r, _| data.minv[(col.max(r), col.min(r))]);
                    data.force_sets[0].set_column(col, &base.act_motion(&m));
                }
            }
            Joint::Fixed if i == 0 => data.force_sets[0].fill(0.0),
            joint => {
                let p = model.parent(i);
                let (s, u, dinv) = (data.s[i], data.u[i], 1.0 / data.d[i]);
                let (pp, pi) = sets(&mut data.force_sets, p, i, k);
                if matches!(joint, Joint::Fixed) {
                    pi.copy_from_slice(pp);
                    continue;
                }
                let row = &mut data.minv.as_mut_slice()[k * nv + k..(k + 1) * nv];
                for ((parent, own), entry) in pp.chunks_exact(6).zip(pi.chunks_exact_mut(6)).zip(row.iter_mut()) {
                    let m = *entry - dinv * dot(&u, parent);
                    *entry = m;
                    axpy(own, parent, &s, m);
                }
            }
        }
    }
    data.minv.fill_upper_triangle_with_lower_triangle();
    &data.minv
}
