//! MJCF import: builds a [`Model`] from a MuJoCo model file, as MuJoCo's compiler reads it.
//!
//! Read, with MuJoCo's defaults and semantics:
//! - `<compiler angle eulerseq meshdir assetdir inertiafromgeom inertiagrouprange boundmass boundinertia
//!   balanceinertia autolimits settotalmass>` (`angle` is **degree** unless set: it applies to `euler`, `axisangle`, and
//!   hinge `range` and `ref`); several `<compiler>` elements merge.
//! - `<option timestep gravity>` and `<flag gravity="disable">`: [`Mjcf::timestep`], [`Mjcf::gravity`]
//!   (the model's gravity).
//! - `<default>` classes, nested (a class inherits its parent's values), chosen by `class=` or by the
//!   nearest `childclass=` of the enclosing bodies and frames, else the top class `main`.
//! - `<include file>` anywhere, spliced in place (paths relative to the main file's folder).
//! - `<replicate count offset euler sep childclass>`, nested or not, expanded as MuJoCo expands it
//!   (`Reader::expand_replicates`).
//! - `<worldbody>`, `<body>` (nested) and `<frame>` with `pos` and every orientation form: `quat` (w x y z),
//!   `axisangle`, `euler` (`eulerseq`: lower case rotating axes, upper case fixed axes), `xyaxes`, `zaxis`;
//!   geoms also `fromto`.
//! - `<joint type="hinge|slide|free">` and `<freejoint>`: `pos`, `axis`, `ref`, `range`, `limited` (auto:
//!   limited when `range` is given), `damping` and `armature` (the model's, per coordinate; none on a free
//!   joint, and `<freejoint>` takes no joint defaults, as in MuJoCo). `stiffness`, `frictionloss` and
//!   `springdamper` are not modelled: a non-zero value is a warning. `<joint type="ball">` becomes [`Joint::Spherical`] turning about
//!   `pos` (q = MuJoCo's qpos with w last; `ref` is ignored, as MuJoCo reads it on hinges and slides only;
//!   a `range`, MuJoCo's cone on the rotation angle, is a warning).
//! - Mass properties: `<inertial pos quat|... mass diaginertia|fullinertia>`, or, per `inertiafromgeom`
//!   (`auto`: when the body has no `<inertial>`), the sum of its geoms' (sphere, capsule, cylinder,
//!   ellipsoid, box; `mass=` or `density=`, 1000 by default; groups within `inertiagrouprange`), by
//!   MuJoCo's formulas [MuJoCo, user_objects.cc: mjCGeom::GetVolume, SetInertia]; then `boundmass`,
//!   `boundinertia` (on the principal moments) and `balanceinertia`. Mesh geoms (STL, OBJ, MSH) by their
//!   triangles as MuJoCo's compiler takes them (`mesh_mass`; `<mesh inertia="convex">` and meshes without
//!   faces are a warning; what MuJoCo refuses, inconsistently oriented faces under `exact` among them
//!   (`inconsistent_edge`), is refused). Where MuJoCo reads the file otherwise, the whole mesh's mass is taken
//!   with a warning ([`crate::mesh::MujocoDiffers`]: OBJ faces in several groups, a face of many corners, an
//!   ASCII STL).
//! - Collision shapes: sphere, capsule, cylinder and box geoms, and meshes (STL, OBJ, MSH) as the convex hull of
//!   their vertices, except geoms with `contype="0" conaffinity="0"` (visual only). Pair filtering by the
//!   bits of `contype`/`conaffinity` is not expressible: every other geom collides. Ellipsoids and
//!   unreadable meshes are listed in a warning.
//! - The floor: the world body's first colliding plane geom, placed where MuJoCo places it, is
//!   [`Mjcf::ground`] with the geom's sliding `friction` (MuJoCo's default 1). Further planes, planes on
//!   moving bodies and height fields are listed in a warning (`lk.Ground.heightfield` takes a height field).
//! - `<actuator>`: `motor`, `position` (`kp`, `kv`), `velocity` (`kv`) and `general` (`gaintype`
//!   fixed/affine, `gainprm`, `biastype` none/affine, `biasprm`, `dyntype none`) on a hinge or slide
//!   `joint=` transmission, with `gear`, `ctrlrange`/`ctrllimited` and `forcerange`/`forcelimited`:
//!   [`Mjcf::actuators`] and [`Mjcf::actuator_torques`]. Other actuators are warnings.
//!
//! The model: body order is MuJoCo's (depth first, in file order), so velocity coordinates come in
//! MuJoCo's dof order, and **q equals MuJoCo's qpos** for hinge and slide joints (the joint frame
//! includes `-ref`; the neutral configuration q = 0 is therefore not MuJoCo's qpos0 = ref). A top-level
//! body with a free joint becomes the free-flyer base (q = [x y z qx qy qz qw], v in the base frame, as
//! everywhere in legkit; MuJoCo's qpos has w first and its free-joint linear velocity is in the world
//! frame); otherwise body 0 is the massless `world`, fixed, and with several free bodies each moves on three
//! slide joints along the world's axes and a ball joint (MuJoCo's own free-joint coordinates). A legkit body turns about its joint frame's
//! origin, so a body whose (last) hinge has `pos` p has its frame at the anchor p (same orientation as the
//! MJCF body frame; mass and shapes shifted by -p). A body with several joints becomes a chain: massless
//! bodies named `body/joint` for all but its last joint, the last one carrying the body's name and mass,
//! as MuJoCo composes joint transforms in order. A body without joints is fixed to its parent. Unnamed
//! bodies and joints are `body<i>` and `joint<i>`, i MuJoCo's id.
//!
//! Every element and attribute must be one MuJoCo knows there (its schema, `schema.rs`): a name it does not
//! know, a typo such as `<joint dampng="1">`, is an error naming it, its element and line, as MuJoCo refuses
//! it (legkit also checks inside `<frame>` and `<replicate>`, which MuJoCo's validator skips).
//!
//! What legkit cannot model (tendons, equality constraints, sensors, contact pairs and excludes,
//! flex and flexcomp, non-joint transmissions, static bodies beside a floating base) loads with a
//! warning naming it, or is an error with [`MjcfOptions::strict`].

mod schema;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use nalgebra::{DVector, Matrix3, Quaternion, SymmetricEigen, Unit, UnitQuaternion, Vector3};
use roxmltree::Node;

use crate::geometry::{Convex, Shape, ShapeKind};
use crate::mesh::{cancel_point, hull_points, mesh_triangles, mesh_vertices};
use crate::sim::Ground;
use crate::validate::check_cancelled;
use crate::{Error, Joint, JointLimits, MassProperties, Model, Result, Transform};

/// How an MJCF becomes a model.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MjcfOptions {
    /// None: as the file says (a free joint on the single moving top-level body makes a floating base);
    /// Some(false) welds a free body to the world; Some(true) frees the single top-level body.
    pub floating_base: Option<bool>,
    /// What would be a warning is an error.
    pub strict: bool,
}

/// An MJCF joint's `type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// `hinge`: a revolute joint.
    Hinge,
    /// `slide`: a prismatic joint.
    Slide,
    /// `free` (or `<freejoint>`): the floating base.
    Free,
    /// `ball`: a spherical joint.
    Ball,
}

/// An MJCF joint and the model coordinates it became.
#[derive(Debug, Clone)]
pub struct MjcfJoint {
    /// The joint's name (MuJoCo's, or the one it would give an unnamed joint).
    pub name: String,
    /// Its type.
    pub kind: JointKind,
    /// The legkit body it moves.
    pub body: usize,
    /// Its first configuration coordinate in the model's q.
    pub idx_q: usize,
    /// Its first velocity coordinate in the model's v.
    pub idx_v: usize,
}

/// An actuator on a joint: force = gain ctrl + bias, gain = g0 + g1 l + g2 l', bias = b0 + b1 l + b2 l',
/// with l = gear q and l' = gear v; ctrl and force clamped to their ranges; joint torque gear · force
/// [MuJoCo, XML reference: actuator].
#[derive(Debug, Clone)]
pub struct Actuator {
    /// The actuator's name.
    pub name: String,
    /// The joint it drives.
    pub joint: String,
    /// The velocity coordinate it drives.
    pub dof: usize,
    /// The transmission's gear ratio.
    pub gear: f64,
    /// `gainprm` [g0, g1, g2].
    pub gain: [f64; 3],
    /// `biasprm` [b0, b1, b2].
    pub bias: [f64; 3],
    /// The range ctrl is clamped to, if limited.
    pub ctrlrange: Option<[f64; 2]>,
    /// The range the force is clamped to, if limited.
    pub forcerange: Option<[f64; 2]>,
}

/// An MJCF read into a model, with what the model does not hold.
#[derive(Debug, Clone)]
pub struct Mjcf {
    /// The kinematic tree, its inertias, limits, armature, damping and collision shapes.
    pub model: Model,
    /// What was accepted with a warning (an error under `strict`).
    pub warnings: Vec<String>,
    /// Every hinge, slide, ball and free joint the model kept, in MuJoCo's order.
    pub joints: Vec<MjcfJoint>,
    /// The actuators on those joints, in MuJoCo's order.
    pub actuators: Vec<Actuator>,
    /// `<option timestep>` (s; MuJoCo's default 0.002).
    pub timestep: f64,
    /// `<option gravity>` (m/s², world frame; zero when `<flag gravity="disable">`), also the model's.
    pub gravity: Vector3<f64>,
    /// The floor: the world body's first colliding plane geom with its sliding friction; None without one.
    pub ground: Option<Ground>,
}

impl Mjcf {
    /// The joint torques (nv) the actuators apply for controls `ctrl` (one per actuator) at (q, v).
    pub fn actuator_torques(&self, q: &[f64], v: &[f64], ctrl: &[f64]) -> Result<DVector<f64>> {
        crate::model::check_vector("q", q, self.model.nq())?;
        crate::model::check_vector("v", v, self.model.nv())?;
        crate::model::check_vector("ctrl", ctrl, self.actuators.len())?;
        let mut tau = DVector::zeros(self.model.nv());
        for (actuator, &u) in self.actuators.iter().zip(ctrl) {
            let joint = self.joints.iter().find(|j| j.idx_v == actuator.dof).expect("actuators drive kept joints");
            let (length, speed) = (actuator.gear * q[joint.idx_q], actuator.gear * v[actuator.dof]);
            let u = actuator.ctrlrange.map_or(u, |[lo, hi]| u.clamp(lo, hi));
            let affine = |p: &[f64; 3]| p[0] + p[1] * length + p[2] * speed;
            let force = affine(&actuator.gain) * u + affine(&actuator.bias);
            let force = actuator.forcerange.map_or(force, |[lo, hi]| force.clamp(lo, hi));
            tau[actuator.dof] += actuator.gear * force;
        }
        Ok(tau)
    }
}

/// Loads an MJCF from a file, or parses it if `path_or_xml` (after a byte order mark and blanks) starts
/// with `<` (then includes and meshes resolve against the working folder).
pub fn load_mjcf(path_or_xml: &str, options: &MjcfOptions) -> Result<Mjcf> {
    let text = path_or_xml.strip_prefix('\u{feff}').unwrap_or(path_or_xml);
    if text.trim_start().starts_with('<') {
        return parse(text, "xml", "<string>", None, options);
    }
    let xml = read_text(Path::new(path_or_xml), "path")?;
    let folder = Path::new(path_or_xml).parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p });
    parse(&xml, "path", path_or_xml, folder, options)
}

