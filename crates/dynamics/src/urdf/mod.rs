//! URDF import: builds a [`Model`] from the kinematic tree and inertial data of a URDF `<robot>`.
//!
//! Supported, per the URDF specification:
//! - `<link name>` with an optional `<inertial>`: `<origin xyz rpy>` (both default to 0), `<mass value>` and
//!   `<inertia ixx ixy ixz iyy iyz izz>` about the centre of mass, in the inertial frame. The link's centre
//!   of mass is `xyz` and its inertia `R I Rᵀ`, R the rotation of `rpy`. A link without `<inertial>`, or
//!   with mass 0 and no inertia, is massless; a link with mass 0 keeps its rotational inertia, as in
//!   Pinocchio.
//! - `<joint name type>` with `<parent link>`, `<child link>`, `<origin xyz rpy>` (default identity) and
//!   `<axis xyz>` (default `1 0 0`, normalised; read only for moving joints). Types: `revolute` and
//!   `continuous` become [`Joint::Revolute`], `prismatic` [`Joint::Prismatic`], `fixed` [`Joint::Fixed`].
//!   `floating` becomes three prismatic joints along the joint frame's x, y, z axes (massless bodies named
//!   `"{child}/{joint}:x"`, `:y`, `:z`) and a [`Joint::Spherical`] moving the child link, because legkit's
//!   free flyer can only be the base: q = `[x, y, z, qx, qy, qz, qw]` equals Pinocchio's `JointModelFreeFlyer`
//!   q, and v = `[ṗ, ω]` has ω in the child frame as Pinocchio's but the linear rate ṗ in the joint frame
//!   where Pinocchio's is `Rᵀṗ`, in the child frame (MuJoCo's free-joint coordinates, as [`crate::mjcf`]
//!   reads a free body below a fixed world). With [`UrdfOptions::floating_base`] a `floating` joint out of
//!   the root link is an error (the base would float twice); load such a file with a fixed base instead.
//!   `spherical`, an extension outside the URDF specification (urdfdom and Pinocchio refuse it), becomes a
//!   [`Joint::Spherical`] (q the unit quaternion `[qx, qy, qz, qw]`, v the angular velocity in the child
//!   frame, as Pinocchio's `JointModelSpherical`) with a warning (an error under `strict`). `<limit>` is
//!   ignored on both; `<dynamics damping>` damps each of their coordinates. Any other type (`planar`, ...) is
//!   an error.
//! - `<limit lower upper effort velocity>` of a moving joint becomes its [`JointLimits`]: `lower` and
//!   `upper` (rad or m; each defaults to 0, as the specification says) bound a `revolute` or `prismatic`
//!   joint; a `continuous` joint has no position limits (its `lower`/`upper` are ignored). `effort`
//!   (N m or N) and `velocity` (rad/s or m/s) must be >= 0; unlike the specification, which requires
//!   them, either may be omitted for no bound, and 0 (which exporters write for "unset") also reads as
//!   no bound, with a warning. A moving joint without `<limit>` has no limits (the specification requires
//!   one on `revolute` and `prismatic` joints; legkit tolerates its absence). `lower > upper`, a negative
//!   `effort` or `velocity`, or a value that is not a finite number is an error naming the joint.
//!   `<limit>` on a fixed joint is ignored.
//! - `rpy` is URDF's fixed-axis roll about x, then pitch about y, then yaw about z:
//!   `R = Rz(yaw) Ry(pitch) Rx(roll)`.
//!
//! - `<collision>` with `<origin>` and a `<geometry>` of `<box size>`, `<sphere radius>`, `<cylinder radius
//!   length>` or `<capsule radius length>` (along z) becomes one of the model's collision shapes
//!   ([`Model::collision_shapes`], several per body allowed), which a simulation uses instead of default
//!   boxes. `<mesh filename scale>` (STL, OBJ or COLLADA; [`crate::mesh`]) becomes the convex hull of its
//!   vertices, scaled; `package://` names (and `package:///`, `model://`) resolve through
//!   [`UrdfOptions::package_dirs`], then `ROS_PACKAGE_PATH`, then `AMENT_PREFIX_PATH`'s `share/` folders, then
//!   the URDF file's folder's ancestors, never climbing out of their package, and relative names against that
//!   folder ([`crate::mesh::resolve_mesh`]; symbolic links followed as ROS follows them). A mesh that cannot be
//!   found or read leaves its link colliding as the box of its inertia, with a warning (`strict` does not
//!   refuse it); one whose vertices or hull cannot be allocated fails the load (`Error::TooLarge` naming `mesh`).
//!
//! - `<dynamics damping>` of a moving joint becomes its damping ([`Model::damping`], as Pinocchio's and
//!   MuJoCo's importers read it; 0 if absent; on every coordinate of a `spherical` or `floating` joint, as MuJoCo
//!   damps a ball or free joint); a negative or non-finite value is an error naming the joint.
//!   `friction` (Coulomb joint friction) is not modelled and is ignored.
//!
//! Everything else (`<visual>`, `<safety_controller>`, `<mimic>`, `<material>`,
//! `<transmission>`, `<gazebo>`, ...) is ignored.
//!
//! Naming and ordering: the tree's single root link (the one link that is no joint's child) becomes the
//! base, body 0, fixed to the world or free-floating, its joint named [`crate::ROOT_JOINT`]. Every other link
//! becomes one body **named after the link**, attached to its parent link's body through the link's parent
//! joint, whose `<origin>` is the body's placement and whose name is the body's joint's name. Bodies are
//! numbered as Pinocchio's `buildModelFromUrdf` numbers its joints: depth first from the root, the children
//! of a link in the order of their joints' names (byte by byte, as urdfdom's `std::map` of joints keeps them),
//! whatever the order of the elements in the file. So q and v are Pinocchio's, coordinate for coordinate (a
//! `continuous` joint's q is its angle, where Pinocchio's is its cosine and sine), and a parent always
//! precedes its children.
//!
//! Every problem in the file is an [`Error`] with argument `"urdf"` and a message naming the offending
//! element, e.g. `joint "knee": unknown parent link "thigh2"`. A document, or the model it describes, too
//! large for memory is `Error::TooLarge` naming `"path"` (or `"xml"` for a string), before it is built.
//!
//! What real exporters write and Pinocchio loads, legkit loads too, as written, with a warning in
//! [`Urdf::warnings`] naming the element: an inertia that is not physical (a negative principal moment,
//! or one above the sum of the other two; round-off within [`MassProperties::inertia_problem`]'s
//! tolerance passes silently), and `effort="0"` or `velocity="0"`. With [`UrdfOptions::strict`] these
//! are errors instead.
//!
//! # Examples
//!
//! A pendulum from a URDF string (a file's path loads the same way): a 1 kg bob 0.3 m below a continuous joint about
//! y, so that holding it at angle θ takes m g l sin θ. A joint naming a link the file lacks is an error naming both.
//!
//! ```
//! use legkit_dynamics::urdf::{load_urdf, UrdfOptions};
//! use legkit_dynamics::{algorithms, Data};
//!
//! let xml = r#"<robot name="pendulum">
//!   <link name="world"/>
//!   <link name="bob">
//!     <inertial><origin xyz="0 0 -0.3"/><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
//!   </link>
//!   <joint name="hinge" type="continuous"><parent link="world"/><child link="bob"/><axis xyz="0 1 0"/></joint>
//! </robot>"#;
//! let urdf = load_urdf(xml, &UrdfOptions::default())?;
//! let model = urdf.model;
//! assert_eq!((model.nq(), model.name(1), model.joint_name(1), urdf.warnings.len()), (1, "bob", "hinge", 0));
//! let theta: f64 = 0.5;
//! let hold = algorithms::rnea(&model, &mut Data::new(&model), &[theta], &[0.0], &[0.0], None)?[0];
//! assert!((hold - 9.81 * 0.3 * theta.sin()).abs() < 1e-12);
//! let typo = xml.replace(r#"<parent link="world"/>"#, r#"<parent link="wrld"/>"#);
//! let error = load_urdf(&typo, &UrdfOptions::default()).unwrap_err();
//! assert_eq!(error.to_string(), r#"urdf: joint "hinge": unknown parent link "wrld""#);
//! # Ok::<(), legkit_dynamics::Error>(())
//! ```
//!
//! [`Joint::Revolute`]: crate::Joint::Revolute
//! [`Joint::Prismatic`]: crate::Joint::Prismatic
//! [`Joint::Fixed`]: crate::Joint::Fixed
//! [`Joint::Spherical`]: crate::Joint::Spherical
//! [`JointLimits`]: crate::JointLimits
//! [`MassProperties::inertia_problem`]: crate::MassProperties::inertia_problem

