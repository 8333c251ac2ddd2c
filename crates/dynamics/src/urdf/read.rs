//! Reading a URDF's elements: links (inertials, collision shapes) and joints (kind, frame, axis, limits, damping),
//! each checked and named in messages.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use roxmltree::Node;

use super::invalid;
use crate::geometry::{Convex, Shape, ShapeKind};
use crate::mesh::{hull_points, mesh_vertices, resolve_mesh};
use crate::validate::{check_cancelled, direction};
use crate::{Error, Joint, JointLimits, MassProperties, Result, Transform};

/// URDF's `rpy`: roll about the fixed x axis, then pitch about the fixed y axis, then yaw about the fixed
/// z axis, `R = Rz(yaw) Ry(pitch) Rx(roll)`.
pub(super) fn rpy_to_matrix(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cr, -sr, 0.0, sr, cr);
    let ry = Matrix3::new(cp, 0.0, sp, 0.0, 1.0, 0.0, -sp, 0.0, cp);
    let rz = Matrix3::new(cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0);
    rz * ry * rx
}

pub(super) struct Link<'a> {
    pub(super) name: &'a str,
    pub(super) body: MassProperties,
    /// Its `<collision>` shapes in the link frame.
    pub(super) shapes: Vec<Shape>,
}

/// A parsed `<joint>`: only what the model needs, plus the name for messages.
pub(super) struct UrdfJoint<'a> {
    pub(super) name: &'a str,
    pub(super) joint: Joint,
    /// A `floating` joint: three prismatic joints before `joint` (a ball).
    pub(super) free: bool,
    pub(super) parent: usize,
    pub(super) child: usize,
    pub(super) placement: Transform,
    pub(super) limits: JointLimits,
    pub(super) damping: f64,
}

/// The child elements of `node` with tag `tag`, in document order.
pub(super) fn elements<'a, 'input: 'a>(node: Node<'a, 'input>, tag: &'a str) -> impl Iterator<Item = Node<'a, 'input>> + 'a {
    node.children().filter(move |n| n.is_element() && n.tag_name().name() == tag)
}

/// The first child element of `node` with tag `tag`.
pub(super) fn element<'a, 'input>(node: Node<'a, 'input>, tag: &str) -> Option<Node<'a, 'input>> {
    node.children().find(|n| n.is_element() && n.tag_name().name() == tag)
}

pub(super) fn line(node: Node) -> String {
    format!("line {}", node.document().text_pos_at(node.range().start).row)
}

pub(super) fn required_name<'a>(node: Node<'a, '_>, tag: &str) -> Result<&'a str> {
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
pub(super) fn inertial(link: Node, name: &str, accept: &mut dyn FnMut(String) -> Result<()>) -> Result<MassProperties> {
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
pub(super) fn collisions(
    link: Node, name: &str, body: &MassProperties, (folder, package_dirs): (Option<&Path>, &[PathBuf]), notes: &mut Vec<String>,
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
pub(super) fn joint<'a>(
    node: Node<'a, '_>, name: &'a str, link_index: &HashMap<&str, usize>, accept: &mut dyn FnMut(String) -> Result<()>,
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