fn read_text(path: &Path, argument: &'static str) -> Result<String> {
    let bytes = crate::validate::read_regular_file(argument, path)?;
    let text = String::from_utf8(bytes).map_err(|e| Error::invalid(argument, format!("{}: not UTF-8 text: {e}", path.display())))?;
    Ok(text.strip_prefix('\u{feff}').map(str::to_owned).unwrap_or(text))
}

fn invalid(reason: String) -> Error {
    Error::invalid("mjcf", reason)
}

/// Includes nest at most this deep (a file including itself is refused at once).
const MAX_INCLUDE_DEPTH: usize = 16;
/// At most this many elements over the file and its includes.
const MAX_ELEMENTS: usize = 2_000_000;
/// Elements nest at most this deep (a body's depth in the tree is its element's): the passes over the
/// tree recurse, about 3 KB of stack a level (a release build), so that deep a file needs 3 MB of stack
/// (Python's loader thread has 16 MB).
pub const MAX_DEPTH: usize = 1000;
/// The peak memory of building a model, per element, beyond roxmltree's (`xml::parse`): measured at
/// 1.1 KB per `<body/>` on 300,000 bodies (peak RSS), with a margin.
const BYTES_PER_ELEMENT: usize = 2048;

/// An element, owned, so that included files splice into one tree. Its tag and attribute names are shared
/// (`Source::name`) and its place holds the file's label by reference: an element owns only its values and lists,
/// so a tree of a million elements is built, and freed when a load is cancelled, in fewer allocations.
#[derive(Debug, Clone)]
struct El {
    tag: Name,
    attrs: Vec<(Name, String)>,
    children: Vec<El>,
    at: At,
}

/// A tag or attribute name, shared by every element that has it.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Name(Rc<str>);

impl Name {
    fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::ops::Deref for Name {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl PartialEq<str> for Name {
    fn eq(&self, other: &str) -> bool {
        &*self.0 == other
    }
}

impl PartialEq<&str> for Name {
    fn eq(&self, other: &&str) -> bool {
        &*self.0 == *other
    }
}

impl From<&str> for Name {
    fn from(name: &str) -> Self {
        Name(Rc::from(name))
    }
}

impl std::fmt::Display for Name {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// Where an element is, for messages: "file:line".
#[derive(Debug, Clone)]
struct At {
    label: Rc<str>,
    line: usize,
}

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "{}:{}", self.label, self.line)
    }
}

impl El {
    fn attr(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }
    fn elements<'a>(&'a self, tag: &'a str) -> impl Iterator<Item = &'a El> + 'a {
        self.children.iter().filter(move |c| c.tag == tag)
    }
    fn what(&self) -> String {
        match self.attr("name") {
            Some(name) => format!("<{} name={name:?}> ({})", self.tag, self.at),
            None => format!("<{}> ({})", self.tag, self.at),
        }
    }
}

struct Source<'a> {
    /// "path" or "xml": what a size that cannot be allocated is reported against.
    argument: &'static str,
    folder: Option<&'a Path>,
    elements: usize,
    stack: Vec<PathBuf>,
    /// The tag and attribute names read so far.
    names: std::collections::HashSet<Rc<str>>,
}

impl Source<'_> {
    fn name(&mut self, name: &str) -> Name {
        if let Some(shared) = self.names.get(name) {
            return Name(Rc::clone(shared));
        }
        let shared: Rc<str> = Rc::from(name);
        self.names.insert(Rc::clone(&shared));
        Name(shared)
    }
}

/// The byte offsets of the line breaks of `text`, to find an element's line by bisection (roxmltree's
/// `text_pos_at` scans from the start: quadratic over a file).
fn line_breaks(text: &str) -> Vec<usize> {
    text.bytes().enumerate().filter(|(_, b)| *b == b'\n').map(|(i, _)| i).collect()
}

/// `node` owned, at `depth` in the tree (the root at 0), with its includes spliced in.
fn own(node: Node, label: &Rc<str>, breaks: &[usize], source: &mut Source, depth: usize) -> Result<El> {
    let row = breaks.partition_point(|&b| b < node.range().start) + 1;
    if depth > MAX_DEPTH {
        return Err(invalid(format!("elements nest deeper than {MAX_DEPTH} levels ({label}:{row})")));
    }
    let mut el = El {
        tag: source.name(node.tag_name().name()),
        attrs: node.attributes().map(|a| (source.name(a.name()), a.value().to_owned())).collect(),
        children: Vec::new(),
        at: At { label: Rc::clone(label), line: row },
    };
    for child in node.children().filter(Node::is_element) {
        source.elements += 1;
        cancel_point("from_mjcf", source.elements)?;
        if source.elements > MAX_ELEMENTS {
            return Err(Error::too_large("mjcf", format!("more than {MAX_ELEMENTS} elements")));
        }
        if child.tag_name().name() == "include" {
            let file = child.attribute("file").ok_or_else(|| invalid(format!("<include> has no file attribute ({label}:{row})")))?;
            let path = source.folder.map_or_else(|| PathBuf::from(file), |f| f.join(file));
            if source.stack.len() >= MAX_INCLUDE_DEPTH || source.stack.contains(&path) {
                return Err(invalid(format!("<include file={file:?}>: includes nest too deep or include themselves ({label})")));
            }
            let text = read_text(&path, "mjcf").map_err(|e| invalid(format!("<include file={file:?}> ({label}:{row}): {}", e.reason())))?;
            let doc = crate::xml::parse(&text, source.argument)?.map_err(|e| invalid(format!("{file}: {e}")))?;
            reserve_build(&doc, source.argument)?;
            if doc.root_element().tag_name().name() != "mujoco" {
                return Err(invalid(format!("{file}: an included file's root must be <mujoco>")));
            }
            source.stack.push(path);
            let included = own(doc.root_element(), &Rc::from(file), &line_breaks(&text), source, depth)?;
            source.stack.pop();
            el.children.extend(included.children);
        } else {
            el.children.push(own(child, label, breaks, source, depth + 1)?);
        }
    }
    Ok(el)
}

/// Whitespace-separated finite numbers.
fn numbers(text: &str, what: &dyn Fn() -> String) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|t| match t.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(invalid(format!("{}: {t:?} is not a finite number", what()))),
        })
        .collect()
}

type Attrs = HashMap<String, String>;
/// A default class: per element kind (joint, geom, actuator, ...), its attribute values.
type Class = HashMap<String, Attrs>;

/// The kind of default an element reads: every actuator shortcut shares one.
fn kind_of(tag: &str) -> &str {
    match tag {
        "motor" | "position" | "velocity" | "general" | "intvelocity" | "damper" | "cylinder" | "muscle" | "adhesion" => "actuator",
        "freejoint" => "joint",
        other => other,
    }
}

fn collect_defaults(el: &El, parent: &Class, name: &str, classes: &mut HashMap<String, Class>) -> Result<()> {
    let mut class = parent.clone();
    for child in el.children.iter().filter(|c| c.tag != "default") {
        let attrs = class.entry(kind_of(&child.tag).to_owned()).or_default();
        for (k, v) in &child.attrs {
            attrs.insert(k.to_string(), v.clone());
        }
    }
    for child in el.elements("default") {
        let child_name = child.attr("class").ok_or_else(|| invalid(format!("a nested <default> has no class ({})", child.at)))?;
        collect_defaults(child, &class, child_name, classes)?;
    }
    // Checked once the nested classes are in: one of them may take its parent's name.
    if classes.insert(name.to_owned(), class).is_some() {
        return Err(invalid(format!("default class {name:?} is defined twice ({})", el.at)));
    }
    Ok(())
}

struct Compiler {
    /// Radians per angle unit.
    angle: f64,
    eulerseq: [u8; 3],
    meshdir: Option<PathBuf>,
    inertia_from_geom: InertiaFromGeom,
    group_range: [i64; 2],
    boundmass: f64,
    boundinertia: f64,
    balanceinertia: bool,
    autolimits: bool,
    /// `settotalmass` (> 0: every body's mass and inertia scaled so that they add up to it).
    total_mass: f64,
}

#[derive(Clone, Copy, PartialEq)]
enum InertiaFromGeom {
    Auto,
    Always,
    Never,
}

/// Reads attributes with defaults, and warns or refuses.
struct Reader<'a> {
    classes: HashMap<String, Class>,
    compiler: Compiler,
    strict: bool,
    warnings: Vec<String>,
    /// Warnings `strict` does not refuse (what legkit cannot read, e.g. a missing mesh file).
    notes: Vec<String>,
    folder: Option<&'a Path>,
}

impl Reader<'_> {
    fn accept(&mut self, problem: String) -> Result<()> {
        if self.strict {
            return Err(invalid(format!("{problem} (strict)")));
        }
        self.warnings.push(problem);
        Ok(())
    }

    fn class_of<'e>(&self, el: &'e El, childclass: &'e str) -> Result<&'e str> {
        let class = el.attr("class").unwrap_or(childclass);
        if !self.classes.contains_key(class) {
            return Err(invalid(format!("{}: unknown default class {class:?}", el.what())));
        }
        Ok(class)
    }

    fn get<'e>(&'e self, el: &'e El, class: &str, key: &str) -> Option<&'e str> {
        el.attr(key).or_else(|| self.classes.get(class)?.get(kind_of(&el.tag))?.get(key).map(String::as_str))
    }

    fn nums(&self, el: &El, class: &str, key: &str) -> Result<Option<Vec<f64>>> {
        self.get(el, class, key).map(|text| numbers(text, &|| format!("{}: {key}", el.what()))).transpose()
    }

    fn fixed<const N: usize>(&self, el: &El, class: &str, key: &str) -> Result<Option<[f64; N]>> {
        match self.nums(el, class, key)? {
            None => Ok(None),
            Some(v) if v.len() == N => Ok(Some(v.try_into().expect("length checked"))),
            Some(v) => Err(invalid(format!("{}: {key} needs {N} numbers, found {}", el.what(), v.len()))),
        }
    }

    fn scalar(&self, el: &El, class: &str, key: &str, default: f64) -> Result<f64> {
        Ok(self.fixed::<1>(el, class, key)?.map_or(default, |[x]| x))
    }

    fn boolean(&self, el: &El, class: &str, key: &str) -> Result<Option<bool>> {
        match self.get(el, class, key) {
            None | Some("auto") => Ok(None),
            Some("true") => Ok(Some(true)),
            Some("false") => Ok(Some(false)),
            Some(other) => Err(invalid(format!("{}: {key}={other:?} must be true, false or auto", el.what()))),
        }
    }

    /// The element's frame in its parent's: `pos` and one orientation form.
    fn frame(&self, el: &El, class: &str) -> Result<Transform> {
        let pos = self.fixed::<3>(el, class, "pos")?.map_or_else(Vector3::zeros, Vector3::from);
        Ok(Transform::new(self.orientation(el, class)?, pos))
    }

    fn orientation(&self, el: &El, class: &str) -> Result<Matrix3<f64>> {
        let forms = ["quat", "axisangle", "euler", "xyaxes", "zaxis"];
        // An orientation on the element replaces one from its class.
        let given: Vec<&str> = forms.iter().copied().filter(|f| el.attr(f).is_some()).collect();
        let given = if given.is_empty() { forms.iter().copied().filter(|f| self.get(el, class, f).is_some()).collect() } else { given };
        let q = match given.as_slice() {
            [] => return Ok(Matrix3::identity()),
            [form] => self.rotation(el, class, form)?,
            _ => return Err(invalid(format!("{}: more than one orientation ({})", el.what(), given.join(", ")))),
        };
        Ok(q.to_rotation_matrix().into_inner())
    }

    fn rotation(&self, el: &El, class: &str, form: &str) -> Result<UnitQuaternion<f64>> {
        let zero = || invalid(format!("{}: {form} is degenerate", el.what()));
        Ok(match form {
            "quat" => {
                let [w, x, y, z] = self.fixed::<4>(el, class, form)?.expect("present");
                let q = Quaternion::new(w, x, y, z);
                if q.norm() < 1e-10 {
                    return Err(zero());
                }
                UnitQuaternion::from_quaternion(q)
            }
            "axisangle" => {
                let [x, y, z, a] = self.fixed::<4>(el, class, form)?.expect("present");
                let axis = Unit::try_new(Vector3::new(x, y, z), 1e-10).ok_or_else(zero)?;
                UnitQuaternion::from_axis_angle(&axis, a * self.compiler.angle)
            }
            "euler" => self.euler(self.fixed::<3>(el, class, form)?.expect("present")),
            "xyaxes" => {
                let v = self.fixed::<6>(el, class, form)?.expect("present");
                let x = Vector3::new(v[0], v[1], v[2]);
                let x = x.try_normalize(1e-10).ok_or_else(zero)?;
                let y = Vector3::new(v[3], v[4], v[5]);
                let y = (y - x * x.dot(&y)).try_normalize(1e-10).ok_or_else(zero)?;
                let m = Matrix3::from_columns(&[x, y, x.cross(&y)]);
                UnitQuaternion::from_matrix(&m)
            }
            _ => {
                let [x, y, z] = self.fixed::<3>(el, class, form)?.expect("present");
                z_to(Vector3::new(x, y, z)).ok_or_else(zero)?
            }
        })
    }
}

