//! The body walker: `<worldbody>` and its bodies and frames, depth first in MuJoCo's numbering, each body's joints,
//! geoms and mass properties (its `<inertial>` or its geoms', bounded as the compiler says), and the floor.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::assets::Meshes;
use super::compiler::{Compiler, InertiaFromGeom};
use super::element::El;
use super::geom::{geom, Contents};
use super::invalid;
use super::joint::{joint, JointSpec};
use super::reader::Reader;
use crate::geometry::Shape;
use crate::mesh::cancel_point;
use crate::sim::Ground;
use crate::{MassProperties, Result, Transform};

/// A body as the file gives it, in MuJoCo's numbering (0 the world).
pub(super) struct Body {
    pub(super) name: String,
    pub(super) parent: usize,
    /// In the parent's MJCF frame.
    pub(super) frame: Transform,
    pub(super) joints: Vec<JointSpec>,
    /// In its own MJCF frame.
    pub(super) mass: MassProperties,
    pub(super) shapes: Vec<Shape>,
}

/// The bodies of every `<worldbody>` (the world first, then MuJoCo's numbering) and the floor.
pub(super) fn bodies(root: &El, reader: &mut Reader, meshes: &Meshes) -> Result<(Vec<Body>, Option<Ground>)> {
    let bodies = vec![Body {
        name: "world".to_owned(),
        parent: 0,
        frame: Transform::identity(),
        joints: Vec::new(),
        mass: MassProperties::zero(),
        shapes: Vec::new(),
    }];
    let mut walker = Walker { reader, meshes, bodies, joint_count: 0, ground: None };
    for world in root.elements("worldbody") {
        walker.body(world, 0, "main")?;
    }
    Ok((walker.bodies, walker.ground))
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
