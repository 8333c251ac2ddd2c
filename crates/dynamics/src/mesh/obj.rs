//! Wavefront OBJ: vertices, and faces cut into triangles as tinyobjloader cuts them for MuJoCo, with what MuJoCo's
//! mass of them leaves out.

use nalgebra::Vector3;

use super::{bad, cancel_point, grow, three, Triangles};
use crate::Result;

/// What an OBJ file's faces hold besides their triangles, where MuJoCo's mass of them differs from legkit's.
#[derive(Debug, Default, PartialEq)]
pub(super) struct ObjFaces {
    /// The line and corner count of the first face of more than `MUJOCO_OBJ_CORNERS` corners.
    pub(super) large: Option<(usize, usize)>,
    /// The faces (`f` lines) in the file.
    pub(super) faces: usize,
    /// The groups that hold at least one face, as tinyobjloader reads them for MuJoCo: a `g` or `o` line (its
    /// letter followed by a space or tab) after faces begins a new group (a new shape), of which MuJoCo 4.0 keeps
    /// only the first for the mesh; `usemtl` begins none.
    pub(super) groups: usize,
    /// The faces of the first group.
    pub(super) first_group: usize,
}

/// OBJ's vertices and, when `triangulate`, its faces of every group (1-based indices, negative ones counted back
/// from the last vertex read), a polygon of any number of corners cut as `clip_ears` cuts it; without, the faces'
/// corners are only checked. Also the faces' groups and the first face of many corners (`ObjFaces`).
pub(super) fn obj_faces(text: &str, triangulate: bool) -> Result<(Triangles, ObjFaces)> {
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