impl Reader<'_> {
    /// The rotation of Euler angles `angles` (in the compiler's unit and sequence).
    fn euler(&self, angles: [f64; 3]) -> UnitQuaternion<f64> {
        let mut q = UnitQuaternion::identity();
        for (&c, angle) in self.compiler.eulerseq.iter().zip(angles) {
            let axis = match c.to_ascii_lowercase() {
                b'x' => Vector3::x_axis(),
                b'y' => Vector3::y_axis(),
                _ => Vector3::z_axis(),
            };
            let turn = UnitQuaternion::from_axis_angle(&axis, angle * self.compiler.angle);
            // Lower case: about the rotating (intrinsic) axes; upper case: the fixed ones.
            q = if c.is_ascii_lowercase() { q * turn } else { turn * q };
        }
        q
    }

    /// `el`'s `<replicate>` children (and theirs, and those nested in them) replaced, in place, by their copies, as
    /// MuJoCo's parser expands them (mjXReader::Body, google-deepmind/mujoco): copy i is a `<frame>` turned by i times
    /// `euler` (in the compiler's unit and sequence) and moved by the sum of `offset` turned by each earlier copy's
    /// rotation, holding the replicate's children with every `name` suffixed by `sep` and i, zero-padded to the digits
    /// of `count`; an inner replicate's suffix comes first. A `count` below 1 makes no copy, as in MuJoCo. `budget`
    /// is the elements still allowed (`MAX_ELEMENTS`); `seen` counts the elements walked, for cancellation.
    fn expand_replicates(&self, el: &mut El, budget: &mut usize, seen: &mut usize) -> Result<()> {
        if !el.children.iter().any(|c| c.tag == "replicate" || !c.children.is_empty()) {
            return Ok(());
        }
        let children = std::mem::take(&mut el.children);
        for mut child in children {
            *seen += 1;
            cancel_point("from_mjcf", *seen)?;
            self.expand_replicates(&mut child, budget, seen)?;
            if child.tag != "replicate" {
                el.children.push(child);
                continue;
            }
            let what = child.what();
            let count = match child.attr("count").map(|c| c.trim().parse::<i64>()) {
                Some(Ok(count)) => usize::try_from(count).unwrap_or(0),
                Some(Err(_)) => return Err(invalid(format!("{what}: count={:?} is not an integer", child.attr("count").unwrap_or("")))),
                None => return Err(invalid(format!("{what}: count is required"))),
            };
            if let Some(inner) = child.children.iter().find(|c| matches!(c.tag.as_str(), "joint" | "freejoint")) {
                return Err(invalid(format!("{}: a <{}> cannot be a direct child of <replicate>, as in MuJoCo", inner.what(), inner.tag)));
            }
            // MuJoCo ignores an <inertial> there (in a <frame>, legkit would give it to the body).
            child.children.retain(|c| c.tag != "inertial");
            // The copies' elements, counted and their memory checked before any is made.
            let size = 1 + child.children.iter().map(El::size).sum::<usize>();
            let (added, bytes) = (count.saturating_mul(size), count.saturating_mul(size).saturating_mul(BYTES_PER_ELEMENT));
            let copies = format!("{what}: count={count} copies of {size} elements");
            if added > *budget {
                return Err(Error::too_large("mjcf", format!("{copies}: more than the {MAX_ELEMENTS} elements an MJCF may have")));
            }
            if !crate::validate::headroom(bytes) {
                return Err(Error::too_large("mjcf", format!("{copies} need up to {bytes} bytes, which cannot be allocated")));
            }
            *budget -= added;
            let offset = self.fixed::<3>(&child, "main", "offset")?.map_or_else(Vector3::zeros, Vector3::from);
            let euler = self.fixed::<3>(&child, "main", "euler")?.unwrap_or([0.0; 3]);
            let sep = child.attr("sep").unwrap_or("");
            let digits = count.to_string().len();
            let mut pos = Vector3::zeros();
            for i in 0..count {
                // Each copy's rotation from i times the angles, as MuJoCo computes it (not the product of i turns).
                let q = self.euler(euler.map(|a| a * i as f64));
                let mut attrs = vec![
                    (Name::from("pos"), format!("{} {} {}", pos.x, pos.y, pos.z)),
                    (Name::from("quat"), format!("{} {} {} {}", q.w, q.i, q.j, q.k)),
                ];
                attrs.extend(child.attrs.iter().filter(|(k, _)| k == "childclass").cloned());
                let suffix = format!("{sep}{i:0digits$}");
                let children = child.children.iter().map(|c| c.suffixed(&suffix, seen)).collect::<Result<_>>()?;
                el.children.push(El { tag: Name::from("frame"), attrs, children, at: child.at.clone() });
                pos += q * offset;
            }
        }
        Ok(())
    }
}

impl El {
    /// The elements of the tree below and including `self`.
    fn size(&self) -> usize {
        1 + self.children.iter().map(El::size).sum::<usize>()
    }

    /// A copy of the tree with `suffix` appended to every `name`; `seen` counts the elements copied, for cancellation.
    fn suffixed(&self, suffix: &str, seen: &mut usize) -> Result<El> {
        *seen += 1;
        cancel_point("from_mjcf", *seen)?;
        let attrs = self.attrs.iter().map(|(k, v)| (k.clone(), if k == "name" { format!("{v}{suffix}") } else { v.clone() })).collect();
        let children = self.children.iter().map(|c| c.suffixed(suffix, seen)).collect::<Result<_>>()?;
        Ok(El { tag: self.tag.clone(), attrs, children, at: self.at.clone() })
    }
}

/// The shortest rotation taking z to `v` (MuJoCo's `mju_quatZ2Vec`: half a turn about x for -z).
fn z_to(v: Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let v = v.try_normalize(1e-14)?;
    let axis = Vector3::z().cross(&v);
    let s = axis.norm();
    if s < 1e-15 {
        return Some(if v.z < 0.0 { UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI) } else { UnitQuaternion::identity() });
    }
    Some(UnitQuaternion::from_axis_angle(&Unit::new_unchecked(axis / s), s.atan2(v.z)))
}

struct JointSpec {
    name: String,
    kind: JointKind,
    pos: Vector3<f64>,
    axis: Vector3<f64>,
    reference: f64,
    range: Option<(f64, f64)>,
    damping: f64,
    armature: f64,
}

/// A body as the file gives it, in MuJoCo's numbering (0 the world).
struct Body {
    name: String,
    parent: usize,
    /// In the parent's MJCF frame.
    frame: Transform,
    joints: Vec<JointSpec>,
    /// In its own MJCF frame.
    mass: MassProperties,
    shapes: Vec<Shape>,
}

/// Fails with `Error::TooLarge` naming `argument` when the memory that building a model from `doc` may take
/// cannot be allocated: the element tree, the bodies and the model grow infallibly.
fn reserve_build(doc: &roxmltree::Document, argument: &'static str) -> Result<()> {
    let elements = doc.descendants().filter(Node::is_element).count();
    let bytes = elements.saturating_mul(BYTES_PER_ELEMENT);
    if crate::validate::headroom(bytes) {
        Ok(())
    } else {
        Err(Error::too_large(argument, format!("building a model of {elements} elements needs up to {bytes} bytes, which cannot be allocated")))
    }
}

