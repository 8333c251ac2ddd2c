//! Analytic derivatives of forward dynamics (Carpentier & Mansard, RSS 2018; Pinocchio's `computeABADerivatives`):
//! q̈ = ABA(q, q̇, τ) solves RNEA(q, q̇, q̈) = τ, so ∂q̈/∂q = −M⁻¹ ∂τ/∂q and ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇ at that q̈, and
//! ∂q̈/∂τ = M⁻¹ (with the model's armature in M).
//!
//! The products by M⁻¹ run where ∂τ is sparse (a branched tree), else solves with the articulated-body factors ABA
//! leaves behind (`aba_derivatives_into`); the outputs can be written in place (`aba_derivatives_into`), with O(n)
//! workspace beyond them.

use nalgebra::{DMatrix, DVector};

use super::aba::{solve_columns, Factors};
use super::aba_unchecked;
use super::checks::{check_forces, check_output, check_state, finite_dynamics};
use super::minv::minv_after_aba_into;
use super::rnea_derivatives::{derivatives_into, lend_squares};
use crate::model::Dense;
use crate::model::BLOCK;
use crate::model::{Data, Model};
use crate::spatial::Force;
use crate::Result;

/// Criterion `derivatives/aba`: with dense products the quadruped (nv 18) took 0.70x the solves' time, the 63-DoF
/// tree 1.33x; in proportion to the products' work (nv per nonzero of ∂τ), they cross between 26 and 47 nonzeros per
/// column of ∂τ (`by_products`).
const DENSE_LIMIT: usize = 32;

/// ∂q̈/∂q, ∂q̈/∂q̇ and ∂q̈/∂τ = M⁻¹ (nv x nv; q on its tangent space) at configuration `q`, velocity `v` and joint
/// forces `tau`, with `f_ext` as in `aba`. Leaves q̈ in `data.ddq`, the first two in `data.derivatives.ddq_dq` and
/// `ddq_dv`, and M⁻¹ (by `minv`'s passes on ABA's factors) in `data.minv`.
///
/// # Examples
///
/// ∂q̈/∂q and ∂q̈/∂q̇ of a double pendulum (two 1 kg links 0.4 m long, hinged about y; built in the hidden lines)
/// against central differences of `aba`, and ∂q̈/∂τ = M⁻¹; `aba_derivatives_into` writes the same numbers into the
/// caller's slices.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
/// # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
/// # let mut model = Model::new(false, MassProperties::zero(), "base");
/// # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
/// # let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
/// # model.add_body(1, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
/// # let mut data = Data::new(&model);
/// # let nudge = |x: [f64; 2], k: usize, step: f64| { let mut x = x; x[k] += step; x };
/// let (q, v, tau, h) = ([0.3, -0.5], [1.0, 2.0], [0.4, -0.1], 1e-6);
/// let (ddq_dq, ddq_dv, ddq_dtau) = algorithms::aba_derivatives(&model, &mut data, &q, &v, &tau, None)?;
/// let (ddq_dq, ddq_dv, ddq_dtau) = (ddq_dq.clone(), ddq_dv.clone(), ddq_dtau.clone());
/// assert!((&ddq_dtau * algorithms::crba(&model, &mut data, &q)? - DMatrix::identity(2, 2)).amax() < 1e-12);
/// for k in 0..2 {
///     let plus = algorithms::aba(&model, &mut data, &nudge(q, k, h), &v, &tau, None)?.clone();
///     let by_q = (plus - algorithms::aba(&model, &mut data, &nudge(q, k, -h), &v, &tau, None)?) / (2.0 * h);
///     let plus = algorithms::aba(&model, &mut data, &q, &nudge(v, k, h), &tau, None)?.clone();
///     let by_v = (plus - algorithms::aba(&model, &mut data, &q, &nudge(v, k, -h), &tau, None)?) / (2.0 * h);
///     assert!((ddq_dq.column(k) - by_q).norm() < 1e-7 && (ddq_dv.column(k) - by_v).norm() < 1e-7);
/// }
/// // A model this small takes M⁻¹ from Minv's recursion.
/// assert!(algorithms::minv_by_recursion(&model));
/// let (mut into_q, mut into_v, mut minv) = ([0.0; 4], [0.0; 4], [0.0; 4]);
/// algorithms::aba_derivatives_into(&model, &mut data, &q, &v, &tau, None, &mut into_q, &mut into_v, &mut minv)?;
/// assert!(into_q == ddq_dq.as_slice() && into_v == ddq_dv.as_slice() && minv == ddq_dtau.as_slice());
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn aba_derivatives<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>,
) -> Result<(&'d DMatrix<f64>, &'d DMatrix<f64>, &'d DMatrix<f64>)> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_forces(model, f_ext)?;
    data.reserve_dense(model, &[Dense::AbaDerivatives, Dense::Inverse])?;
    lend_squares(
        model,
        data,
        |d| [&mut d.derivatives.ddq_dq, &mut d.derivatives.ddq_dv, &mut d.minv],
        |data, [dq, dv, minv]| {
            aba_derivatives_into_unchecked(model, data, q, v, tau, f_ext, dq, dv, minv);
        },
    );
    // M⁻¹ is positive definite: a singular M shows on its diagonal, and spreads to the other two.
    for matrix in [&data.derivatives.ddq_dq, &data.derivatives.ddq_dv, &data.minv] {
        finite_dynamics(model, data, matrix.as_slice())?;
    }
    Ok((&data.derivatives.ddq_dq, &data.derivatives.ddq_dv, &data.minv))
}

