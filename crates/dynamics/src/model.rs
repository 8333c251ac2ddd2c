//! `Model`, the immutable description of a kinematic tree, and `Data`, the workspace every algorithm
//! writes into (allocated once per model, as in Pinocchio).
//!
//! Body 0 is the base: fixed to the world, or moved by a free-flyer joint with configuration
//! `[x, y, z, qx, qy, qz, qw]` and velocity `[v; ω]` in the base frame. Every other body hangs off a
//! one-degree-of-freedom or fixed joint ([`Joint`], in `joint.rs`) whose frame is placed in its parent
//! body's frame; the body's frame is the joint frame after the joint's motion. Bodies are numbered parent
//! before child.
//!
//! Bodies and joints have names, in two namespaces as a URDF's links and joints: a body's joint is named
//! after the body unless a loader names it ([`Model::set_joint_name`]), and the base's joint is
//! [`ROOT_JOINT`], as Pinocchio names the free flyer it puts under a URDF.
//!
//! Each joint may carry [`JointLimits`] (position range, effort and velocity bounds). The dynamics
//! algorithms ignore them: they describe the mechanism for the simulation (which enforces the position
//! range and the effort bound) and for controllers (which read them with [`Model::limits`]).

use std::collections::HashMap;
use std::ops::Range;
use std::sync::OnceLock;

use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX, Vector3, Vector6};

use crate::geometry::Shape;
use crate::joint::Joint;
use crate::spatial::{spatial, Force, Inertia, Motion, RateMatrix, RigidInertia, Transform};
use crate::validate::{array_len, filled, finite_vector, rotation, with_capacity};
use crate::{Error, MassProperties, Result};

/// Limits of a revolute or prismatic joint, in the joint's coordinate: position range `lower..=upper`
/// (rad or m; ±inf where unbounded), and bounds on the magnitude of its generalized force `effort`
/// (N m or N) and of its velocity `velocity` (rad/s or m/s), each +inf where unbounded.
///
/// Build with [`JointLimits::new`] (checked) or start from [`JointLimits::NONE`]; [`Model::add_body`]
/// checks again, so a model never holds invalid limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lowest position (rad or m), −inf if unbounded.
    pub lower: f64,
    /// Highest position (rad or m), +inf if unbounded.
    pub upper: f64,
    /// Largest magnitude of the joint's generalized force (N m or N), +inf if unbounded.
    pub effort: f64,
    /// Largest magnitude of the joint's velocity (rad/s or m/s), +inf if unbounded.
    pub velocity: f64,
}

impl JointLimits {
    /// No limit at all: the only limits a fixed joint or the base can have.
    pub const NONE: JointLimits = JointLimits { lower: f64::NEG_INFINITY, upper: f64::INFINITY, effort: f64::INFINITY, velocity: f64::INFINITY };

    /// Checked limits: `lower` finite or −inf, `upper` finite or +inf, `lower <= upper`, `effort` and
    /// `velocity` > 0 (+inf allowed). Errors name the argument `"limits"`.
    pub fn new(lower: f64, upper: f64, effort: f64, velocity: f64) -> Result<Self> {
        let limits = JointLimits { lower, upper, effort, velocity };
        limits.check()?;
        Ok(limits)
    }

    /// A position range only (no effort or velocity bound).
    pub fn position(lower: f64, upper: f64) -> Result<Self> {
        Self::new(lower, upper, f64::INFINITY, f64::INFINITY)
    }

    /// Whether any of the four bounds is finite.
    pub fn is_limited(&self) -> bool {
        *self != Self::NONE
    }

    /// Whether the position range has a finite end.
    pub fn has_position_limits(&self) -> bool {
        self.lower.is_finite() || self.upper.is_finite()
    }

    fn check(&self) -> Result<()> {
        let bad = |reason: String| Err(Error::invalid("limits", reason));
        if self.lower.is_nan() || self.lower == f64::INFINITY {
            return bad(format!("lower must be finite or -inf, got {}", self.lower));
        }
        if self.upper.is_nan() || self.upper == f64::NEG_INFINITY {
            return bad(format!("upper must be finite or +inf, got {}", self.upper));
        }
        if self.lower > self.upper {
            return bad(format!("lower ({}) must be <= upper ({})", self.lower, self.upper));
        }
        for (name, value) in [("effort", self.effort), ("velocity", self.velocity)] {
            // NaN fails `> 0`.
            if !(value > 0.0) {
                return bad(format!("{name} must be > 0 (+inf for no limit), got {value}"));
            }
        }
        Ok(())
    }
}

