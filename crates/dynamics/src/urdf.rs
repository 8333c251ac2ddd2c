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

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use roxmltree::Node;

use crate::geometry::{Convex, Shape, ShapeKind};
use crate::mesh::{hull_points, mesh_vertices, resolve_mesh};
use crate::validate::{check_cancelled, direction, filled, with_capacity, CANCEL_INTERVAL};
use crate::{Error, Joint, JointLimits, MassProperties, Model, Result, Transform};

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

    // The root, and Pinocchio's depth-first order from it.
    let roots: Vec<usize> = (0..links.len()).filter(|&l| parent_joint[l].is_none()).collect();
    let root = match roots.as_slice() {
        [root] => *root,
        [] => {
            return Err(invalid(format!(
                "no root link: every link is the child of a joint, so the joints form a cycle ({})",
                describe_cycle(&links, &joints, &parent_joint, 0)
            )))
        }
        _ => {
            let names: Vec<String> = roots.iter().map(|&l| format!("{:?}", links[l].name)).collect();
            return Err(invalid(format!(
                "more than one root link (links that are no joint's child): {}; a URDF must be a single tree",
                names.join(", ")
            )));
        }
    };
    // Each link's child joints by name: `by_parent[first_child[l]..first_child[l + 1]]` (a counting sort,
    // in two tables rather than a vector per link, then each link's joints sorted).
    let mut first_child: Vec<usize> = filled(argument, links.len() + 1, 0)?;
    for joint in &joints {
        first_child[joint.parent + 1] += 1;
    }
    for l in 0..links.len() {
        first_child[l + 1] += first_child[l];
    }
    let mut next: Vec<usize> = filled(argument, links.len(), 0)?;
    next.copy_from_slice(&first_child[..links.len()]);
    let mut by_parent: Vec<usize> = filled(argument, joints.len(), 0)?;
    for (j, joint) in joints.iter().enumerate() {
        by_parent[next[joint.parent]] = j;
        next[joint.parent] += 1;
    }
    for l in 0..links.len() {
        by_parent[first_child[l]..first_child[l + 1]].sort_unstable_by_key(|&j| joints[j].name);
    }

    if let Some(joint) = joints.iter().find(|j| options.floating_base && j.free && j.parent == root) {
        return Err(invalid(format!(
            "joint {:?}: a floating joint out of the root link {:?} with floating_base: the base would float twice (load with a fixed base)",
            joint.name, links[root].name
        )));
    }
    let mut model = Model::new(options.floating_base, links[root].body, links[root].name);
    let floating = joints.iter().filter(|j| j.free).count();
    model.try_reserve(argument, links.len() - 1 + 3 * floating, joints.iter().map(|j| j.joint.nv()).sum::<usize>() + 3 * floating)?;
    let mut body_of_link: Vec<Option<usize>> = filled(argument, links.len(), None)?;
    body_of_link[root] = Some(0);
    // Joints still to add, the next on top: a link's child joints go on in reverse name order, so that the
    // first comes off first, and its subtree before its siblings.
    let mut stack: Vec<usize> = with_capacity(argument, joints.len())?;
    stack.extend(by_parent[first_child[root]..first_child[root + 1]].iter().rev());
    while let Some(j) = stack.pop() {
        cancel_point(model.nbodies())?;
        let joint = &joints[j];
        let child = &links[joint.child];
        let fail = |e: Error| invalid(format!("joint {:?}: {e}", joint.name));
        let (mut parent, mut placement) = (body_of_link[joint.parent].expect("a joint is added after its parent link"), joint.placement);
        if joint.free {
            for (k, axis) in ["x", "y", "z"].iter().zip([Vector3::x(), Vector3::y(), Vector3::z()]) {
                let name = format!("{}/{}:{k}", child.name, joint.name);
                parent = model.add_body(parent, Joint::Prismatic(axis), placement, MassProperties::zero(), &name, JointLimits::NONE).map_err(fail)?;
                placement = Transform::identity();
            }
        }
        let body = model.add_body(parent, joint.joint, placement, child.body, child.name, joint.limits).map_err(fail)?;
        model.set_joint_name(body, joint.name);
        body_of_link[joint.child] = Some(body);
        stack.extend(by_parent[first_child[joint.child]..first_child[joint.child + 1]].iter().rev());
    }
    // With one parent per link and a single root, a link not reached from the root lies on a cycle.
    if let Some(unreached) = body_of_link.iter().position(Option::is_none) {
        return Err(invalid(format!("the joints form a cycle ({}), which is not a tree", describe_cycle(&links, &joints, &parent_joint, unreached))));
    }
    let mut damping = model.damping().to_vec();
    for joint in joints.iter().filter(|j| j.joint.nv() > 0) {
        // A `floating` joint's three slides sit just before its ball, and take its damping too (MuJoCo damps
        // every coordinate of a free or ball joint by its one damping).
        let (slides, end) =
            (if joint.free { 3 } else { 0 }, model.idx_v(body_of_link[joint.child].expect("every link has a body")) + joint.joint.nv());
        damping[end - joint.joint.nv() - slides..end].fill(joint.damping);
    }
    model.set_damping(&damping)?;
    if links.iter().any(|link| !link.shapes.is_empty()) {
        let shapes = links.iter().zip(&body_of_link).flat_map(|(link, body)| {
            let body = body.expect("every link has a body");
            link.shapes.iter().map(move |shape| (body, shape.clone()))
        });
        model.set_collision_shapes(shapes.collect())?;
    }
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

/// URDF's `rpy`: roll about the fixed x axis, then pitch about the fixed y axis, then yaw about the fixed
/// z axis, `R = Rz(yaw) Ry(pitch) Rx(roll)`.
pub(crate) fn rpy_to_matrix(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cr, -sr, 0.0, sr, cr);
    let ry = Matrix3::new(cp, 0.0, sp, 0.0, 1.0, 0.0, -sp, 0.0, cp);
    let rz = Matrix3::new(cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0);
    rz * ry * rx
}

struct Link<'a> {
    name: &'a str,
    body: MassProperties,
    /// Its `<collision>` shapes in the link frame.
    shapes: Vec<Shape>,
}

/// A parsed `<joint>`: only what the model needs, plus the name for messages.
struct UrdfJoint<'a> {
    name: &'a str,
    joint: Joint,
    /// A `floating` joint: three prismatic joints before `joint` (a ball).
    free: bool,
    parent: usize,
    child: usize,
    placement: Transform,
    limits: JointLimits,
    damping: f64,
}

/// The error of a table of `count` `what` that cannot be allocated.
fn too_large(argument: &'static str, what: &str, count: usize) -> Error {
    Error::too_large(argument, format!("cannot allocate the table of {count} {what}"))
}

fn invalid(reason: String) -> Error {
    Error::invalid("urdf", reason)
}

/// The child elements of `node` with tag `tag`, in document order.
fn elements<'a, 'input: 'a>(node: Node<'a, 'input>, tag: &'a str) -> impl Iterator<Item = Node<'a, 'input>> + 'a {
    node.children().filter(move |n| n.is_element() && n.tag_name().name() == tag)
}

/// The first child element of `node` with tag `tag`.
fn element<'a, 'input>(node: Node<'a, 'input>, tag: &str) -> Option<Node<'a, 'input>> {
    node.children().find(|n| n.is_element() && n.tag_name().name() == tag)
}

fn line(node: Node) -> String {
    format!("line {}", node.document().text_pos_at(node.range().start).row)
}

fn required_name<'a>(node: Node<'a, '_>, tag: &str) -> Result<&'a str> {
    match node.attribute("name") {
        Some(name) if !name.trim().is_empty() => Ok(name),
        _ => Err(invalid(format!("a <{tag}> has no name attribute ({})", line(node)))),
    }
}

