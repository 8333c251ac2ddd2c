//! Collision shapes in a body's frame (boxes, spheres, capsules, cylinders, convex hulls), checked on
//! construction, and their parry counterparts: below both `model` (which carries a model's collision shapes)
//! and `sim` (which collides them).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use parry3d_f64::math::{Matrix, Pose, Rotation, Vector};
use parry3d_f64::shape::{ConvexPolyhedron, SharedShape};
use std::sync::Arc;

use crate::spatial::Transform;
use crate::validate::{finite, finite_vector, rotation};
use crate::{Error, MassProperties, Result};

/// Edges of default boxes are at least this long (m), so point masses and thin rods still collide.
pub const MIN_DEFAULT_EDGE: f64 = 1e-3;

/// A collision shape in a body's frame. `placement` (the shape frame in the body frame) defaults to the
/// body's centre of mass with the body's axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// The geometry, in the shape frame.
    pub kind: ShapeKind,
    /// The shape frame in the body frame; None for the body's centre of mass with the body's axes.
    pub placement: Option<Transform>,
}

/// The geometry of a [`Shape`], sizes in m.
#[derive(Debug, Clone, PartialEq)]
pub enum ShapeKind {
    /// Full edge lengths along the shape's x, y, z.
    Box(Vector3<f64>),
    /// A sphere of this radius about the shape frame's origin.
    Sphere(f64),
    /// Along the shape's z axis: half the length of the axis segment, and the radius.
    Capsule {
        /// Half the length of the axis segment.
        half_height: f64,
        /// Radius about the segment.
        radius: f64,
    },
    /// Along the shape's z axis.
    Cylinder {
        /// Half the height.
        half_height: f64,
        /// Radius.
        radius: f64,
    },
    /// A convex polyhedron (a mesh's convex hull).
    Convex(Convex),
}

/// The convex hull of points in the shape frame (a collision mesh's vertices).
#[derive(Clone)]
pub struct Convex {
    vertices: Arc<[Vector3<f64>]>,
    shape: SharedShape,
}

impl Convex {
    /// The hull of `points` (finite, within `MAX_SHAPE_SIZE`): its vertices are the points at its corners, its
    /// collision shape their hull with each point moved inwards by less than `HULL_NUDGE` of its distance from
    /// their centroid (`off_planes`); an error if they span no volume, or if parry fails on them (a panic inside
    /// it, caught: a numerical failure).
    pub fn hull(points: &[Vector3<f64>]) -> Result<Self> {
        for p in points {
            for x in finite_vector("shapes", *p)?.iter() {
                within_size("shapes", *x)?;
            }
        }
        let flat = || {
            Error::invalid("shapes", format!("the convex hull of {} points has no volume (they lie in a plane or are fewer than 4)", points.len()))
        };
        if !spans_volume(points) {
            return Err(flat());
        }
        let mut parry: Vec<Vector> = crate::validate::with_capacity("shapes", points.len())?;
        parry.extend(points.iter().map(to_vector));
        off_planes(&mut parry);
        // Parry allocates its working set infallibly (an allocation failure inside it aborts the process): the
        // room for it is claimed and given back first, so that a hull too large for memory is an error instead.
        // This is a check made just before, not a reservation: another thread may take the room meanwhile.
        let room = points.len().saturating_mul(HULL_BYTES_PER_POINT);
        let mut probe = Vec::<u8>::new();
        probe.try_reserve_exact(room).map_err(|_| {
            Error::too_large("shapes", format!("cannot allocate the {room} bytes the convex hull of {} points may need", points.len()))
        })?;
        drop(probe);
        let hull = std::panic::catch_unwind(|| ConvexPolyhedron::from_convex_hull(&parry))
            .map_err(|_| Error::numerical("shapes", format!("parry failed to build the convex hull of {} points", points.len())))?
            .ok_or_else(flat)?;
        // The hull's corners as the points given (the shape keeps them nudged).
        let mut given = std::collections::HashMap::new();
        given.try_reserve(parry.len()).map_err(|_| Error::too_large("shapes", format!("cannot allocate the index of {} points", points.len())))?;
        given.extend(parry.iter().zip(points).map(|(nudged, p)| (nudged.to_array().map(f64::to_bits), *p)));
        let mut vertices = crate::validate::with_capacity("shapes", hull.points().len())?;
        vertices.extend(hull.points().iter().map(|p| given[&p.to_array().map(f64::to_bits)]));
        Ok(Convex { vertices: vertices.into(), shape: SharedShape::new(hull) })
    }

    /// The hull's vertices.
    pub fn vertices(&self) -> &[Vector3<f64>] {
        &self.vertices
    }
}

/// How far `off_planes` moves a point towards the points' centroid, at most, as a share of its distance from it.
pub const HULL_NUDGE: f64 = 1e-9;