impl Default for JointLimits {
    fn default() -> Self {
        Self::NONE
    }
}

/// The name of the base's joint (Pinocchio's name for the free flyer `buildModelFromUrdf` adds).
pub const ROOT_JOINT: &str = "root_joint";

/// Standard gravity (m/s²): a new model's gravity is (0, 0, −g).
pub const STANDARD_GRAVITY: f64 = 9.81;

/// A kinematic tree: joints, their placements and limits, and the bodies' mass properties, built body by body
/// with [`Model::add_body`] or loaded ([`crate::urdf`], [`crate::mjcf`]). Immutable once built, except for gravity,
/// armature, damping and collision shapes; every algorithm reads it alongside a [`Data`] sized for it.
#[derive(Debug, Clone)]
pub struct Model {
    joints: Vec<Joint>,
    limits: Vec<JointLimits>,
    parents: Vec<usize>,
    placements: Vec<Transform>,
    bodies: Vec<MassProperties>,
    inertias: Vec<RigidInertia>,
    names: Vec<String>,
    /// Each name's body, so that adding and finding a body by name does not scan the others.
    index_of_name: HashMap<String, usize>,
    /// The name of each body's joint.
    joint_names: Vec<String>,
    /// Each joint name's body (the first, should two joints share a name), built by the first lookup.
    index_of_joint_name: OnceLock<HashMap<String, usize>>,
    idx_q: Vec<usize>,
    idx_v: Vec<usize>,
    /// The velocity indices of each body's subtree as increasing ranges (one range when bodies are
    /// numbered depth first); computed by the first call that needs them, in one pass over the bodies
    /// (extending every ancestor's ranges as each body is added took time quadratic in the depth).
    subtree_columns: OnceLock<Vec<Vec<Range<usize>>>>,
    nq: usize,
    nv: usize,
    /// Gravity in the world frame.
    pub gravity: Vector3<f64>,
    /// Per velocity coordinate: reflected rotor inertia and viscous damping (see `armature`, `damping`).
    armature: Vec<f64>,
    damping: Vec<f64>,
    /// The collision geometry the model was described with (URDF `<collision>`s), several shapes per
    /// body allowed; None when it has none (a simulation then gives every body a default box).
    collision: Option<Vec<(usize, Shape)>>,
}

impl Model {
    /// A model with only its base: fixed to the world, or free-floating.
    pub fn new(floating_base: bool, base: MassProperties, base_name: &str) -> Self {
        let joint = if floating_base { Joint::FreeFlyer } else { Joint::Fixed };
        Model {
            joints: vec![joint],
            limits: vec![JointLimits::NONE],
            parents: vec![0],
            placements: vec![Transform::identity()],
            bodies: vec![base],
            inertias: vec![RigidInertia::from_body(&base)],
            names: vec![base_name.to_owned()],
            index_of_name: HashMap::from([(base_name.to_owned(), 0)]),
            joint_names: vec![ROOT_JOINT.to_owned()],
            index_of_joint_name: OnceLock::new(),
            idx_q: vec![0],
            idx_v: vec![0],
            subtree_columns: OnceLock::new(),
            nq: joint.nq(),
            nv: joint.nv(),
            gravity: Vector3::new(0.0, 0.0, -STANDARD_GRAVITY),
            armature: vec![0.0; joint.nv()],
            damping: vec![0.0; joint.nv()],
            collision: None,
        }
    }

    /// The collision geometry the model was described with, if any: (body, shape) pairs, in body frames.
    pub fn collision_shapes(&self) -> Option<&[(usize, Shape)]> {
        self.collision.as_deref()
    }

    /// Sets the model's collision geometry (bodies may have several shapes, or none). A body that does
    /// not exist is an error.
    pub fn set_collision_shapes(&mut self, shapes: Vec<(usize, Shape)>) -> Result<()> {
        if let Some((body, _)) = shapes.iter().find(|(body, _)| *body >= self.nbodies()) {
            return Err(Error::invalid("shapes", format!("body {body} does not exist (the model has {} bodies)", self.nbodies())));
        }
        self.collision = Some(shapes);
        Ok(())
    }

