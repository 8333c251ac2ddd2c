//! The algorithms, one per file, each a free function `algorithm(model, data, q, ...)` that writes its
//! intermediates into `data` and allocates nothing. The public functions check their arguments first (`checks`: the
//! `data` is the model's, sizes, finiteness, unit quaternions) and their outputs after (an overflow or a singular mass
//! matrix is `Error::Numerical`), returning the crate's [`Error`](crate::Error) naming the argument; those the crate's
//! own inner loops call (the simulation, the derivatives) have an unchecked twin there, `algorithm_unchecked`.

pub(crate) mod aba;
pub(crate) mod aba_derivatives;
pub(crate) mod centroidal;
pub(crate) mod centroidal_derivatives;
pub(crate) mod centroidal_hessian;
mod checks;
pub(crate) mod com;
pub(crate) mod configuration;
pub(crate) mod contact;
pub(crate) mod contact_derivatives;
pub(crate) mod crba;
pub(crate) mod energy;
pub(crate) mod integrate;
pub(crate) mod jacobian;
pub(crate) mod kinematic_hessian;
pub(crate) mod kinematics;
pub(crate) mod kinematics_derivatives;
pub(crate) mod minv;
pub(crate) mod rnea;
pub(crate) mod rnea_derivatives;
pub(crate) mod rnea_second_order_derivatives;

pub use aba::{aba, aba_with_armature};
pub(crate) use aba::{aba_unchecked, aba_with_armature_unchecked, placement_update_unchecked};
pub use aba_derivatives::{aba_derivatives, aba_derivatives_into, minv_by_recursion};
pub use centroidal::{center_of_mass_jacobian, centroidal_map, centroidal_momentum, centroidal_momentum_rate};
pub use centroidal_derivatives::centroidal_derivatives;
pub use centroidal_hessian::{center_of_mass_hessian, centroidal_momentum_hessian};
pub use checks::{finite_dynamics, finite_result, singular, singular_factor};
pub use com::{center_of_mass, subtree_mass_properties};
pub use configuration::{difference, difference_jacobians, integrate, integrate_jacobians};
pub(crate) use configuration::{integrate_jacobians_unchecked, integrate_unchecked};
pub use contact::{
    check_contacts, contact_dynamics, impact, point_accelerations, reduced_dynamics, ContactDim, ContactDynamics, ContactPoint, ReducedDynamics,
};
pub use contact_derivatives::{
    contact_dynamics_derivatives, contact_dynamics_derivatives_into, impact_derivatives, impact_derivatives_into, ContactDynamicsDerivatives,
    ImpactDerivatives,
};
pub use crba::crba;
pub(crate) use crba::crba_unchecked;
pub use energy::{kinetic_energy, potential_energy};
pub use integrate::{free_rollout, Integrator, Method};
pub use jacobian::{jacobian, Frame};
pub use kinematic_hessian::{kinematic_hessian, point_acceleration_hessian, point_velocity_hessian};
pub use kinematics::forward_kinematics;
pub(crate) use kinematics::forward_kinematics_unchecked;
pub use kinematics_derivatives::{
    frame_acceleration, frame_acceleration_derivatives, frame_velocity, frame_velocity_derivatives, jacobian_time_variation,
    FrameAccelerationDerivatives,
};
pub(crate) use minv::minv as minv_unchecked;
pub use rnea::rnea;
pub(crate) use rnea::rnea_unchecked;
pub(crate) use rnea_derivatives::rnea_derivatives_unchecked;
pub use rnea_derivatives::{rnea_derivatives, rnea_derivatives_into};
pub use rnea_second_order_derivatives::rnea_second_order_derivatives;

use crate::joint::Dofs;
use crate::model::{Data, Dense, Model};
use crate::Result;
use checks::{check_state, finite_dynamics as finite_factor};
use nalgebra::{DMatrix, Vector3};

use crate::spatial::{spatial, Motion, Transform};

/// The inverse of the joint-space mass matrix, M(q)⁻¹ (nv x nv), by the O(n) articulated-body recursion [Carpentier
/// 2018], without forming or factorising M: written to `data.minv` and returned. Errors: `data` of another model, `q`
/// not a configuration of the model; `Error::Numerical` for a singular mass matrix, `Error::TooLarge` for an nv x nv
/// matrix that cannot be allocated. (Checked here rather than in `minv.rs`, whose kernel is being tuned apart.)
///
/// # Examples
///
/// On a double pendulum (two 1 kg links 0.4 m long, hinged about y; built in the hidden lines): M⁻¹ M = I, M from
/// `crba`. A link without mass makes M singular, an error rather than infinities.
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
/// let q = [0.3, -0.5];
/// let mass = algorithms::crba(&model, &mut data, &q)?.clone();
/// let inverse = algorithms::minv(&model, &mut data, &q)?;
/// assert!((inverse * mass - DMatrix::identity(2, 2)).amax() < 1e-12);
///
/// let mut massless = Model::new(false, MassProperties::zero(), "base");
/// massless.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), MassProperties::zero(), "link", JointLimits::NONE)?;
/// let error = algorithms::minv(&massless, &mut Data::new(&massless), &[0.0]).unwrap_err();
/// assert!(error.to_string().starts_with("model: the mass matrix is singular"));
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn minv<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> Result<&'d DMatrix<f64>> {
    check_state(model, data, q, &[])?;
    data.reserve_dense(model, &[Dense::Inverse])?;
    minv_unchecked(model, data, q);
    // M⁻¹ is positive definite, so |M⁻¹_ij| <= sqrt(M⁻¹_ii M⁻¹_jj): a singular M shows on the diagonal.
    finite_factor(model, data, data.minv.as_slice())?;
    Ok(&data.minv)
}

/// The motion across joint `i` for joint velocity `v` (the model's full velocity vector), in body `i`'s frame.
#[inline(always)]
pub(crate) fn joint_motion(model: &Model, i: usize, v: &[f64]) -> Motion {
    let k = model.idx_v(i);
    match model.joint(i).dofs() {
        Dofs::Free => Motion::from_column_slice(&v[k..k + 6]),
        Dofs::Zero => Motion::zeros(),
        Dofs::One(s) => s * v[k],
        Dofs::Ball => spatial(Vector3::zeros(), Vector3::from_column_slice(&v[k..k + 3])),
    }
}

/// `pose` followed by joint `i`'s motion for configuration `q`.
#[inline(always)]
fn after_joint(model: &Model, i: usize, pose: Transform, q: &[f64]) -> Transform {
    model.joint(i).after(pose, &q[model.idx_q(i)..])
}

/// Pose of body `i` in its parent for configuration `q`: its placement followed by the joint's motion.
#[inline(always)]
pub(crate) fn joint_placement(model: &Model, i: usize, q: &[f64]) -> Transform {
    after_joint(model, i, *model.placement(i), q)
}

/// Pose of body `i` in the world, given its parent's: parent ∘ placement ∘ joint motion, composed in that
/// order so that a placement without rotation (the usual case) costs no rotation product.
#[inline(always)]
pub(crate) fn world_pose(model: &Model, i: usize, parent: &Transform, q: &[f64]) -> Transform {
    let placement = model.placement(i);
    let placed = if placement.is_translation() {
        Transform::new(parent.rotation, parent.transform_point(&placement.translation))
    } else {
        parent.compose(placement)
    };
    after_joint(model, i, placed, q)
}