/// `argument` ("path" or "xml") is what a size that cannot be allocated is reported against; `label` names
/// the text in messages.
fn parse(xml: &str, argument: &'static str, label: &str, folder: Option<&Path>, options: &MjcfOptions) -> Result<Mjcf> {
    let doc = crate::xml::parse(xml, argument)?.map_err(invalid)?;
    reserve_build(&doc, argument)?;
    if doc.root_element().tag_name().name() != "mujoco" {
        return Err(invalid(format!("the root element must be <mujoco>, found <{}>", doc.root_element().tag_name().name())));
    }
    let mut source = Source { argument, folder, elements: 0, stack: Vec::new(), names: Default::default() };
    let mut root = own(doc.root_element(), &Rc::from(label), &line_breaks(xml), &mut source, 0)?;
    drop(doc);
    schema::check(&root)?;

    let mut compiler = Compiler {
        angle: std::f64::consts::PI / 180.0,
        eulerseq: *b"xyz",
        meshdir: None,
        inertia_from_geom: InertiaFromGeom::Auto,
        group_range: [0, 5],
        boundmass: 0.0,
        boundinertia: 0.0,
        balanceinertia: false,
        autolimits: true,
        total_mass: -1.0,
    };
    let mut assetdir = None;
    for c in root.elements("compiler") {
        let flag = |key: &str| -> Result<Option<bool>> {
            match c.attr(key) {
                None => Ok(None),
                Some("true") => Ok(Some(true)),
                Some("false") => Ok(Some(false)),
                Some(other) => Err(invalid(format!("<compiler {key}={other:?}>: expected true or false"))),
            }
        };
        match c.attr("angle") {
            None => {}
            Some("degree") => compiler.angle = std::f64::consts::PI / 180.0,
            Some("radian") => compiler.angle = 1.0,
            Some(other) => return Err(invalid(format!("<compiler angle={other:?}>: expected degree or radian"))),
        }
        if let Some(seq) = c.attr("eulerseq") {
            let bytes = seq.as_bytes();
            if bytes.len() != 3 || !bytes.iter().all(|b| b"xyzXYZ".contains(b)) {
                return Err(invalid(format!("<compiler eulerseq={seq:?}>: expected three of x, y, z, X, Y, Z")));
            }
            compiler.eulerseq = [bytes[0], bytes[1], bytes[2]];
        }
        if let Some(dir) = c.attr("meshdir") {
            compiler.meshdir = Some(PathBuf::from(dir));
        }
        if let Some(dir) = c.attr("assetdir") {
            assetdir = Some(PathBuf::from(dir));
        }
        match c.attr("inertiafromgeom") {
            None => {}
            Some("auto") => compiler.inertia_from_geom = InertiaFromGeom::Auto,
            Some("true") => compiler.inertia_from_geom = InertiaFromGeom::Always,
            Some("false") => compiler.inertia_from_geom = InertiaFromGeom::Never,
            Some(other) => return Err(invalid(format!("<compiler inertiafromgeom={other:?}>: expected true, false or auto"))),
        }
        if let Some(text) = c.attr("inertiagrouprange") {
            match numbers(text, &|| "<compiler inertiagrouprange>".into())?.as_slice() {
                [a, b] => compiler.group_range = [*a as i64, *b as i64],
                _ => return Err(invalid("<compiler inertiagrouprange>: expected 2 numbers".into())),
            }
        }
        for (key, slot) in
            [("boundmass", &mut compiler.boundmass), ("boundinertia", &mut compiler.boundinertia), ("settotalmass", &mut compiler.total_mass)]
        {
            if let Some(text) = c.attr(key) {
                match numbers(text, &|| format!("<compiler {key}>"))?.as_slice() {
                    [x] => *slot = *x,
                    _ => return Err(invalid(format!("<compiler {key}>: expected 1 number"))),
                }
            }
        }
        if let Some(b) = flag("balanceinertia")? {
            compiler.balanceinertia = b;
        }
        if let Some(b) = flag("autolimits")? {
            compiler.autolimits = b;
        }
        if c.attr("coordinate").is_some_and(|v| v != "local") {
            return Err(invalid("<compiler coordinate=\"global\"> is not supported (MuJoCo removed it too)".into()));
        }
    }
    if compiler.meshdir.is_none() {
        compiler.meshdir = assetdir;
    }

    let mut classes = HashMap::new();
    let mut main = Class::new();
    for d in root.elements("default") {
        // The top <default> is class "main"; its children inherit from it.
        if d.attr("class").is_some_and(|name| name != "main") {
            return Err(invalid(format!("the top <default> is class \"main\" and cannot be renamed ({})", d.at)));
        }
        let mut top = HashMap::new();
        collect_defaults(d, &main, "main", &mut top)?;
        main = top.remove("main").expect("collected");
        for (name, class) in top {
            if classes.insert(name.clone(), class).is_some() {
                return Err(invalid(format!("default class {name:?} is defined twice")));
            }
        }
    }
    classes.insert("main".to_owned(), main);

    let mut reader = Reader { classes, compiler, strict: options.strict, warnings: Vec::new(), notes: Vec::new(), folder };

    let (mut timestep, mut gravity) = (0.002, Vector3::new(0.0, 0.0, -9.81));
    for option in root.elements("option") {
        timestep = reader.scalar(option, "main", "timestep", timestep)?;
        if let Some(g) = reader.fixed::<3>(option, "main", "gravity")? {
            gravity = Vector3::from(g);
        }
        if option.elements("flag").any(|f| f.attr("gravity") == Some("disable")) {
            gravity = Vector3::zeros();
        }
    }

    for tag in ["tendon", "equality", "sensor", "contact", "deformable", "extension", "custom"] {
        let listed: Vec<String> = root.elements(tag).flat_map(|e| e.children.iter().map(El::what)).collect();
        if !listed.is_empty() && tag != "custom" {
            reader.accept(format!("<{tag}> is not modelled: {}", listed.join(", ")))?;
        }
    }

    let (mut budget, mut seen) = (MAX_ELEMENTS.saturating_sub(source.elements), 0);
    for world in root.children.iter_mut().filter(|c| c.tag == "worldbody") {
        reader.expand_replicates(world, &mut budget, &mut seen)?;
    }

    let meshes = mesh_assets(&root, &mut reader)?;
    let bodies = vec![Body {
        name: "world".to_owned(),
        parent: 0,
        frame: Transform::identity(),
        joints: Vec::new(),
        mass: MassProperties::zero(),
        shapes: Vec::new(),
    }];
    let mut walker = Walker { reader: &mut reader, meshes: &meshes, bodies, joint_count: 0, ground: None };
    for world in root.elements("worldbody") {
        walker.body(world, 0, "main")?;
    }
    let (mut bodies, ground) = (walker.bodies, walker.ground);

    if reader.compiler.total_mass > 0.0 {
        // MuJoCo's mj_setTotalmass: every mass and inertia times one factor.
        let total: f64 = bodies.iter().map(|b| b.mass.mass()).sum();
        if total > 0.0 {
            let scale = reader.compiler.total_mass / total;
            for body in &mut bodies {
                body.mass = MassProperties::as_written(body.mass.mass() * scale, body.mass.com(), body.mass.inertia() * scale)?;
            }
        }
    }
    let (model, joints) = build(&bodies, options, &mut reader)?;
    let mut model = model;
    model.gravity = gravity;
    let actuators = actuators(&root, &joints, &mut reader)?;
    let Reader { mut warnings, notes, .. } = reader;
    warnings.extend(notes);
    Ok(Mjcf { model, warnings, joints, actuators, timestep, gravity, ground })
}

/// `<asset><mesh>` by name: the file's vertices scaled, or why they could not be read.
fn mesh_assets(root: &El, reader: &mut Reader) -> Result<Meshes> {
    let mut meshes = HashMap::new();
    for asset in root.elements("asset") {
        for mesh in asset.elements("mesh") {
            let class = reader.class_of(mesh, "main")?;
            let Some(file) = reader.get(mesh, class, "file") else {
                meshes.insert(mesh.attr("name").unwrap_or("").to_owned(), Err("no file (vertices given inline are not read)".to_owned()));
                continue;
            };
            let name = mesh
                .attr("name")
                .map_or_else(|| Path::new(file).file_stem().map_or(String::new(), |s| s.to_string_lossy().into_owned()), str::to_owned);
            let scale = reader.fixed::<3>(mesh, class, "scale")?.map_or(Vector3::repeat(1.0), Vector3::from);
            let mode = reader.get(mesh, class, "inertia").unwrap_or("legacy").to_owned();
            let mode = mode.as_str();
            if !matches!(mode, "legacy" | "exact" | "convex" | "shell") {
                return Err(invalid(format!("{}: unknown inertia {mode:?}", mesh.what())));
            }
            let mut path = PathBuf::from(file);
            if path.is_relative() {
                if let Some(dir) = &reader.compiler.meshdir {
                    path = dir.join(path);
                }
                if let (true, Some(folder)) = (path.is_relative(), reader.folder) {
                    path = folder.join(path);
                }
            }
            // MuJoCo stores vertices in single precision and scales them in double.
            let scaled = |mut vertices: Vec<Vector3<f64>>| -> Vec<Vector3<f64>> {
                vertices.iter_mut().for_each(|v| *v = v.map(|x| x as f32 as f64).component_mul(&scale));
                vertices
            };
            // Reading a mesh may take long: a cancelled load stops before the next.
            check_cancelled("from_mjcf")?;
            // What MuJoCo refuses in a mesh, legkit refuses too: its mass would be a wrong answer.
            let refused = |reason: String| invalid(format!("{} ({}): {reason}, which MuJoCo refuses too", mesh.what(), path.display()));
            let asset = match readable(mesh_triangles(&path))? {
                Ok(((vertices, mut faces), differs)) => {
                    // Where MuJoCo reads the file otherwise: its mass of the faces (not taken under "convex", whose
                    // hull is of every vertex in both), or its refusal of the file.
                    let mass = differs.mass.into_iter().filter(|_| mode != "convex");
                    for note in differs.refused.into_iter().chain(mass) {
                        reader.accept(format!("{}: {note}", mesh.what()))?;
                    }
                    if mode == "exact" {
                        if let Some([a, b]) = inconsistent_edge(&vertices, &faces)? {
                            let reason = format!(
                                "its faces have inconsistent orientation (two faces run along the edge from vertex {} to vertex {}) under \
                                 inertia=\"exact\"",
                                a + 1,
                                b + 1
                            );
                            return Err(refused(reason));
                        }
                    }
                    let vertices = scaled(vertices);
                    // A mirroring scale turns the faces inside out; MuJoCo turns them back.
                    if scale.product() < 0.0 {
                        faces.iter_mut().for_each(|f| f.swap(1, 2));
                    }
                    let mass = match mode {
                        "convex" => Err("inertia=\"convex\" (the hull's volume) is not computed".to_owned()),
                        // MuJoCo leaves an overflowing mass out without a word: here, a warning.
                        _ => match mesh_mass(&vertices, &faces, mode) {
                            Err(reason) if reason != OVERFLOW => return Err(refused(reason)),
                            mass => mass,
                        },
                    };
                    Ok(MeshAsset { vertices, mass })
                }
                Err(faceless) => readable(mesh_vertices(&path))?.map(|vertices| MeshAsset { vertices: scaled(vertices), mass: Err(faceless) }),
            };
            meshes.insert(name, asset);
        }
    }
    Ok(meshes)
}

/// What reading a mesh file gave: a file that cannot be read is a warning (Ok(Err(reason))), but one too large for
/// memory fails the load (`Error::TooLarge`: a MemoryError, as for any other part of the model), and so does a
/// cancelled load.
fn readable<T>(read: Result<T>) -> Result<std::result::Result<T, String>> {
    match read {
        Ok(x) => Ok(Ok(x)),
        Err(e @ (Error::TooLarge { .. } | Error::Numerical { .. })) => Err(e),
        Err(other) => Ok(Err(other.reason().to_owned())),
    }
}

type Meshes = HashMap<String, std::result::Result<MeshAsset, String>>;

/// A mesh asset: its vertices (scaled) for the collision hull, and its mass per unit density, or why that
/// could not be computed.
struct MeshAsset {
    vertices: Vec<Vector3<f64>>,
    mass: std::result::Result<MeshMass, String>,
}

/// A mesh's volume (its area for `inertia="shell"`), centre of mass and inertia about it per unit density, in
/// the mesh file's frame.
struct MeshMass {
    volume: f64,
    com: Vector3<f64>,
    inertia: Matrix3<f64>,
}

