//! `<geom>`: a geom's mass by MuJoCo's volume and inertia formulas (or its mesh's), and its collision shape.

use nalgebra::{Matrix3, Vector3};

use super::assets::{MeshAsset, Meshes};
use super::element::El;
use super::invalid;
use super::reader::{z_to, Reader};
use crate::geometry::{Convex, Shape, ShapeKind};
use crate::mesh::hull_points;
use crate::{MassProperties, Result, Transform};

/// What a body's elements add up to: its `<inertial>`, its geoms' masses, and what they leave out.
#[derive(Default)]
pub(super) struct Contents {
    pub(super) inertial: Option<MassProperties>,
    pub(super) geoms: Vec<MassProperties>,
    pub(super) mesh_mass: Vec<String>,
    pub(super) unshaped: Vec<String>,
    /// Its colliding plane geoms: what they are, their frames in the body's and their sliding friction.
    pub(super) planes: Vec<(String, Transform, f64)>,
}

/// A geom's mass (into `contents`, when its group counts) and collision shape (into `shapes`).
pub(super) fn geom(
    el: &El, class: &str, prefix: &Transform, reader: &mut Reader, meshes: &Meshes, contents: &mut Contents, shapes: &mut Vec<Shape>,
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
