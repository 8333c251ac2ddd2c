//! `Data`, the workspace every algorithm writes into (allocated once per model, as in Pinocchio), and the
//! fallible sizing of its dense parts.

use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX, Vector6};

use super::workspaces::{ContactWorkspace, Derivatives};
use super::Model;
use crate::spatial::{Force, Inertia, Motion, RigidInertia, Transform};
use crate::validate::{array_len, filled, with_capacity};
use crate::{MassProperties, Result};

/// Every intermediate of the algorithms, sized for one model; each field has one meaning, whichever
/// algorithm writes it. Per-body quantities are in body frames, except those named for the world (`o_`)
/// and those of the world-frame recursions (ABA, CRBA, Minv), which work in the *centred* frame: the
/// world's axes at the base's origin (`kinematics::base_centred_kinematics`).
#[derive(Debug, Clone)]
pub struct Data {
    /// Pose of each body in its parent (RNEA, centroidal momentum).
    pub li_m_i: Vec<Transform>,
    /// Pose of each body in the world.
    pub o_m_i: Vec<Transform>,
    /// Pose of each body in the centred frame (ABA, CRBA, Minv).
    pub centred_m_i: Vec<Transform>,
    /// Velocity, acceleration and net force of each body in its own frame (RNEA, centroidal momentum,
    /// energy, contact).
    pub v: Vec<Motion>,
    /// Acceleration of each body in its own frame.
    pub a: Vec<Motion>,
    /// Net force on each body in its own frame (after RNEA's backward pass, on its subtree).
    pub f: Vec<Force>,
    /// Velocity and acceleration of each body in the centred frame (ABA; the acceleration with gravity as
    /// a base acceleration).
    pub centred_v: Vec<Motion>,
    /// Acceleration of each body in the centred frame, gravity included as a base acceleration.
    pub centred_a: Vec<Motion>,
    /// Velocity-product acceleration of each joint (the `c` of Table 7.1; centred frame).
    pub c: Vec<Motion>,
    /// Articulated-body inertias (ABA, Minv; centred frame).
    pub inertia: Vec<Inertia>,
    /// Each body's own rigid inertia (ABA; centred frame).
    pub rigid: Vec<Inertia>,
    /// Composite-rigid-body inertias (CRBA; centred frame).
    pub composite: Vec<RigidInertia>,
    /// Articulated bias forces (ABA; centred frame).
    pub bias: Vec<Force>,
    /// Motion subspace of each one-degree-of-freedom joint in the centred frame (ABA, CRBA, Minv).
    pub s: Vec<Motion>,
    /// `U = I^A S` and `D⁻¹ = (Sᵀ U)⁻¹` of one-degree-of-freedom joints.
    pub u: Vec<Vector6<f64>>,
    /// `D⁻¹ = (Sᵀ U)⁻¹` of each one-degree-of-freedom joint [Featherstone 2008, Table 7.1].
    pub d_inv: Vec<f64>,
    /// Mass properties of the subtree rooted at each body, in world coordinates.
    pub subtree: Vec<MassProperties>,
    /// A frame Jacobian, 6 x nv.
    pub jacobian: Matrix6xX<f64>,
    /// The centroidal momentum matrix A_G, 6 x nv.
    pub centroidal_map: Matrix6xX<f64>,
    /// The centre of mass's Jacobian ∂c/∂q, 3 x nv (world axes, q on its tangent space).
    pub com_jacobian: Matrix3xX<f64>,
    /// Generalized forces (nv), the output of `rnea`.
    pub tau: DVector<f64>,
    /// Generalized accelerations (nv), the output of `aba`.
    pub ddq: DVector<f64>,
    /// M and M⁻¹ (nv x nv), sized by the first `crba` and `minv` call: the O(n) algorithms need neither, and a
    /// large model should not hold them (a 20,000-link chain's would take 6.4 GB).
    pub mass_matrix: DMatrix<f64>,
    /// M⁻¹ (nv x nv), the output of `minv`.
    pub minv: DMatrix<f64>,
    /// Per-body 6 x nv force (then motion) sets of the inverse-mass-matrix recursion; sized by its
    /// first call, since only `minv` needs these O(n nv) numbers.
    pub(crate) force_sets: Vec<Matrix6xX<f64>>,
    /// The derivative algorithms' workspace and outputs, sized by their first call.
    pub(crate) derivatives: Derivatives,
    /// The contact kernels' k-dependent matrices, sized by their first call.
    pub(crate) contact: ContactWorkspace,
    /// The id of the model that built it (`Model::id`): a checked entry point refuses another model's.
    pub(crate) model: u64,
}

/// `reserve_square` with fallible allocation (n x n checked by the caller): `Error::TooLarge` naming the
/// model instead of an abort.
fn try_reserve_square(matrix: &mut DMatrix<f64>, n: usize) -> Result<()> {
    if matrix.shape() != (n, n) {
        *matrix = DMatrix::from_vec(n, n, filled("model", n * n, 0.0)?);
    }
    Ok(())
}

/// A dense part of `Data` (nv x nv, or nbodies x 6 x nv), which the kernels that need it size on their first
/// call: 3.2 GB per nv x nv matrix on a 20,000-link chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dense {
    /// M (`crba`).
    MassMatrix,
    /// M⁻¹ and its recursion's per-body force sets (`minv`, and what solves with M⁻¹).
    Inverse,
    /// The RNEA derivatives' ∂τ/∂q and ∂τ/∂v.
    RneaDerivatives,
    /// The ABA derivatives' ∂q̈/∂q and ∂q̈/∂v.
    AbaDerivatives,
    /// The RNEA's four nv x nv x nv second-derivative tensors.
    SecondOrder,
    /// The derivative algorithms' O(n) workspace (`Data::derivatives` less its outputs), which every derivative
    /// kernel and the contact kernels use; included in the three parts above.
    Workspace,
}