/// Moves each point towards the points' centroid by a share of its distance from it below `HULL_NUDGE`, the same
/// for the same points (a hash of its index), so that no four lie in one plane: parry's quickhull takes time and
/// memory quadratic in the points on one face of the hull (the base of a cone of 2,000 segments: 0.73 s and
/// 285 MB; of 6,000: 3 GB, and an allocation failure aborts), and in general position 2 ms and 4 MB. The hull
/// lies inside the points' by less than `HULL_NUDGE` of their extent; its near-coplanar triangles still merge
/// into one face (parry merges normals within 1.5e-4 rad).
fn off_planes(points: &mut [Vector]) {
    let centroid = points.iter().fold(Vector::ZERO, |sum, p| sum + *p) / points.len() as f64;
    for (k, p) in points.iter_mut().enumerate() {
        // splitmix64 of the index: a share in [0, 1).
        let mut h = (k as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        let share = ((h ^ (h >> 31)) >> 11) as f64 / (1u64 << 53) as f64;
        *p = centroid + (*p - centroid) * (1.0 - HULL_NUDGE * share);
    }
}

/// Parry's peak memory per input point while it takes a hull, when every point is a vertex of it (points on a
/// sphere: about 1.2 KB, measured for 10^5 and 10^6 points; points filling a volume need a tenth of that).
const HULL_BYTES_PER_POINT: usize = 1280;

/// Some point lies off the plane through three others by more than 1e-9 of the points' extent.
fn spans_volume(points: &[Vector3<f64>]) -> bool {
    let Some(first) = points.first() else { return false };
    let farthest =
        |score: &dyn Fn(&Vector3<f64>) -> f64| points.iter().map(|p| (score(p), *p)).fold((0.0, *first), |a, b| if b.0 > a.0 { b } else { a });
    let (extent, second) = farthest(&|p| (p - first).norm());
    let along = (second - first) / extent.max(f64::MIN_POSITIVE);
    let (_, third) = farthest(&|p| (p - first).cross(&along).norm());
    let normal = (second - first).cross(&(third - first));
    let (height, _) = farthest(&|p| (p - first).dot(&normal).abs() / normal.norm().max(f64::MIN_POSITIVE));
    extent > 0.0 && height > 1e-9 * extent
}

impl PartialEq for Convex {
    fn eq(&self, other: &Self) -> bool {
        self.vertices == other.vertices
    }
}

impl std::fmt::Debug for Convex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Convex({} vertices)", self.vertices.len())
    }
}

fn positive(argument: &'static str, x: f64) -> Result<f64> {
    if finite(argument, x)? <= 0.0 {
        return Err(Error::invalid(argument, format!("must be > 0, got {x}")));
    }
    Ok(x)
}

/// The largest size or offset (m) of a collision shape: a robot is far smaller, and parry's geometry
/// overflows (and panics) on sizes near the square root of the largest float.
pub const MAX_SHAPE_SIZE: f64 = 1e6;

/// `x` if it is at most `MAX_SHAPE_SIZE` in magnitude.
fn within_size(argument: &'static str, x: f64) -> Result<f64> {
    if x.abs() > MAX_SHAPE_SIZE {
        return Err(Error::invalid(argument, format!("sizes and offsets must be at most {MAX_SHAPE_SIZE:e} m, got {x}")));
    }
    Ok(x)
}

impl Shape {
    /// Checks sizes (finite, > 0, at most `MAX_SHAPE_SIZE`) and the placement (a proper rotation, a finite
    /// translation within `MAX_SHAPE_SIZE`).
    pub fn new(kind: ShapeKind, placement: Option<Transform>) -> Result<Self> {
        match &kind {
            ShapeKind::Box(size) => {
                for s in size.iter() {
                    within_size("shapes", positive("shapes", *s)?)?;
                }
            }
            ShapeKind::Sphere(r) => {
                within_size("shapes", positive("shapes", *r)?)?;
            }
            ShapeKind::Capsule { half_height, radius } | ShapeKind::Cylinder { half_height, radius } => {
                within_size("shapes", positive("shapes", *radius)?)?;
                if within_size("shapes", finite("shapes", *half_height)?)? < 0.0 {
                    return Err(Error::invalid("shapes", format!("half_height must be >= 0, got {half_height}")));
                }
            }
            // Checked by `Convex::hull`, its only maker.
            ShapeKind::Convex(_) => {}
        }
        if let Some(p) = &placement {
            rotation("shapes", &p.rotation)?;
            for x in finite_vector("shapes", p.translation)?.iter() {
                within_size("shapes", *x)?;
            }
        }
        Ok(Shape { kind, placement })
    }