/// Parses whitespace-separated finite numbers; `what` names the attribute for messages.
fn numbers(text: &str, what: &dyn Fn() -> String) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|token| match token.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            Ok(_) => Err(invalid(format!("{}: {token:?} is not finite", what()))),
            Err(_) => Err(invalid(format!("{}: {token:?} is not a number", what()))),
        })
        .collect()
}

/// The attribute `attr` of `node` as 3 numbers, or `default` if absent.
fn vector3(node: Node, attr: &str, default: Vector3<f64>, owner: &str) -> Result<Vector3<f64>> {
    let Some(text) = node.attribute(attr) else { return Ok(default) };
    let what = || format!("{owner}: <{} {attr}=\"{text}\">", node.tag_name().name());
    let values = numbers(text, &what)?;
    if values.len() != 3 {
        return Err(invalid(format!("{}: expected 3 numbers, found {}", what(), values.len())));
    }
    Ok(Vector3::new(values[0], values[1], values[2]))
}

/// The required single-number attribute `attr` of `node`.
fn scalar(node: Node, attr: &str, owner: &str) -> Result<f64> {
    let tag = node.tag_name().name();
    let Some(text) = node.attribute(attr) else {
        return Err(invalid(format!("{owner}: <{tag}> has no {attr} attribute")));
    };
    let what = || format!("{owner}: <{tag} {attr}=\"{text}\">");
    match numbers(text, &what)?.as_slice() {
        [x] => Ok(*x),
        values => Err(invalid(format!("{}: expected 1 number, found {}", what(), values.len()))),
    }
}

/// The `<origin>` child of `node` as a transform (identity if absent).
fn origin(node: Node, owner: &str) -> Result<Transform> {
    let Some(origin) = element(node, "origin") else { return Ok(Transform::identity()) };
    let xyz = vector3(origin, "xyz", Vector3::zeros(), owner)?;
    let rpy = vector3(origin, "rpy", Vector3::zeros(), owner)?;
    Ok(Transform::new(rpy_to_matrix(rpy.x, rpy.y, rpy.z), xyz))
}

/// The mass properties of a `<link>` in the link frame; a non-physical inertia goes to `accept`.
fn inertial(link: Node, name: &str, accept: &mut dyn FnMut(String) -> Result<()>) -> Result<MassProperties> {
    let owner = format!("link {name:?}");
    let Some(inertial) = element(link, "inertial") else { return Ok(MassProperties::zero()) };
    let frame = origin(inertial, &owner)?;
    let Some(mass_node) = element(inertial, "mass") else {
        return Err(invalid(format!("{owner}: <inertial> has no <mass>")));
    };
    let mass = scalar(mass_node, "value", &owner)?;
    if mass < 0.0 {
        return Err(invalid(format!("{owner}: mass must be >= 0, got {mass}")));
    }
    let Some(inertia_node) = element(inertial, "inertia") else {
        return Err(invalid(format!("{owner}: <inertial> has no <inertia>")));
    };
    let mut moments = [0.0; 6];
    for (value, attr) in moments.iter_mut().zip(["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]) {
        *value = scalar(inertia_node, attr, &owner)?;
    }
    let [ixx, ixy, ixz, iyy, iyz, izz] = moments;
    let inertia = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
    if let Some(problem) = MassProperties::inertia_problem(&inertia) {
        accept(format!("{owner}: non-physical <inertial> ({problem}), kept as written"))?;
    }
    MassProperties::as_written(mass, Vector3::zeros(), inertia)
        .and_then(|body| body.transformed(&frame.rotation, &frame.translation))
        .map_err(|e| invalid(format!("{owner}: <inertial>: {e}")))
}

/// The `<collision>` shapes of a `<link>` in the link frame. A mesh that cannot be found or read leaves the
/// link colliding as the box of its inertia (`Shape::default_box`), and `notes` says so.
fn collisions(
    link: Node,
    name: &str,
    body: &MassProperties,
    (folder, package_dirs): (Option<&Path>, &[PathBuf]),
    notes: &mut Vec<String>,
) -> Result<Vec<Shape>> {
    let owner = format!("link {name:?}");
    let mut shapes = Vec::new();
    let mut unread = Vec::new();
    for collision in elements(link, "collision") {
        let placement = origin(collision, &owner)?;
        let Some(geometry) = element(collision, "geometry").and_then(|g| g.children().find(|c| c.is_element())) else {
            return Err(invalid(format!("{owner}: <collision> has no <geometry> ({})", line(collision))));
        };
        let half_length = |g: Node| -> Result<f64> { Ok(0.5 * scalar(g, "length", &owner)?) };
        let kind = match geometry.tag_name().name() {
            "box" => ShapeKind::Box(vector3(geometry, "size", Vector3::zeros(), &owner)?),
            "sphere" => ShapeKind::Sphere(scalar(geometry, "radius", &owner)?),
            "cylinder" => ShapeKind::Cylinder { half_height: half_length(geometry)?, radius: scalar(geometry, "radius", &owner)? },
            "capsule" => ShapeKind::Capsule { half_height: half_length(geometry)?, radius: scalar(geometry, "radius", &owner)? },
            "mesh" => {
                let filename = geometry.attribute("filename").unwrap_or("");
                let scale = vector3(geometry, "scale", Vector3::repeat(1.0), &owner)?;
                // Reading a mesh and taking its hull may take long: a cancelled load stops before the next.
                check_cancelled("from_urdf")?;
                let hull = resolve_mesh(filename, folder, package_dirs).and_then(|path| mesh_vertices(&path)).and_then(|mut vertices| {
                    vertices.iter_mut().for_each(|v| v.component_mul_assign(&scale));
                    let (points, thinned) = hull_points(&vertices)?;
                    notes.extend(thinned.map(|note| format!("{owner}: <collision> mesh {filename:?}: {note}")));
                    Convex::hull(&points)
                });
                match hull {
                    Ok(convex) => ShapeKind::Convex(convex),
                    // A mesh too large for memory is no unreadable file: the load fails (MemoryError), not the mesh.
                    Err(Error::TooLarge { reason, .. }) => return Err(Error::too_large("mesh", format!("{owner}: {filename:?}: {reason}"))),
                    Err(e) => {
                        unread.push(format!("{filename:?} ({e})"));
                        continue;
                    }
                }
            }
            other => return Err(invalid(format!("{owner}: <collision> has an unknown geometry <{other}> ({})", line(geometry)))),
        };
        shapes.push(Shape::new(kind, Some(placement)).map_err(|e| invalid(format!("{owner}: <collision> <{}>: {e}", geometry.tag_name().name())))?);
    }
    if !unread.is_empty() {
        notes.push(format!("{owner}: <collision> meshes not read: {}; it collides as the box of its inertia", unread.join(", ")));
        shapes.extend(Shape::default_box(body));
    }
    Ok(shapes)
}

/// A `<joint>`, its links resolved to indices.
fn joint<'a>(
    node: Node<'a, '_>,
    name: &'a str,
    link_index: &HashMap<&str, usize>,
    accept: &mut dyn FnMut(String) -> Result<()>,
) -> Result<UrdfJoint<'a>> {
    let owner = format!("joint {name:?}");
    let link = |tag: &str| -> Result<usize> {
        let link = element(node, tag).and_then(|e| e.attribute("link")).ok_or_else(|| invalid(format!("{owner}: missing <{tag} link=\"...\"/>")))?;
        link_index.get(link).copied().ok_or_else(|| invalid(format!("{owner}: unknown {tag} link {link:?}")))
    };
    let parent = link("parent")?;
    let child = link("child")?;
    let placement = origin(node, &owner)?;
    let axis = || -> Result<Vector3<f64>> {
        let axis = match element(node, "axis") {
            Some(axis) => vector3(axis, "xyz", Vector3::x(), &owner)?,
            None => Vector3::x(),
        };
        direction("axis", axis).map_err(|e| invalid(format!("{owner}: <axis xyz=\"{} {} {}\">: {e}", axis.x, axis.y, axis.z)))
    };
    let (joint, bounded) = match node.attribute("type") {
        Some("revolute") => (Joint::Revolute(axis()?), true),
        Some("continuous") => (Joint::Revolute(axis()?), false),
        Some("prismatic") => (Joint::Prismatic(axis()?), true),
        Some("fixed") => (Joint::Fixed, false),
        Some("floating") => (Joint::Spherical, false),
        Some("spherical") => {
            accept(format!("{owner}: type \"spherical\" is not in the URDF specification; read as a ball joint"))?;
            (Joint::Spherical, false)
        }
        Some(other) => {
            return Err(invalid(format!(
                "{owner}: unsupported type {other:?} (supported: revolute, continuous, prismatic, fixed, floating, spherical)"
            )))
        }
        None => return Err(invalid(format!("{owner}: has no type attribute"))),
    };
    // Only a one-coordinate joint reads `<limit>`; every moving joint reads `<dynamics>`.
    let limits = match element(node, "limit") {
        Some(limit) if joint.nv() == 1 => limits(limit, bounded, &owner, accept)?,
        _ => JointLimits::NONE,
    };
    let damping = match element(node, "dynamics") {
        Some(dynamics) if joint.nv() > 0 && dynamics.attribute("damping").is_some() => {
            let damping = scalar(dynamics, "damping", &owner)?;
            if damping < 0.0 {
                return Err(invalid(format!("{owner}: <dynamics damping> must be >= 0, got {damping}")));
            }
            damping
        }
        _ => 0.0,
    };
    let free = node.attribute("type") == Some("floating");
    Ok(UrdfJoint { name, joint, free, parent, child, placement, limits, damping })
}

