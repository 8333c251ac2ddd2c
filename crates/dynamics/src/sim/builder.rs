//! From a legkit `Model` to a Rapier world: one rigid body per movable body (bodies on fixed joints are
//! merged into their parent, which keeps the multibody's dense mass matrix small), one multibody joint
//! per revolute or prismatic joint (with the model's position limits as Rapier joint limits), and one
//! collider per body.
//!
//! Frames: the Rapier frame of every jointed body is its legkit body frame. The Rapier frame of the
//! base is the legkit base frame moved to the centre of mass of the base and everything merged into it
//! (a free multibody root integrates its frame origin with the velocity of its centre of mass, so the
//! two must coincide).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rapier3d_f64::math::{Matrix, Pose, Rotation, Vector};
use rapier3d_f64::prelude::{
    ColliderBuilder, CoefficientCombineRule, FrictionModel, GenericJointBuilder, IntegrationParameters, JointAxesMask, JointAxis, MassProperties as RapierMass,
    MultibodyJointHandle, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle, SharedShape,
};

use crate::model::{Joint, Model};
use crate::spatial::Transform;
use crate::validate::{finite, finite_vector, rotation};
use crate::{Error, MassProperties, Result};

use super::ground::Ground;

/// Edges of default boxes are at least this long (m), so point masses and thin rods still collide.
pub const MIN_DEFAULT_EDGE: f64 = 1e-3;
/// Friction coefficient of body-body contacts when there is no ground to take it from.
pub const DEFAULT_FRICTION: f64 = 0.8;
/// Marks the ground collider in `Collider::user_data` (bodies store their legkit index).
pub const GROUND_TAG: u128 = u128::MAX;

/// A collision shape in a body's frame. `placement` (the shape frame in the body frame) defaults to the
/// body's centre of mass with the body's axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    pub kind: ShapeKind,
    pub placement: Option<Transform>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ShapeKind {
    /// Full edge lengths along the shape's x, y, z.
    Box(Vector3<f64>),
    Sphere(f64),
    /// Along the shape's z axis: half the length of the axis segment, and the radius.
    Capsule { half_height: f64, radius: f64 },
    /// Along the shape's z axis.
    Cylinder { half_height: f64, radius: f64 },
}

fn positive(argument: &'static str, x: f64) -> Result<f64> {
    if finite(argument, x)? <= 0.0 {
        return Err(Error::invalid(argument, format!("must be > 0, got {x}")));
    }
    Ok(x)
}

impl Shape {
    /// Checks sizes (finite, > 0) and the placement (a proper rotation, finite translation).
    pub fn new(kind: ShapeKind, placement: Option<Transform>) -> Result<Self> {
        match kind {
            ShapeKind::Box(size) => {
                for s in size.iter() {
                    positive("shapes", *s)?;
                }
            }
            ShapeKind::Sphere(r) => {
                positive("shapes", r)?;
            }
            ShapeKind::Capsule { half_height, radius } | ShapeKind::Cylinder { half_height, radius } => {
                positive("shapes", radius)?;
                if finite("shapes", half_height)? < 0.0 {
                    return Err(Error::invalid("shapes", format!("half_height must be >= 0, got {half_height}")));
                }
            }
        }
        if let Some(p) = &placement {
            rotation("shapes", &p.rotation)?;
            finite_vector("shapes", p.translation)?;
        }
        Ok(Shape { kind, placement })
    }

    /// The uniform box with the body's mass and principal moments, centred at its COM along its principal
    /// axes: edges a² = 6 (I₂ + I₃ − I₁) / m and cyclically, floored at `MIN_DEFAULT_EDGE`. None for a
    /// massless body.
    pub fn default_box(body: &MassProperties) -> Option<Shape> {
        if body.mass() <= 0.0 {
            return None;
        }
        let eigen = SymmetricEigen::new(body.inertia());
        let mut axes = eigen.eigenvectors;
        if axes.determinant() < 0.0 {
            axes.set_column(2, &(-axes.column(2)));
        }
        let moments = eigen.eigenvalues;
        let edge = |k: usize| {
            let squared = 6.0 * (moments[(k + 1) % 3] + moments[(k + 2) % 3] - moments[k]) / body.mass();
            squared.max(0.0).sqrt().max(MIN_DEFAULT_EDGE)
        };
        Some(Shape {
            kind: ShapeKind::Box(Vector3::new(edge(0), edge(1), edge(2))),
            placement: Some(Transform::new(axes, body.com())),
        })
    }

    fn shared_shape(&self) -> (SharedShape, Transform) {
        // Parry's cylinder runs along its y axis: turn it onto z (x → x, y → z, z → −y).
        let y_to_z = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
        match self.kind {
            ShapeKind::Box(size) => (SharedShape::cuboid(size.x / 2.0, size.y / 2.0, size.z / 2.0), Transform::identity()),
            ShapeKind::Sphere(r) => (SharedShape::ball(r), Transform::identity()),
            ShapeKind::Capsule { half_height, radius } => (SharedShape::capsule_z(half_height, radius), Transform::identity()),
            ShapeKind::Cylinder { half_height, radius } => {
                (SharedShape::cylinder(half_height, radius), Transform::new(y_to_z, Vector3::zeros()))
            }
        }
    }
}

pub(crate) fn to_pose(t: &Transform) -> Pose {
    let r = &t.rotation;
    let m = Matrix::from_cols(
        Vector::new(r[(0, 0)], r[(1, 0)], r[(2, 0)]),
        Vector::new(r[(0, 1)], r[(1, 1)], r[(2, 1)]),
        Vector::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]),
    );
    Pose::from_parts(to_vector(&t.translation), Rotation::from_mat3(&m).normalize())
}

