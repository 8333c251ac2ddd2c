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
//!
//! # Examples
//!
//! A pendulum from an MJCF string (a file's path loads the same way): a 1 kg bob 0.3 m below a hinge about y, driven
//! by a motor of gear 2, with MuJoCo's options beside the model. An attribute MuJoCo does not know is an error naming it.
//!
//! ```
//! use legkit_dynamics::mjcf::{load_mjcf, MjcfOptions};
//! use legkit_dynamics::{algorithms, Data};
//!
//! let xml = r#"<mujoco>
//!   <option timestep="0.005"/>
//!   <worldbody>
//!     <body name="bob">
//!       <joint name="hinge" type="hinge" axis="0 1 0"/>
//!       <inertial pos="0 0 -0.3" mass="1" diaginertia="0.01 0.01 0.01"/>
//!     </body>
//!   </worldbody>
//!   <actuator><motor joint="hinge" gear="2"/></actuator>
//! </mujoco>"#;
//! let mjcf = load_mjcf(xml, &MjcfOptions::default())?;
//! let model = &mjcf.model;
//! assert_eq!((model.nv(), model.name(1), mjcf.timestep, mjcf.actuators.len()), (1, "bob", 0.005, 1));
//! let theta: f64 = 0.5;
//! let hold = algorithms::rnea(model, &mut Data::new(model), &[theta], &[0.0], &[0.0], None)?[0];
//! assert!((hold - 9.81 * 0.3 * theta.sin()).abs() < 1e-12);
//! assert_eq!(mjcf.actuator_torques(&[theta], &[0.0], &[0.25])?.as_slice(), &[0.5]);
//! let error = load_mjcf(&xml.replace("axis=", "axs="), &MjcfOptions::default()).unwrap_err();
//! assert!(error.to_string().contains("axs"), "{error}");
//! # Ok::<(), legkit_dynamics::Error>(())
//! ```
//!
//! [`Joint::Spherical`]: crate::Joint::Spherical

mod actuators;
mod assets;
mod body;
mod build;
mod compiler;
mod defaults;
mod element;
mod geom;
mod joint;
mod reader;
mod replicate;
mod schema;
#[cfg(test)]
mod tests;

use std::path::Path;
use std::rc::Rc;

use nalgebra::{DVector, Vector3};

use crate::sim::Ground;
use crate::{Error, MassProperties, Model, Result};
use compiler::Compiler;
use element::{line_breaks, own, read_text, reserve_build, El, Source};
use reader::Reader;

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

    let compiler = Compiler::read(&root)?;
    let classes = defaults::classes(&root)?;
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

    let meshes = assets::mesh_assets(&root, &mut reader)?;
    let (mut bodies, ground) = body::bodies(&root, &mut reader, &meshes)?;

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
    let (model, joints) = build::build(&bodies, options, &mut reader)?;
    let mut model = model;
    model.gravity = gravity;
    let actuators = actuators::actuators(&root, &joints, &mut reader)?;
    let Reader { mut warnings, notes, .. } = reader;
    warnings.extend(notes);
    Ok(Mjcf { model, warnings, joints, actuators, timestep, gravity, ground })
}
