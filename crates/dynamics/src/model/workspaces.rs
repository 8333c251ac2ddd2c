//! The workspaces `Data` holds for the derivative and contact kernels (sized by their first call), and the
//! square matrices they share.

use nalgebra::{DMatrix, Matrix6xX};

use super::Model;
use crate::spatial::{Force, Motion, RateMatrix, RigidInertia};
use crate::validate::{array_len, filled};
use crate::Result;

/// Right-hand sides `aba::solve_columns` takes at once: its per-body work runs across them as short vectors.
pub(crate) const BLOCK: usize = 8;

/// A 6-vector per column of a block, stored row by row.
pub(crate) type Block6 = [[f64; BLOCK]; 6];

/// The RNEA's second derivatives (`rnea_second_order_derivatives`): four tensors, each nv³ numbers, entry (i, j, k)
/// at (i nv + j) nv + k (row-major, as NumPy's (nv, nv, nv)): each the slope along its last index of a first
/// derivative: `dqdq` ∂/∂q_k of ∂τ_i/∂q_j, `dvdv` ∂/∂q̇_k of ∂τ_i/∂q̇_j, `dqdv` ∂/∂q̇_k of ∂τ_i/∂q_j and `dadq`
/// ∂/∂q_k of ∂τ_i/∂q̈_j = M_ij (Pinocchio's d2tau_dqdq, d2tau_dvdv, dtau_dqdv and dtau_dadq).
#[derive(Debug, Clone, Default)]
pub struct SecondOrder {
    /// ∂²τ/∂q².
    pub dqdq: Vec<f64>,
    /// ∂²τ/∂q̇².
    pub dvdv: Vec<f64>,
    /// ∂²τ/∂q∂q̇.
    pub dqdv: Vec<f64>,
    /// ∂M/∂q.
    pub dadq: Vec<f64>,
}

/// The contact kernels' k-dependent matrices (column-major), kept in `Data` and reused while r (the constraint rows)
/// and nv stay; sized with fallible allocation, so that too many contacts are a `TooLarge` naming them.
#[derive(Debug, Clone, Default)]
pub(crate) struct ContactWorkspace {
    /// (r, nv) for which the buffers are sized (and the model's bodies).
    pub(crate) shape: (usize, usize),
    pub(crate) bodies: usize,
    /// J (r x nv): the constraint rows, world axes at the points.
    pub(crate) jacobian: Vec<f64>,
    /// γ (r): the rows' velocity-product accelerations; then the right-hand side of a solve.
    pub(crate) drift: Vec<f64>,
    /// M⁻¹ Jᵀ (nv x r).
    pub(crate) minv_jt: Vec<f64>,
    /// S⁻¹ = (J M⁻¹ Jᵀ)⁻¹ (r x r), and the Cholesky factor it is computed from.
    pub(crate) schur_inverse: Vec<f64>,
    pub(crate) schur: Vec<f64>,
    pub(crate) cholesky: Vec<f64>,
    /// Gᵀ = M⁻¹ Jᵀ S⁻¹ (nv x r) and G (r x nv).
    pub(crate) gain_t: Vec<f64>,
    pub(crate) gain: Vec<f64>,
    /// M⁻¹ − M⁻¹ Jᵀ G (nv x nv).
    pub(crate) projected: Vec<f64>,
    /// Right-hand sides of the derivatives' solve: nv x 2nv and r x 2nv.
    pub(crate) rhs_top: Vec<f64>,
    pub(crate) rhs_rows: Vec<f64>,
    /// nv numbers: zero accelerations, then the solution's generalized part.
    pub(crate) zeros: Vec<f64>,
    pub(crate) solution: Vec<f64>,
    /// r numbers: the solution's forces (or impulses).
    pub(crate) forces: Vec<f64>,
    /// nv numbers: an impact's change of velocity.
    pub(crate) change: Vec<f64>,
    /// The forces as external forces on the bodies (`rnea`'s f_ext).
    pub(crate) body_forces: Vec<Force>,
}