impl Data {
    /// Sizes the dense `parts` for `model` as their kernels would on their first call, but with fallible
    /// allocation: `Error::TooLarge` (naming the model) where the kernels would abort the process. Callers that
    /// take sizes from untrusted input reserve first.
    pub fn reserve_dense(&mut self, model: &Model, parts: &[Dense]) -> Result<()> {
        let (n, nv) = (model.nbodies(), model.nv());
        // Counted in squares and force sets first: a workspace already sized returns at once.
        let unsized_square = |m: &DMatrix<f64>| usize::from(m.shape() != (nv, nv));
        let d = &self.derivatives;
        let (squares, sets) = parts.iter().fold((0, 0), |(squares, sets), part| match part {
            Dense::MassMatrix => (squares + unsized_square(&self.mass_matrix), sets),
            Dense::Inverse => (squares + unsized_square(&self.minv), sets + usize::from(self.force_sets.len() != n)),
            Dense::RneaDerivatives => (squares + unsized_square(&d.dtau_dq) + unsized_square(&d.dtau_dv), sets),
            Dense::AbaDerivatives => (squares + unsized_square(&d.ddq_dq) + unsized_square(&d.ddq_dv), sets),
            Dense::SecondOrder | Dense::Workspace => (squares, sets),
        });
        let cube = array_len("model", &[nv, nv, nv], std::mem::size_of::<f64>())?;
        let cubes = if parts.contains(&Dense::SecondOrder) && d.second_order.dqdq.len() != cube { 4 } else { 0 };
        if parts.iter().any(|part| matches!(part, Dense::Workspace | Dense::RneaDerivatives | Dense::AbaDerivatives | Dense::SecondOrder)) {
            self.derivatives.try_reserve(model)?;
        }
        if squares + sets + cubes == 0 {
            return Ok(());
        }
        let square = array_len("model", &[nv, nv], std::mem::size_of::<f64>())?;
        let set = array_len("model", &[n, 6, nv], std::mem::size_of::<f64>())?;
        let needed = square.saturating_mul(squares).saturating_add(set.saturating_mul(sets)).saturating_add(cube.saturating_mul(cubes));
        // Asked for as one block first, which the allocator refuses at once if it cannot hold it all, before
        // gigabytes of it are written and then given up.
        drop(with_capacity::<f64>("model", needed)?);
        for part in parts {
            match part {
                Dense::MassMatrix => try_reserve_square(&mut self.mass_matrix, nv)?,
                Dense::Inverse => {
                    try_reserve_square(&mut self.minv, nv)?;
                    if self.force_sets.len() != n {
                        let mut sets = with_capacity("model", n)?;
                        for _ in 0..n {
                            sets.push(Matrix6xX::from_vec(filled("model", 6 * nv, 0.0)?));
                        }
                        self.force_sets = sets;
                    }
                }
                Dense::SecondOrder => {
                    let t = &mut self.derivatives.second_order;
                    for tensor in [&mut t.dqdq, &mut t.dvdv, &mut t.dqdv, &mut t.dadq] {
                        if tensor.len() != cube {
                            *tensor = filled("model", cube, 0.0)?;
                        }
                    }
                }
                Dense::Workspace => {}
                Dense::RneaDerivatives | Dense::AbaDerivatives => {
                    let d = &mut self.derivatives;
                    let (a, b) = if *part == Dense::RneaDerivatives { (&mut d.dtau_dq, &mut d.dtau_dv) } else { (&mut d.ddq_dq, &mut d.ddq_dv) };
                    try_reserve_square(a, nv)?;
                    try_reserve_square(b, nv)?;
                }
            }
        }
        Ok(())
    }

    /// A workspace for `model`, its per-body parts sized; the dense ones wait for the kernels that need them
    /// (see [`Dense`]).
    pub fn new(model: &Model) -> Self {
        let n = model.nbodies();
        Data {
            li_m_i: vec![Transform::identity(); n],
            o_m_i: vec![Transform::identity(); n],
            centred_m_i: vec![Transform::identity(); n],
            v: vec![Motion::zeros(); n],
            a: vec![Motion::zeros(); n],
            f: vec![Force::zeros(); n],
            centred_v: vec![Motion::zeros(); n],
            centred_a: vec![Motion::zeros(); n],
            c: vec![Motion::zeros(); n],
            inertia: vec![Inertia::zeros(); n],
            rigid: vec![Inertia::zeros(); n],
            composite: vec![RigidInertia::zeros(); n],
            bias: vec![Force::zeros(); n],
            s: vec![Motion::zeros(); n],
            u: vec![Vector6::zeros(); n],
            d_inv: vec![0.0; n],
            subtree: vec![MassProperties::zero(); n],
            jacobian: Matrix6xX::zeros(model.nv()),
            centroidal_map: Matrix6xX::zeros(model.nv()),
            com_jacobian: Matrix3xX::zeros(model.nv()),
            tau: DVector::zeros(model.nv()),
            ddq: DVector::zeros(model.nv()),
            mass_matrix: DMatrix::zeros(0, 0),
            minv: DMatrix::zeros(0, 0),
            force_sets: Vec::new(),
            derivatives: Derivatives::default(),
            contact: Default::default(),
            model: model.id(),
        }
    }
}
