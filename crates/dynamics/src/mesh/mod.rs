//! Mesh files as URDFs and MJCFs name them (STL binary and ASCII, Wavefront OBJ, COLLADA, MuJoCo's MSH): their
//! vertices, which a collision shape wraps in their convex hull (`hull`), and their triangles, whose volume and
//! inertia MuJoCo's compiler takes (`inertia`). Normals and materials are not read: they change neither.

mod collada;
mod hull;
mod inertia;
mod obj;
mod path;
#[cfg(test)]
mod tests;

use std::path::Path;

use nalgebra::Vector3;

use crate::{Error, Result};
pub(crate) use hull::hull_points;
pub use hull::HULL_POINTS;
pub(crate) use inertia::{inconsistent_edge, mesh_mass, MeshMass, OVERFLOW};
pub use obj::MUJOCO_OBJ_CORNERS;
pub use path::resolve_mesh;

/// The vertices of the mesh file at `path`, in the file's units (COLLADA's `<unit meter>` and `<up_axis>`
/// applied: metres, z up). The format is chosen by the extension (case-insensitive).
/// A list too large to allocate is `Error::TooLarge` naming `mesh` (where an infallible allocation would abort
/// the process), anything else wrong with the file `Error::Invalid` naming `mesh`.
pub(crate) fn mesh_vertices(path: &Path) -> Result<Vec<Vector3<f64>>> {
    let bytes = crate::validate::read_regular_file("mesh", path)?;
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let vertices = match extension.as_str() {
        "stl" => stl(&bytes),
        "obj" => obj::obj_faces(&String::from_utf8_lossy(&bytes), false).map(|((vertices, _), _)| vertices),
        "dae" => collada::collada(&String::from_utf8_lossy(&bytes)),
        "msh" => msh(&bytes).map(|(vertices, _)| vertices),
        other => Err(bad(format!("unknown mesh format {other:?} (expected .stl, .obj, .dae or .msh)"))),
    }
    .map_err(|e| in_file(path, e))?;
    if vertices.is_empty() {
        return Err(in_file(path, bad("no vertices")));
    }
    finite_vertices(path, &vertices)?;
    Ok(vertices)
}

/// A triangle mesh: its vertices, and its faces as indices into them.
pub type Triangles = (Vec<Vector3<f64>>, Vec<[usize; 3]>);

/// Where MuJoCo reads a mesh file otherwise than legkit (`mesh_triangles`): each a sentence naming the file, which
/// the MJCF reader gives as a warning (an error under `strict`).
#[derive(Debug, Default, PartialEq)]
pub struct MujocoDiffers {
    /// MuJoCo's mass of the faces differs from legkit's, which is the whole mesh's: an OBJ face of more than
    /// `MUJOCO_OBJ_CORNERS` corners, OBJ faces in more than one group (`ObjFaces::groups`).
    pub mass: Vec<String>,
    /// MuJoCo refuses the file, which legkit reads: an ASCII STL.
    pub refused: Option<String>,
}