    /// Appends a body on `joint` below body `parent`, the joint frame at `placement` in the parent's frame,
    /// with the joint's `limits` (`JointLimits::NONE` for none). Returns the new body's index. Axes are
    /// normalised; a zero axis, a parent that does not exist yet, an improper rotation, a repeated name,
    /// invalid limits or limits on a fixed joint are errors.
    pub fn add_body(
        &mut self,
        parent: usize,
        joint: Joint,
        placement: Transform,
        body: MassProperties,
        name: &str,
        limits: JointLimits,
    ) -> Result<usize> {
        if parent >= self.joints.len() {
            return Err(Error::invalid("parent", format!("body {parent} does not exist (the model has {} bodies)", self.joints.len())));
        }
        let joint = joint.checked_below_base()?;
        rotation("placement", &placement.rotation)?;
        finite_vector("placement", placement.translation)?;
        limits.check()?;
        if joint == Joint::Fixed && limits.is_limited() {
            return Err(Error::invalid("limits", "a fixed joint has no coordinate to limit"));
        }
        if self.index_of_name.contains_key(name) {
            return Err(Error::invalid("name", format!("a body is already named {name:?}")));
        }
        self.joints.push(joint);
        self.limits.push(limits);
        self.parents.push(parent);
        self.placements.push(placement);
        self.bodies.push(body);
        self.inertias.push(RigidInertia::from_body(&body));
        self.names.push(name.to_owned());
        self.index_of_name.insert(name.to_owned(), self.joints.len() - 1);
        self.joint_names.push(name.to_owned());
        self.index_of_joint_name = OnceLock::new();
        self.idx_q.push(self.nq);
        self.idx_v.push(self.nv);
        self.nq += joint.nq();
        self.nv += joint.nv();
        self.armature.resize(self.nv, 0.0);
        self.damping.resize(self.nv, 0.0);
        self.subtree_columns = OnceLock::new();
        Ok(self.joints.len() - 1)
    }

    /// Reserves room for `bodies` more bodies with `dofs` velocity coordinates between them, fallibly: a
    /// loader that knows the size of the model it builds fails with `Error::TooLarge` naming `argument`
    /// (where `add_body` would abort the process when memory runs out).
    pub fn try_reserve(&mut self, argument: &'static str, bodies: usize, dofs: usize) -> Result<()> {
        let fail = |_| Error::too_large(argument, format!("cannot allocate a model of {bodies} more bodies"));
        self.joints.try_reserve_exact(bodies).map_err(fail)?;
        self.limits.try_reserve_exact(bodies).map_err(fail)?;
        self.parents.try_reserve_exact(bodies).map_err(fail)?;
        self.placements.try_reserve_exact(bodies).map_err(fail)?;
        self.bodies.try_reserve_exact(bodies).map_err(fail)?;
        self.inertias.try_reserve_exact(bodies).map_err(fail)?;
        self.names.try_reserve_exact(bodies).map_err(fail)?;
        self.index_of_name.try_reserve(bodies).map_err(fail)?;
        self.joint_names.try_reserve_exact(bodies).map_err(fail)?;
        self.idx_q.try_reserve_exact(bodies).map_err(fail)?;
        self.idx_v.try_reserve_exact(bodies).map_err(fail)?;
        self.armature.try_reserve_exact(dofs).map_err(fail)?;
        self.damping.try_reserve_exact(dofs).map_err(fail)
    }

    /// Every body's subtree columns (see `subtree_columns`), children before parents: each body's ranges
    /// are its own columns and its children's ranges, sorted and merged where they meet.
    fn all_subtree_columns(&self) -> Vec<Vec<Range<usize>>> {
        let n = self.nbodies();
        let mut columns: Vec<Vec<Range<usize>>> =
            (0..n).map(|i| Some(self.idx_v[i]..self.idx_v[i] + self.joints[i].nv()).filter(|r| !r.is_empty()).into_iter().collect()).collect();
        for i in (0..n).rev() {
            let mut ranges = std::mem::take(&mut columns[i]);
            ranges.sort_unstable_by_key(|r| r.start);
            let mut merged: Vec<Range<usize>> = Vec::with_capacity(ranges.len());
            for range in ranges {
                match merged.last_mut() {
                    Some(last) if last.end == range.start => last.end = range.end,
                    _ => merged.push(range),
                }
            }
            if i > 0 {
                let parent = self.parents[i];
                columns[parent].extend(merged.iter().cloned());
            }
            columns[i] = merged;
        }
        columns
    }

