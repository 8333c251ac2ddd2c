//! Analytic derivatives of forward dynamics (Carpentier & Mansard, RSS 2018; Pinocchio's `computeABADerivatives`):
//! q̈ = ABA(q, q̇, τ) solves RNEA(q, q̇, q̈) = τ, so ∂q̈/∂q = −M⁻¹ ∂τ/∂q and ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇ at that q̈, and
//! ∂q̈/∂τ = M⁻¹ (with the model's armature in M).
//!
//! The products by M⁻¹ are, up to `DENSE_LIMIT` velocity coordinates, dense products by M⁻¹ (`minv`), as Pinocchio's
//! (O(nv³), in few enough operations to win on a small robot); beyond, solves with the articulated-body factors ABA
//! leaves behind (`aba::solve_columns`: O(n) per column, O(n nv) per matrix), which are also backward stable where the
//! dense product loses digits to M's condition number. (MuJoCo likewise works dense below 60 degrees of freedom.)

use nalgebra::{DMatrix, DVector};

use super::aba::{solve_columns, Factors};
use super::minv::minv_after_aba;
use super::{aba, rnea_derivatives};
use crate::model::{reserve_square, Data, Model};
use crate::spatial::Force;

/// Criterion `derivatives/aba`: with the dense products the quadruped (nv 18) took 0.70x the solves' time, the 63-DoF
/// tree 1.33x; in proportion to nv, they cross between 26 and 47.
const DENSE_LIMIT: usize = 32;

/// ∂q̈/∂q, ∂q̈/∂q̇ and ∂q̈/∂τ = M⁻¹ (nv x nv; q on its tangent space) at configuration `q`, velocity `v` and joint
/// forces `tau`, with `f_ext` as in `aba`. Leaves q̈ in `data.ddq`, the first two in `data.derivatives.ddq_dq` and
/// `ddq_dv`, and M⁻¹ (by `minv`'s passes on ABA's factors) in `data.minv`.
pub fn aba_derivatives<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    f_ext: Option<&[Force]>,
) -> (&'d DMatrix<f64>, &'d DMatrix<f64>, &'d DMatrix<f64>) {
    aba(model, data, q, v, tau, f_ext);
    // An empty vector holds no allocation: q̈ is lent to the RNEA derivatives and put back.
    let ddq = std::mem::replace(&mut data.ddq, DVector::zeros(0));
    rnea_derivatives(model, data, q, v, ddq.as_slice(), f_ext);
    data.ddq = ddq;
    reserve_square(&mut data.derivatives.ddq_dq, model.nv());
    reserve_square(&mut data.derivatives.ddq_dv, model.nv());
    if model.nv() <= DENSE_LIMIT {
        minv_after_aba(model, data);
        let d = &mut data.derivatives;
        negated_product(&data.minv, &d.dtau_dq, &mut d.ddq_dq);
        negated_product(&data.minv, &d.dtau_dv, &mut d.ddq_dv);
        return (&data.derivatives.ddq_dq, &data.derivatives.ddq_dv, &data.minv);
    }
    let Data { centred_m_i, inertia, s, u, d_inv, derivatives: d, .. } = data;
    let factors = Factors { poses: centred_m_i, inertia, s, u, d_inv };
    for (out, dtau) in [(&mut d.ddq_dq, &d.dtau_dq), (&mut d.ddq_dv, &d.dtau_dv)] {
        out.zip_apply(dtau, |x, y| *x = -y);
        solve_columns(model, &factors, out.as_mut_slice(), &mut d.block_rows, &mut d.block_forces, &mut d.block_accelerations);
    }
    minv_after_aba(model, data);
    (&data.derivatives.ddq_dq, &data.derivatives.ddq_dv, &data.minv)
}

/// `out = −a b` for square matrices, four columns of `out` at a time (each column of `a` read once for the four,
/// contiguous columns the compiler vectorises), without the packing buffers a general matrix product allocates.
fn negated_product(a: &DMatrix<f64>, b: &DMatrix<f64>, out: &mut DMatrix<f64>) {
    let n = a.nrows();
    if n == 0 {
        return;
    }
    let (a, b, out) = (a.as_slice(), b.as_slice(), out.as_mut_slice());
    out.fill(0.0);
    for (block, columns) in out.chunks_mut(4 * n).enumerate() {
        let j0 = 4 * block;
        if columns.len() == 4 * n {
            let (c0, rest) = columns.split_at_mut(n);
            let (c1, rest) = rest.split_at_mut(n);
            let (c2, c3) = rest.split_at_mut(n);
            for (k, a_k) in a.chunks_exact(n).enumerate() {
                let f = [-b[j0 * n + k], -b[(j0 + 1) * n + k], -b[(j0 + 2) * n + k], -b[(j0 + 3) * n + k]];
                for ((((x, y0), y1), y2), y3) in a_k.iter().zip(c0.iter_mut()).zip(c1.iter_mut()).zip(c2.iter_mut()).zip(c3.iter_mut()) {
                    *y0 += f[0] * x;
                    *y1 += f[1] * x;
                    *y2 += f[2] * x;
                    *y3 += f[3] * x;
                }
            }
        } else {
            for (jj, column) in columns.chunks_exact_mut(n).enumerate() {
                for (k, a_k) in a.chunks_exact(n).enumerate() {
                    let factor = -b[(j0 + jj) * n + k];
                    for (x, y) in column.iter_mut().zip(a_k) {
                        *x += factor * y;
                    }
                }
            }
        }
    }
}