/// The triangles of the mesh file at `path`, as vertices and faces indexing them, for a mesh's volume and
/// inertia: STL's triangles, OBJ's faces (of every group; a polygon cut into triangles as MuJoCo cuts it: see
/// `clip_ears`), and MuJoCo's binary MSH; and where MuJoCo's reading of the file differs (`MujocoDiffers`).
/// Errors as `mesh_vertices`'.
pub fn mesh_triangles(path: &Path) -> Result<(Triangles, MujocoDiffers)> {
    let bytes = crate::validate::read_regular_file("mesh", path)?;
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let mut differs = MujocoDiffers::default();
    let file = path.display();
    let (vertices, faces) = match extension.as_str() {
        // Each triangle lists its corners: those equal to the bit are one vertex, as MuJoCo's STL decoder merges
        // them (google-deepmind/mujoco), so that its faces share edges (see `inconsistent_edge`).
        "stl" => stl(&bytes).and_then(|corners| {
            if binary_stl(&bytes).is_none() {
                differs.refused = Some(format!("{file}: an ASCII STL, which MuJoCo refuses (it reads binary STL only); legkit reads it"));
            }
            let (vertices, index) = hull::distinct_points(&corners)?;
            let mut faces = Vec::new();
            grow(&mut faces, index.len() / 3, "faces")?;
            faces.extend(index.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            Ok((vertices, faces))
        }),
        "obj" => obj::obj_faces(&String::from_utf8_lossy(&bytes), true).map(|(triangles, obj)| {
            if let Some((line, corners)) = obj.large {
                differs.mass.push(format!(
                    "{file}: line {line}: a face of {corners} corners, whose mass MuJoCo takes otherwise (it leaves part or all \
                     of a face of more than {MUJOCO_OBJ_CORNERS} corners out)"
                ));
            }
            if obj.groups > 1 {
                differs.mass.push(format!(
                    "{file}: its {} faces lie in {} groups (OBJ `g`/`o` lines): MuJoCo's mass takes only the first group's {} \
                     faces, legkit's is the whole mesh's",
                    obj.faces, obj.groups, obj.first_group
                ));
            }
            triangles
        }),
        "msh" => msh(&bytes),
        other => Err(bad(format!("no faces read from {other:?} files (expected .stl, .obj or .msh)"))),
    }
    .map_err(|e| in_file(path, e))?;
    if faces.is_empty() {
        return Err(in_file(path, bad("no faces")));
    }
    finite_vertices(path, &vertices)?;
    Ok(((vertices, faces), differs))
}

/// `e`, from reading the mesh file at `path`, with the path in its reason: a list too large to allocate stays
/// `Error::TooLarge` (where an infallible allocation would abort the process) and a cancelled load stays
/// `Error::Numerical`; anything else wrong with the file is `Error::Invalid` naming `mesh`.
fn in_file(path: &Path, e: Error) -> Error {
    match e {
        Error::TooLarge { argument, reason } => Error::too_large(argument, format!("{}: {reason}", path.display())),
        Error::Numerical { .. } => e,
        other => Error::invalid("mesh", format!("{}: {}", path.display(), other.reason())),
    }
}

fn finite_vertices(path: &Path, vertices: &[Vector3<f64>]) -> Result<()> {
    match vertices.iter().find(|v| !v.iter().all(|x| x.is_finite())) {
        Some(v) => Err(in_file(path, bad(format!("a vertex is not finite: {v:?}")))),
        None => Ok(()),
    }
}

/// Every `CANCEL_INTERVAL` items of a loop over a file (`k` counts them), fails (naming `what`) if the load was
/// cancelled (`validate::cancellable`): a file of hundreds of megabytes takes seconds to read.
pub(crate) fn cancel_point(what: &'static str, k: usize) -> Result<()> {
    if k.is_multiple_of(crate::validate::CANCEL_INTERVAL) {
        crate::validate::check_cancelled(what)?;
    }
    Ok(())
}

/// What is wrong with a mesh file (`mesh_vertices` adds its path).
fn bad(reason: impl Into<String>) -> Error {
    Error::invalid("mesh", reason)
}

/// `list` (the file's `what`) with room for `more`, or `Error::TooLarge` naming `mesh`. Reserving one at a time
/// still grows the list geometrically.
fn grow<T>(list: &mut Vec<T>, more: usize, what: &str) -> Result<()> {
    list.try_reserve(more).map_err(|_| {
        let len = list.len().saturating_add(more);
        Error::too_large("mesh", format!("cannot allocate {} bytes for its {len} {what}", len.saturating_mul(size_of::<T>())))
    })
}

/// The triangle count of a binary STL: an 80-byte header, the count, then 50 bytes per triangle (normal, three
/// vertices, attribute). None for anything else: ASCII files also start with "solid", so the length decides.
fn binary_stl(bytes: &[u8]) -> Option<usize> {
    let count = u32::from_le_bytes(bytes.get(80..84)?.try_into().ok()?) as usize;
    (bytes.len() == 84 + 50 * count).then_some(count)
}

fn stl(bytes: &[u8]) -> Result<Vec<Vector3<f64>>> {
    if let Some(count) = binary_stl(bytes) {
        let float = |at: usize| f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]) as f64;
        let mut vertices = Vec::new();
        grow(&mut vertices, 3 * count, "vertices")?;
        vertices.extend(
            (0..count).flat_map(|t| (1..4).map(move |v| 84 + 50 * t + 12 * v)).map(|at| Vector3::new(float(at), float(at + 4), float(at + 8))),
        );
        return Ok(vertices);
    }
    let text = std::str::from_utf8(bytes).map_err(|_| bad("neither binary STL (wrong length) nor ASCII STL"))?;
    let mut vertices = Vec::new();
    let mut words = text.split_whitespace().enumerate();
    while let Some((k, word)) = words.next() {
        cancel_point("mesh", k)?;
        if word == "vertex" {
            grow(&mut vertices, 1, "vertices")?;
            vertices.push(three(&mut (&mut words).map(|(_, w)| w)).ok_or_else(|| bad("a vertex without three numbers"))?);
        }
    }
    Ok(vertices)
}

/// MuJoCo's binary MSH: four counts (vertices, normals, texture coordinates, faces), then the vertices' and
/// normals' float triples, the texture coordinates' pairs and the faces' index triples, little-endian.
fn msh(bytes: &[u8]) -> Result<Triangles> {
    let word = |at: usize| [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]];
    if bytes.len() < 16 {
        return Err(bad("an MSH file shorter than its header"));
    }
    let counts: Vec<usize> = (0..4).map(|k| i32::from_le_bytes(word(4 * k))).map(|n| usize::try_from(n).unwrap_or(usize::MAX)).collect();
    let [nv, nn, nt, nf] = [counts[0], counts[1], counts[2], counts[3]];
    let size = [(nv, 12), (nn, 12), (nt, 8), (nf, 12)].iter().try_fold(16usize, |total, &(n, width)| total.checked_add(n.checked_mul(width)?));
    if size != Some(bytes.len()) {
        return Err(bad(format!("an MSH file of {} bytes for {nv} vertices, {nn} normals, {nt} texture coordinates and {nf} faces", bytes.len())));
    }
    let (mut vertices, mut faces) = (Vec::new(), Vec::new());
    grow(&mut vertices, nv, "vertices")?;
    grow(&mut faces, nf, "faces")?;
    let float = |at: usize| f32::from_le_bytes(word(at)) as f64;
    vertices.extend((0..nv).map(|i| 16 + 12 * i).map(|at| Vector3::new(float(at), float(at + 4), float(at + 8))));
    let start = 16 + 12 * (nv + nn) + 8 * nt;
    let index = |at: usize| usize::try_from(i32::from_le_bytes(word(at))).ok().filter(|&i| i < nv);
    for f in 0..nf {
        let at = start + 12 * f;
        match (index(at), index(at + 4), index(at + 8)) {
            (Some(a), Some(b), Some(c)) => faces.push([a, b, c]),
            _ => return Err(bad(format!("face {f} names no vertex"))),
        }
    }
    Ok((vertices, faces))
}

fn three<'a>(words: &mut impl Iterator<Item = &'a str>) -> Option<Vector3<f64>> {
    let mut next = || words.next()?.parse::<f64>().ok();
    Some(Vector3::new(next()?, next()?, next()?))
}
