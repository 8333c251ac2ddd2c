//! The vertices of mesh files as URDFs name them (STL binary and ASCII, Wavefront OBJ, COLLADA), which a
//! collision shape wraps in their convex hull. Only positions are read: faces, normals and materials do
//! not change a hull.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

use nalgebra::{Matrix3, Matrix4, Rotation3, Unit, Vector3, Vector4};
use roxmltree::Node;

use crate::{Error, Result};

/// The vertices of the mesh file at `path`, in the file's units (COLLADA's `<unit meter>` and `<up_axis>`
/// applied: metres, z up). The format is chosen by the extension (case-insensitive).
/// A list too large to allocate is `Error::TooLarge` naming `mesh` (where an infallible allocation would abort
/// the process), anything else wrong with the file `Error::Invalid` naming `mesh`.
pub(crate) fn mesh_vertices(path: &Path) -> Result<Vec<Vector3<f64>>> {
    let bytes = crate::validate::read_regular_file("mesh", path)?;
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let vertices = match extension.as_str() {
        "stl" => stl(&bytes),
        "obj" => obj_faces(&String::from_utf8_lossy(&bytes), false).map(|((vertices, _), _)| vertices),
        "dae" => collada(&String::from_utf8_lossy(&bytes)),
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

/// At most this many points go into a collision mesh's convex hull. Parry takes it in one call that cannot be
/// interrupted, in time growing faster than the number of points on the hull: about 0.7 s of CPU for this
/// many points on a sphere, 7.7 s for 100,000 and 52 s for 300,000 (release build).
pub const HULL_POINTS: usize = 25_000;

/// `points` without repeats (equal to the bit), in the order they first appear, and the index among them of each
/// point. Interruptible.
fn distinct_points(points: &[Vector3<f64>]) -> Result<(Vec<Vector3<f64>>, Vec<usize>)> {
    let too_large = || Error::too_large("mesh", format!("cannot allocate the set of its {} vertices", points.len()));
    let mut seen: HashMap<[u64; 3], usize> = HashMap::new();
    let (mut distinct, mut index) = (Vec::new(), crate::validate::with_capacity("mesh", points.len())?);
    for (k, p) in points.iter().enumerate() {
        cancel_point("mesh", k)?;
        if seen.len() == seen.capacity() {
            seen.try_reserve(seen.len().max(16)).map_err(|_| too_large())?;
            distinct.try_reserve(seen.capacity().saturating_sub(distinct.len())).map_err(|_| too_large())?;
        }
        index.push(*seen.entry(p.map(f64::to_bits).into()).or_insert_with(|| {
            distinct.push(*p);
            distinct.len() - 1
        }));
    }
    Ok((distinct, index))
}

/// The points a hull is taken over (`hull_points`), and the note saying they are fewer than the mesh's.
pub(crate) type HullPoints<'a> = (Cow<'a, [Vector3<f64>]>, Option<String>);

/// The points a convex hull of `points` is taken over, and a note when they are fewer than the mesh's
/// distinct points: beyond `HULL_POINTS` distinct points, one per cell of the finest grid over the bounding
/// box that leaves at most that many (the one farthest from the box's centre), so that every point lies within
/// a cell's diagonal of the hull taken, which lies inside the mesh's. Interruptible (`validate::cancellable`).
pub(crate) fn hull_points(points: &[Vector3<f64>]) -> Result<HullPoints<'_>> {
    if points.len() <= HULL_POINTS {
        return Ok((Cow::Borrowed(points), None));
    }
    // An STL lists each triangle's corners: a closed mesh has about a sixth as many distinct points.
    let (distinct, _) = distinct_points(points)?;
    if distinct.len() <= HULL_POINTS {
        return Ok((Cow::Owned(distinct), None));
    }
    let points = &distinct[..];
    let (lower, upper) =
        points.iter().fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let centre = (lower + upper) / 2.0;
    let mut cells = 1024usize;
    loop {
        let size = (upper - lower).map(|e| e / cells as f64);
        let mut kept: HashMap<[usize; 3], usize> = HashMap::new();
        for (k, p) in points.iter().enumerate() {
            cancel_point("mesh", k)?;
            let cell = [0, 1, 2].map(|i| if size[i] > 0.0 { (((p[i] - lower[i]) / size[i]) as usize).min(cells - 1) } else { 0 });
            if kept.len() == kept.capacity() {
                kept.try_reserve(kept.len().max(16))
                    .map_err(|_| Error::too_large("mesh", format!("cannot allocate the grid over its {} vertices", points.len())))?;
            }
            let at = kept.entry(cell).or_insert(k);
            if (p - centre).norm_squared() > (points[*at] - centre).norm_squared() {
                *at = k;
            }
            if kept.len() > HULL_POINTS && cells > 1 {
                break;
            }
        }
        if kept.len() <= HULL_POINTS || cells == 1 {
            let mut chosen: Vec<usize> = kept.into_values().collect();
            chosen.sort_unstable();
            let note = (chosen.len() < points.len()).then(|| {
                format!(
                    "its convex hull is taken over {} of its {} distinct vertices (each within {:.2e} m of one)",
                    chosen.len(),
                    points.len(),
                    size.norm()
                )
            });
            let mut out = crate::validate::with_capacity("mesh", chosen.len())?;
            out.extend(chosen.into_iter().map(|k| points[k]));
            return Ok((Cow::Owned(out), note));
        }
        cells = cells * 3 / 4;
    }
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
        // them (google-deepmind/mujoco), so that its faces share edges (see `mjcf::inconsistent_edge`).
        "stl" => stl(&bytes).and_then(|corners| {
            if binary_stl(&bytes).is_none() {
                differs.refused = Some(format!("{file}: an ASCII STL, which MuJoCo refuses (it reads binary STL only); legkit reads it"));
            }
            let (vertices, index) = distinct_points(&corners)?;
            let mut faces = Vec::new();
            grow(&mut faces, index.len() / 3, "faces")?;
            faces.extend(index.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            Ok((vertices, faces))
        }),
        "obj" => obj_faces(&String::from_utf8_lossy(&bytes), true).map(|(triangles, obj)| {
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

/// Where a URDF's mesh `filename` lies, read as Pinocchio and ROS read it:
///
/// - `package://name/rest` is `dir/name/rest` (or `dir/rest` when `dir` is the package `name` itself) for the
///   first such file over `package_dirs`, then `ROS_PACKAGE_PATH`'s folders,
///   then each of `AMENT_PREFIX_PATH`'s prefixes' `share/` (a sourced ROS 2 workspace), then the URDF folder's
///   ancestors (`urdf_dir`). Empty segments are skipped, so `package:///name/rest` (as example-robot-data
///   writes it) is the same name; `model://` (Gazebo's) is read as `package://`. The name may not climb
///   (`..`): it is refused (`Error::Invalid` naming `filename`). See `confined` for symbolic links.
/// - `file://path` and absolute paths are read as written.
/// - A relative path is taken against `urdf_dir` (the working folder if None), then, if it does not climb,
///   against each of `package_dirs` (confined to it, as a package name is).
pub fn resolve_mesh(filename: &str, urdf_dir: Option<&Path>, package_dirs: &[PathBuf]) -> Result<PathBuf> {
    let outside = || Error::invalid("filename", format!("{filename:?} names a file outside its package (only names below it are allowed)"));
    if let Some(rest) = ["package://", "model://"].iter().find_map(|scheme| filename.strip_prefix(scheme)) {
        let mut parts = Vec::new();
        for component in Path::new(rest).components() {
            match component {
                Component::Normal(part) => parts.push(part),
                Component::RootDir | Component::CurDir => {}
                // `..` or a drive would reach files outside the package (which the viewer would then embed).
                Component::ParentDir | Component::Prefix(_) => return Err(outside()),
            }
        }
        let Some((&package, inside)) = parts.split_first() else {
            return Err(Error::invalid("filename", format!("{filename:?} names no package")));
        };
        let inside: PathBuf = inside.iter().collect();
        let paths = |variable: &str| std::env::var_os(variable).map(|p| std::env::split_paths(&p).collect::<Vec<_>>()).unwrap_or_default();
        let ament_shares = paths("AMENT_PREFIX_PATH").into_iter().map(|prefix| prefix.join("share"));
        let ancestors = urdf_dir.into_iter().flat_map(Path::ancestors).map(Path::to_path_buf);
        let mut searched = Vec::new();
        for dir in package_dirs.iter().cloned().chain(paths("ROS_PACKAGE_PATH")).chain(ament_shares).chain(ancestors) {
            let itself = dir.file_name().is_some_and(|name| name == package);
            for root in [dir.join(package)].into_iter().chain(itself.then(|| dir.clone())) {
                let candidate = root.join(&inside);
                if candidate.is_file() {
                    return confined(filename, candidate, &root);
                }
            }
            searched.push(dir.display().to_string());
        }
        return Err(Error::invalid("package_dirs", format!("{filename:?} is in none of {}", searched.join(", "))));
    }
    let path = Path::new(filename.strip_prefix("file://").unwrap_or(filename));
    let beside = match urdf_dir {
        Some(dir) if path.is_relative() => dir.join(path),
        _ => path.to_path_buf(),
    };
    if beside.is_file() {
        return Ok(beside);
    }
    // Pinocchio's fallback for a relative name: each package folder, which the name may not leave.
    if path.is_relative() && path.components().all(|c| matches!(c, Component::Normal(_) | Component::CurDir)) {
        if let Some(dir) = package_dirs.iter().find(|dir| dir.join(path).is_file()) {
            return confined(filename, dir.join(path), dir);
        }
    }
    Err(Error::invalid("mesh", format!("{filename:?}: no such file ({})", beside.display())))
}

/// `candidate`, a name below `root`, once its symbolic links are checked. They are followed wherever they lead,
/// as Pinocchio and ROS follow them: a colcon `--symlink-install` share folder links each installed file to
/// its source, a catkin devel space links into `src/`, and the user made those links, not the URDF. A name
/// cannot climb out of its package (the callers refuse `..`), but a package from an archive may bring links
/// of its own: one that leads out of the package must reach a file of the name's kind (the same extension,
/// as colcon's and catkin's links keep it), never a key or a configuration file that the viewer would embed.
fn confined(filename: &str, candidate: PathBuf, root: &Path) -> Result<PathBuf> {
    let real = |path: &Path| path.canonicalize().map_err(|e| Error::invalid("filename", format!("{filename:?}: {}: {e}", path.display())));
    let (file, folder) = (real(&candidate)?, real(root)?);
    let extension = |path: &Path| path.extension().map(|e| e.to_ascii_lowercase());
    if !file.starts_with(&folder) && (extension(&candidate).is_none() || extension(&file) != extension(&candidate)) {
        return Err(Error::invalid(
            "filename",
            format!(
                "{filename:?} leads outside its package {} to a file of another kind (a symbolic link reaches {})",
                folder.display(),
                file.display()
            ),
        ));
    }
    Ok(candidate)
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

/// What an OBJ file's faces hold besides their triangles, where MuJoCo's mass of them differs from legkit's.
#[derive(Debug, Default, PartialEq)]
struct ObjFaces {
    /// The line and corner count of the first face of more than `MUJOCO_OBJ_CORNERS` corners.
    large: Option<(usize, usize)>,
    /// The faces (`f` lines) in the file.
    faces: usize,
    /// The groups that hold at least one face, as tinyobjloader reads them for MuJoCo: a `g` or `o` line (its
    /// letter followed by a space or tab) after faces begins a new group (a new shape), of which MuJoCo 4.0 keeps
    /// only the first for the mesh; `usemtl` begins none.
    groups: usize,
    /// The faces of the first group.
    first_group: usize,
}

/// OBJ's vertices and, when `triangulate`, its faces of every group (1-based indices, negative ones counted back
/// from the last vertex read), a polygon of any number of corners cut as `clip_ears` cuts it; without, the faces'
/// corners are only checked. Also the faces' groups and the first face of many corners (`ObjFaces`).
fn obj_faces(text: &str, triangulate: bool) -> Result<(Triangles, ObjFaces)> {
    let (mut vertices, mut faces, mut polygon) = (Vec::new(), Vec::new(), Vec::new());
    let (mut work, mut obj, mut in_group) = (0, ObjFaces::default(), 0usize);
    for (n, line) in text.lines().enumerate() {
        cancel_point("mesh", n)?;
        if matches!(line.trim_start_matches([' ', '\t']).as_bytes(), [b'g' | b'o', b' ' | b'\t', ..]) {
            in_group = 0;
            continue;
        }
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                grow(&mut vertices, 1, "vertices")?;
                vertices.push(three(&mut words).ok_or_else(|| bad(format!("line {}: a vertex without three numbers", n + 1)))?);
            }
            Some("f") => {
                let count = vertices.len() as i64;
                polygon.clear();
                for w in words {
                    grow(&mut polygon, 1, "face corners")?;
                    polygon.push(match w.split('/').next().and_then(|i| i.parse::<i64>().ok()) {
                        Some(i) if i > 0 && i <= count => i as usize - 1,
                        Some(i) if i < 0 && -i <= count => (count + i) as usize,
                        _ => return Err(bad(format!("line {}: face corner {w:?} names no vertex", n + 1))),
                    });
                }
                if polygon.len() < 3 {
                    return Err(bad(format!("line {}: a face with fewer than three corners", n + 1)));
                }
                if polygon.len() > MUJOCO_OBJ_CORNERS && obj.large.is_none() {
                    obj.large = Some((n + 1, polygon.len()));
                }
                if in_group == 0 {
                    obj.groups += 1;
                }
                in_group += 1;
                obj.faces += 1;
                if obj.groups == 1 {
                    obj.first_group += 1;
                }
                if triangulate {
                    clip_ears(&vertices, &mut polygon, &mut faces, &mut work)?;
                }
            }
            _ => {}
        }
    }
    Ok(((vertices, faces), obj))
}

/// The most corners of an OBJ face whose triangles MuJoCo's mass takes as `clip_ears` cuts them. Of a larger face,
/// MuJoCo (4.0, measured) leaves part or all of the area out: all of a regular polygon's, from 101 corners to 2000.
/// legkit takes the whole face, of any size.
pub const MUJOCO_OBJ_CORNERS: usize = 100;

/// Cuts `polygon` (vertex indices) into triangles appended to `faces` as tinyobjloader does for MuJoCo, so
/// that masses agree on any polygon, planar or not, convex or not, repeating corners or not: a quadrilateral
/// along its shorter diagonal (the second on a tie); a larger polygon by clipping ears in the coordinate plane
/// most nearly facing its first turning corner, an ear skipped if it turns against the sign of its first
/// edge's area term or holds another corner, and the corners left after a lap of skips dropped. In f32, as
/// tinyobjloader reads coordinates, so that ties fall the same way. Each ear tried costs a pass over the corners
/// left: about n² / 2 corner tests for a convex polygon of n corners, up to n³ / 2 for one whose ears are skipped
/// lap after lap. `work` counts the corner tests in the file, for cancellation every `TESTS_PER_CANCEL_POINT`.
fn clip_ears(vertices: &[Vector3<f64>], polygon: &mut Vec<usize>, faces: &mut Vec<[usize; 3]>, work: &mut usize) -> Result<()> {
    let point = |i: usize| vertices[i].map(|x| x as f32);
    let n = polygon.len();
    if let [a, b, c, d] = polygon[..] {
        grow(faces, 2, "faces")?;
        let shorter = (point(c) - point(a)).norm_squared() < (point(d) - point(b)).norm_squared();
        faces.extend(if shorter { [[a, b, c], [a, c, d]] } else { [[a, b, d], [b, c, d]] });
        return Ok(());
    }
    let mut axes = (1, 2);
    for k in 0..n {
        let (a, b, c) = (point(polygon[k]), point(polygon[(k + 1) % n]), point(polygon[(k + 2) % n]));
        let [cx, cy, cz] = [0, 1, 2].map(|i| (b - a).cross(&(c - b))[i].abs());
        if cx > f32::EPSILON || cy > f32::EPSILON || cz > f32::EPSILON {
            if !(cx > cy && cx > cz) {
                axes = if cz > cx && cz > cy { (0, 1) } else { (0, 2) };
            }
            break;
        }
    }
    let flat = |i: usize| {
        let p = point(i);
        (p[axes.0], p[axes.1])
    };
    let (mut guess, mut laps_left, mut last_len) = (0, n, n);
    while polygon.len() > 3 && laps_left > 0 {
        let m = polygon.len();
        let before = *work;
        *work = work.saturating_add(m);
        if before / TESTS_PER_CANCEL_POINT != *work / TESTS_PER_CANCEL_POINT {
            crate::validate::check_cancelled("mesh")?;
        }
        if guess >= m {
            guess -= m;
        }
        if last_len != m {
            (last_len, laps_left) = (m, m);
        } else {
            laps_left -= 1;
        }
        let ear = [0, 1, 2].map(|k| polygon[(guess + k) % m]);
        let corners = ear.map(flat);
        let [p0, p1, p2] = corners;
        let turn = (p1.0 - p0.0) * (p2.1 - p1.1) - (p1.1 - p0.1) * (p2.0 - p1.0);
        let area = (p0.0 * p1.1 - p0.1 * p1.0) * 0.5;
        if turn * area < 0.0 || (3..m).any(|k| inside(&corners, flat(polygon[(guess + k) % m]))) {
            guess += 1;
            continue;
        }
        grow(faces, 1, "faces")?;
        faces.push(ear);
        polygon.remove((guess + 1) % m);
    }
    if let [a, b, c] = polygon[..] {
        grow(faces, 1, "faces")?;
        faces.push([a, b, c]);
    }
    Ok(())
}

/// Corner tests (a few nanoseconds each) between two checks for cancellation in `clip_ears`: about a millisecond.
const TESTS_PER_CANCEL_POINT: usize = 1 << 18;

/// Whether `(x, y)` lies inside the triangle by the crossing count, as tinyobjloader's `pnpoly` tells it (a
/// corner on an edge may count either way; the same way as there).
fn inside(triangle: &[(f32, f32); 3], (x, y): (f32, f32)) -> bool {
    let mut odd = false;
    for (i, j) in [(0, 2), (1, 0), (2, 1)] {
        let (a, b) = (triangle[i], triangle[j]);
        if (a.1 > y) != (b.1 > y) && x < (b.0 - a.0) * (y - a.1) / (b.1 - a.1) + a.0 {
            odd = !odd;
        }
    }
    odd
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

/// COLLADA: the positions of every `<instance_geometry>` of the visual scene, through its nodes'
/// transforms (or every geometry as written when the scene instantiates none).
fn collada(text: &str) -> Result<Vec<Vector3<f64>>> {
    let doc = crate::xml::parse(text, "mesh")?.map_err(bad)?;
    let root = doc.root_element();
    let asset = child(root, "asset");
    let meter = asset
        .and_then(|a| child(a, "unit"))
        .and_then(|u| u.attribute("meter"))
        .map_or(Ok(1.0), |m| m.trim().parse::<f64>().map_err(|_| bad(format!("<unit meter={m:?}> is not a number"))))?;
    // Turn the file's up axis onto z.
    let up = match asset.and_then(|a| child(a, "up_axis")).and_then(|u| u.text()).map(str::trim) {
        Some("Y_UP") => Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0),
        Some("X_UP") => Matrix3::new(0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0),
        _ => Matrix3::identity(),
    };
    let mut correction = Matrix4::identity();
    correction.fixed_view_mut::<3, 3>(0, 0).copy_from(&(up * meter));
    // The first element of each id, as a search in document order would find it.
    let mut ids: HashMap<&str, Node> = HashMap::new();
    for node in root.descendants() {
        if let Some(id) = node.attribute("id") {
            ids.entry(id).or_insert(node);
        }
    }
    let mut vertices = Vec::new();
    for scene in root.descendants().filter(|n| n.has_tag_name("visual_scene")) {
        instances(&ids, scene, correction, &mut vertices)?;
    }
    if vertices.is_empty() {
        for geometry in root.descendants().filter(|n| n.has_tag_name("geometry")) {
            positions(&ids, geometry, &correction, &mut vertices)?;
        }
    }
    Ok(vertices)
}

/// The geometries instantiated by the `<node>`s under `scene`, through the nodes' transforms, in document
/// order. The walk keeps its own stack: a file's nesting depth must not decide the depth of the call stack.
fn instances(ids: &HashMap<&str, Node>, scene: Node, correction: Matrix4<f64>, out: &mut Vec<Vector3<f64>>) -> Result<()> {
    let mut stack: Vec<(Node, Matrix4<f64>)> = scene.children().filter(|n| n.has_tag_name("node")).map(|n| (n, correction)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        if node.has_tag_name("instance_geometry") {
            let url = node.attribute("url").unwrap_or("").trim_start_matches('#');
            let geometry = ids.get(url).ok_or_else(|| bad(format!("<instance_geometry url=\"#{url}\"> names no geometry")))?;
            positions(ids, *geometry, &parent, out)?;
            continue;
        }
        let transform = parent * node_transform(node)?;
        let first = stack.len();
        stack
            .extend(node.children().filter(|item| item.has_tag_name("instance_geometry") || item.has_tag_name("node")).map(|item| (item, transform)));
        stack[first..].reverse();
    }
    Ok(())
}

/// The product of a `<node>`'s transform elements, in order.
fn node_transform(node: Node) -> Result<Matrix4<f64>> {
    let mut transform = Matrix4::identity();
    for step in node.children().filter(Node::is_element) {
        // At most one number more than any transform takes: enough to tell a wrong count, whatever the text's size.
        let numbers = || -> Result<Vec<f64>> {
            step.text()
                .unwrap_or("")
                .split_whitespace()
                .take(17)
                .map(|w| w.parse::<f64>().map_err(|_| bad(format!("<{}> holds {w:?}", step.tag_name().name()))))
                .collect()
        };
        let local = match step.tag_name().name() {
            "matrix" => {
                let m = numbers()?;
                (m.len() == 16).then(|| Matrix4::from_row_slice(&m)).ok_or_else(|| bad("<matrix> needs 16 numbers"))?
            }
            "translate" => match numbers()?[..] {
                [x, y, z] => Matrix4::new_translation(&Vector3::new(x, y, z)),
                _ => return Err(bad("<translate> needs 3 numbers")),
            },
            "rotate" => match numbers()?[..] {
                [x, y, z, degrees] => Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(x, y, z)), degrees.to_radians()).to_homogeneous(),
                _ => return Err(bad("<rotate> needs 4 numbers")),
            },
            "scale" => match numbers()?[..] {
                [x, y, z] => Matrix4::new_nonuniform_scaling(&Vector3::new(x, y, z)),
                _ => return Err(bad("<scale> needs 3 numbers")),
            },
            _ => continue,
        };
        transform *= local;
    }
    Ok(transform)
}

/// The POSITION inputs' floats of a `<geometry>`'s meshes, transformed, appended to `out`, which grows fallibly:
/// every instance of a geometry adds its positions again, so a small file can ask for far more than it holds.
fn positions(ids: &HashMap<&str, Node>, geometry: Node, transform: &Matrix4<f64>, out: &mut Vec<Vector3<f64>>) -> Result<()> {
    for mesh in geometry.children().filter(|n| n.has_tag_name("mesh")) {
        for vertices in mesh.children().filter(|n| n.has_tag_name("vertices")) {
            for input in vertices.children().filter(|n| n.has_tag_name("input") && n.attribute("semantic") == Some("POSITION")) {
                let id = input.attribute("source").unwrap_or("").trim_start_matches('#');
                let array =
                    ids.get(id).and_then(|s| child(*s, "float_array")).ok_or_else(|| bad(format!("POSITION source #{id} has no <float_array>")))?;
                let (mut numbers, mut p) = (0usize, [0.0; 3]);
                for word in array.text().unwrap_or("").split_whitespace() {
                    p[numbers % 3] = word.parse::<f64>().map_err(|_| bad(format!("<float_array> holds {word:?}")))?;
                    numbers += 1;
                    if numbers.is_multiple_of(3) {
                        grow(out, 1, "vertices")?;
                        out.push((transform * Vector4::new(p[0], p[1], p[2], 1.0)).xyz());
                    }
                }
                if !numbers.is_multiple_of(3) {
                    return Err(bad(format!("POSITION source #{id} has {numbers} numbers, not a multiple of 3")));
                }
            }
        }
    }
    Ok(())
}

fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(tag))
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE: [[f64; 3]; 8] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.], [0., 0., 1.], [1., 0., 1.], [0., 1., 1.], [1., 1., 1.]];
    /// The cube's 12 triangles as vertex indices.
    const FACES: [[usize; 3]; 12] =
        [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]];

    fn write(name: &str, bytes: &[u8]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("legkit-mesh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    /// Every vertex read is a corner of `expected` (scaled, shifted), and every corner is read.
    fn assert_corners(read: &[Vector3<f64>], expected: impl Fn(Vector3<f64>) -> Vector3<f64>) {
        let corners: Vec<Vector3<f64>> = CUBE.iter().map(|c| expected(Vector3::from(*c))).collect();
        for v in read {
            assert!(corners.iter().any(|c| (c - v).norm() < 1e-6), "{v:?} is no corner of {corners:?}");
        }
        for c in &corners {
            assert!(read.iter().any(|v| (c - v).norm() < 1e-6), "corner {c:?} missing");
        }
    }

    #[test]
    fn binary_and_ascii_stl() {
        let mut binary = vec![0u8; 80];
        binary.extend((FACES.len() as u32).to_le_bytes());
        let mut ascii = String::from("solid cube\n");
        for face in FACES {
            binary.extend([0u8; 12]);
            ascii.push_str("facet normal 0 0 0\nouter loop\n");
            for &v in &face {
                binary.extend(CUBE[v].iter().flat_map(|x| (*x as f32).to_le_bytes()));
                ascii.push_str(&format!("vertex {} {} {}\n", CUBE[v][0], CUBE[v][1], CUBE[v][2]));
            }
            binary.extend([0u8; 2]);
            ascii.push_str("endloop\nendfacet\n");
        }
        ascii.push_str("endsolid cube\n");
        assert_corners(&mesh_vertices(&write("cube.STL", &binary)).unwrap(), |c| c);
        assert_corners(&mesh_vertices(&write("cube-ascii.stl", ascii.as_bytes())).unwrap(), |c| c);
        let truncated = &binary[..binary.len() - 7];
        assert!(mesh_vertices(&write("broken.stl", truncated)).is_err());
        // MuJoCo refuses the ASCII file, which the MJCF reader is told.
        assert_eq!(mesh_triangles(&write("cube.STL", &binary)).unwrap().1, MujocoDiffers::default());
        let refused = mesh_triangles(&write("cube-ascii.stl", ascii.as_bytes())).unwrap().1.refused.unwrap();
        assert!(refused.ends_with("cube-ascii.stl: an ASCII STL, which MuJoCo refuses (it reads binary STL only); legkit reads it"), "{refused}");
    }

    #[test]
    fn a_vertex_list_beyond_memory_is_too_large_naming_the_mesh() {
        let error = grow(&mut Vec::<Vector3<f64>>::new(), usize::MAX / 32, "vertices").unwrap_err();
        assert!(matches!(error, Error::TooLarge { argument: "mesh", .. }) && error.to_string().contains("bytes"), "{error}");
    }

    #[test]
    fn hull_points_are_all_the_points_up_to_the_bound_then_one_per_grid_cell_within_it() {
        let few: Vec<Vector3<f64>> = (0..HULL_POINTS).map(|k| Vector3::new(k as f64, (k * k) as f64, 1.0)).collect();
        let (same, note) = hull_points(&few).unwrap();
        assert!(matches!(same, Cow::Borrowed(_)) && note.is_none());
        // Each point three times, as an STL lists shared corners: the hull takes every distinct point, without a note.
        let repeated: Vec<Vector3<f64>> = few.iter().flat_map(|p| [*p; 3]).collect();
        let (distinct, note) = hull_points(&repeated).unwrap();
        assert!(note.is_none() && distinct[..] == few[..]);
        // 200,000 points on a helix around the unit sphere: a subset within a cell's diagonal of each of them.
        let many: Vec<Vector3<f64>> = (0..200_000)
            .map(|k| {
                let t = k as f64 / 200_000.0;
                let (z, phi) = (2.0 * t - 1.0, 2000.0 * t);
                let r = (1.0 - z * z).sqrt();
                Vector3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        let (thinned, note) = hull_points(&many).unwrap();
        assert!(thinned.len() <= HULL_POINTS && thinned.len() > HULL_POINTS / 2, "{}", thinned.len());
        let bits = |p: &Vector3<f64>| p.map(f64::to_bits);
        let all: std::collections::HashSet<_> = many.iter().map(bits).collect();
        assert!(thinned.iter().all(|p| all.contains(&bits(p))));
        let within: f64 = note.unwrap().split("within ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
        assert!(many.iter().step_by(997).all(|p| thinned.iter().any(|q| (p - q).norm() <= within)));
    }

    #[test]
    fn obj_vertices() {
        let text: String = CUBE.iter().map(|c| format!("v {} {} {}\n", c[0], c[1], c[2])).chain(["vn 0 0 1\nf 1 2 3\n".into()]).collect();
        assert_corners(&mesh_vertices(&write("cube.obj", text.as_bytes())).unwrap(), |c| c);
        assert!(mesh_vertices(&write("bad.obj", b"v 1 2\n")).unwrap_err().to_string().contains("line 1"));
    }

    #[test]
    fn obj_groups_are_runs_of_faces_begun_by_g_or_o_lines_as_tinyobjloader_reads_them() {
        let cube: String = CUBE.iter().map(|c| format!("v {} {} {}\n", c[0], c[1], c[2])).collect();
        let groups = |body: &str| {
            let (_, obj) = obj_faces(&format!("{cube}{body}"), true).unwrap();
            (obj.groups, obj.first_group, obj.faces)
        };
        // Faces before any group line are the first group; `g` or `o` lines without faces after them begin none;
        // `usemtl` and a bare `g` (no space after the letter: tinyobjloader's test) begin none.
        assert_eq!(groups("f 1 2 3\nf 2 3 4\n"), (1, 2, 2));
        assert_eq!(groups("g a\no b\n  g c\nf 1 2 3\nusemtl m\nf 2 3 4\ng\nf 1 2 4\ng d\n"), (1, 3, 3));
        assert_eq!(groups("f 1 2 3\ng a\nf 2 3 4 5\n\to\tb\nf 1 2 4\nf 1 3 4\ng c\ng d\n"), (3, 1, 4));
        // What mesh_triangles says of it: the file, the groups and faces, and the first group's faces.
        let path = write("groups.obj", format!("{cube}f 1 2 3\ng a\nf 2 3 4 5\n").as_bytes());
        let ((_, triangles), differs) = mesh_triangles(&path).unwrap();
        assert_eq!(triangles.len(), 3, "every group's faces are taken");
        let expected = format!(
            "{}: its 2 faces lie in 2 groups (OBJ `g`/`o` lines): MuJoCo's mass takes only the first group's 1 faces, legkit's is \
             the whole mesh's",
            path.display()
        );
        assert_eq!(differs, MujocoDiffers { mass: vec![expected], refused: None });
        let one = write("one.obj", format!("{cube}g a\nf 1 2 3\n").as_bytes());
        assert_eq!(mesh_triangles(&one).unwrap().1, MujocoDiffers::default());
    }

    #[test]
    fn collada_units_up_axis_and_node_transforms() {
        let floats: Vec<String> = CUBE.iter().flatten().map(|x| x.to_string()).collect();
        let dae = format!(
            r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="0.001"/><up_axis>Y_UP</up_axis></asset>
  <library_geometries><geometry id="cube"><mesh>
    <source id="cube-positions"><float_array id="cube-array" count="24">{}</float_array></source>
    <vertices id="cube-vertices"><input semantic="POSITION" source="#cube-positions"/></vertices>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="scene">
    <node id="outer"><translate>10 0 0</translate>
      <node id="inner"><scale>2 2 2</scale><instance_geometry url="#cube"/></node>
    </node>
  </visual_scene></library_visual_scenes>
</COLLADA>"##,
            floats.join(" ")
        );
        // Millimetres, y up: (x, y, z) mm -> (x, -z, y) m, after the nodes' scale 2 then shift 10 along x.
        let read = mesh_vertices(&write("cube.dae", dae.as_bytes())).unwrap();
        assert_corners(&read, |c| Vector3::new(2.0 * c.x + 10.0, -2.0 * c.z, 2.0 * c.y) * 1e-3);
    }

    #[test]
    fn package_paths_resolve_against_the_search_path_then_the_urdf_folders_ancestors() {
        let root = std::env::temp_dir().join(format!("legkit-mesh-{}", std::process::id()));
        std::fs::create_dir_all(root.join("pkg_a/meshes")).unwrap();
        std::fs::write(root.join("pkg_a/meshes/part.stl"), b"solid\nendsolid\n").unwrap();
        let found = resolve_mesh("package://pkg_a/meshes/part.stl", None, std::slice::from_ref(&root)).unwrap();
        assert_eq!(found, root.join("pkg_a/meshes/part.stl"));
        // The package folder itself as a search folder.
        assert_eq!(resolve_mesh("package://pkg_a/meshes/part.stl", None, &[root.join("pkg_a")]).unwrap(), found);
        let urdf_dir = root.join("pkg_a/urdf");
        std::fs::create_dir_all(&urdf_dir).unwrap();
        assert_eq!(resolve_mesh("package://pkg_a/meshes/part.stl", Some(&urdf_dir), &[]).unwrap(), found);
        assert_eq!(resolve_mesh("../meshes/part.stl", Some(&urdf_dir), &[]).unwrap(), urdf_dir.join("../meshes/part.stl"));
        let missing = resolve_mesh("package://nowhere/x.stl", Some(&urdf_dir), &[]).unwrap_err().to_string();
        assert!(missing.contains("package_dirs") && missing.contains("nowhere"), "{missing}");
        // A package name cannot climb out of its package, even to a file that exists.
        for escape in ["package://pkg_a/../pkg_a/meshes/part.stl", "package://../pkg_a/meshes/part.stl", "model://pkg_a/../../x.stl"] {
            let refused = resolve_mesh(escape, Some(&urdf_dir), std::slice::from_ref(&root)).unwrap_err();
            assert!(refused.argument() == "filename" && refused.to_string().contains("outside its package"), "{refused}");
        }
        // Empty segments are skipped, as Pinocchio and ROS read them: example-robot-data's three slashes, and a
        // root inside the name stays below the package.
        assert_eq!(resolve_mesh("package:///pkg_a/meshes/part.stl", None, std::slice::from_ref(&root)).unwrap(), found);
        assert_eq!(resolve_mesh("model://pkg_a//meshes/part.stl", None, std::slice::from_ref(&root)).unwrap(), found);
        assert_eq!(resolve_mesh("package://pkg_a//etc/passwd", None, std::slice::from_ref(&root)).unwrap_err().argument(), "package_dirs");
        // A relative name not beside the URDF: in the package folders, as Pinocchio looks for it.
        assert_eq!(resolve_mesh("meshes/part.stl", None, &[root.join("pkg_a")]).unwrap(), root.join("pkg_a").join("meshes/part.stl"));
        // Symbolic links are followed: inside the package, and out of it to a file of the name's kind (colcon's
        // --symlink-install links each installed file to its source); out of it to another kind, refused.
        std::fs::write(root.join("source.stl"), b"solid\nendsolid\n").unwrap();
        std::fs::write(root.join("secret.key"), b"not a mesh").unwrap();
        let link = |target: &str, name: &str| {
            let path = root.join("pkg_a/meshes").join(name);
            let _ = std::fs::remove_file(&path);
            std::os::unix::fs::symlink(root.join(target), &path).unwrap();
            path
        };
        let (inward, installed, disguised) =
            (link("pkg_a/meshes/part.stl", "inward.stl"), link("source.stl", "installed.stl"), link("secret.key", "key.stl"));
        assert_eq!(resolve_mesh("package://pkg_a/meshes/inward.stl", None, std::slice::from_ref(&root)).unwrap(), inward);
        assert_eq!(resolve_mesh("package://pkg_a/meshes/installed.stl", None, std::slice::from_ref(&root)).unwrap(), installed);
        let refused = resolve_mesh("package://pkg_a/meshes/key.stl", None, std::slice::from_ref(&root)).unwrap_err();
        assert!(refused.argument() == "filename" && refused.to_string().contains("another kind"), "{refused} ({disguised:?})");
        // A FIFO is refused before it is opened (opening one blocks until a writer comes).
        let fifo = root.join("pipe.stl");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
        if made {
            let refused = mesh_vertices(&fifo).unwrap_err().to_string();
            assert!(refused.contains("not a regular file"), "{refused}");
        }
    }

    #[test]
    fn collada_nesting_deeper_than_the_call_stack_allows() {
        let depth = 100_000;
        let cube: String = (0..8).map(|k| format!("{} {} {} ", k & 1, (k >> 1) & 1, (k >> 2) & 1)).collect();
        let text = format!(
            "<COLLADA><library_geometries><geometry id=\"g\"><mesh><source id=\"p\"><float_array>{cube}</float_array></source>\
             <vertices id=\"v\"><input semantic=\"POSITION\" source=\"#p\"/></vertices></mesh></geometry></library_geometries>\
             <library_visual_scenes><visual_scene>{}<instance_geometry url=\"#g\"/>{}</visual_scene></library_visual_scenes></COLLADA>",
            "<node><translate>1 0 0</translate>".repeat(depth),
            "</node>".repeat(depth)
        );
        let vertices = collada(&text).unwrap();
        assert_eq!(vertices.len(), 8);
        assert_eq!(vertices[0], Vector3::new(depth as f64, 0.0, 0.0));
    }
}