/// A moving joint's `<limit>`: the position range if `bounded` (attributes default to 0, as URDF says),
/// effort and velocity bounds if given (+inf if absent, or 0 after a warning to `accept`).
fn limits(limit: Node, bounded: bool, owner: &str, accept: &mut dyn FnMut(String) -> Result<()>) -> Result<JointLimits> {
    let optional = |attr: &str, default: f64| -> Result<f64> {
        if limit.attribute(attr).is_some() {
            scalar(limit, attr, owner)
        } else {
            Ok(default)
        }
    };
    let (lower, upper) = if bounded { (optional("lower", 0.0)?, optional("upper", 0.0)?) } else { (f64::NEG_INFINITY, f64::INFINITY) };
    // A zero bound is an exporter's "unset"; anything else `JointLimits::new` checks.
    let mut bound = |attr: &str| -> Result<f64> {
        let value = optional(attr, f64::INFINITY)?;
        if value == 0.0 {
            accept(format!("{owner}: <limit> {attr}=\"0\" read as no bound"))?;
            return Ok(f64::INFINITY);
        }
        Ok(value)
    };
    let (effort, velocity) = (bound("effort")?, bound("velocity")?);
    JointLimits::new(lower, upper, effort, velocity).map_err(|e| invalid(format!("{owner}: <limit>: {e}")))
}