impl ContactWorkspace {
    /// Sizes the buffers for r constraint rows on `model`, or `TooLarge` naming the contacts.
    pub(crate) fn reserve(&mut self, model: &Model, r: usize) -> Result<()> {
        let nv = model.nv();
        if self.shape == (r, nv) && self.bodies == model.nbodies() {
            return Ok(());
        }
        let len = |shape: &[usize]| array_len("contacts", shape, std::mem::size_of::<f64>());
        let buffer = |shape: &[usize]| filled("contacts", len(shape)?, 0.0);
        // All at once, so that a refusal leaves the workspace as it was.
        let fresh = ContactWorkspace {
            shape: (r, nv),
            bodies: model.nbodies(),
            jacobian: buffer(&[r, nv])?,
            drift: buffer(&[r])?,
            minv_jt: buffer(&[nv, r])?,
            schur_inverse: buffer(&[r, r])?,
            schur: buffer(&[r, r])?,
            cholesky: buffer(&[r, r])?,
            gain_t: buffer(&[nv, r])?,
            gain: buffer(&[r, nv])?,
            projected: buffer(&[nv, nv])?,
            rhs_top: buffer(&[nv, 2, nv])?,
            rhs_rows: buffer(&[r, 2, nv])?,
            zeros: buffer(&[nv])?,
            solution: buffer(&[nv])?,
            forces: buffer(&[r])?,
            change: buffer(&[nv])?,
            body_forces: filled("contacts", model.nbodies(), Force::zeros())?,
        };
        *self = fresh;
        Ok(())
    }
}

/// The workspace and outputs of the derivative algorithms (`rnea_derivatives`, `aba_derivatives`), in the centred
/// frame (see `Data`). Empty until their first call sizes it, so that a model that is never differentiated does not
/// hold its nv x nv outputs.
#[derive(Debug, Clone, Default)]
pub(crate) struct Derivatives {
    /// Per body: velocity, acceleration with gravity as a base acceleration, and (after the backward pass) the net
    /// force on its subtree less the external forces.
    pub velocity: Vec<Motion>,
    pub acceleration: Vec<Motion>,
    pub force: Vec<Force>,
    /// Per body: the subtree's composite rigid inertia and the sum of its bodies' `RigidInertia::rate_matrix`.
    pub composite: Vec<RigidInertia>,
    pub rate: Vec<RateMatrix>,
    /// Per velocity coordinate (6 x nv): its joint's motion S in the centred frame (a column of the world Jacobian
    /// J), and what a change of that coordinate does to its body: ∂v/∂q, ∂a/∂q, ∂a/∂q̇ (less the rigid motion of
    /// the subtree, which the backward pass adds as J ×*).
    pub subspace: Matrix6xX<f64>,
    pub dv_dq: Matrix6xX<f64>,
    pub da_dq: Matrix6xX<f64>,
    pub da_dv: Matrix6xX<f64>,
    /// Per velocity coordinate (6 x nv): the change of its joint's subtree force with q, q̇ and q̈, and Bᵀ S.
    pub df_dq: Matrix6xX<f64>,
    pub df_dv: Matrix6xX<f64>,
    pub df_da: Matrix6xX<f64>,
    pub rate_subspace: Matrix6xX<f64>,
    /// ∂τ/∂q, ∂τ/∂q̇ (RNEA) and ∂q̈/∂q, ∂q̈/∂q̇ (ABA), nv x nv; q on the tangent space.
    pub dtau_dq: DMatrix<f64>,
    pub dtau_dv: DMatrix<f64>,
    pub ddq_dq: DMatrix<f64>,
    pub ddq_dv: DMatrix<f64>,
    /// The solves by M (`aba::solve_columns`): a block of right-hand sides row by row (nv), and its bias forces and
    /// accelerations per body.
    pub block_rows: Vec<[f64; BLOCK]>,
    pub block_forces: Vec<Block6>,
    pub block_accelerations: Vec<Block6>,
    /// A frame's ∂v/∂q, ∂v/∂q̇ and ∂a/∂q, ∂a/∂q̇, ∂a/∂q̈, and its Jacobian's time derivative (6 x nv each;
    /// `kinematics_derivatives`).
    pub frame_velocity_dq: Matrix6xX<f64>,
    pub frame_velocity_dv: Matrix6xX<f64>,
    pub frame_acceleration_dq: Matrix6xX<f64>,
    pub frame_acceleration_dv: Matrix6xX<f64>,
    pub frame_acceleration_da: Matrix6xX<f64>,
    pub jacobian_rate: Matrix6xX<f64>,
    /// Per velocity coordinate on a frame's support (6 x nv): the world velocity of its joint and the joints after it
    /// (`point_velocity_hessian`).
    pub velocity_after: Matrix6xX<f64>,
    /// Per velocity coordinate on a frame's support (6 x nv, `point_acceleration_hessian`): the world velocity of the
    /// joints before its joint, through it (its own included) and the acceleration terms of its joint and after it.
    pub velocity_before: Matrix6xX<f64>,
    pub velocity_through: Matrix6xX<f64>,
    pub acceleration_after: Matrix6xX<f64>,
    /// ∂h_O/∂q (6 x nv), the momentum about the centred frame's origin (`centroidal_momentum_hessian`).
    pub origin_momentum_dq: Matrix6xX<f64>,
    /// The centroidal derivatives (`centroidal_derivatives`): per body its momentum I v (after the backward pass its
    /// subtree's), and ∂h/∂q, ∂ḣ/∂q, ∂ḣ/∂q̇ (6 x nv, about the centre of mass; ∂ḣ/∂q̈ = A_G is `Data::centroidal_map`).
    pub momentum: Vec<Force>,
    pub dh_dq: Matrix6xX<f64>,
    pub dhdot_dq: Matrix6xX<f64>,
    pub dhdot_dv: Matrix6xX<f64>,
    /// The RNEA's second derivatives (`rnea_second_order_derivatives`), nv³ numbers each, sized on first use.
    pub second_order: SecondOrder,
}