/// A triangle's area, unit normal and centre; a triangle whose cross product is below MuJoCo's `mjMINVAL`
/// has no area.
fn triangle(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> (f64, Vector3<f64>, Vector3<f64>) {
    let center = (a + b + c) / 3.0;
    let normal = (b - a).cross(&(c - a));
    let len = normal.norm();
    if len < 1e-15 {
        return (0.0, normal, center);
    }
    (0.5 * len, normal / len, center)
}

/// The first directed edge (vertex indices, in sorted order) that two faces run along, counting faces of area above
/// `sqrt(mjMINVAL)` in the mesh file's units: a closed or open surface whose faces are consistently oriented runs
/// along each edge once in each direction at most. MuJoCo refuses such a mesh under `inertia="exact"`, whose
/// signed volumes would partly cancel (mjCMesh::Process, google-deepmind/mujoco); STL corners are merged first
/// (`mesh_triangles`), OBJ and MSH vertices are taken as indexed.
fn inconsistent_edge(vertices: &[Vector3<f64>], faces: &[[usize; 3]]) -> Result<Option<[usize; 2]>> {
    let mut edges = crate::validate::with_capacity("mesh", faces.len().saturating_mul(3))?;
    for (k, f) in faces.iter().enumerate() {
        cancel_point("mesh", k)?;
        // MuJoCo stores vertices in single precision and checks them before scaling.
        let [a, b, c] = f.map(|i| vertices[i].map(|x| x as f32 as f64));
        if triangle(&a, &b, &c).0 > 1e-15f64.sqrt() {
            edges.extend([[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]]);
        }
    }
    check_cancelled("mesh")?;
    edges.sort_unstable();
    Ok(edges.windows(2).find(|pair| pair[0] == pair[1]).map(|pair| pair[0]))
}

/// Why `mesh_mass` fails on numbers beyond float64 (where a silent NaN would leave the geom's mass out unsaid).
const OVERFLOW: &str = "its volume or inertia overflows float64 (is its scale physical?)";

/// A mesh's mass per unit density from its triangles, step by step as MuJoCo's compiler takes it
/// [MuJoCo, user_mesh.cc: mjCMesh::Process, ComputeFaceCentroid, ComputeVolume, ComputeInertia]: the pyramids
/// from the faces' area-weighted centroid to each face give the centre of mass, then the pyramids from the
/// centre of mass to each face the volume and the inertia (for `legacy`, MuJoCo's default, each pyramid's
/// volume counts positive whatever the face's orientation; `shell` weighs the faces by area).
fn mesh_mass(vertices: &[Vector3<f64>], faces: &[[usize; 3]], mode: &str) -> std::result::Result<MeshMass, String> {
    let corners = |f: &[usize; 3]| (&vertices[f[0]], &vertices[f[1]], &vertices[f[2]]);
    let (mut area, mut facecen) = (0.0, Vector3::zeros());
    for f in faces {
        let (a, b, c) = corners(f);
        let (s, _, center) = triangle(a, b, c);
        area += s;
        facecen += center * s;
    }
    // Negated comparisons, so that NaN (a scale that overflows) fails them too.
    if !(area >= 1e-15) {
        return Err(if area.is_finite() { "its surface area is too small" } else { OVERFLOW }.into());
    }
    facecen /= area;
    let shell = mode == "shell";
    let pyramid = |s: f64, normal: &Vector3<f64>, apex_to_center: &Vector3<f64>| -> f64 {
        let v = if shell { s } else { apex_to_center.dot(normal) * s / 3.0 };
        if mode == "legacy" {
            v.abs()
        } else {
            v
        }
    };
    let (mut total, mut com) = (0.0, Vector3::zeros());
    for f in faces {
        let (a, b, c) = corners(f);
        let (s, normal, center) = triangle(a, b, c);
        let v = pyramid(s, &normal, &(center - facecen));
        total += v;
        com += (center * 0.75 + facecen * 0.25) * v;
    }
    if !(total >= 1e-15) {
        return Err(match total {
            t if t < 0.0 => "its volume is negative (misoriented faces)",
            t if t.is_nan() => OVERFLOW,
            _ => "its volume is too small",
        }
        .into());
    }
    com /= total;
    // Second moments P = Σ v/C (2 Σ D Dᵀ + Σ (D Eᵀ + E Dᵀ)) over each face's corners D, E, F about the centre of mass.
    let (mut volume, mut p) = (0.0, Matrix3::zeros());
    let weight = if shell { 12.0 } else { 20.0 };
    for f in faces {
        let (a, b, c) = corners(f);
        let (d, e, g) = (a - com, b - com, c - com);
        let (s, normal, center) = triangle(&d, &e, &g);
        let v = pyramid(s, &normal, &center);
        volume += v;
        let outer = |x: &Vector3<f64>, y: &Vector3<f64>| x * y.transpose() + y * x.transpose();
        p += (2.0 * (d * d.transpose() + e * e.transpose() + g * g.transpose()) + outer(&d, &e) + outer(&d, &g) + outer(&e, &g)) * (v / weight);
    }
    let inertia = Matrix3::identity() * p.trace() - p;
    if !(volume.is_finite() && com.iter().chain(inertia.iter()).all(|x| x.is_finite())) {
        return Err(OVERFLOW.into());
    }
    if SymmetricEigen::new(inertia).eigenvalues.min() <= 0.0 {
        return Err("its inertia is not positive".into());
    }
    Ok(MeshMass { volume, com, inertia })
}

/// What a body's elements add up to: its `<inertial>`, its geoms' masses, and what they leave out.
#[derive(Default)]
struct Contents {
    inertial: Option<MassProperties>,
    geoms: Vec<MassProperties>,
    mesh_mass: Vec<String>,
    unshaped: Vec<String>,
    /// Its colliding plane geoms: what they are, their frames in the body's and their sliding friction.
    planes: Vec<(String, Transform, f64)>,
}

/// Reads bodies depth first (MuJoCo's numbering) into `bodies`.
struct Walker<'r, 'a> {
    reader: &'r mut Reader<'a>,
    meshes: &'r Meshes,
    bodies: Vec<Body>,
    joint_count: usize,
    /// The world's first plane, the floor.
    ground: Option<Ground>,
}

impl Walker<'_, '_> {
    /// Body `index` (0 the world) from its element `el`: its contents, then its mass properties.
    fn body(&mut self, el: &El, index: usize, childclass: &str) -> Result<()> {
        let mut contents = Contents::default();
        self.children(el, index, &Transform::identity(), childclass, &mut contents)?;
        let reader = &mut *self.reader;
        let name = &self.bodies[index].name;
        let mut planes = contents.planes.into_iter();
        if index == 0 && self.ground.is_none() {
            if let Some((what, placement, friction)) = planes.next() {
                self.ground = Some(Ground::placed_plane(friction, placement).map_err(|e| invalid(format!("{what}: {e}")))?);
            }
        }
        contents.unshaped.extend(planes.map(|(what, ..)| format!("{what} (a plane besides the floor)")));
        if !contents.unshaped.is_empty() {
            reader.notes.push(format!("body {name:?}: geoms without a collision shape: {}", contents.unshaped.join(", ")));
        }
        if index == 0 {
            return Ok(());
        }
        let from_geoms = match reader.compiler.inertia_from_geom {
            InertiaFromGeom::Always => true,
            InertiaFromGeom::Never => false,
            InertiaFromGeom::Auto => contents.inertial.is_none(),
        };
        let mass = if from_geoms {
            if !contents.mesh_mass.is_empty() {
                reader.accept(format!("body {name:?}: the mass of mesh geoms {} is not computed: left out", contents.mesh_mass.join(", ")))?;
            }
            contents.geoms.into_iter().sum()
        } else {
            contents.inertial.unwrap_or_else(MassProperties::zero)
        };
        self.bodies[index].mass = bounded(mass, &reader.compiler).map_err(|e| invalid(format!("body {name:?}: {e}")))?;
        Ok(())
    }

    /// The children of `el` (a body or a `<frame>` in it, placed by `prefix` in body `index`'s frame).
    fn children(&mut self, el: &El, index: usize, prefix: &Transform, childclass: &str, contents: &mut Contents) -> Result<()> {
        for child in &el.children {
            let class = self.reader.class_of(child, childclass)?.to_owned();
            let inner = child.attr("childclass").unwrap_or(childclass);
            if !self.reader.classes.contains_key(inner) {
                return Err(invalid(format!("{}: unknown childclass {inner:?}", child.what())));
            }
            match child.tag.as_str() {
                "body" => {
                    cancel_point("from_mjcf", self.bodies.len())?;
                    let frame = prefix.compose(&self.reader.frame(child, &class)?);
                    let number = self.bodies.len();
                    let name = child.attr("name").map_or_else(|| format!("body{number}"), str::to_owned);
                    self.bodies.push(Body { name, parent: index, frame, joints: Vec::new(), mass: MassProperties::zero(), shapes: Vec::new() });
                    self.body(child, number, inner)?;
                }
                // A frame's elements belong to the enclosing body, placed by the frame.
                "frame" => {
                    let frame = prefix.compose(&self.reader.frame(child, &class)?);
                    self.children(child, index, &frame, inner, contents)?;
                }
                "joint" | "freejoint" => {
                    if index == 0 {
                        return Err(invalid(format!("{}: the world body cannot have joints", child.what())));
                    }
                    let spec = joint(child, &class, prefix, self.reader, self.joint_count)?;
                    self.joint_count += 1;
                    self.bodies[index].joints.push(spec);
                }
                "geom" => geom(child, &class, prefix, self.reader, self.meshes, contents, &mut self.bodies[index].shapes)?,
                "inertial" => {
                    let frame = prefix.compose(&self.reader.frame(child, &class)?);
                    contents.inertial = Some(inertial_of(child, &class, &frame, self.reader)?);
                }
                "flexcomp" | "attach" | "plugin" | "skin" => {
                    self.reader.accept(format!("{} is not supported: left out", child.what()))?;
                }
                _ => {} // site, camera, light: no effect on the dynamics
            }
        }
        Ok(())
    }
}

fn joint(el: &El, class: &str, prefix: &Transform, reader: &mut Reader, id: usize) -> Result<JointSpec> {
    let name = el.attr("name").map_or_else(|| format!("joint{id}"), str::to_owned);
    if el.tag == "freejoint" {
        // MuJoCo's <freejoint> takes no joint defaults: no damping, armature or stiffness.
        return Ok(JointSpec {
            name,
            kind: JointKind::Free,
            pos: Vector3::zeros(),
            axis: Vector3::z(),
            reference: 0.0,
            range: None,
            damping: 0.0,
            armature: 0.0,
        });
    }
    let kind = reader.get(el, class, "type").unwrap_or("hinge");
    let kind = match kind {
        "hinge" => JointKind::Hinge,
        "slide" => JointKind::Slide,
        "free" => JointKind::Free,
        "ball" => JointKind::Ball,
        other => return Err(invalid(format!("joint {name:?} ({}): unknown type {other:?}", el.at))),
    };
    let pos = prefix.transform_point(&reader.fixed::<3>(el, class, "pos")?.map_or_else(Vector3::zeros, Vector3::from));
    let axis = prefix.rotation * reader.fixed::<3>(el, class, "axis")?.map_or_else(Vector3::z, Vector3::from);
    let axis = axis.try_normalize(1e-10).ok_or_else(|| invalid(format!("joint {name:?}: zero axis")))?;
    let scale = if matches!(kind, JointKind::Hinge | JointKind::Ball) { reader.compiler.angle } else { 1.0 };
    let range = reader.fixed::<2>(el, class, "range")?;
    let limited = match reader.boolean(el, class, "limited")? {
        Some(b) => b,
        None => reader.compiler.autolimits && range.is_some(),
    };
    let range = match (kind, limited, range) {
        (JointKind::Free, _, _) | (_, false, _) => None,
        // A ball joint's range bounds its rotation angle (MuJoCo's cone), which JointLimits cannot express.
        (JointKind::Ball, true, r) => {
            reader.accept(format!("joint {name:?}: the range {r:?} of a ball joint is not modelled"))?;
            None
        }
        (_, true, r) => {
            let [lo, hi] = r.unwrap_or([0.0, 0.0]);
            if lo > hi {
                return Err(invalid(format!("joint {name:?}: range {lo} > {hi}")));
            }
            Some((lo * scale, hi * scale))
        }
    };
    // MuJoCo reads `ref` on hinges and slides only: a ball joint's qpos0 is the identity.
    let reference = if matches!(kind, JointKind::Hinge | JointKind::Slide) { reader.scalar(el, class, "ref", 0.0)? * scale } else { 0.0 };
    let damping = reader.scalar(el, class, "damping", 0.0)?;
    let armature = reader.scalar(el, class, "armature", 0.0)?;
    if damping < 0.0 || armature < 0.0 {
        return Err(invalid(format!("joint {name:?}: damping and armature must be >= 0")));
    }
    for key in ["stiffness", "frictionloss"] {
        let value = reader.scalar(el, class, key, 0.0)?;
        if value != 0.0 {
            reader.accept(format!("joint {name:?}: {key}={value} is not modelled"))?;
        }
    }
    // MuJoCo derives a stiffness and a damping from the joint's effective mass in place of `damping`.
    if let Some(value @ [timeconst, _]) = reader.fixed::<2>(el, class, "springdamper")? {
        if timeconst > 0.0 {
            reader.accept(format!("joint {name:?}: springdamper={value:?} is not modelled (its damping={damping} applies)"))?;
        }
    }
    Ok(JointSpec { name, kind, pos, axis, reference, range, damping, armature })
}

/// A geom's mass (into `contents`, when its group counts) and collision shape (into `shapes`).
fn geom(
    el: &El,
    class: &str,
    prefix: &Transform,
    reader: &mut Reader,
    meshes: &Meshes,
    contents: &mut Contents,
    shapes: &mut Vec<Shape>,
) -> Result<()> {
    let what = el.what();
    let kind = reader.get(el, class, "type").unwrap_or("sphere").to_owned();
    let mut size = [0.0; 3];
    if let Some(values) = reader.nums(el, class, "size")? {
        if values.len() > 3 {
            return Err(invalid(format!("{what}: size has more than 3 numbers")));
        }
        size[..values.len()].copy_from_slice(&values);
    }
    let mut frame = reader.frame(el, class)?;
    if let Some(ft) = reader.fixed::<6>(el, class, "fromto")? {
        let (from, to) = (Vector3::new(ft[0], ft[1], ft[2]), Vector3::new(ft[3], ft[4], ft[5]));
        let half = (to - from).norm() / 2.0;
        if half < 1e-14 {
            return Err(invalid(format!("{what}: fromto points too close")));
        }
        match kind.as_str() {
            "capsule" | "cylinder" => size[1] = half,
            "box" | "ellipsoid" => {
                size[2] = half;
                size[1] = size[0];
            }
            _ => return Err(invalid(format!("{what}: fromto requires a capsule, cylinder, box or ellipsoid"))),
        }
        let rotation = z_to(from - to).expect("points apart").to_rotation_matrix().into_inner();
        frame = Transform::new(rotation, (from + to) / 2.0);
    }
    let frame = prefix.compose(&frame);
    let [a, b, c] = size;
    let pi = std::f64::consts::PI;
    // [MuJoCo, user_objects.cc: mjCGeom::GetVolume, SetInertia]: volume, and the inertia per unit mass.
    let shape_inertia: Option<(f64, [f64; 3])> = match kind.as_str() {
        "sphere" => Some((4.0 * pi * a.powi(3) / 3.0, [2.0 * a * a / 5.0; 3])),
        "capsule" => {
            let h = 2.0 * b;
            let sphere = 4.0 * a / (4.0 * a + 3.0 * h);
            let cylinder = 1.0 - sphere;
            let side = cylinder * (3.0 * a * a + h * h) / 12.0 + 2.0 * sphere * a * a / 5.0 + sphere * h * (3.0 * a + 2.0 * h) / 8.0;
            let axial = cylinder * a * a / 2.0 + 2.0 * sphere * a * a / 5.0;
            Some((pi * (a * a * h + 4.0 * a.powi(3) / 3.0), [side, side, axial]))
        }
        "cylinder" => {
            let h = 2.0 * b;
            Some((pi * a * a * h, [(3.0 * a * a + h * h) / 12.0, (3.0 * a * a + h * h) / 12.0, a * a / 2.0]))
        }
        "ellipsoid" => Some((4.0 * pi * a * b * c / 3.0, [(b * b + c * c) / 5.0, (a * a + c * c) / 5.0, (a * a + b * b) / 5.0])),
        "box" => Some((8.0 * a * b * c, [(b * b + c * c) / 3.0, (a * a + c * c) / 3.0, (a * a + b * b) / 3.0])),
        "plane" | "hfield" | "mesh" | "sdf" => None,
        other => return Err(invalid(format!("{what}: unknown geom type {other:?}"))),
    };
    let mesh = match kind.as_str() {
        "mesh" => {
            let name = reader.get(el, class, "mesh").unwrap_or("");
            Some((name, meshes.get(name).ok_or_else(|| invalid(format!("{what}: unknown mesh {name:?}")))?))
        }
        _ => None,
    };
    let group = reader.scalar(el, class, "group", 0.0)? as i64;
    let counts = (reader.compiler.group_range[0]..=reader.compiler.group_range[1]).contains(&group);
    let given_mass = reader.fixed::<1>(el, class, "mass")?.map(|[m]| m);
    let density = reader.scalar(el, class, "density", 1000.0)?;
    // The geom's volume, and its centre of mass and inertia per unit mass in the geom's frame.
    let per_mass = match (shape_inertia, mesh) {
        (Some((volume, per_mass)), _) => Some((volume, Vector3::zeros(), Matrix3::from_diagonal(&Vector3::from(per_mass)))),
        (None, Some((_, Ok(MeshAsset { mass: Ok(m), .. })))) => Some((m.volume, m.com, m.inertia / m.volume)),
        (None, Some((name, asset))) => {
            if counts && given_mass != Some(0.0) && density != 0.0 {
                let reason = match asset {
                    Ok(MeshAsset { mass: Err(e), .. }) | Err(e) => e.as_str(),
                    Ok(_) => "",
                };
                contents.mesh_mass.push(format!("{what} (mesh {name:?}: {reason})"));
            }
            None
        }
        (None, None) => None,
    };
    if let (true, Some((volume, com, per_mass))) = (counts, per_mass) {
        let mass = match given_mass {
            Some(m) if volume > 1e-15 || m == 0.0 => m,
            Some(_) => 0.0,
            None => density * volume,
        };
        if mass < 0.0 {
            return Err(invalid(format!("{what}: negative mass or density")));
        }
        // MuJoCo leaves out geoms of mass up to mjEPS.
        if mass > 1e-14 {
            let inertia = frame.rotation * (per_mass * mass) * frame.rotation.transpose();
            let center = frame.transform_point(&com);
            contents.geoms.push(MassProperties::as_written(mass, center, inertia).map_err(|e| invalid(format!("{what}: {e}")))?);
        }
    }
    let contype = reader.scalar(el, class, "contype", 1.0)?;
    let conaffinity = reader.scalar(el, class, "conaffinity", 1.0)?;
    if contype == 0.0 && conaffinity == 0.0 {
        return Ok(());
    }
    let shape_kind = match kind.as_str() {
        "sphere" => ShapeKind::Sphere(a),
        "capsule" => ShapeKind::Capsule { half_height: b, radius: a },
        "cylinder" => ShapeKind::Cylinder { half_height: b, radius: a },
        "box" => ShapeKind::Box(Vector3::new(2.0 * a, 2.0 * b, 2.0 * c)),
        "plane" => {
            let friction = reader.nums(el, class, "friction")?.and_then(|f| f.first().copied()).unwrap_or(1.0);
            contents.planes.push((what, frame, friction));
            return Ok(());
        }
        "mesh" => match mesh {
            Some((name, Ok(asset))) => match hull_points(&asset.vertices).and_then(|(points, thinned)| Ok((Convex::hull(&points)?, thinned))) {
                Ok((hull, thinned)) => {
                    if let Some(note) = thinned {
                        reader.accept(format!("{what} (mesh {name:?}): {note}"))?;
                    }
                    ShapeKind::Convex(hull)
                }
                Err(e) => {
                    contents.unshaped.push(format!("{what} (mesh: {})", e.reason()));
                    return Ok(());
                }
            },
            Some((name, Err(e))) => {
                contents.unshaped.push(format!("{what} (mesh {name:?}: {e})"));
                return Ok(());
            }
            None => unreachable!("a mesh geom has its mesh"),
        },
        _ => {
            contents.unshaped.push(format!("{what} ({kind})"));
            return Ok(());
        }
    };
    shapes.push(Shape::new(shape_kind, Some(frame)).map_err(|e| invalid(format!("{what}: {e}")))?);
    Ok(())
}

fn inertial_of(el: &El, class: &str, frame: &Transform, reader: &mut Reader) -> Result<MassProperties> {
    let what = el.what();
    let mass = reader.fixed::<1>(el, class, "mass")?.ok_or_else(|| invalid(format!("{what} has no mass")))?[0];
    let inertia = match (reader.fixed::<3>(el, class, "diaginertia")?, reader.fixed::<6>(el, class, "fullinertia")?) {
        (Some(d), None) => Matrix3::from_diagonal(&Vector3::from(d)),
        (None, Some([xx, yy, zz, xy, xz, yz])) => Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz),
        (None, None) => Matrix3::zeros(),
        (Some(_), Some(_)) => return Err(invalid(format!("{what}: both diaginertia and fullinertia"))),
    };
    if let Some(problem) = MassProperties::inertia_problem(&inertia) {
        reader.accept(format!("{what}: non-physical inertia ({problem}), kept as written"))?;
    }
    MassProperties::as_written(mass, Vector3::zeros(), inertia)
        .and_then(|body| body.transformed(&frame.rotation, &frame.translation))
        .map_err(|e| invalid(format!("{what}: {e}")))
}