pub(crate) fn from_pose(p: &Pose) -> Transform {
    let m = Matrix::from_quat(p.rotation);
    let (x, y, z) = (m.col(0), m.col(1), m.col(2));
    Transform::new(Matrix3::new(x.x, y.x, z.x, x.y, y.y, z.y, x.z, y.z, z.z), from_vector(p.translation))
}

#[inline]
pub(crate) fn to_vector(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

#[inline]
pub(crate) fn from_vector(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

/// A rotation taking the x axis onto the unit vector `axis` (Rapier's one-axis joints move along x).
fn x_onto(axis: &Vector3<f64>) -> Matrix3<f64> {
    let helper = if axis.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let y = axis.cross(&helper).normalize();
    let z = axis.cross(&y);
    Matrix3::from_columns(&[*axis, y, z])
}

/// Construction options of a simulation (see `Simulation::new`).
#[derive(Debug, Clone)]
pub struct Options {
    /// Step length (s), > 0.
    pub dt: f64,
    pub ground: Option<Ground>,
    /// Shapes replacing the default box of the listed bodies; `None` removes a body's collider.
    pub shapes: Vec<(usize, Option<Shape>)>,
    /// Contacts between bodies of the robot (never between a body and its parent).
    pub self_collision: bool,
    /// Viscous damping (N m s/rad or N s/m) on every revolute and prismatic joint, integrated implicitly.
    pub joint_damping: f64,
    /// Reflected rotor inertia (kg m² or kg) added on every revolute and prismatic joint, as a geared
    /// servo's motor adds to the joint's diagonal of the mass matrix.
    pub joint_armature: f64,
    /// Rapier substeps per step (its solver iterations): each re-evaluates the multibody dynamics, so
    /// more substeps integrate more accurately at a proportional cost.
    pub substeps: usize,
}

impl Options {
    pub fn new(dt: f64) -> Self {
        Options { dt, ground: None, shapes: Vec::new(), self_collision: false, joint_damping: 0.0, joint_armature: 0.0, substeps: 1 }
    }

    pub(crate) fn check(&self, model: &Model) -> Result<()> {
        if finite("dt", self.dt)? <= 0.0 {
            return Err(Error::invalid("dt", format!("must be > 0, got {}", self.dt)));
        }
        if finite("joint_damping", self.joint_damping)? < 0.0 {
            return Err(Error::invalid("joint_damping", format!("must be >= 0, got {}", self.joint_damping)));
        }
        if finite("joint_armature", self.joint_armature)? < 0.0 {
            return Err(Error::invalid("joint_armature", format!("must be >= 0, got {}", self.joint_armature)));
        }
        if self.substeps == 0 {
            return Err(Error::invalid("substeps", "must be >= 1"));
        }
        let mut seen = vec![false; model.nbodies()];
        for (body, _) in &self.shapes {
            if *body >= model.nbodies() {
                return Err(Error::invalid("shapes", format!("body {body} does not exist (the model has {} bodies)", model.nbodies())));
            }
            if std::mem::replace(&mut seen[*body], true) {
                return Err(Error::invalid("shapes", format!("body {body} is given more than once")));
            }
        }
        Ok(())
    }
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
    // Carriers and offsets: fixed joints merge into the parent's carrier.
    let mut carrier = vec![0usize; n];
    let mut offset = vec![Transform::identity(); n];
    let mut owner = vec![0usize]; // legkit body defining each Rapier body
    for i in 1..n {
        if *model.joint(i) == Joint::Fixed {
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
        world.insert_collider(ground.collider().user_data(GROUND_TAG), Some(ground_body));
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
        let builder = builder
            .pose(to_pose(&pose))
            .can_sleep(false)
            .linear_damping(0.0)
            .angular_damping(0.0)
            .ccd_enabled(false)
            .gyroscopic_forces_enabled(true);
        let builder = if m.mass() > 0.0 {
            builder.additional_mass_properties(RapierMass::with_inertia_matrix(to_vector(&m.com()), m.mass(), to_matrix(&m.inertia())))
        } else {
            builder
        };
        handles.push(world.insert_body(builder));
    }

    // Colliders, attached to the carrier at the body's offset.
    for i in 0..n {
        let shape = match options.shapes.iter().find(|(b, _)| *b == i) {
            Some((_, shape)) => shape.clone(),
            None => Shape::default_box(model.body(i)),
        };
        let Some(shape) = shape else { continue };
        let (shared, correction) = shape.shared_shape();
        let in_body = shape.placement.unwrap_or_else(|| Transform::from_translation(model.body(i).com()));
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
        let (axis, locked, free) = match *model.joint(i) {
            Joint::Revolute(a) => (a, JointAxesMask::LOCKED_REVOLUTE_AXES, JointAxis::AngX),
            Joint::Prismatic(a) => (a, JointAxesMask::LOCKED_PRISMATIC_AXES, JointAxis::LinX),
            Joint::Fixed | Joint::FreeFlyer => unreachable!("only one-degree-of-freedom joints define Rapier bodies"),
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
            .ok_or_else(|| Error::invalid("model", format!("Rapier refused the joint of body {i}")))?;
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
        // Settle the root's degrees of freedom (fixed or free), then set exact joint dynamics: no damping
        // (Rapier defaults to 0.1 on angular ones) and no armature other than requested, no friction.
        multibody.forward_kinematics(&world.bodies, true);
        let root_dofs = multibody.ndofs() - (model.nv() - if model.floating_base() { 6 } else { 0 });
        for k in 0..multibody.ndofs() {
            multibody.damping_mut()[k] = if k < root_dofs { 0.0 } else { options.joint_damping };
            multibody.armature_mut()[k] = if k < root_dofs { 0.0 } else { options.joint_armature };
            multibody.frictions_mut()[k] = 0.0;
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
