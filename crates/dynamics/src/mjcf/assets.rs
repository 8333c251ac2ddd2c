//! `<asset><mesh>`: each mesh file's vertices, scaled, for its collision hull, and its mass per unit density as
//! MuJoCo's compiler takes it, or why either could not be read.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::element::El;
use super::invalid;
use super::reader::Reader;
use crate::mesh::{inconsistent_edge, mesh_mass, mesh_triangles, mesh_vertices, MeshMass, OVERFLOW};
use crate::validate::check_cancelled;
use crate::{Error, Result};

/// `<asset><mesh>` by name: the file's vertices scaled, or why they could not be read.
pub(super) fn mesh_assets(root: &El, reader: &mut Reader) -> Result<Meshes> {
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

pub(super) type Meshes = HashMap<String, std::result::Result<MeshAsset, String>>;

/// A mesh asset: its vertices (scaled) for the collision hull, and its mass per unit density, or why that
/// could not be computed.
pub(super) struct MeshAsset {
    pub(super) vertices: Vec<Vector3<f64>>,
    pub(super) mass: std::result::Result<MeshMass, String>,
}