    /// Number of bodies, the base included.
    pub fn nbodies(&self) -> usize {
        self.joints.len()
    }
    /// Length of a configuration q (a unit quaternion counts 4).
    pub fn nq(&self) -> usize {
        self.nq
    }
    /// Length of a velocity v (the tangent space: a rotation counts 3).
    pub fn nv(&self) -> usize {
        self.nv
    }
    /// Whether the base moves on a free-flyer joint.
    pub fn floating_base(&self) -> bool {
        self.joints[0] == Joint::FreeFlyer
    }
    /// The joint that moves body `i` relative to its parent.
    pub fn joint(&self, i: usize) -> &Joint {
        &self.joints[i]
    }
    /// Limits of the joint of body `i` (`JointLimits::NONE` for the base and fixed joints). Ignored by the
    /// dynamics algorithms; enforced by the simulation (position range, effort).
    pub fn limits(&self, i: usize) -> &JointLimits {
        &self.limits[i]
    }
    /// Parent of body `i`; the base (0) is its own parent.
    pub fn parent(&self, i: usize) -> usize {
        self.parents[i]
    }
    /// The frame of body `i`'s joint in its parent's frame (the body's frame at zero joint coordinates).
    pub fn placement(&self, i: usize) -> &Transform {
        &self.placements[i]
    }
    /// Mass properties of body `i` in its own frame.
    pub fn body(&self, i: usize) -> &MassProperties {
        &self.bodies[i]
    }
    /// Spatial inertia of body `i` in its own frame.
    pub fn inertia(&self, i: usize) -> &RigidInertia {
        &self.inertias[i]
    }
    /// Name of body `i` (unique in the model).
    pub fn name(&self, i: usize) -> &str {
        &self.names[i]
    }
    /// The body named `name`, if any.
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.index_of_name.get(name).copied()
    }
    /// Name of the joint that moves body `i`.
    pub fn joint_name(&self, i: usize) -> &str {
        &self.joint_names[i]
    }
    /// Names the joint that moves body `i` (which must exist) `name`.
    pub fn set_joint_name(&mut self, i: usize, name: &str) {
        name.clone_into(&mut self.joint_names[i]);
        self.index_of_joint_name = OnceLock::new();
    }
    /// The body moved by the joint named `name`, if any (the first, should two joints share the name).
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        let index = self.index_of_joint_name.get_or_init(|| {
            let mut index = HashMap::with_capacity(self.joint_names.len());
            for (i, joint_name) in self.joint_names.iter().enumerate() {
                index.entry(joint_name.clone()).or_insert(i);
            }
            index
        });
        index.get(name).copied()
    }
    /// Index of body `i`'s joint's first coordinate in q.
    pub fn idx_q(&self, i: usize) -> usize {
        self.idx_q[i]
    }
    /// Index of body `i`'s joint's first coordinate in v.
    pub fn idx_v(&self, i: usize) -> usize {
        self.idx_v[i]
    }
    /// The velocity indices of body `i`'s subtree (its own included), as increasing ranges.
    pub fn subtree_columns(&self, i: usize) -> &[Range<usize>] {
        &self.subtree_columns.get_or_init(|| self.all_subtree_columns())[i]
    }
    /// A copy of the model in which body `i` (which must exist) has the mass properties `body`.
    pub fn with_body(&self, i: usize, body: MassProperties) -> Model {
        let mut model = self.clone();
        model.bodies[i] = body;
        model.inertias[i] = RigidInertia::from_body(&body);
        model
    }

    /// Each velocity coordinate's armature (kg m² or kg): a geared motor's rotor inertia reflected through
    /// its gearbox, Pinocchio's `Model::armature`. RNEA, CRBA, ABA, Minv and the kinetic energy work with
    /// M + diag(armature); the centroidal quantities, which are the rigid bodies', do not. Zero by default.
    pub fn armature(&self) -> &[f64] {
        &self.armature
    }

    /// Each velocity coordinate's viscous damping (N m s/rad or N s/m): the simulation applies the passive
    /// force −damping v (implicitly); the dynamics algorithms ignore it, as Pinocchio's do. Zero by default.
    pub fn damping(&self) -> &[f64] {
        &self.damping
    }

    /// Sets every velocity coordinate's armature (length nv, each finite and >= 0; zero on a free-flyer
    /// base, whose six coordinates have none).
    pub fn set_armature(&mut self, armature: &[f64]) -> Result<()> {
        self.armature = self.joint_coefficients("armature", armature)?;
        Ok(())
    }

    /// Sets every velocity coordinate's damping (as `set_armature`).
    pub fn set_damping(&mut self, damping: &[f64]) -> Result<()> {
        self.damping = self.joint_coefficients("damping", damping)?;
        Ok(())
    }

    fn joint_coefficients(&self, argument: &'static str, values: &[f64]) -> Result<Vec<f64>> {
        check_vector(argument, values, self.nv)?;
        if let Some(k) = values.iter().position(|x| *x < 0.0) {
            return Err(Error::invalid(argument, format!("element {k} is negative ({})", values[k])));
        }
        if self.floating_base() && values[..6].iter().any(|x| *x != 0.0) {
            return Err(Error::invalid(argument, "the free-flyer base's six coordinates have none: they must be 0"));
        }
        Ok(values.to_vec())
    }

    /// Sum of the bodies' masses (kg).
    pub fn total_mass(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass()).sum()
    }

    /// The neutral configuration: zero joint coordinates, base at the origin, identity orientations.
    pub fn neutral(&self) -> DVector<f64> {
        let mut q = DVector::zeros(self.nq);
        for (joint, &k) in self.joints.iter().zip(&self.idx_q) {
            if let Some(quaternion) = joint.quaternion_coordinates() {
                q[k + quaternion.end - 1] = 1.0;
            }
        }
        q
    }

    /// Checks a configuration: length `nq`, finite, and unit quaternions (to 1e-6): the base's and the ball joints'.
    pub fn check_configuration(&self, q: &[f64]) -> Result<()> {
        self.check_configuration_named("q", q)
    }

    /// `check_configuration` of the argument named `argument` (e.g. "q0").
    pub fn check_configuration_named(&self, argument: &'static str, q: &[f64]) -> Result<()> {
        check_vector(argument, q, self.nq)?;
        for (i, (joint, &k)) in self.joints.iter().zip(&self.idx_q).enumerate() {
            let Some(quaternion) = joint.quaternion_coordinates() else { continue };
            let (a, b) = (k + quaternion.start, k + quaternion.end);
            let norm = q[a..b].iter().map(|x| x * x).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-6 {
                let whose = if i == 0 { "the base quaternion".to_string() } else { format!("the quaternion of ball joint '{}'", self.names[i]) };
                return Err(Error::invalid(argument, format!("{whose} {argument}[{a}:{b}] must have unit norm, got {norm:.9}")));
            }
        }
        Ok(())
    }

    /// Spatial acceleration standing in for gravity, in world coordinates (Featherstone's trick, §5.3).
    pub(crate) fn gravity_bias(&self) -> Motion {
        spatial(-self.gravity, Vector3::zeros())
    }
}