/// Sizes `matrix` n x n unless it already is (its numbers are then to be overwritten).
pub(crate) fn reserve_square(matrix: &mut DMatrix<f64>, n: usize) {
    if matrix.shape() != (n, n) {
        *matrix = DMatrix::zeros(n, n);
    }
}

impl Derivatives {
    /// Sizes the workspace for `model` unless it already is, all but the nv x nv outputs, which the RNEA and ABA
    /// derivatives size on their first call (`reserve_square`): the frame and centroidal derivatives need O(n nv).
    /// The kernels call it on first use, where a refused allocation aborts as a `Vec`'s would; callers that must
    /// not abort reserve first with `Data::reserve_dense` (`Dense::Workspace`), which reports `TooLarge` instead.
    pub(crate) fn reserve(&mut self, model: &Model) {
        if self.try_reserve(model).is_err() {
            std::alloc::handle_alloc_error(std::alloc::Layout::new::<Derivatives>());
        }
    }

    /// `reserve` with fallible allocation: `Error::TooLarge` naming the model, the workspace left as it was.
    pub(super) fn try_reserve(&mut self, model: &Model) -> Result<()> {
        let (n, nv) = (model.nbodies(), model.nv());
        if self.velocity.len() == n && self.subspace.ncols() == nv {
            return Ok(());
        }
        let per_body = |value| filled("model", n, value);
        let columns = || -> Result<Matrix6xX<f64>> {
            Ok(Matrix6xX::from_vec(filled("model", array_len("model", &[6, nv], std::mem::size_of::<f64>())?, 0.0)?))
        };
        let empty = || DMatrix::zeros(0, 0);
        // All at once, so that a refusal leaves the workspace as it was.
        *self = Derivatives {
            velocity: per_body(Motion::zeros())?,
            acceleration: per_body(Motion::zeros())?,
            force: filled("model", n, Force::zeros())?,
            composite: filled("model", n, RigidInertia::zeros())?,
            rate: filled("model", n, RateMatrix::zeros())?,
            subspace: columns()?,
            dv_dq: columns()?,
            da_dq: columns()?,
            da_dv: columns()?,
            df_dq: columns()?,
            df_dv: columns()?,
            df_da: columns()?,
            rate_subspace: columns()?,
            dtau_dq: empty(),
            dtau_dv: empty(),
            ddq_dq: empty(),
            ddq_dv: empty(),
            block_rows: filled("model", nv, [0.0; BLOCK])?,
            block_forces: filled("model", n, [[0.0; BLOCK]; 6])?,
            block_accelerations: filled("model", n, [[0.0; BLOCK]; 6])?,
            frame_velocity_dq: columns()?,
            frame_velocity_dv: columns()?,
            frame_acceleration_dq: columns()?,
            frame_acceleration_dv: columns()?,
            frame_acceleration_da: columns()?,
            jacobian_rate: columns()?,
            velocity_after: columns()?,
            velocity_before: columns()?,
            velocity_through: columns()?,
            acceleration_after: columns()?,
            origin_momentum_dq: columns()?,
            momentum: filled("model", n, Force::zeros())?,
            dh_dq: columns()?,
            dhdot_dq: columns()?,
            dhdot_dv: columns()?,
            second_order: SecondOrder::default(),
        };
        Ok(())
    }
}
