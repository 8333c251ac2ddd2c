//! From a legkit `Model` to a Rapier world: one rigid body per movable body (bodies on fixed joints are
//! merged into their parent, which keeps the multibody's dense mass matrix small), one multibody joint
//! per revolute or prismatic joint (with the model's position limits as Rapier joint limits), and one
//! collider per body.
//!
//! Frames: the Rapier frame of every jointed body is its legkit body frame. The Rapier frame of the
//! base is the legkit base frame moved to the centre of mass of the base and everything merged into it
//! (a free multibody root integrates its frame origin with the velocity of its centre of mass, so the
//! two must coincide).

use nalgebra::{Matrix3, Vector3};
use rapier3d_f64::math::{Matrix, Vector};
use rapier3d_f64::prelude::{
    CoefficientCombineRule, ColliderBuilder, FrictionModel, GenericJointBuilder, IntegrationParameters, JointAxesMask, JointAxis,
    MassProperties as RapierMass, MultibodyJointHandle, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};

use crate::joint::{Dofs, Joint};
use crate::model::Model;
use crate::spatial::{angular, linear, Transform};
use crate::validate::{array_len, with_capacity};
use crate::{Error, MassProperties, Result};

use crate::geometry::{to_pose, to_vector};
use crate::sim::options::{Options, DEFAULT_FRICTION};
use crate::sim::Ground;

/// Marks the ground collider in `Collider::user_data` (bodies store their legkit index).
pub const GROUND_TAG: u128 = u128::MAX;

/// A one-degree-of-freedom joint as Rapier's multibody has it, read from the joint's motion subspace:
/// rotation about an axis (Rapier's revolute joint) or translation along it (prismatic).
#[derive(Debug, Clone, Copy)]
pub(crate) enum RapierAxis {
    Angular(Vector3<f64>),
    Linear(Vector3<f64>),
}

impl RapierAxis {
    /// The joint's Rapier axis; None for a joint Rapier's multibody does not have (or with no coordinate).
    pub(crate) fn of(joint: &Joint) -> Option<RapierAxis> {
        match joint.dofs() {
            Dofs::One(s) if linear(&s) == Vector3::zeros() => Some(RapierAxis::Angular(angular(&s))),
            Dofs::One(s) if angular(&s) == Vector3::zeros() => Some(RapierAxis::Linear(linear(&s))),
            _ => None,
        }
    }

    /// Where the joint's coordinate is among the Rapier joint's six (angular x or linear x).
    pub(crate) fn coordinate(&self) -> usize {
        match self {
            RapierAxis::Angular(_) => 3,
            RapierAxis::Linear(_) => 0,
        }
    }
}

/// A rotation taking the x axis onto the unit vector `axis` (Rapier's one-axis joints move along x).
fn x_onto(axis: &Vector3<f64>) -> Matrix3<f64> {
    let helper = if axis.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let y = axis.cross(&helper).normalize();
    let z = axis.cross(&y);
    Matrix3::from_columns(&[*axis, y, z])
}

/// Where each legkit body lives in the Rapier world.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// Rapier body (index into `handles`) carrying each legkit body.
    pub carrier: Vec<usize>,
    /// Pose of each legkit body in its carrier's Rapier frame (identity for jointed bodies).
    pub offset: Vec<Transform>,
    pub handles: Vec<RigidBodyHandle>,
    /// Centre of mass of each Rapier body in its Rapier frame.
    pub local_com: Vec<Vector3<f64>>,
    /// The multibody link of each Rapier body (0 for the base); None when the model has no joints.
    pub links: Option<Vec<usize>>,
    pub joint_handle: Option<MultibodyJointHandle>,
}