mod build;
mod read;
#[cfg(test)]
mod tests;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::validate::{check_cancelled, filled, with_capacity, CANCEL_INTERVAL};
use crate::{Error, Model, Result};
use read::{collisions, elements, inertial, joint, line, required_name, Link, UrdfJoint};

/// How a URDF becomes a model.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct UrdfOptions {
    /// The base (root link) is free-floating rather than fixed to the world.
    pub floating_base: bool,
    /// What would be a warning (non-physical inertias, zero effort or velocity bounds) is an error.
    pub strict: bool,
    /// Folders holding ROS packages, searched first for `package://` mesh names.
    pub package_dirs: Vec<PathBuf>,
}

/// A URDF read into a model, and what was accepted with a warning (each naming its element).
#[derive(Debug, Clone)]
pub struct Urdf {
    /// The kinematic tree, its inertias, limits and collision shapes.
    pub model: Model,
    /// What was accepted with a warning (an error under `strict`).
    pub warnings: Vec<String>,
}

/// Loads a URDF from a file, or parses it directly if `path_or_xml` (after a byte order mark and blanks)
/// starts with `<`. A file that cannot be read, or that is not a regular file (a FIFO, a device), is an
/// error on argument `"path"`; the [module documentation](self) says what is read, what is accepted with a
/// warning and what is an error. Mesh names in a file resolve against its
/// folder.
pub fn load_urdf(path_or_xml: &str, options: &UrdfOptions) -> Result<Urdf> {
    let text = path_or_xml.strip_prefix(BYTE_ORDER_MARK).unwrap_or(path_or_xml);
    if text.trim_start().starts_with('<') {
        return parse(text, "xml", options, None);
    }
    let bytes = crate::validate::read_regular_file("path", Path::new(path_or_xml))?;
    let xml = String::from_utf8(bytes).map_err(|e| Error::invalid("path", format!("{path_or_xml}: not UTF-8 text: {e}")))?;
    let xml = xml.strip_prefix(BYTE_ORDER_MARK).unwrap_or(&xml);
    let folder = Path::new(path_or_xml).parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p });
    parse(xml, "path", options, folder)
}