    /// The uniform box with the body's mass and principal moments, centred at its COM along its principal
    /// axes: edges a² = 6 (I₂ + I₃ − I₁) / m and cyclically, floored at `MIN_DEFAULT_EDGE`. None for a
    /// massless body.
    pub fn default_box(body: &MassProperties) -> Option<Shape> {
        if body.mass() <= 0.0 {
            return None;
        }
        let eigen = SymmetricEigen::new(body.inertia());
        let mut axes = eigen.eigenvectors;
        if axes.determinant() < 0.0 {
            axes.set_column(2, &(-axes.column(2)));
        }
        let moments = eigen.eigenvalues;
        let edge = |k: usize| {
            let squared = 6.0 * (moments[(k + 1) % 3] + moments[(k + 2) % 3] - moments[k]) / body.mass();
            squared.max(0.0).sqrt().max(MIN_DEFAULT_EDGE)
        };
        Some(Shape { kind: ShapeKind::Box(Vector3::new(edge(0), edge(1), edge(2))), placement: Some(Transform::new(axes, body.com())) })
    }

    pub(crate) fn shared_shape(&self) -> (SharedShape, Transform) {
        // Parry's cylinder runs along its y axis: turn it onto z (x → x, y → z, z → −y).
        let y_to_z = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
        match &self.kind {
            ShapeKind::Box(size) => (SharedShape::cuboid(size.x / 2.0, size.y / 2.0, size.z / 2.0), Transform::identity()),
            ShapeKind::Sphere(r) => (SharedShape::ball(*r), Transform::identity()),
            ShapeKind::Capsule { half_height, radius } => (SharedShape::capsule_z(*half_height, *radius), Transform::identity()),
            ShapeKind::Cylinder { half_height, radius } => (SharedShape::cylinder(*half_height, *radius), Transform::new(y_to_z, Vector3::zeros())),
            ShapeKind::Convex(convex) => (convex.shape.clone(), Transform::identity()),
        }
    }
}

pub(crate) fn to_pose(t: &Transform) -> Pose {
    let r = &t.rotation;
    let m = Matrix::from_cols(
        Vector::new(r[(0, 0)], r[(1, 0)], r[(2, 0)]),
        Vector::new(r[(0, 1)], r[(1, 1)], r[(2, 1)]),
        Vector::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]),
    );
    Pose::from_parts(to_vector(&t.translation), Rotation::from_mat3(&m).normalize())
}

#[cfg(feature = "rapier")]
pub(crate) fn from_pose(p: &Pose) -> Transform {
    let m = Matrix::from_quat(p.rotation);
    let (x, y, z) = (m.col(0), m.col(1), m.col(2));
    Transform::new(Matrix3::new(x.x, y.x, z.x, x.y, y.y, z.y, x.z, y.z, z.z), from_vector(p.translation))
}

#[inline]
pub(crate) fn to_vector(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

#[inline]
pub(crate) fn from_vector(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cone of `segments` on the unit circle, apex at z = 1, and the exact volume of its hull.
    fn cone(segments: usize) -> (Vec<Vector3<f64>>, f64) {
        let mut points = vec![Vector3::new(0.0, 0.0, 1.0)];
        let angle = |k: usize| k as f64 * std::f64::consts::TAU / segments as f64;
        points.extend((0..segments).map(|k| Vector3::new(angle(k).cos(), angle(k).sin(), 0.0)));
        (points, segments as f64 / 2.0 * angle(1).sin() / 3.0)
    }

    #[test]
    fn a_cone_with_thousands_of_points_on_its_base_takes_its_hull_in_bounded_time_with_the_exact_volume() {
        // Unnudged, parry took 0.73 s and 285 MB for 2,000 segments and aborted the process for 6,000.
        for segments in [4, 100, 6000, 25_000] {
            let (points, volume) = cone(segments);
            let started = std::time::Instant::now();
            let hull = Convex::hull(&points).unwrap();
            let seconds = started.elapsed().as_secs_f64();
            let mass = hull.shape.mass_properties(1.0).mass();
            assert!((mass - volume).abs() <= 1e-8 * volume, "{segments}: volume {mass}, exactly {volume}");
            assert!(hull.vertices().len() > segments / 5 && seconds < 20.0, "{segments}: {} vertices, {seconds} s", hull.vertices().len());
            let radius = hull.vertices().iter().map(|v| v.xy().norm()).fold(0.0, f64::max);
            assert!(radius <= 1.0 && radius > 1.0 - 2.0 * HULL_NUDGE, "{segments}: {radius}");
        }
    }

    #[test]
    fn nudging_is_the_same_every_time_and_a_boxs_hull_keeps_its_corners_as_given() {
        let corners: Vec<Vector3<f64>> = (0..8).map(|k| Vector3::new((k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64)).collect();
        let (a, b) = (Convex::hull(&corners).unwrap(), Convex::hull(&corners).unwrap());
        assert_eq!(a, b);
        let mut vertices = a.vertices().to_vec();
        vertices.sort_by(|p, q| p.as_slice().partial_cmp(q.as_slice()).unwrap());
        let mut expected = corners.clone();
        expected.sort_by(|p, q| p.as_slice().partial_cmp(q.as_slice()).unwrap());
        assert_eq!(vertices, expected);
        let volume = a.shape.mass_properties(1.0).mass();
        assert!((volume - 1.0).abs() <= 3.0 * HULL_NUDGE, "{volume}");
    }
}