/// Builds the world: gravity, integration parameters, ground, bodies, joints, colliders.
pub(crate) fn build(model: &Model, options: &Options) -> Result<(PhysicsWorld, Layout)> {
    let n = model.nbodies();
    // Rapier's multibody holds dense blocks: its mass matrix and their factors (4 nv x nv) and a 6 x nv Jacobian
    // per body, twice with the undo checkpoint. Asked for as one block first, so that a model too large for
    // them is `Error::TooLarge` naming it rather than an abort inside Rapier.
    let rows = (4 * model.nv()).saturating_add(6 * n);
    drop(with_capacity::<f64>("model", array_len("model", &[2, rows, model.nv()], std::mem::size_of::<f64>())?)?);
    // Carriers and offsets: fixed joints merge into the parent's carrier.
    let mut carrier = vec![0usize; n];
    let mut offset = vec![Transform::identity(); n];
    let mut owner = vec![0usize]; // legkit body defining each Rapier body
    for i in 1..n {
        if model.joint(i).nv() == 0 {
            let p = model.parent(i);
            carrier[i] = carrier[p];
            offset[i] = offset[p].compose(model.placement(i));
        } else {
            carrier[i] = owner.len();
            owner.push(i);
        }
    }
    // Mass properties of each Rapier body in the frame of its defining legkit body.
    let mut mass = vec![MassProperties::zero(); owner.len()];
    for i in 0..n {
        let o = &offset[i];
        mass[carrier[i]] = mass[carrier[i]] + model.body(i).transformed_unchecked(&o.rotation, &o.translation);
    }
    // The base's Rapier frame sits at its centre of mass when it floats.
    if model.floating_base() && mass[0].mass() > 0.0 {
        let shift = Transform::from_translation(-mass[0].com());
        for i in 0..n {
            if carrier[i] == 0 {
                offset[i] = shift.compose(&offset[i]);
            }
        }
        mass[0] = mass[0].transformed_unchecked(&Matrix3::identity(), &-mass[0].com());
    }

    let mut world = PhysicsWorld::new();
    world.gravity = to_vector(&model.gravity);
    world.integration_parameters = integration_parameters(options);

    let friction = options.ground.as_ref().map_or(DEFAULT_FRICTION, Ground::friction);
    if let Some(ground) = &options.ground {
        let ground_body = world.insert_body(RigidBodyBuilder::fixed());
        let (shape, pose) = ground.shape();
        let collider = ColliderBuilder::new(shape).position(pose).friction(ground.friction()).restitution(0.0).density(0.0);
        world.insert_collider(collider.user_data(GROUND_TAG), Some(ground_body));
    }

    // Rigid bodies at the neutral configuration: world pose of each legkit body.
    let neutral = model.neutral();
    let mut poses = vec![Transform::identity(); n];
    for i in 1..n {
        poses[i] = crate::algorithms::world_pose(model, i, &poses[model.parent(i)], neutral.as_slice());
    }
    let mut handles = Vec::with_capacity(owner.len());
    for (r, &i) in owner.iter().enumerate() {
        // The Rapier frame of carrier r is the pose of its defining body composed with the inverse offset.
        let pose = poses[i].compose(&offset[i].inverse());
        let builder = if r == 0 && !model.floating_base() { RigidBodyBuilder::fixed() } else { RigidBodyBuilder::dynamic() };
        let m = &mass[r];
        let builder =
            builder.pose(to_pose(&pose)).can_sleep(false).linear_damping(0.0).angular_damping(0.0).ccd_enabled(false).gyroscopic_forces_enabled(true);
        let builder = if m.mass() > 0.0 {
            builder.additional_mass_properties(RapierMass::with_inertia_matrix(to_vector(&m.com()), m.mass(), to_matrix(&m.inertia())))
        } else {
            builder
        };
        handles.push(world.insert_body(builder));
    }

    // Colliders, attached to the carrier at the body's offset.
    for (i, shape, in_body) in options.colliders(model) {
        let (shared, correction) = shape.shared_shape();
        let in_carrier = offset[i].compose(&in_body).compose(&correction);
        let collider = ColliderBuilder::new(shared)
            .position(to_pose(&in_carrier))
            .density(0.0)
            .friction(friction)
            .friction_combine_rule(CoefficientCombineRule::Average)
            .restitution(0.0)
            .user_data(i as u128);
        world.insert_collider(collider, Some(handles[carrier[i]]));
    }

    // Multibody joints, parent before child.
    let mut joint_handle = None;
    for (r, &i) in owner.iter().enumerate().skip(1) {
        let p = model.parent(i);
        let frame_in_parent = offset[p].compose(model.placement(i));
        let (axis, locked, free) = match RapierAxis::of(model.joint(i)) {
            Some(RapierAxis::Angular(a)) => (a, JointAxesMask::LOCKED_REVOLUTE_AXES, JointAxis::AngX),
            Some(RapierAxis::Linear(a)) => (a, JointAxesMask::LOCKED_PRISMATIC_AXES, JointAxis::LinX),
            None => {
                let kind = model.joint(i).kind();
                return Err(Error::numerical("model", format!("Rapier's multibody has no {kind} joint (body {i}); the tree backend has")));
            }
        };
        let to_axis = Transform::new(x_onto(&axis), Vector3::zeros());
        let mut joint = GenericJointBuilder::new(locked)
            .local_frame1(to_pose(&frame_in_parent.compose(&to_axis)))
            .local_frame2(to_pose(&to_axis))
            .contacts_enabled(false)
            .build();
        let limits = model.limits(i);
        if limits.has_position_limits() {
            // The free axis's coordinate is the legkit joint coordinate (see `state`). Rapier's limit is a
            // velocity constraint that engages once the coordinate is past a bound and drives it back
            // within one substep (its joint softness is nearly rigid), so a moving joint overshoots its
            // limit by at most about one substep of travel. An infinite side becomes Rapier's own
            // "unbounded" value.
            joint.set_limits(free, [limits.lower.max(f64::MIN), limits.upper.min(f64::MAX)]);
        }
        let handle = world
            .multibody_joints
            .insert(handles[carrier[p]], handles[r], joint, true)
            .ok_or_else(|| Error::numerical("model", format!("Rapier refused the joint of body {i}")))?;
        joint_handle = Some(handle);
    }

    let links = if let Some(handle) = joint_handle {
        let links = handles
            .iter()
            .map(|h| world.multibody_joints.rigid_body_link(*h).map(|l| l.id))
            .collect::<Option<Vec<usize>>>()
            .ok_or_else(|| Error::invalid("model", "a body is missing from the Rapier multibody"))?;
        let (multibody, _) = world.multibody_joints.get_mut(handle).expect("inserted above");
        multibody.set_self_contacts_enabled(options.self_collision);
        // Settle the root's degrees of freedom (fixed or free), then set exact joint dynamics: the model's
        // damping (Rapier defaults to 0.1 on angular ones) and armature, no friction.
        multibody.forward_kinematics(&world.bodies, true);
        multibody.damping_mut().fill(0.0);
        multibody.armature_mut().fill(0.0);
        multibody.frictions_mut().fill(0.0);
        for &i in &owner[1..] {
            let (k, dof) = (model.idx_v(i), multibody.link(links[carrier[i]]).expect("link exists").assembly_id());
            multibody.damping_mut()[dof] = model.damping()[k];
            multibody.armature_mut()[dof] = model.armature()[k];
        }
        multibody.update_rigid_bodies(&mut world.bodies, true);
        Some(links)
    } else {
        None
    };

    let local_com = mass.iter().map(|m| m.com()).collect();
    Ok((world, Layout { carrier, offset, handles, local_com, links, joint_handle }))
}

fn to_matrix(m: &Matrix3<f64>) -> Matrix {
    Matrix::from_cols(
        Vector::new(m[(0, 0)], m[(1, 0)], m[(2, 0)]),
        Vector::new(m[(0, 1)], m[(1, 1)], m[(2, 1)]),
        Vector::new(m[(0, 2)], m[(1, 2)], m[(2, 2)]),
    )
}

/// Rapier's parameters for exact, deterministic stepping: no continuous collision detection, no contact
/// recycling (contacts are recomputed every step), Coulomb friction at every contact point, `substeps`
/// solver iterations.
fn integration_parameters(options: &Options) -> IntegrationParameters {
    IntegrationParameters {
        dt: options.dt,
        num_solver_iterations: options.substeps,
        max_ccd_substeps: 0,
        contact_recycling: false,
        friction_model: FrictionModel::Coulomb,
        ..IntegrationParameters::default()
    }
}