/// `boundmass`, `boundinertia` and `balanceinertia` on the body's mass and principal moments.
fn bounded(body: MassProperties, compiler: &Compiler) -> Result<MassProperties> {
    let bound = compiler.boundmass > 0.0 || compiler.boundinertia > 0.0 || compiler.balanceinertia;
    if !bound {
        return Ok(body);
    }
    let mass = body.mass().max(compiler.boundmass);
    let eigen = SymmetricEigen::new(body.inertia());
    let mut moments = eigen.eigenvalues.map(|m| m.max(compiler.boundinertia));
    let (x, y, z) = (moments[0], moments[1], moments[2]);
    if compiler.balanceinertia && (x + y < z || x + z < y || y + z < x) {
        moments = Vector3::repeat((x + y + z) / 3.0);
    }
    let inertia = eigen.eigenvectors * Matrix3::from_diagonal(&moments) * eigen.eigenvectors.transpose();
    MassProperties::as_written(mass, body.com(), inertia)
}

/// The model: the world (or the free body) as the base, then MuJoCo's bodies in order.
fn build(bodies: &[Body], options: &MjcfOptions, reader: &mut Reader) -> Result<(Model, Vec<MjcfJoint>)> {
    let top: Vec<usize> = (1..bodies.len()).filter(|&b| bodies[b].parent == 0).collect();
    for body in &bodies[1..] {
        let free = body.joints.iter().filter(|j| j.kind == JointKind::Free).count();
        if free > 0 && (body.parent != 0 || body.joints.len() > 1) {
            return Err(invalid(format!("body {:?}: a free joint must be the only joint of a top-level body", body.name)));
        }
    }
    let has_free = |b: usize| bodies[b].joints.iter().any(|j| j.kind == JointKind::Free);
    let moving: Vec<usize> = top.iter().copied().filter(|&b| !bodies[b].joints.is_empty()).collect();
    let free: Vec<usize> = top.iter().copied().filter(|&b| has_free(b)).collect();
    let names = |list: &[usize]| list.iter().map(|&b| format!("{:?}", bodies[b].name)).collect::<Vec<_>>().join(", ");
    // Several free bodies (a robot and a ball): a fixed world, each free body on three slides along the world's
    // axes and a ball joint, which are MuJoCo's free-joint coordinates (position, and linear velocity, in the world
    // frame; orientation, and angular velocity, in the body's).
    let free_chains = options.floating_base.is_none() && free.len() > 1;
    let floating = options.floating_base.unwrap_or(free.len() == 1);
    let base_body = if floating {
        let candidates = if moving.is_empty() { top.clone() } else { moving.clone() };
        match candidates.as_slice() {
            [b] if bodies[*b].joints.iter().all(|j| j.kind == JointKind::Free) => Some(*b),
            [b] => return Err(invalid(format!("body {:?}: a floating base cannot also have hinge or slide joints", bodies[*b].name))),
            [] => return Err(invalid("no body to make the floating base".into())),
            _ => return Err(invalid(format!("a floating base needs a single moving top-level body; found {}", names(&candidates)))),
        }
    } else {
        None
    };
    let mut model;
    let mut kept = vec![false; bodies.len()];
    // The legkit body of each MJCF body, and the anchor offset of its frame.
    let mut legkit = vec![(0usize, Vector3::zeros()); bodies.len()];
    let mut joints = Vec::new();
    let mut damping = Vec::new();
    let mut armature = Vec::new();
    if let Some(b) = base_body {
        let body = &bodies[b];
        model = Model::new(true, body.mass, &body.name);
        kept[b] = true;
        let spec = &body.joints[0];
        joints.push(MjcfJoint { name: spec.name.clone(), kind: JointKind::Free, body: 0, idx_q: 0, idx_v: 0 });
        // legkit's free-flyer coordinates carry no armature or damping (Pinocchio's neither).
        for (key, value) in [("damping", spec.damping), ("armature", spec.armature)] {
            if value != 0.0 {
                reader.accept(format!("free joint {:?}: {key}={value} is not modelled on a floating base", spec.name))?;
            }
        }
        let dropped: Vec<usize> = top.iter().copied().filter(|&t| t != b).collect();
        if !dropped.is_empty() {
            reader.accept(format!("static top-level bodies {} are left out of the floating-base model", names(&dropped)))?;
        }
        if let Some(shapes) = Some(&bodies[0].shapes).filter(|s| !s.is_empty()) {
            reader.notes.push(format!("the world's {} collision geoms are left out of the floating-base model (use lk.Ground)", shapes.len()));
        }
    } else {
        model = Model::new(false, MassProperties::zero(), "world");
        kept[0] = true;
    }
    let mut shapes: Vec<(usize, Shape)> = Vec::new();
    let shifted = |shape: &Shape, shift: &Vector3<f64>| -> Shape {
        let mut s = shape.clone();
        let p = s.placement.unwrap_or_default();
        s.placement = Some(Transform::from_translation(-shift).compose(&p));
        s
    };
    if base_body.is_none() {
        shapes.extend(bodies[0].shapes.iter().map(|s| (0, s.clone())));
    } else if let Some(b) = base_body {
        shapes.extend(bodies[b].shapes.iter().map(|s| (0, s.clone())));
    }
    for (b, body) in bodies.iter().enumerate().skip(1) {
        cancel_point("from_mjcf", b)?;
        if kept[b] || !kept[body.parent] {
            continue;
        }
        kept[b] = true;
        let (mut parent, parent_shift) = legkit[body.parent];
        let mut frame = Transform::from_translation(-parent_shift).compose(&body.frame);
        let mut anchor = Vector3::zeros();
        let free_welded = body.joints.iter().any(|j| j.kind == JointKind::Free);
        let moving: Vec<&JointSpec> = if free_welded { Vec::new() } else { body.joints.iter().collect() };
        let fail = |e: Error| invalid(format!("body {:?}: {e}", body.name));
        if free_welded && free_chains {
            let spec = &body.joints[0];
            let first = model.nbodies();
            for (k, axis) in ["x", "y", "z"].iter().zip([Vector3::x(), Vector3::y(), Vector3::z()]) {
                let name = format!("{}/{}:{k}", body.name, spec.name);
                parent = model
                    .add_body(parent, Joint::Prismatic(axis), Transform::identity(), MassProperties::zero(), &name, JointLimits::NONE)
                    .map_err(fail)?;
            }
            parent = model.add_body(parent, Joint::Spherical, Transform::identity(), body.mass, &body.name, JointLimits::NONE).map_err(fail)?;
            let (idx_q, idx_v) = (model.idx_q(first), model.idx_v(first));
            joints.push(MjcfJoint { name: spec.name.clone(), kind: JointKind::Free, body: parent, idx_q, idx_v });
            for k in idx_v..idx_v + 6 {
                damping.push((k, spec.damping));
                armature.push((k, spec.armature));
            }
            legkit[b] = (parent, anchor);
            shapes.extend(body.shapes.iter().map(|s| (parent, s.clone())));
            continue;
        }
        for (k, spec) in moving.iter().enumerate() {
            let last = k + 1 == moving.len();
            let name = if last { body.name.clone() } else { format!("{}/{}", body.name, spec.name) };
            let (joint, placement) = match spec.kind {
                JointKind::Hinge => {
                    let placement = frame.compose(&Transform::from_translation(spec.pos - anchor)).rotated_about(&spec.axis, -spec.reference);
                    anchor = spec.pos;
                    (Joint::Revolute(spec.axis), placement)
                }
                // Turns about its anchor, as a hinge: q is MuJoCo's qpos with w last.
                JointKind::Ball => {
                    let placement = frame.compose(&Transform::from_translation(spec.pos - anchor));
                    anchor = spec.pos;
                    (Joint::Spherical, placement)
                }
                _ => (Joint::Prismatic(spec.axis), frame.compose(&Transform::from_translation(-spec.axis * spec.reference))),
            };
            let limits = match spec.range {
                Some((lo, hi)) => JointLimits::new(lo, hi, f64::INFINITY, f64::INFINITY).map_err(fail)?,
                None => JointLimits::NONE,
            };
            let mass = if last { body.mass.transformed_unchecked(&Matrix3::identity(), &-anchor) } else { MassProperties::zero() };
            parent = model.add_body(parent, joint, placement, mass, &name, limits).map_err(fail)?;
            let kind = spec.kind;
            joints.push(MjcfJoint { name: spec.name.clone(), kind, body: parent, idx_q: model.idx_q(parent), idx_v: model.idx_v(parent) });
            for k in model.idx_v(parent)..model.idx_v(parent) + model.joint(parent).nv() {
                damping.push((k, spec.damping));
                armature.push((k, spec.armature));
            }
            frame = Transform::identity();
        }
        if moving.is_empty() {
            parent = model.add_body(parent, Joint::Fixed, frame, body.mass, &body.name, JointLimits::NONE).map_err(fail)?;
        }
        legkit[b] = (parent, anchor);
        shapes.extend(body.shapes.iter().map(|s| (parent, shifted(s, &anchor))));
    }
    let set = |values: &[(usize, f64)], n: usize| -> Vec<f64> {
        let mut out = vec![0.0; n];
        for &(k, x) in values {
            out[k] = x;
        }
        out
    };
    model.set_damping(&set(&damping, model.nv()))?;
    model.set_armature(&set(&armature, model.nv()))?;
    if !shapes.is_empty() {
        model.set_collision_shapes(shapes)?;
    }
    Ok((model, joints))
}