/// `aba_derivatives` into `ddq_dq`, `ddq_dv` and `minv` (nv x nv each, column-major; every entry written) instead of
/// `Data`. ∂τ/∂q and ∂τ/∂q̇ are formed in the first two and turned into −M⁻¹ ∂τ in place, so the only workspace
/// beyond the outputs is O(n) (and M⁻¹'s recursion's force sets on small models, `minv_by_recursion`).
///
/// −M⁻¹ ∂τ runs as products by M⁻¹ where ∂τ is sparse enough, else as solves with the articulated-body factors ABA
/// leaves behind (`aba::solve_columns`: O(n) per column, O(n nv) per matrix), which are also backward stable where
/// the dense product loses digits to M's condition number. Column j of ∂τ is nonzero only on the coordinates of j's
/// ancestors and of its subtree [Carpentier & Mansard 2018], so on a branched tree a product costs far less than
/// nv³: nv per nonzero of ∂τ. (MuJoCo likewise works dense below 60 degrees of freedom.)
#[allow(clippy::too_many_arguments)]
pub fn aba_derivatives_into(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>, ddq_dq: &mut [f64], ddq_dv: &mut [f64],
    minv: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_forces(model, f_ext)?;
    let nv = model.nv();
    check_output("ddq_dq", ddq_dq, nv * nv)?;
    check_output("ddq_dv", ddq_dv, nv * nv)?;
    check_output("minv", minv, nv * nv)?;
    // M⁻¹'s recursion's force sets (and M⁻¹'s own square, which stays unused) on the models that use them.
    let dense: &[Dense] = if minv_by_recursion(model) { &[Dense::Inverse, Dense::Workspace] } else { &[Dense::Workspace] };
    data.reserve_dense(model, dense)?;
    aba_derivatives_into_unchecked(model, data, q, v, tau, f_ext, ddq_dq, ddq_dv, minv);
    // M⁻¹ is positive definite: a singular M shows on its diagonal, and spreads to the other two.
    for matrix in [&*ddq_dq, &*ddq_dv, &*minv] {
        finite_dynamics(model, data, matrix)?;
    }
    Ok(())
}

