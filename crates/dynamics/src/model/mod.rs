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
//!
//! # Examples
//!
//! A two-link arm on a fixed base, built body by body, each on a joint placed in its parent's frame: the model's sizes,
//! tree and names follow. A body that would break the tree, or take a name already given, is refused.
//!
//! ```
//! use legkit_dynamics::{Joint, JointLimits, MassProperties, Model, Transform};
//! use nalgebra::{Matrix3, Vector3};
//!
//! let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
//! let mut model = Model::new(false, MassProperties::zero(), "base");
//! let upper = model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
//! let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
//! let lower = model.add_body(upper, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
//! assert_eq!((model.nbodies(), model.nq(), model.nv(), model.total_mass()), (3, 2, 2, 2.0));
//! assert_eq!((model.parent(lower), model.body_index("lower"), model.idx_v(lower)), (upper, Some(2), 1));
//! let error = model.add_body(7, Joint::Fixed, elbow, link, "hand", JointLimits::NONE).unwrap_err();
//! assert_eq!(error.to_string(), "parent: body 7 does not exist (the model has 3 bodies)");
//! let error = model.add_body(lower, Joint::Fixed, elbow, link, "upper", JointLimits::NONE).unwrap_err();
//! assert_eq!(error.to_string(), "name: a body is already named \"upper\"");
//! // A free-flyer base: q = [x, y, z, qx, qy, qz, qw], v = [v; ω].
//! let floating = Model::new(true, link, "box");
//! assert_eq!((floating.nq(), floating.nv(), floating.neutral().as_slice()), (7, 6, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0][..]));
//! # Ok::<(), legkit_dynamics::Error>(())
//! ```

mod check;
mod data;
mod limits;
mod workspaces;

use std::collections::HashMap;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

use nalgebra::{DVector, Vector3};

use crate::geometry::Shape;
use crate::joint::Joint;
use crate::spatial::{spatial, Motion, RigidInertia, Transform};
use crate::validate::{finite_vector, rotation};
use crate::{Error, MassProperties, Result};

pub use check::{check_data, check_vector};
pub use data::{Data, Dense};
pub use limits::JointLimits;
pub use workspaces::SecondOrder;
pub(crate) use workspaces::{reserve_square, Block6, ContactWorkspace, BLOCK};

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
    /// Which model this is, for the [`Data`] it builds (see `check::check_data`): new for each model and each body
    /// added, kept by a clone.
    id: u64,
}

/// A fresh model id: every model built, and every body added, gets one no other model has.
fn next_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed)
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
            id: next_id(),
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
        &mut self, parent: usize, joint: Joint, placement: Transform, body: MassProperties, name: &str, limits: JointLimits,
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
        // A workspace sized for the model as it was no longer fits it.
        self.id = next_id();
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

    /// The model's identity, which the [`Data`] it builds records.
    pub(crate) fn id(&self) -> u64 {
        self.id
    }

    /// Spatial acceleration standing in for gravity, in world coordinates (Featherstone's trick, §5.3).
    pub(crate) fn gravity_bias(&self) -> Motion {
        spatial(-self.gravity, Vector3::zeros())
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