fn actuators(root: &El, joints: &[MjcfJoint], reader: &mut Reader) -> Result<Vec<Actuator>> {
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    for section in root.elements("actuator") {
        for el in &section.children {
            let class = reader.class_of(el, "main")?.to_owned();
            let name = el.attr("name").map_or_else(|| format!("actuator{}", out.len() + skipped.len()), str::to_owned);
            let Some(target) = reader.get(el, &class, "joint") else {
                skipped.push(format!("{} (not a joint transmission)", el.what()));
                continue;
            };
            let Some(joint) = joints.iter().find(|j| j.name == target) else {
                return Err(invalid(format!("{}: unknown joint {target:?}", el.what())));
            };
            if matches!(joint.kind, JointKind::Free | JointKind::Ball) {
                skipped.push(format!("{} (on a {} joint)", el.what(), if joint.kind == JointKind::Free { "free" } else { "ball" }));
                continue;
            }
            let gear = reader.nums(el, &class, "gear")?.map_or(1.0, |g| g.first().copied().unwrap_or(1.0));
            let kp = reader.scalar(el, &class, "kp", 1.0)?;
            let kv = reader.scalar(el, &class, "kv", if el.tag == "velocity" { 1.0 } else { 0.0 })?;
            let params = |key: &str| -> Result<[f64; 3]> {
                let mut p = [0.0; 3];
                if let Some(v) = reader.nums(el, &class, key)? {
                    for (slot, x) in p.iter_mut().zip(v) {
                        *slot = x;
                    }
                }
                Ok(p)
            };
            let (gain, bias) = match el.tag.as_str() {
                "motor" => ([1.0, 0.0, 0.0], [0.0; 3]),
                "position" => {
                    if reader.scalar(el, &class, "timeconst", 0.0)? != 0.0 || reader.get(el, &class, "dampratio").is_some() {
                        skipped.push(format!("{} (timeconst or dampratio)", el.what()));
                        continue;
                    }
                    ([kp, 0.0, 0.0], [0.0, -kp, -kv])
                }
                "velocity" => ([kv, 0.0, 0.0], [0.0, 0.0, -kv]),
                "general" => {
                    let dyn_ok = reader.get(el, &class, "dyntype").is_none_or(|d| d == "none");
                    let gain_type = reader.get(el, &class, "gaintype").unwrap_or("fixed");
                    let bias_type = reader.get(el, &class, "biastype").unwrap_or("none");
                    if !dyn_ok || !matches!(gain_type, "fixed" | "affine") || !matches!(bias_type, "none" | "affine") {
                        skipped.push(format!("{} (dyntype, gaintype or biastype)", el.what()));
                        continue;
                    }
                    let mut gain = params("gainprm")?;
                    if reader.nums(el, &class, "gainprm")?.is_none() {
                        gain[0] = 1.0;
                    }
                    if gain_type == "fixed" {
                        gain[1] = 0.0;
                        gain[2] = 0.0;
                    }
                    let bias = if bias_type == "none" { [0.0; 3] } else { params("biasprm")? };
                    (gain, bias)
                }
                _ => {
                    skipped.push(format!("{} (kind)", el.what()));
                    continue;
                }
            };
            let range = |key: &str, limited: &str| -> Result<Option<[f64; 2]>> {
                let r = reader.fixed::<2>(el, &class, key)?;
                let on = reader.boolean(el, &class, limited)?.unwrap_or(reader.compiler.autolimits && r.is_some());
                Ok(if on { Some(r.unwrap_or([0.0, 0.0])) } else { None })
            };
            let ctrlrange = range("ctrlrange", "ctrllimited")?;
            let forcerange = range("forcerange", "forcelimited")?;
            out.push(Actuator { name, joint: target.to_owned(), dof: joint.idx_v, gear, gain, bias, ctrlrange, forcerange });
        }
    }
    if !skipped.is_empty() {
        reader.accept(format!("actuators not supported: {}", skipped.join(", ")))?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(xml: &str) -> Mjcf {
        load_mjcf(xml, &MjcfOptions::default()).unwrap()
    }

    #[test]
    fn elements_nested_deeper_than_max_depth_are_refused_before_the_passes_recurse() {
        let nested = |depth: usize| format!("<mujoco><worldbody>{}{}</worldbody></mujoco>", "<body>".repeat(depth), "</body>".repeat(depth));
        // A debug build's frames are larger than a release build's: a stack to match.
        let run = |xml: String| {
            std::thread::Builder::new().stack_size(64 << 20).spawn(move || load_mjcf(&xml, &MjcfOptions::default())).unwrap().join().unwrap()
        };
        // The worldbody is at depth 1, its bodies below it.
        assert_eq!(run(nested(MAX_DEPTH - 1)).unwrap().model.nbodies(), MAX_DEPTH);
        for depth in [MAX_DEPTH, 100 * MAX_DEPTH] {
            let error = run(nested(depth)).unwrap_err();
            assert!(error.to_string().contains("nest deeper than 1000 levels (<string>:1)"), "{error}");
        }
    }

    #[test]
    fn springdamper_is_a_warning_and_leaves_the_damping_read() {
        let xml = "<mujoco><default><joint damping='0.3'/></default><worldbody><body><joint name='h' springdamper='0.1 1'/><geom size='.1'/></body></worldbody></mujoco>";
        let loaded = load(xml);
        assert_eq!(loaded.model.damping(), &[0.3]);
        assert!(
            loaded.warnings.iter().any(|w| w.contains("joint \"h\": springdamper=[0.1, 1.0] is not modelled (its damping=0.3 applies)")),
            "{:?}",
            loaded.warnings
        );
        assert!(load_mjcf(xml, &MjcfOptions { strict: true, ..MjcfOptions::default() }).is_err());
    }

    #[test]
    fn z_to_takes_z_to_the_vector_and_minus_z_by_half_a_turn_about_x() {
        for v in [Vector3::new(0.2, -0.3, 0.9), Vector3::new(-1.0, 0.0, 0.0), Vector3::z(), -Vector3::z()] {
            let q = z_to(v).unwrap();
            assert!((q * Vector3::z() - v.normalize()).norm() < 1e-14, "{v:?}");
        }
        assert!((z_to(-Vector3::z()).unwrap() * Vector3::y() + Vector3::y()).norm() < 1e-14);
        assert!(z_to(Vector3::zeros()).is_none());
    }

    #[test]
    fn euler_lower_case_turns_about_moving_axes_upper_case_about_fixed_ones() {
        let pose = |seq: &str| {
            let xml =
                format!("<mujoco><compiler angle='radian' eulerseq='{seq}'/><worldbody><body name='b' euler='0.3 0.5 0.7'/></worldbody></mujoco>");
            *load(&xml).model.placement(1)
        };
        let r = |axis: Vector3<f64>, a: f64| Transform::rotation_about(&axis, a);
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        assert!((pose("xyz").rotation - r(x, 0.3) * r(y, 0.5) * r(z, 0.7)).norm() < 1e-14);
        assert!((pose("XYZ").rotation - r(z, 0.7) * r(y, 0.5) * r(x, 0.3)).norm() < 1e-14);
    }

    #[test]
    fn a_hinge_with_an_anchor_and_a_reference_turns_about_the_anchor_with_q_as_mujocos_qpos() {
        let xml = "<mujoco><compiler angle='radian'/><worldbody><body name='b' pos='1 0 0'>
            <joint name='j' pos='0 0 0.5' axis='0 1 0' ref='0.25' range='-1 1'/><geom size='0.1' pos='0 0 0.5'/></body></worldbody></mujoco>";
        let mjcf = load(xml);
        let model = &mjcf.model;
        // The legkit frame sits at the anchor, turned by -ref; the sphere's centre is the anchor.
        let placement = model.placement(1);
        assert!((placement.translation - Vector3::new(1.0, 0.0, 0.5)).norm() < 1e-15);
        assert!((placement.rotation - Transform::rotation_about(&Vector3::y(), -0.25)).norm() < 1e-15);
        assert!(model.body(1).com().norm() < 1e-15);
        assert_eq!((model.limits(1).lower, model.limits(1).upper), (-1.0, 1.0));
        assert_eq!(mjcf.joints[0].idx_q, 0);
    }

    #[test]
    fn a_ball_joint_is_spherical_about_its_anchor_and_ignores_ref() {
        let xml =
            "<mujoco><worldbody><body pos='0 0 1'><joint name='s' type='ball' pos='0 0 0.5' ref='30'/><geom size='.1'/></body></worldbody></mujoco>";
        let loaded = load_mjcf(xml, &MjcfOptions::default()).unwrap();
        let model = &loaded.model;
        assert_eq!((*model.joint(1), model.nq(), model.nv()), (Joint::Spherical, 4, 3));
        assert_eq!(model.placement(1).translation, Vector3::new(0.0, 0.0, 1.5));
        assert_eq!(loaded.joints[0].kind, JointKind::Ball);
    }

    /// A box's triangles, half-sizes `h`, turned by `r` and moved by `t`, with every other face turned inside out.
    fn box_mesh(h: Vector3<f64>, r: &Matrix3<f64>, t: &Vector3<f64>) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
        let corner = |i: usize| {
            r * Vector3::new(
                h.x * if i & 1 == 0 { -1.0 } else { 1.0 },
                h.y * if i & 2 == 0 { -1.0 } else { 1.0 },
                h.z * if i & 4 == 0 { -1.0 } else { 1.0 },
            ) + t
        };
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let faces = quads
            .iter()
            .enumerate()
            .flat_map(|(k, q)| if k % 2 == 0 { [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] } else { [[q[0], q[2], q[1]], [q[0], q[3], q[2]]] })
            .collect();
        ((0..8).map(corner).collect(), faces)
    }

    #[test]
    fn a_box_meshs_legacy_mass_is_the_solid_box_whatever_its_faces_orientation() {
        let (h, r, t) =
            (Vector3::new(0.1, 0.2, 0.3), Transform::rotation_about(&Vector3::new(1.0, 2.0, 3.0).normalize(), 0.7), Vector3::new(0.5, -1.0, 2.0));
        let (vertices, faces) = box_mesh(h, &r, &t);
        let mass = mesh_mass(&vertices, &faces, "legacy").unwrap();
        let inertia = r
            * Matrix3::from_diagonal(&Vector3::new(h.y * h.y + h.z * h.z, h.x * h.x + h.z * h.z, h.x * h.x + h.y * h.y))
            * r.transpose()
            * (8.0 * h.x * h.y * h.z / 3.0);
        assert!((mass.volume - 8.0 * h.x * h.y * h.z).abs() < 1e-15);
        assert!((mass.com - t).norm() < 1e-14);
        assert!((mass.inertia - inertia).norm() < 1e-9 * inertia.norm(), "{} vs {inertia}", mass.inertia);
        // "exact" sums signed pyramids: the inside-out faces cancel their opposites. MuJoCo refuses the mesh before:
        // the inside-out faces run along the edges they share with their neighbours in the same direction.
        assert!(mesh_mass(&vertices, &faces, "exact").is_err());
        assert_eq!(inconsistent_edge(&vertices, &faces).unwrap(), Some([1, 5]));
        let outward: Vec<[usize; 3]> = faces.iter().enumerate().map(|(k, f)| if (k / 2) % 2 == 1 { [f[0], f[2], f[1]] } else { *f }).collect();
        assert_eq!(inconsistent_edge(&vertices, &outward).unwrap(), None);
        // Faces of no area do not count.
        let sliver = [outward.as_slice(), &[[0, 0, 1], [0, 0, 1]]].concat();
        assert_eq!(inconsistent_edge(&vertices, &sliver).unwrap(), None);
    }

    #[test]
    fn several_free_bodies_move_on_slides_and_a_ball_under_a_fixed_world() {
        let xml = "<mujoco><worldbody><body name='a' pos='0 0 1'><freejoint/><geom size='.1'/><body name='c'><joint axis='1 0 0'/><geom size='.1' pos='0 0 .3'/></body></body>
            <body name='b' pos='1 0 1'><joint name='f' type='free' damping='0.5'/><geom size='.2'/></body></worldbody></mujoco>";
        let loaded = load(xml);
        let model = &loaded.model;
        assert!(!model.floating_base());
        assert_eq!((model.nq(), model.nv()), (15, 13));
        let kinds: Vec<_> = (1..model.nbodies()).map(|i| model.joint(i).kind()).collect();
        assert_eq!(kinds, ["prismatic", "prismatic", "prismatic", "spherical", "revolute", "prismatic", "prismatic", "prismatic", "spherical"]);
        assert_eq!((loaded.joints[2].name.as_str(), loaded.joints[2].idx_q, loaded.joints[2].idx_v), ("f", 8, 7));
        assert_eq!(&model.damping()[7..13], &[0.5; 6]);
        assert!(load_mjcf(xml, &MjcfOptions { floating_base: Some(false), strict: false }).unwrap().model.nv() == 1);
    }

    #[test]
    fn replicate_copies_are_named_and_placed_as_mujoco_places_them() {
        let xml = "<mujoco><compiler angle='radian'/><worldbody><replicate count='2' sep='-'>
            <replicate count='10' offset='1 0 0' euler='0 0 1.5707963267948966'><body name='b'><joint/></body></replicate>
            </replicate></worldbody></mujoco>";
        let model = load(xml).model;
        assert_eq!(model.nbodies(), 21);
        assert_eq!((model.name(1), model.name(10), model.name(11), model.name(20)), ("b00-0", "b09-0", "b00-1", "b09-1"));
        // Copy i is turned by i quarter turns and sits at the sum of the offsets turned by the copies before it.
        let expected = [Vector3::zeros(), Vector3::x(), Vector3::new(1.0, 1.0, 0.0), Vector3::y()];
        for (i, p) in expected.iter().enumerate() {
            assert!((model.placement(i + 1).translation - p).norm() < 1e-15, "{i}");
        }
        assert!((model.placement(2).rotation - Transform::rotation_about(&Vector3::z(), std::f64::consts::FRAC_PI_2)).norm() < 1e-15);
        let nested = "<replicate count='1000'>".repeat(3) + "<body/>" + &"</replicate>".repeat(3);
        let error = load_mjcf(&format!("<mujoco><worldbody>{nested}</worldbody></mujoco>"), &MjcfOptions::default()).unwrap_err();
        assert!(matches!(error, Error::TooLarge { .. }) && error.to_string().contains("count=1000 copies of 2001 elements"), "{error}");
    }

    #[test]
    fn unknown_classes_are_errors_naming_them() {
        let error = load_mjcf("<mujoco><worldbody><body childclass='x'/></worldbody></mujoco>", &MjcfOptions::default());
        assert!(error.unwrap_err().to_string().contains("unknown childclass \"x\""));
    }

    #[test]
    fn includes_that_include_themselves_are_refused() {
        let folder = std::env::temp_dir().join(format!("legkit-mjcf-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        let file = folder.join("loop.xml");
        std::fs::write(&file, "<mujoco><include file='loop.xml'/></mujoco>").unwrap();
        let error = load_mjcf(file.to_str().unwrap(), &MjcfOptions::default()).unwrap_err();
        assert!(error.to_string().contains("include themselves"), "{error}");
        std::fs::remove_dir_all(&folder).unwrap();
    }
}
