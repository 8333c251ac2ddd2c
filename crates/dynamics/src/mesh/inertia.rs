//! A mesh's volume, centre of mass and inertia from its triangles, as MuJoCo's compiler takes them, and the check
//! of its faces' orientation MuJoCo makes before.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::cancel_point;
use crate::validate::check_cancelled;
use crate::Result;

/// A mesh's volume (its area for `inertia="shell"`), centre of mass and inertia about it per unit density, in
/// the mesh file's frame.
pub(crate) struct MeshMass {
    pub(crate) volume: f64,
    pub(crate) com: Vector3<f64>,
    pub(crate) inertia: Matrix3<f64>,
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
pub(crate) fn inconsistent_edge(vertices: &[Vector3<f64>], faces: &[[usize; 3]]) -> Result<Option<[usize; 2]>> {
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
pub(crate) const OVERFLOW: &str = "its volume or inertia overflows float64 (is its scale physical?)";

/// A mesh's mass per unit density from its triangles, step by step as MuJoCo's compiler takes it
/// [MuJoCo, user_mesh.cc: mjCMesh::Process, ComputeFaceCentroid, ComputeVolume, ComputeInertia]: the pyramids
/// from the faces' area-weighted centroid to each face give the centre of mass, then the pyramids from the
/// centre of mass to each face the volume and the inertia (for `legacy`, MuJoCo's default, each pyramid's
/// volume counts positive whatever the face's orientation; `shell` weighs the faces by area).
pub(crate) fn mesh_mass(vertices: &[Vector3<f64>], faces: &[[usize; 3]], mode: &str) -> std::result::Result<MeshMass, String> {
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