/// Checks a coordinate vector: length `n` and finite.
pub fn check_vector(argument: &'static str, x: &[f64], n: usize) -> Result<()> {
    if x.len() != n {
        return Err(Error::invalid(argument, format!("expected length {n}, got {}", x.len())));
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(argument, format!("element {i} is not finite ({})", x[i])));
    }
    Ok(())
}

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
}

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
    fn try_reserve(&mut self, model: &Model) -> Result<()> {
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
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_joint_model(joint: Joint, limits: JointLimits) -> Result<Model> {
        let mut model = Model::new(false, MassProperties::zero(), "base");
        model.add_body(0, joint, Transform::identity(), MassProperties::zero(), "link", limits)?;
        Ok(model)
    }

    #[test]
    fn a_reservation_beyond_memory_is_too_large_and_changes_nothing() {
        let mut model = Model::new(false, MassProperties::zero(), "base");
        let error = model.try_reserve("path", usize::MAX / 64, 0).unwrap_err();
        assert!(matches!(error, Error::TooLarge { argument: "path", .. }), "{error}");
        assert_eq!((model.nbodies(), model.nv()), (1, 0));
        model.try_reserve("path", 3, 3).unwrap();
    }

    #[test]
    fn subtree_columns_follow_any_parent_before_child_numbering() {
        let mut model = Model::new(true, MassProperties::zero(), "base");
        let mut add = |parent: usize, joint: Joint, name: &str| {
            model.add_body(parent, joint, Transform::identity(), MassProperties::zero(), name, JointLimits::NONE).unwrap()
        };
        // Bodies 1 and 2 hang off the base, 3 off 1 (not depth first), 4 is fixed below 3, 5 below 4.
        let y = Joint::Revolute(Vector3::y());
        let (a, b) = (add(0, y, "a"), add(0, y, "b"));
        let c = add(a, y, "c");
        let d = add(c, Joint::Fixed, "d");
        let e = add(d, y, "e");
        let columns = |i: usize| model.subtree_columns(i).to_vec();
        assert_eq!(columns(0), vec![0..10]);
        assert_eq!(columns(a), vec![6..7, 8..10]);
        assert_eq!(columns(b), vec![7..8]);
        assert_eq!(columns(c), vec![8..10]);
        assert_eq!(columns(d), vec![9..10]);
        assert_eq!(columns(e), vec![9..10]);
    }

    #[test]
    fn limits_are_stored_per_body() {
        let limits = JointLimits::new(-0.5, 1.5, 20.0, f64::INFINITY).unwrap();
        let model = one_joint_model(Joint::Prismatic(Vector3::z()), limits).unwrap();
        assert_eq!(*model.limits(0), JointLimits::NONE);
        assert_eq!(*model.limits(1), JointLimits { lower: -0.5, upper: 1.5, effort: 20.0, velocity: f64::INFINITY });
        assert!(model.limits(1).has_position_limits() && model.limits(1).is_limited());
        let one_sided = JointLimits::position(f64::NEG_INFINITY, 0.0).unwrap();
        assert!(one_sided.has_position_limits());
        let effort_only = JointLimits::new(f64::NEG_INFINITY, f64::INFINITY, 2.0, f64::INFINITY).unwrap();
        assert!(!effort_only.has_position_limits() && effort_only.is_limited());
        assert!(!JointLimits::default().is_limited());
        // A zero-width range (a locked joint) is allowed.
        assert!(JointLimits::position(0.3, 0.3).is_ok());
    }

    #[test]
    fn invalid_limits_are_rejected_naming_limits() {
        let (inf, nan) = (f64::INFINITY, f64::NAN);
        for (lower, upper, effort, velocity, needle) in [
            (1.0, -1.0, inf, inf, "lower (1) must be <= upper (-1)"),
            (nan, 1.0, inf, inf, "lower must be finite or -inf"),
            (inf, inf, inf, inf, "lower must be finite or -inf"),
            (-1.0, nan, inf, inf, "upper must be finite or +inf"),
            (-inf, -inf, inf, inf, "upper must be finite or +inf"),
            (-1.0, 1.0, 0.0, inf, "effort must be > 0"),
            (-1.0, 1.0, -2.0, inf, "effort must be > 0"),
            (-1.0, 1.0, inf, nan, "velocity must be > 0"),
        ] {
            let error = JointLimits::new(lower, upper, effort, velocity).unwrap_err();
            assert_eq!(error.argument(), "limits");
            assert!(error.to_string().contains(needle), "{error} does not contain {needle:?}");
            // add_body checks limits built field by field as well, and leaves the model unchanged.
            let mut model = Model::new(false, MassProperties::zero(), "base");
            let raw = JointLimits { lower, upper, effort, velocity };
            let error = model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), MassProperties::zero(), "l", raw).unwrap_err();
            assert_eq!(error.argument(), "limits");
            assert_eq!((model.nbodies(), model.nq()), (1, 0));
        }
        let fixed = one_joint_model(Joint::Fixed, JointLimits::position(-1.0, 1.0).unwrap()).unwrap_err();
        assert_eq!(fixed.argument(), "limits");
        assert!(one_joint_model(Joint::Fixed, JointLimits::NONE).is_ok());
    }

    #[test]
    fn armature_and_damping_are_per_coordinate_non_negative_and_none_on_the_base() {
        let mut model = Model::new(true, MassProperties::zero(), "base");
        model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), MassProperties::zero(), "a", JointLimits::NONE).unwrap();
        assert_eq!(model.armature(), &[0.0; 7]);
        let mut values = [0.0; 7];
        values[6] = 0.25;
        model.set_armature(&values).unwrap();
        model.set_damping(&values).unwrap();
        assert_eq!((model.armature()[6], model.damping()[6]), (0.25, 0.25));
        model.add_body(1, Joint::Prismatic(Vector3::x()), Transform::identity(), MassProperties::zero(), "b", JointLimits::NONE).unwrap();
        assert_eq!(model.armature().len(), 8);
        assert_eq!(model.armature()[7], 0.0);
        for bad in [vec![0.0; 7], vec![-1.0; 8], vec![f64::NAN; 8], {
            let mut v = vec![0.0; 8];
            v[0] = 1.0;
            v
        }] {
            assert_eq!(model.set_armature(&bad).unwrap_err().argument(), "armature");
            assert_eq!(model.set_damping(&bad).unwrap_err().argument(), "damping");
        }
        assert_eq!(model.armature()[6], 0.25, "a refused value leaves the model as it was");
    }
}