/// U+FEFF, which editors on Windows put at the start of UTF-8 files.
const BYTE_ORDER_MARK: char = '\u{feff}';

/// Parses URDF text, as `load_urdf` does, for the tests. Relative mesh names resolve against the working folder.
#[cfg(test)]
fn parse_urdf(xml: &str, options: &UrdfOptions) -> Result<Urdf> {
    parse(xml, "xml", options, None)
}

/// `argument` ("path" or "xml") is what a size that cannot be allocated is reported against.
fn parse(xml: &str, argument: &'static str, options: &UrdfOptions, folder: Option<&Path>) -> Result<Urdf> {
    let mut warnings = Vec::new();
    // Warnings that `strict` does not turn into errors: what legkit cannot read yet.
    let mut notes = Vec::new();
    let mut accept = |problem: String| -> Result<()> {
        if options.strict {
            return Err(invalid(format!("{problem} (strict)")));
        }
        warnings.push(problem);
        Ok(())
    };
    let trimmed = xml.trim_start();
    let moved;
    let xml = if trimmed.len() < xml.len() && trimmed.starts_with("<?xml") {
        // An XML declaration must open the document: move the blank lines before it to just after it, so
        // that line numbers in messages still match the text.
        let end = trimmed.find("?>").map_or(trimmed.len(), |i| i + 2);
        let newlines = xml[..xml.len() - trimmed.len()].matches('\n').count();
        moved = format!("{}{}{}", &trimmed[..end], "\n".repeat(newlines), &trimmed[end..]);
        moved.as_str()
    } else {
        xml
    };
    let doc = crate::xml::parse(xml, argument)?.map_err(invalid)?;
    let robot = doc.root_element();
    if robot.tag_name().name() != "robot" {
        return Err(invalid(format!("the root element must be <robot>, found <{}>", robot.tag_name().name())));
    }

    // Links, by name. Every table below is reserved whole, fallibly, from the counts of links and joints.
    let (nlinks, njoints) = (elements(robot, "link").count(), elements(robot, "joint").count());
    let mut links: Vec<Link> = with_capacity(argument, nlinks)?;
    let mut link_index: HashMap<&str, usize> = HashMap::new();
    link_index.try_reserve(nlinks).map_err(|_| too_large(argument, "links", nlinks))?;
    for (k, node) in elements(robot, "link").enumerate() {
        cancel_point(k)?;
        let name = required_name(node, "link")?;
        if link_index.insert(name, links.len()).is_some() {
            return Err(invalid(format!("link {name:?} is defined twice ({})", line(node))));
        }
        let body = inertial(node, name, &mut accept)?;
        let shapes = collisions(node, name, &body, (folder, &options.package_dirs), &mut notes)?;
        links.push(Link { name, body, shapes });
    }
    if links.is_empty() {
        return Err(invalid("<robot> has no <link>".to_owned()));
    }

    // Joints, and the parent joint of each link.
    let mut joints: Vec<UrdfJoint> = with_capacity(argument, njoints)?;
    let mut joint_names: HashMap<&str, ()> = HashMap::new();
    joint_names.try_reserve(njoints).map_err(|_| too_large(argument, "joints", njoints))?;
    let mut parent_joint: Vec<Option<usize>> = filled(argument, links.len(), None)?;
    for (k, node) in elements(robot, "joint").enumerate() {
        cancel_point(k)?;
        let name = required_name(node, "joint")?;
        if joint_names.insert(name, ()).is_some() {
            return Err(invalid(format!("joint {name:?} is defined twice ({})", line(node))));
        }
        let joint = joint(node, name, &link_index, &mut accept)?;
        if let Some(other) = parent_joint[joint.child] {
            return Err(invalid(format!(
                "link {:?} has two parents: it is the child of joint {:?} and of joint {name:?}",
                links[joint.child].name, joints[other].name
            )));
        }
        parent_joint[joint.child] = Some(joints.len());
        joints.push(joint);
    }

    let model = build::model(&links, &joints, &parent_joint, options, argument)?;
    warnings.extend(notes);
    Ok(Urdf { model, warnings })
}

/// Every `CANCEL_INTERVAL` items of a loop over the document (`k` counts them), fails if the load was
/// cancelled (`validate::cancellable`).
fn cancel_point(k: usize) -> Result<()> {
    if k.is_multiple_of(CANCEL_INTERVAL) {
        check_cancelled("from_urdf")?;
    }
    Ok(())
}

/// The error of a table of `count` `what` that cannot be allocated.
fn too_large(argument: &'static str, what: &str, count: usize) -> Error {
    Error::too_large(argument, format!("cannot allocate the table of {count} {what}"))
}

fn invalid(reason: String) -> Error {
    Error::invalid("urdf", reason)
}