/// [`aba_derivatives_into`] without its checks, for `aba_derivatives`' own outputs.
#[allow(clippy::too_many_arguments)]
pub(crate) fn aba_derivatives_into_unchecked(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>, ddq_dq: &mut [f64], ddq_dv: &mut [f64],
    minv: &mut [f64],
) {
    let nv = model.nv();
    let square = nv * nv;
    assert!(ddq_dq.len() == square && ddq_dv.len() == square && minv.len() == square, "aba_derivatives_into: outputs of nv x nv");
    aba_unchecked(model, data, q, v, tau, f_ext);
    // An empty vector holds no allocation: q̈ is lent to the RNEA derivatives and put back.
    let ddq = std::mem::replace(&mut data.ddq, DVector::zeros(0));
    // On ABA's poses (same q): the forward pass composes no transform again.
    derivatives_into::<true>(model, data, q, v, ddq.as_slice(), f_ext, model.gravity_bias(), ddq_dq, ddq_dv);
    data.ddq = ddq;
    if minv_by_recursion(model) {
        minv_after_aba_into(model, data, minv);
    }
    let Data { centred_m_i, inertia, s, u, d_inv, derivatives: d, .. } = data;
    let factors = Factors { poses: centred_m_i, inertia, s, u, d_inv };
    if !minv_by_recursion(model) {
        minv.fill(0.0);
        minv.iter_mut().step_by(nv + 1).for_each(|x| *x = 1.0);
        solve_columns(model, &factors, minv, &mut d.block_rows, &mut d.block_forces, &mut d.block_accelerations);
    }
    if by_products(model) {
        negated_product_in_place(minv, ddq_dq, &mut d.block_rows);
        negated_product_in_place(minv, ddq_dv, &mut d.block_rows);
        return;
    }
    ddq_dq.iter_mut().chain(ddq_dv.iter_mut()).for_each(|x| *x = -*x);
    for out in [ddq_dq, ddq_dv] {
        solve_columns(model, &factors, out, &mut d.block_rows, &mut d.block_forces, &mut d.block_accelerations);
    }
}

/// The most numbers `minv`'s recursion may hold in its per-body force sets (6 n nv) for `aba_derivatives_into`,
/// 1 MB: beyond, M⁻¹ comes from solves with the identity (`aba::solve_columns`, O(n) workspace), which measured
/// slower on chain64 (0.68x Pinocchio's time against 0.62x) and no slower on chain512.
const FORCE_SETS_LIMIT: usize = 1 << 17;

/// Whether `aba_derivatives_into` takes M⁻¹ from `minv`'s recursion, whose force sets `Dense::Inverse` reserves.
pub fn minv_by_recursion(model: &Model) -> bool {
    6 * model.nbodies() * model.nv() <= FORCE_SETS_LIMIT
}

/// Whether `aba_derivatives_into` forms −M⁻¹ ∂τ as products by M⁻¹ rather than by solves: where ∂τ has at most `DENSE_LIMIT` nonzeros per column on
/// average. Column j's nonzeros are its ancestors' and its subtree's coordinates, so their count is
/// Σ_j (ancestors' + subtree's) = 2 Σ_i nv_i · (i's subtree's coordinates) − Σ_i nv_i² (each ancestor pair counted from
/// both ends, a joint's own block twice), O(n) by the subtrees' column ranges.
pub(crate) fn by_products(model: &Model) -> bool {
    let nv = model.nv();
    if nv <= DENSE_LIMIT {
        return true;
    }
    let mut nonzeros = 0;
    for i in 0..model.nbodies() {
        let own = model.joint(i).nv();
        let subtree: usize = model.subtree_columns(i).iter().map(|r| r.len()).sum();
        nonzeros += 2 * own * subtree - own * own;
    }
    nonzeros <= DENSE_LIMIT * nv
}

/// `b = −a b` in place for square matrices (column-major), four columns of `b` at a time into `block` (nv rows of
/// `BLOCK`, the solves' buffer): each column of `a` is read once for the four and skipped where the four's entries
/// are zero (the sparsity of ∂τ), without the packing buffers a general matrix product allocates.
fn negated_product_in_place(a: &[f64], b: &mut [f64], block: &mut [[f64; BLOCK]]) {
    const WIDTH: usize = 4;
    let n = block.len();
    if n == 0 {
        return;
    }
    for columns in b.chunks_mut(WIDTH * n) {
        let width = columns.len() / n;
        for row in block.iter_mut() {
            row[..WIDTH].fill(0.0);
        }
        for (k, a_k) in a.chunks_exact(n).enumerate() {
            let f: [f64; WIDTH] = std::array::from_fn(|c| if c < width { -columns[c * n + k] } else { 0.0 });
            if f == [0.0; WIDTH] {
                continue;
            }
            for (x, row) in a_k.iter().zip(block.iter_mut()) {
                for c in 0..WIDTH {
                    row[c] += f[c] * x;
                }
            }
        }
        for (c, column) in columns.chunks_exact_mut(n).enumerate() {
            for (y, row) in column.iter_mut().zip(block.iter()) {
                *y = row[c];
            }
        }
    }
}
