//! Analytic derivatives of forward dynamics (Carpentier & Mansard, RSS 2018; Pinocchio's `computeABADerivatives`):
//! q̈ = ABA(q, q̇, τ) solves RNEA(q, q̇, q̈) = τ, so ∂q̈/∂q = −M⁻¹ ∂τ/∂q and ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇ at that q̈, and
//! ∂q̈/∂τ = M⁻¹ (with the model's armature in M).
//!
//! The products by M⁻¹ are solves with the articulated-body factors ABA leaves behind (`aba::solve_columns`):
//! O(n) per column, O(n nv) per matrix, where Pinocchio multiplies by a dense M⁻¹ in O(nv³).

use nalgebra::{DMatrix, DVector};

use super::aba::{solve_columns, Factors};
use super::{aba, minv, rnea_derivatives};
use crate::model::{Data, Model};
use crate::spatial::Force;

/// ∂q̈/∂q, ∂q̈/∂q̇ and ∂q̈/∂τ = M⁻¹ (nv x nv; q on its tangent space) at configuration `q`, velocity `v` and joint
/// forces `tau`, with `f_ext` as in `aba`. Leaves q̈ in `data.ddq`, the first two in `data.derivatives.ddq_dq` and
/// `ddq_dv`, and M⁻¹ (by `minv`) in `data.minv`.
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
    let Data { centred_m_i, inertia, s, u, d_inv, derivatives: d, .. } = data;
    let factors = Factors { poses: centred_m_i, inertia, s, u, d_inv };
    for (out, dtau) in [(&mut d.ddq_dq, &d.dtau_dq), (&mut d.ddq_dv, &d.dtau_dv)] {
        out.zip_apply(dtau, |x, y| *x = -y);
        solve_columns(model, &factors, out.as_mut_slice(), &mut d.block_rows, &mut d.block_forces, &mut d.block_accelerations);
    }
    minv(model, data, q);
    (&data.derivatives.ddq_dq, &data.derivatives.ddq_dv, &data.minv)
}