/// Follows parent joints from link `start` until a link repeats; describes that cycle.
fn describe_cycle(links: &[Link], joints: &[UrdfJoint], parent_joint: &[Option<usize>], start: usize) -> String {
    let mut path = vec![start];
    let mut link = start;
    while let Some(j) = parent_joint[link] {
        link = joints[j].parent;
        if let Some(first) = path.iter().position(|&l| l == link) {
            // Listed parent -> child: the walk went child -> parent.
            let mut cycle: Vec<String> = path[first..].iter().map(|&l| format!("{:?}", links[l].name)).collect();
            cycle.push(format!("{:?}", links[link].name));
            cycle.reverse();
            return format!("parent -> child: {}", cycle.join(" -> "));
        }
        path.push(link);
    }
    // Unreachable for the callers (every link on the walk has a parent), kept total for safety.
    format!("through link {:?}", links[start].name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mass::tests::brute_force;
    use nalgebra::{Rotation3, Unit};
    use std::f64::consts::FRAC_PI_2;

    const FIXED: &UrdfOptions = &UrdfOptions { floating_base: false, strict: false, package_dirs: Vec::new() };
    const FLOATING: &UrdfOptions = &UrdfOptions { floating_base: true, strict: false, package_dirs: Vec::new() };

    const TOL: f64 = 1e-12;

    fn close(a: &Matrix3<f64>, b: &Matrix3<f64>, tol: f64) -> bool {
        (a - b).amax() <= tol
    }

    fn close3(a: &Vector3<f64>, b: &Vector3<f64>, tol: f64) -> bool {
        (a - b).amax() <= tol
    }

    /// Independent of `rpy_to_matrix`: nalgebra's Euler angles, checked against URDF's convention below.
    fn expected_placement(xyz: [f64; 3], rpy: [f64; 3]) -> Transform {
        Transform::new(Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner(), Vector3::new(xyz[0], xyz[1], xyz[2]))
    }

    fn assert_placement(model: &Model, body: usize, expected: &Transform) {
        let p = model.placement(body);
        assert!(close(&p.rotation, &expected.rotation, TOL), "body {body}: {:?} vs {:?}", p.rotation, expected.rotation);
        assert!(close3(&p.translation, &expected.translation, TOL), "body {body}: {:?}", p.translation);
    }

    fn inertia_attrs(i: &Matrix3<f64>) -> String {
        format!(r#"ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}""#, i[(0, 0)], i[(0, 1)], i[(0, 2)], i[(1, 1)], i[(1, 2)], i[(2, 2)])
    }

    #[test]
    fn nalgebra_euler_angles_and_rpy_to_matrix_follow_urdfs_fixed_axis_convention() {
        // URDF: roll about the fixed x, then pitch about the fixed y, then yaw about the fixed z, so
        // R = Rz(yaw) Ry(pitch) Rx(roll). nalgebra documents from_euler_angles as "roll, then pitch, then
        // yaw" about fixed axes; check both against the product of elementary rotations.
        let about = |axis: Vector3<f64>, angle: f64| Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle);
        for &(r, p, y) in &[(0.3, -0.7, 1.1), (-1.2, 0.4, 2.5), (2.9, 1.4, -3.0), (0.0, 0.0, 0.0)] {
            let product = (about(Vector3::z(), y) * about(Vector3::y(), p) * about(Vector3::x(), r)).into_inner();
            assert!(close(&Rotation3::from_euler_angles(r, p, y).into_inner(), &product, TOL));
            assert!(close(&rpy_to_matrix(r, p, y), &product, TOL));
        }
        // Concrete cases that tell the conventions apart: yaw takes x to y, roll takes y to z, and roll
        // then pitch (fixed axes) takes y to z and then z to x; the moving-axis Rx Ry would give z.
        assert!(close3(&(rpy_to_matrix(0.0, 0.0, FRAC_PI_2) * Vector3::x()), &Vector3::y(), TOL));
        assert!(close3(&(rpy_to_matrix(FRAC_PI_2, 0.0, 0.0) * Vector3::y()), &Vector3::z(), TOL));
        assert!(close3(&(rpy_to_matrix(FRAC_PI_2, FRAC_PI_2, 0.0) * Vector3::y()), &Vector3::x(), TOL));
    }

    fn pendulum_xml() -> (String, Vector3<f64>, Matrix3<f64>, Matrix3<f64>, f64) {
        // The upper link's body is a cloud of point masses given in its inertial frame (COM at the origin).
        let masses = [1.0, 2.0, 0.5, 1.5];
        let raw = [Vector3::new(0.3, 0.1, -0.2), Vector3::new(-0.1, 0.4, 0.05), Vector3::new(0.2, -0.3, 0.6), Vector3::new(-0.25, -0.1, -0.3)];
        let (_, c, _) = brute_force(&masses, &raw);
        let points: Vec<Vector3<f64>> = raw.iter().map(|p| p - c).collect();
        let (_, _, inertia_local) = brute_force(&masses, &points);
        let mass: f64 = masses.iter().sum();
        // Brute force in the link frame: move every point by the inertial origin and recompute.
        let (rpy, xyz) = ([0.3, -0.7, 1.1], Vector3::new(0.1, -0.2, 0.3));
        let rot = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner();
        let moved: Vec<Vector3<f64>> = points.iter().map(|p| rot * p + xyz).collect();
        let (_, com_link, inertia_link) = brute_force(&masses, &moved);
        let xml = format!(
            r#"<?xml version="1.0"?>
            <robot name="pendulum">
              <link name="base">
                <inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
              </link>
              <link name="upper">
                <visual><geometry><box size="0.1 0.1 1"/></geometry></visual>
                <inertial>
                  <origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.7 1.1"/>
                  <mass value="{mass}"/>
                  <inertia {attrs}/>
                </inertial>
              </link>
              <link name="lower">
                <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.025"/></inertial>
              </link>
              <joint name="shoulder" type="revolute">
                <parent link="base"/><child link="upper"/>
                <origin xyz="0 0 1" rpy="0.1 0.2 0.3"/>
                <axis xyz="0 2 0"/>
                <limit lower="-1" upper="1" effort="10" velocity="1"/>
              </joint>
              <joint name="elbow" type="continuous">
                <parent link="upper"/><child link="lower"/>
                <origin xyz="0.5 0 -0.25" rpy="-1.2 0.4 2.5"/>
                <axis xyz="1 1 0"/>
              </joint>
            </robot>"#,
            attrs = inertia_attrs(&inertia_local)
        );
        (xml, com_link, inertia_link, inertia_local, mass)
    }

    #[test]
    fn two_link_pendulum_structure_placements_axes_and_inertials() {
        let (xml, com_link, inertia_link, inertia_local, mass) = pendulum_xml();
        let model = parse_urdf(&xml, FIXED).unwrap().model;
        assert_eq!(model.nbodies(), 3);
        assert_eq!((model.nq(), model.nv()), (2, 2));
        assert!(!model.floating_base());
        assert_eq!([model.name(0), model.name(1), model.name(2)], ["base", "upper", "lower"]);
        assert_eq!([model.parent(1), model.parent(2)], [0, 1]);
        assert_eq!(*model.joint(0), Joint::Fixed);

        assert_placement(&model, 0, &Transform::identity());
        assert_placement(&model, 1, &expected_placement([0.0, 0.0, 1.0], [0.1, 0.2, 0.3]));
        assert_placement(&model, 2, &expected_placement([0.5, 0.0, -0.25], [-1.2, 0.4, 2.5]));

        // Axes are normalised.
        let Joint::Revolute(a1) = *model.joint(1) else { panic!("{:?}", model.joint(1)) };
        assert!(close3(&a1, &Vector3::new(0.0, 1.0, 0.0), TOL));
        let Joint::Revolute(a2) = *model.joint(2) else { panic!("{:?}", model.joint(2)) };
        let s = 0.5f64.sqrt();
        assert!(close3(&a2, &Vector3::new(s, s, 0.0), TOL));

        // The rotated, offset inertial agrees with the brute force over the moved point cloud.
        let upper = model.body(1);
        assert!((upper.mass() - mass).abs() < TOL);
        assert!(close3(&upper.com(), &com_link, 1e-12));
        assert!(close(&upper.inertia(), &inertia_link, 1e-12), "{:?} vs {:?}", upper.inertia(), inertia_link);
        // and it really was rotated: the inertia in the inertial frame is far from it.
        assert!(!close(&upper.inertia(), &inertia_local, 1e-2));

        // No <origin> in <inertial>: the inertia is taken as is, the COM at the link origin.
        let lower = model.body(2);
        assert_eq!(lower.mass(), 1.0);
        assert_eq!(lower.com(), Vector3::zeros());
        assert_eq!(lower.inertia(), Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.025)));
        assert_eq!(model.body(0).mass(), 2.0);
        assert!((model.total_mass() - (3.0 + mass)).abs() < TOL);
    }

    #[test]
    fn branching_tree_listed_in_scrambled_order_is_numbered_parent_before_child() {
        let legs = ["FL", "FR", "RL", "RR"];
        let chain = ["hip", "thigh", "calf", "foot"];
        let mut links = vec!["trunk".to_owned(), "imu".to_owned()];
        // (joint name, type, parent link, child link)
        let mut joints = vec![("imu_joint".to_owned(), "fixed", "trunk".to_owned(), "imu".to_owned())];
        for leg in legs {
            let mut parent = "trunk".to_owned();
            for (k, part) in chain.iter().enumerate() {
                let child = format!("{leg}_{part}");
                let kind = if k == 3 { "fixed" } else { "revolute" };
                joints.push((format!("{leg}_{part}_joint"), kind, parent.clone(), child.clone()));
                links.push(child.clone());
                parent = child;
            }
        }
        let expected_parent: HashMap<String, String> = joints.iter().map(|(_, _, parent, child)| (child.clone(), parent.clone())).collect();
        // Scramble: links and joints deepest first, interleaved, with the root link in the middle.
        links.reverse();
        links.rotate_left(7);
        joints.reverse();
        let mut body = String::new();
        for k in 0..links.len().max(joints.len()) {
            if let Some((name, kind, parent, child)) = joints.get(k) {
                body += &format!(
                    r#"<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>
                       <origin xyz="0.1 0.2 -0.3" rpy="0.1 0 0"/><axis xyz="0 1 0"/></joint>"#
                );
            }
            if let Some(name) = links.get(k) {
                body += &format!(
                    r#"<link name="{name}"><inertial><mass value="0.5"/>
                       <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>"#
                );
            }
        }
        let xml = format!("<robot name=\"dog\">{body}</robot>");
        // The scramble did put children before parents in the file.
        assert!(xml.find("name=\"FL_foot\"").unwrap() < xml.find("name=\"FL_hip\"").unwrap());
        assert!(xml.find("name=\"FL_foot_joint\"").unwrap() < xml.find("name=\"FL_hip_joint\"").unwrap());

        for floating in [false, true] {
            let model = parse_urdf(&xml, &UrdfOptions { floating_base: floating, ..Default::default() }).unwrap().model;
            assert_eq!(model.nbodies(), 18);
            assert_eq!(model.name(0), "trunk");
            let moving = 12;
            let (nq, nv) = if floating { (7 + moving, 6 + moving) } else { (moving, moving) };
            assert_eq!((model.nq(), model.nv()), (nq, nv));
            for i in 1..model.nbodies() {
                assert!(model.parent(i) < i, "body {i} ({}) has parent {}", model.name(i), model.parent(i));
                assert_eq!(model.name(model.parent(i)), expected_parent[model.name(i)], "body {}", model.name(i));
            }
            let mut names: Vec<&str> = (0..model.nbodies()).map(|i| model.name(i)).collect();
            names.sort_unstable();
            let mut all: Vec<&str> = links.iter().map(String::as_str).collect();
            all.sort_unstable();
            assert_eq!(names, all);
        }
    }

    #[test]
    fn joints_are_numbered_as_pinocchio_numbers_them_depth_first_siblings_by_joint_name() {
        // (joint, parent link, child link, type) in file order; sibling joints out of name order, a fixed joint
        // with a moving child, and names where byte order differs from case-blind order ("Z_h" < "a_c").
        let joints = [
            ("z_b", "root", "B", "revolute"),
            ("a_c", "root", "C", "revolute"),
            ("m_d", "B", "D", "revolute"),
            ("b_e", "C", "E", "revolute"),
            ("f_f", "root", "F", "fixed"),
            ("c_g", "F", "G", "revolute"),
            ("Z_h", "root", "H", "revolute"),
        ];
        let mut body: String = ["G", "root", "B", "C", "D", "E", "F", "H"].iter().map(|l| format!(r#"<link name="{l}"/>"#)).collect();
        for (name, parent, child, kind) in joints {
            body += &format!(r#"<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/><axis xyz="0 0 1"/></joint>"#);
        }
        let xml = format!("<robot name=\"order\">{body}</robot>");
        for floating in [false, true] {
            let model = parse_urdf(&xml, &UrdfOptions { floating_base: floating, ..Default::default() }).unwrap().model;
            // What pin.buildModelFromUrdf gives for this file (model.names[1:], and the bodies of model.frames).
            let joint_names: Vec<&str> = (0..model.nbodies()).map(|i| model.joint_name(i)).collect();
            assert_eq!(joint_names, [crate::ROOT_JOINT, "Z_h", "a_c", "b_e", "f_f", "c_g", "z_b", "m_d"]);
            let body_names: Vec<&str> = (0..model.nbodies()).map(|i| model.name(i)).collect();
            assert_eq!(body_names, ["root", "H", "C", "E", "F", "G", "B", "D"]);
            for (i, name) in joint_names.iter().enumerate() {
                assert_eq!(model.joint_index(name), Some(i));
            }
            assert_eq!(model.joint_index("B"), None);
        }
    }

    #[test]
    fn fixed_continuous_and_prismatic_joints_and_floating_base() {
        let xml = r#"
            <robot name="mixed">
              <link name="root"><inertial><mass value="3"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
              <link name="bracket"/>
              <link name="wheel"><inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
              <link name="slider"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
              <link name="tip"><inertial><origin xyz="0 0 0.2"/><mass value="0.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
              <joint name="mount" type="fixed">
                <parent link="root"/><child link="bracket"/><origin xyz="0 0 0.5"/><axis xyz="0 0 0"/>
              </joint>
              <joint name="spin" type="continuous"><parent link="bracket"/><child link="wheel"/></joint>
              <joint name="slide" type="prismatic">
                <parent link="wheel"/><child link="slider"/><origin rpy="0 0 1.5707963267948966"/><axis xyz="0 0 -3"/>
              </joint>
              <joint name="twist" type="revolute"><parent link="slider"/><child link="tip"/><axis xyz="0 0 1"/></joint>
              <transmission name="t"><joint name="spin"/><actuator name="m"/></transmission>
            </robot>"#;
        let model = parse_urdf(xml, FIXED).unwrap().model;
        assert_eq!(model.nbodies(), 5);
        assert_eq!((model.nq(), model.nv()), (3, 3));
        assert_eq!(*model.joint(1), Joint::Fixed);
        // Continuous joint without <axis>: the default x axis; without <origin>: identity.
        assert_eq!(*model.joint(2), Joint::Revolute(Vector3::x()));
        assert_placement(&model, 2, &Transform::identity());
        let Joint::Prismatic(axis) = *model.joint(3) else { panic!("{:?}", model.joint(3)) };
        assert!(close3(&axis, &-Vector3::z(), TOL));
        assert_placement(&model, 3, &expected_placement([0.0; 3], [0.0, 0.0, FRAC_PI_2]));
        assert_eq!(*model.joint(4), Joint::Revolute(Vector3::z()));
        assert_placement(&model, 1, &expected_placement([0.0, 0.0, 0.5], [0.0; 3]));
        // Massless links: no <inertial>, or mass 0.
        assert!(model.body(1).is_zero() && model.body(2).is_zero());
        assert_eq!(model.body(4).com(), Vector3::new(0.0, 0.0, 0.2));
        assert_eq!([model.idx_q(2), model.idx_q(3), model.idx_q(4)], [0, 1, 2]);

        let floating = parse_urdf(xml, FLOATING).unwrap().model;
        assert!(floating.floating_base());
        assert_eq!(*floating.joint(0), Joint::FreeFlyer);
        assert_eq!((floating.nq(), floating.nv()), (7 + 3, 6 + 3));
        assert_eq!(floating.nbodies(), 5);
        assert_eq!(floating.name(0), "root");
    }

    #[test]
    fn a_cancelled_load_stops_and_an_uncancelled_one_is_unchanged() {
        use std::sync::atomic::{AtomicBool, Ordering};
        use std::sync::Arc;
        let links: String = (1..3000)
            .map(|i| format!(r#"<link name="l{i}"/><joint name="j{i}" type="fixed"><parent link="l{}"/><child link="l{i}"/></joint>"#, i - 1))
            .collect();
        let xml = format!(r#"<robot name="r"><link name="l0"/>{links}</robot>"#);
        let flag = Arc::new(AtomicBool::new(false));
        let loaded = crate::validate::cancellable(Arc::clone(&flag), || parse_urdf(&xml, FIXED)).unwrap();
        assert_eq!(loaded.model.nbodies(), 3000);
        flag.store(true, Ordering::Relaxed);
        let error = crate::validate::cancellable(Arc::clone(&flag), || parse_urdf(&xml, FIXED)).unwrap_err();
        assert!(error.to_string().contains("cancelled"), "{error}");
        // Outside `cancellable` the flag is not this thread's.
        assert_eq!(parse_urdf(&xml, FIXED).unwrap().model.nbodies(), 3000);
    }

    #[test]
    fn load_urdf_reads_files_and_inline_xml() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/two_link_pendulum.urdf");
        let from_file = load_urdf(path, FIXED).unwrap().model;
        let text = std::fs::read_to_string(path).unwrap();
        let inline = load_urdf(&format!("\n  {text}"), FIXED).unwrap().model;
        assert_eq!(from_file.nbodies(), 3);
        assert_eq!((from_file.nq(), from_file.nv()), (2, 2));
        assert_eq!(from_file.name(2), "forearm");
        assert_placement(&from_file, 2, &Transform::from_translation(Vector3::new(0.0, 0.0, -1.0)));
        assert_eq!(from_file.body(2).com(), Vector3::new(0.0, 0.0, -0.5));
        for i in 0..3 {
            assert_eq!(from_file.placement(i), inline.placement(i));
            assert_eq!(from_file.body(i), inline.body(i));
            assert_eq!(from_file.name(i), inline.name(i));
        }

        let missing = load_urdf("/nonexistent/robot.urdf", FIXED).unwrap_err();
        assert_eq!(missing.argument(), "path");
        assert!(missing.to_string().contains("/nonexistent/robot.urdf"), "{missing}");
    }

    /// Parses `xml`, expecting an error on argument "urdf" whose message contains every one of `needles`.
    fn assert_fails(xml: &str, needles: &[&str]) {
        let error = match parse_urdf(xml, &UrdfOptions { strict: true, ..Default::default() }) {
            Ok(urdf) => panic!("expected an error containing {needles:?}, got a model with {} bodies", urdf.model.nbodies()),
            Err(e) => e,
        };
        assert_eq!(error.argument(), "urdf");
        let message = error.to_string();
        for needle in needles {
            assert!(message.contains(needle), "{message:?} does not contain {needle:?}");
        }
    }

    const INERTIA: &str = r#"<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>"#;

    /// A robot with links `a` and `b` joined by revolute `j`, plus `extra`.
    fn robot(extra: &str) -> String {
        format!(
            r#"<robot name="r"><link name="a"/><link name="b"/>
               <joint name="j" type="revolute"><parent link="a"/><child link="b"/></joint>{extra}</robot>"#
        )
    }

    /// A robot whose only link `heavy` has the given inertial contents.
    fn inertial_robot(inertial: &str) -> String {
        format!(r#"<robot name="r"><link name="heavy"><inertial>{inertial}</inertial></link></robot>"#)
    }

    fn joint_robot(joint: &str) -> String {
        format!(r#"<robot name="r"><link name="a"/><link name="b"/>{joint}</robot>"#)
    }

    #[test]
    fn the_helpers_build_valid_robots() {
        // So that each error below is due to its one defect.
        assert_eq!(parse_urdf(&robot(""), FIXED).unwrap().model.nbodies(), 2);
        let ok = inertial_robot(&format!(r#"<mass value="1"/>{INERTIA}"#));
        assert_eq!(parse_urdf(&ok, FIXED).unwrap().model.body(0).mass(), 1.0);
        let ok = joint_robot(r#"<joint name="j" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>"#);
        assert_eq!(parse_urdf(&ok, FIXED).unwrap().model.nv(), 1);
    }

    #[test]
    fn malformed_documents_are_errors() {
        assert_fails("not xml at all", &["not valid XML"]);
        assert_fails("<robot name=\"r\"><link name=\"a\">", &["not valid XML"]);
        assert_fails(r#"<model name="m"><link name="a"/></model>"#, &["<robot>", "<model>"]);
        assert_fails(r#"<robot name="r"/>"#, &["no <link>"]);
        assert_fails(r#"<robot name="r"><link/></robot>"#, &["<link> has no name", "line 1"]);
        // Blank lines before an XML declaration are tolerated and counted.
        assert_fails("\n\n<?xml version=\"1.0\"?>\n<robot name=\"r\">\n<link/></robot>", &["no name", "line 5"]);
        assert_fails(&robot(r#"<joint type="fixed"><parent link="a"/><child link="b"/></joint>"#), &["<joint> has no name"]);
    }

    #[test]
    fn duplicate_and_unknown_names_are_errors() {
        assert_fails(&robot(r#"<link name="a"/>"#), &[r#"link "a" is defined twice"#]);
        assert_fails(
            &robot(r#"<link name="c"/><joint name="j" type="fixed"><parent link="b"/><child link="c"/></joint>"#),
            &[r#"joint "j" is defined twice"#],
        );
        assert_fails(
            &joint_robot(r#"<joint name="knee" type="revolute"><parent link="thigh2"/><child link="b"/></joint>"#),
            &[r#"joint "knee": unknown parent link "thigh2""#],
        );
        assert_fails(
            &joint_robot(r#"<joint name="knee" type="revolute"><parent link="a"/><child link="shin"/></joint>"#),
            &[r#"joint "knee": unknown child link "shin""#],
        );
        assert_fails(&joint_robot(r#"<joint name="knee" type="revolute"><child link="b"/></joint>"#), &[r#"joint "knee": missing <parent"#]);
        assert_fails(&joint_robot(r#"<joint name="knee" type="revolute"><parent link="a"/><child/></joint>"#), &[r#"joint "knee": missing <child"#]);
    }

    #[test]
    fn non_tree_structures_are_errors() {
        // A link with two parents.
        assert_fails(
            &robot(
                r#"<link name="c"/><joint name="j1" type="fixed"><parent link="a"/><child link="c"/></joint>
                      <joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint>"#,
            ),
            &[r#"link "c" has two parents"#, r#""j1""#, r#""j2""#],
        );
        // A cycle beside a proper root.
        assert_fails(
            r#"<robot name="r"><link name="root"/><link name="x"/><link name="y"/>
               <joint name="j1" type="fixed"><parent link="x"/><child link="y"/></joint>
               <joint name="j2" type="fixed"><parent link="y"/><child link="x"/></joint></robot>"#,
            &["cycle", r#""x" -> "y" -> "x""#],
        );
        // A joint from a link to itself.
        assert_fails(
            r#"<robot name="r"><link name="root"/><link name="x"/>
               <joint name="j" type="fixed"><parent link="x"/><child link="x"/></joint></robot>"#,
            &["cycle", r#""x" -> "x""#],
        );
        // No root at all.
        assert_fails(
            r#"<robot name="r"><link name="x"/><link name="y"/>
               <joint name="j1" type="fixed"><parent link="x"/><child link="y"/></joint>
               <joint name="j2" type="fixed"><parent link="y"/><child link="x"/></joint></robot>"#,
            &["no root link", "cycle", r#""x""#, r#""y""#],
        );
        // Two roots.
        assert_fails(&robot(r#"<link name="island"/>"#), &["more than one root link", r#""a""#, r#""island""#]);
    }

    #[test]
    fn bad_inertials_are_errors_naming_the_link() {
        let link = r#"link "heavy""#;
        assert_fails(&inertial_robot(&format!(r#"<mass value="-1"/>{INERTIA}"#)), &[link, "mass must be >= 0"]);
        assert_fails(&inertial_robot(&format!(r#"<mass value="nan"/>{INERTIA}"#)), &[link, "not finite"]);
        assert_fails(&inertial_robot(&format!(r#"<mass value="inf"/>{INERTIA}"#)), &[link, "not finite"]);
        assert_fails(&inertial_robot(&format!(r#"<mass value="heavy"/>{INERTIA}"#)), &[link, "not a number"]);
        assert_fails(&inertial_robot(&format!(r#"<mass value="1 2"/>{INERTIA}"#)), &[link, "expected 1 number"]);
        assert_fails(&inertial_robot(&format!(r#"<mass/>{INERTIA}"#)), &[link, "no value attribute"]);
        assert_fails(&inertial_robot(INERTIA), &[link, "no <mass>"]);
        assert_fails(&inertial_robot(r#"<mass value="1"/>"#), &[link, "no <inertia>"]);
        // Principal moments 1, 1, 3 violate the triangle inequality.
        let triangle = r#"<mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"/>"#;
        assert_fails(&inertial_robot(triangle), &[link, "non-physical", "inertia"]);
        let negative = r#"<mass value="1"/><inertia ixx="-1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>"#;
        assert_fails(&inertial_robot(negative), &[link, "non-physical"]);
        let unparsable = r#"<mass value="1"/><inertia ixx="abc" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>"#;
        assert_fails(&inertial_robot(unparsable), &[link, "ixx", "not a number"]);
        let missing = r#"<mass value="1"/><inertia ixx="1" ixz="0" iyy="1" iyz="0" izz="1"/>"#;
        assert_fails(&inertial_robot(missing), &[link, "no ixy attribute"]);
        let short_rpy = format!(r#"<origin rpy="0 1"/><mass value="1"/>{INERTIA}"#);
        assert_fails(&inertial_robot(&short_rpy), &[link, "rpy", "expected 3 numbers, found 2"]);
    }

    #[test]
    fn limits_are_read_per_joint_type() {
        let (xml, ..) = pendulum_xml();
        let model = parse_urdf(&xml, FIXED).unwrap().model;
        assert_eq!(*model.limits(0), JointLimits::NONE);
        assert_eq!(*model.limits(1), JointLimits { lower: -1.0, upper: 1.0, effort: 10.0, velocity: 1.0 });
        // "elbow" is continuous without <limit>.
        assert_eq!(*model.limits(2), JointLimits::NONE);
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/two_link_pendulum.urdf");
        let fixture = load_urdf(path, FIXED).unwrap().model;
        assert_eq!(*fixture.limits(2), JointLimits { lower: -2.5, upper: 2.5, effort: 10.0, velocity: 5.0 });

        let joint = |kind: &str, limit: &str| {
            let xml = joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/>{limit}</joint>"#));
            *parse_urdf(&xml, FIXED).unwrap().model.limits(1)
        };
        let inf = f64::INFINITY;
        // A continuous joint keeps effort and velocity but has no position range, whatever it says.
        assert_eq!(
            joint("continuous", r#"<limit lower="-1" upper="1" effort="5" velocity="2"/>"#),
            JointLimits { lower: -inf, upper: inf, effort: 5.0, velocity: 2.0 }
        );
        // lower and upper default to 0 (URDF specification); effort and velocity to no bound.
        assert_eq!(joint("revolute", r#"<limit effort="3"/>"#), JointLimits { lower: 0.0, upper: 0.0, effort: 3.0, velocity: inf });
        assert_eq!(
            joint("prismatic", r#"<limit upper="0.25" velocity="0.5"/>"#),
            JointLimits { lower: 0.0, upper: 0.25, effort: inf, velocity: 0.5 }
        );
        assert_eq!(joint("revolute", ""), JointLimits::NONE);
        // Limits on a fixed joint mean nothing and are ignored.
        assert_eq!(joint("fixed", r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#), JointLimits::NONE);
    }

    #[test]
    fn dynamics_damping_is_read_per_moving_joint() {
        let damping = |kind: &str, dynamics: &str| {
            let xml = joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/>{dynamics}</joint>"#));
            parse_urdf(&xml, FIXED).map(|urdf| urdf.model.damping().to_vec())
        };
        assert_eq!(damping("revolute", r#"<dynamics damping="0.25" friction="0.2"/>"#).unwrap(), vec![0.25]);
        assert_eq!(damping("prismatic", r#"<dynamics friction="0.2"/>"#).unwrap(), vec![0.0]);
        assert_eq!(damping("fixed", r#"<dynamics damping="0.25"/>"#).unwrap(), Vec::<f64>::new());
        assert_eq!(damping("spherical", r#"<dynamics damping="0.25"/>"#).unwrap(), vec![0.25; 3]);
        assert_eq!(damping("floating", r#"<dynamics damping="0.5"/>"#).unwrap(), vec![0.5; 6]);
        let error = damping("spherical", r#"<dynamics damping="-1"/>"#).unwrap_err().to_string();
        assert!(error.contains("damping> must be >= 0"), "{error}");
        let knee = r#"joint "knee""#;
        let error = damping("revolute", r#"<dynamics damping="-1"/>"#).unwrap_err().to_string();
        assert!(error.contains(knee) && error.contains("damping> must be >= 0"), "{error}");
        let error = damping("continuous", r#"<dynamics damping="nan"/>"#).unwrap_err().to_string();
        assert!(error.contains(knee), "{error}");
    }

    #[test]
    fn bad_limits_are_errors_naming_the_joint() {
        let joint = |kind: &str, limit: &str| {
            joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/><limit {limit}/></joint>"#))
        };
        let knee = r#"joint "knee""#;
        assert_fails(&joint("revolute", r#"lower="1" upper="-1""#), &[knee, "lower (1) must be <= upper (-1)"]);
        assert_fails(&joint("prismatic", r#"lower="0.5""#), &[knee, "lower (0.5) must be <= upper (0)"]);
        assert_fails(&joint("revolute", r#"lower="-1" upper="1" effort="-1""#), &[knee, "effort must be > 0", "got -1"]);
        assert_fails(&joint("continuous", r#"velocity="-2""#), &[knee, "velocity must be > 0", "got -2"]);
        // What exporters write for "unset": no bound with a warning, an error only when strict.
        assert_fails(&joint("revolute", r#"lower="-1" upper="1" effort="0""#), &[knee, r#"effort="0" read as no bound"#, "strict"]);
        assert_fails(&joint("revolute", r#"lower="low" upper="1""#), &[knee, "lower", r#""low" is not a number"#]);
        assert_fails(&joint("revolute", r#"lower="-1" upper="inf""#), &[knee, "upper", "not finite"]);
        assert_fails(&joint("prismatic", r#"effort="1 2""#), &[knee, "effort", "expected 1 number, found 2"]);
        assert_fails(&joint("revolute", r#"upper="""#), &[knee, "upper", "expected 1 number, found 0"]);
    }

    #[test]
    fn what_exporters_write_loads_as_written_with_warnings() {
        let urdf = |xml: &str| parse_urdf(xml, FIXED).unwrap();
        // effort="0" and velocity="0" mean "unset".
        let unset = urdf(&joint_robot(
            r#"<joint name="knee" type="revolute"><parent link="a"/><child link="b"/><limit lower="-1" upper="1" effort="0" velocity="0"/></joint>"#,
        ));
        assert_eq!(*unset.model.limits(1), JointLimits { lower: -1.0, upper: 1.0, effort: f64::INFINITY, velocity: f64::INFINITY });
        assert_eq!(unset.warnings.len(), 2);
        assert!(unset.warnings.iter().all(|w| w.starts_with(r#"joint "knee": <limit>"#)), "{:?}", unset.warnings);
        // A non-physical inertia (moments 1, 1, 3) is kept as written, turned by the inertial frame.
        let triangle = urdf(&inertial_robot(
            r#"<origin rpy="0 1.5707963267948966 0"/><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"/>"#,
        ));
        let body = triangle.model.body(0);
        assert!((body.inertia() - Matrix3::from_diagonal(&Vector3::new(3.0, 1.0, 1.0))).amax() < 1e-12);
        assert_eq!(body.mass(), 2.0);
        assert_eq!(triangle.warnings.len(), 1);
        assert!(triangle.warnings[0].contains(r#"link "heavy": non-physical <inertial>"#) && triangle.warnings[0].contains("kept as written"));
        // Round-off passes silently: a written-out zero inertia with a 1e-35 term (iCub's head), and a
        // principal moment of -2e-22 beside real ones.
        assert!(urdf(&inertial_robot(r#"<mass value="1"/><inertia ixx="0" ixy="0" ixz="2.4e-35" iyy="0" iyz="0" izz="0"/>"#)).warnings.is_empty());
        assert!(urdf(&inertial_robot(r#"<mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="-2e-22"/>"#))
            .warnings
            .is_empty());
        // A massless link keeps its rotational inertia, as in Pinocchio.
        let massless =
            urdf(&inertial_robot(r#"<origin xyz="1 2 3"/><mass value="0"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.3"/>"#));
        let body = massless.model.body(0);
        assert_eq!(body.mass(), 0.0);
        assert!(!body.is_zero());
        assert_eq!(body.inertia(), Matrix3::from_diagonal(&Vector3::new(0.1, 0.2, 0.3)));
        assert!(massless.warnings.is_empty());
    }

    #[test]
    fn collisions_become_the_models_collision_shapes() {
        let xml = r#"<robot name="r">
            <link name="a"><collision><geometry><box size="1 2 3"/></geometry></collision></link>
            <link name="b">
              <inertial><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
              <collision><origin xyz="0 0 -0.5" rpy="1.5707963267948966 0 0"/><geometry><cylinder radius="0.1" length="0.4"/></geometry></collision>
              <collision><origin xyz="0 0 -1"/><geometry><sphere radius="0.02"/></geometry></collision>
              <collision><geometry><capsule radius="0.05" length="0.3"/></geometry></collision>
            </link>
            <link name="c"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
              <collision><geometry><mesh filename="package://r/c.stl"/></geometry></collision></link>
            <link name="d"/>
            <joint name="j" type="revolute"><parent link="a"/><child link="b"/><limit lower="-1" upper="1"/></joint>
            <joint name="k" type="fixed"><parent link="b"/><child link="c"/></joint>
            <joint name="l" type="fixed"><parent link="c"/><child link="d"/></joint>
        </robot>"#;
        let urdf = parse_urdf(xml, FIXED).unwrap();
        let shapes = urdf.model.collision_shapes().unwrap();
        let kinds: Vec<(usize, ShapeKind)> = shapes.iter().map(|(b, s)| (*b, s.kind.clone())).collect();
        assert_eq!(
            kinds,
            vec![
                (0, ShapeKind::Box(Vector3::new(1.0, 2.0, 3.0))),
                (1, ShapeKind::Cylinder { half_height: 0.2, radius: 0.1 }),
                (1, ShapeKind::Sphere(0.02)),
                (1, ShapeKind::Capsule { half_height: 0.15, radius: 0.05 }),
                (2, Shape::default_box(urdf.model.body(2)).unwrap().kind),
            ]
        );
        let (placement, expected) = (shapes[1].1.placement.unwrap(), expected_placement([0.0, 0.0, -0.5], [FRAC_PI_2, 0.0, 0.0]));
        assert!(close(&placement.rotation, &expected.rotation, TOL) && close3(&placement.translation, &expected.translation, TOL));
        assert_eq!(urdf.warnings.len(), 1);
        assert!(urdf.warnings[0].contains(r#"link "c": <collision> meshes not read: "package://r/c.stl" ("#), "{}", urdf.warnings[0]);
        // A robot without any <collision> has no collision shapes (simulations give it default boxes).
        assert!(parse_urdf(&robot(""), FIXED).unwrap().model.collision_shapes().is_none());
        let bad = r#"<robot name="r"><link name="a"><collision><geometry><sphere radius="-1"/></geometry></collision></link></robot>"#;
        assert_fails(bad, &[r#"link "a""#, "<sphere>", "must be > 0"]);
        let unknown = r#"<robot name="r"><link name="a"><collision><geometry><cone radius="1"/></geometry></collision></link></robot>"#;
        assert_fails(unknown, &[r#"link "a""#, "unknown geometry <cone>"]);
    }

    #[test]
    fn collision_meshes_become_convex_hulls_found_by_package_and_relative_names() {
        let root = std::env::temp_dir().join(format!("legkit-urdf-meshes-{}", std::process::id()));
        std::fs::create_dir_all(root.join("bot/meshes")).unwrap();
        std::fs::create_dir_all(root.join("bot/urdf")).unwrap();
        // A unit cube's corners plus its centre (not a hull vertex).
        let corners: Vec<[f64; 3]> = (0..8).map(|k| [(k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64]).collect();
        let obj: String = corners.iter().chain([[0.5, 0.5, 0.5]].iter()).map(|c| format!("v {} {} {}\n", c[0], c[1], c[2])).collect();
        std::fs::write(root.join("bot/meshes/cube.obj"), obj).unwrap();
        let link = |name: &str, filename: &str| {
            format!(r#"<link name="{name}"><collision><geometry><mesh filename="{filename}" scale="0.1 0.2 0.3"/></geometry></collision></link>"#)
        };
        let xml = format!(
            r#"<robot name="r">{}{}{}<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint><joint name="k" type="fixed"><parent link="a"/><child link="c"/></joint></robot>"#,
            link("a", "package://bot/meshes/cube.obj"),
            link("b", "../meshes/cube.obj"),
            link("c", "package://bot/meshes/missing.stl"),
        );
        let path = root.join("bot/urdf/r.urdf");
        std::fs::write(&path, &xml).unwrap();
        let urdf = load_urdf(path.to_str().unwrap(), FIXED).unwrap();
        let shapes = urdf.model.collision_shapes().unwrap();
        for (body, shape) in &shapes[..2] {
            let ShapeKind::Convex(hull) = &shape.kind else { panic!("body {body}: {:?}", shape.kind) };
            assert_eq!(hull.vertices().len(), 8);
            for c in &corners {
                let scaled = Vector3::new(0.1 * c[0], 0.2 * c[1], 0.3 * c[2]);
                assert!(hull.vertices().iter().any(|v| (v - scaled).norm() < 1e-12), "{scaled:?} missing on body {body}");
            }
        }
        // The missing mesh: the inertia box (here none: a massless link) and a warning naming it.
        assert_eq!(shapes.len(), 2);
        assert_eq!(urdf.warnings.len(), 1);
        assert!(
            urdf.warnings[0].contains(r#"link "c""#) && urdf.warnings[0].contains("missing.stl") && urdf.warnings[0].contains("package_dirs"),
            "{}",
            urdf.warnings[0]
        );
        // Parsed from a string, package names still resolve through package_dirs.
        let options = UrdfOptions { package_dirs: vec![root.clone()], ..Default::default() };
        let from_text = parse_urdf(&xml, &options).unwrap();
        assert!(matches!(from_text.model.collision_shapes().unwrap()[0].1.kind, ShapeKind::Convex(_)));
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn bad_joints_are_errors_naming_the_joint() {
        let joint =
            |kind: &str, inner: &str| joint_robot(&format!(r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/>{inner}</joint>"#));
        let knee = r#"joint "knee""#;
        assert_fails(&joint("revolute", r#"<origin xyz="1 2"/>"#), &[knee, "xyz", "expected 3 numbers, found 2"]);
        assert_fails(&joint("revolute", r#"<origin xyz="1 2 3 4"/>"#), &[knee, "expected 3 numbers, found 4"]);
        assert_fails(&joint("revolute", r#"<origin xyz="1 2 x"/>"#), &[knee, r#""x" is not a number"#]);
        assert_fails(&joint("revolute", r#"<origin rpy="0 0 inf"/>"#), &[knee, "rpy", "not finite"]);
        assert_fails(&joint("revolute", r#"<axis xyz="0 0 0"/>"#), &[knee, "<axis", "must be a non-zero direction"]);
        assert_fails(&joint("prismatic", r#"<axis xyz="0 0 0"/>"#), &[knee, "<axis", "must be a non-zero direction"]);
        assert_fails(&joint("continuous", r#"<axis xyz="0 1"/>"#), &[knee, "axis", "expected 3 numbers"]);
        for kind in ["planar", "REVOLUTE"] {
            assert_fails(&joint(kind, ""), &[knee, &format!("unsupported type {kind:?}"), "floating, spherical"]);
        }
        assert_fails(&joint_robot(r#"<joint name="knee"><parent link="a"/><child link="b"/></joint>"#), &[knee, "no type"]);
        // The base cannot float twice.
        let error = parse_urdf(&joint("floating", ""), FLOATING).unwrap_err().to_string();
        assert!(error.contains(knee) && error.contains(r#"root link "a""#) && error.contains("float twice"), "{error}");
    }

    #[test]
    fn floating_joints_are_three_slides_and_a_ball_and_spherical_joints_a_ball_with_a_warning() {
        let joint = |kind: &str| {
            joint_robot(&format!(
                r#"<joint name="knee" type="{kind}"><parent link="a"/><child link="b"/><origin xyz="1 2 3" rpy="0.1 0.2 0.3"/>
                   <limit lower="-1" upper="1" effort="0"/><dynamics damping="2"/></joint>"#
            ))
        };
        let floating = parse_urdf(&joint("floating"), FIXED).unwrap();
        assert!(floating.warnings.is_empty(), "{:?}", floating.warnings);
        let model = &floating.model;
        assert_eq!((model.nbodies(), model.nq(), model.nv()), (5, 7, 6));
        let names: Vec<&str> = (0..5).map(|b| model.name(b)).collect();
        assert_eq!(names, ["a", "b/knee:x", "b/knee:y", "b/knee:z", "b"]);
        for (body, axis) in [(1, Vector3::x()), (2, Vector3::y()), (3, Vector3::z())] {
            assert_eq!(*model.joint(body), Joint::Prismatic(axis));
            assert_eq!(model.parent(body), body - 1);
        }
        assert_eq!(*model.joint(4), Joint::Spherical);
        assert_placement(model, 1, &expected_placement([1.0, 2.0, 3.0], [0.1, 0.2, 0.3]));
        for body in 2..5 {
            assert_placement(model, body, &Transform::identity());
        }
        assert!(model.damping().iter().all(|d| *d == 2.0) && (1..5).all(|b| *model.limits(b) == JointLimits::NONE));
        // Below a floating base, a floating joint is another free body.
        assert_eq!(
            parse_urdf(&robot(r#"<link name="c"/><joint name="f" type="floating"><parent link="b"/><child link="c"/></joint>"#), FLOATING)
                .unwrap()
                .model
                .nv(),
            6 + 1 + 6
        );

        let spherical = parse_urdf(&joint("spherical"), FIXED).unwrap();
        assert_eq!((spherical.model.nbodies(), spherical.model.nq(), spherical.model.nv()), (2, 4, 3));
        assert_eq!(*spherical.model.joint(1), Joint::Spherical);
        assert_placement(&spherical.model, 1, &expected_placement([1.0, 2.0, 3.0], [0.1, 0.2, 0.3]));
        assert_eq!(spherical.warnings, [r#"joint "knee": type "spherical" is not in the URDF specification; read as a ball joint"#]);
        assert_fails(&joint("spherical"), &[r#"joint "knee": type "spherical""#, "(strict)"]);
    }
}
