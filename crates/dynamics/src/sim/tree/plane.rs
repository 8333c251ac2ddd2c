//! Contacts of the four primitive shapes (not convex meshes) with the ground plane z = 0, in closed form: no allocation, and
//! each point named by a feature of its shape (a box vertex, a capsule end, a cylinder rim point), so the
//! next step finds its impulses by name.

use nalgebra::Vector3;

use crate::geometry::ShapeKind;
use crate::spatial::Transform;

/// The most features a shape has: a cylinder's two lowest rim points and four rim points per cap.
pub(super) const MAX_FEATURES: usize = 10;

/// cos 30°: rim points this close in direction to a cylinder's lowest rim point are left out.
const NEAR_LOWEST: f64 = 0.866_025_403_784_438_6;

/// A point of a shape within `prediction` of the plane: its feature, the point on the shape's surface,
/// and its height (negative below the plane).
#[derive(Debug, Clone, Copy)]
pub(super) struct PlanePoint {
    pub feature: usize,
    pub surface: Vector3<f64>,
    pub height: f64,
}

/// The distance from a shape's frame origin within which all its points lie; None for a convex mesh, which
/// meets the plane through parry's manifolds (see `collision`).
pub(super) fn reach(kind: &ShapeKind) -> Option<f64> {
    match *kind {
        ShapeKind::Box(size) => Some(0.5 * size.norm()),
        ShapeKind::Sphere(r) => Some(r),
        ShapeKind::Capsule { half_height, radius } => Some(half_height + radius),
        ShapeKind::Cylinder { half_height, radius } => Some(half_height.hypot(radius)),
        ShapeKind::Convex(_) => None,
    }
}

/// Calls `emit` for each point of `kind` (whose `reach` is given: it is computed once per shape) at world
/// pose `pose` (shape frame) within `prediction` of z = 0.
pub(super) fn plane_points(kind: &ShapeKind, reach: Option<f64>, pose: &Transform, prediction: f64, mut emit: impl FnMut(PlanePoint)) {
    let mut point = |feature: usize, surface: Vector3<f64>| {
        if surface.z <= prediction {
            emit(PlanePoint { feature, surface, height: surface.z });
        }
    };
    let Some(reach) = reach else { return };
    if pose.translation.z - reach > prediction {
        return;
    }
    let down = Vector3::new(0.0, 0.0, -1.0);
    match *kind {
        ShapeKind::Box(size) => {
            for feature in 0..8 {
                let corner = Vector3::new(
                    if feature & 1 == 0 { -0.5 } else { 0.5 } * size.x,
                    if feature & 2 == 0 { -0.5 } else { 0.5 } * size.y,
                    if feature & 4 == 0 { -0.5 } else { 0.5 } * size.z,
                );
                point(feature, pose.transform_point(&corner));
            }
        }
        ShapeKind::Sphere(r) => point(0, pose.translation + down * r),
        ShapeKind::Capsule { half_height, radius } => {
            let axis = pose.rotation.column(2).into_owned();
            for (feature, side) in [(0, -1.0), (1, 1.0)] {
                point(feature, pose.translation + axis * (side * half_height) + down * radius);
            }
        }
        ShapeKind::Cylinder { half_height, radius } => {
            let (u, v, axis) = (pose.rotation.column(0).into_owned(), pose.rotation.column(1).into_owned(), pose.rotation.column(2).into_owned());
            // The lowest rim point of each cap, where the axis is tilted (a cylinder on its side touches
            // along a line), and four rim points per cap (a cylinder on its end stands on them), but not
            // those within 30 degrees of the lowest: near-duplicates of it that only slow the solver.
            let across = down - axis * down.dot(&axis);
            let lowest = (across.norm() > 1e-9).then(|| across.normalize());
            for (cap, side) in [(0, -1.0), (1, 1.0)] {
                let centre = pose.translation + axis * (side * half_height);
                if let Some(lowest) = lowest {
                    point(cap, centre + lowest * radius);
                }
                for (k, direction) in [u, -u, v, -v].into_iter().enumerate() {
                    if lowest.is_none_or(|l| direction.dot(&l) < NEAR_LOWEST) {
                        point(2 + 4 * cap + k, centre + direction * radius);
                    }
                }
            }
        }
        ShapeKind::Convex(_) => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn collect(kind: ShapeKind, pose: Transform) -> Vec<PlanePoint> {
        let mut out = Vec::new();
        plane_points(&kind, reach(&kind), &pose, 1e-3, |p| out.push(p));
        out
    }

    #[test]
    fn box_flat_on_the_plane_touches_at_its_four_lower_corners() {
        let points = collect(ShapeKind::Box(Vector3::new(0.4, 0.2, 0.1)), Transform::from_translation(Vector3::new(1.0, 2.0, 0.049)));
        assert_eq!(points.len(), 4);
        for p in &points {
            assert!(
                (p.height + 0.001).abs() < 1e-12
                    && ((p.surface.x - 1.0).abs() - 0.2).abs() < 1e-12
                    && ((p.surface.y - 2.0).abs() - 0.1).abs() < 1e-12
            );
            assert!(p.feature & 4 == 0);
        }
    }

    #[test]
    fn tilted_box_touches_at_its_lowest_corner_only() {
        let rotation = Rotation3::from_euler_angles(0.3, 0.2, 0.0).into_inner();
        let pose = Transform::new(rotation, Vector3::new(0.0, 0.0, 0.12));
        let points = collect(ShapeKind::Box(Vector3::new(0.2, 0.2, 0.2)), pose);
        // Brute force over the corners: the lowest one is the only one within 1 mm.
        let corners: Vec<f64> = (0..8)
            .map(|f| {
                pose.transform_point(&Vector3::new(
                    if f & 1 == 0 { -0.1 } else { 0.1 },
                    if f & 2 == 0 { -0.1 } else { 0.1 },
                    if f & 4 == 0 { -0.1 } else { 0.1 },
                ))
                .z
            })
            .collect();
        let lowest = corners.iter().cloned().fold(f64::INFINITY, f64::min);
        assert_eq!(points.len(), corners.iter().filter(|z| **z <= 1e-3).count());
        assert!(points.iter().any(|p| p.height == lowest));
    }

    #[test]
    fn sphere_capsule_and_cylinder_touch_where_expected() {
        let sphere = collect(ShapeKind::Sphere(0.05), Transform::from_translation(Vector3::new(0.0, 0.0, 0.0495)));
        assert_eq!(sphere.len(), 1);
        assert!((sphere[0].height + 5e-4).abs() < 1e-15);
        // A capsule lying along x touches at both ends; standing, only at its lower end.
        let lying = Rotation3::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0).into_inner();
        assert_eq!(collect(ShapeKind::Capsule { half_height: 0.1, radius: 0.02 }, Transform::new(lying, Vector3::new(0.0, 0.0, 0.02))).len(), 2);
        assert_eq!(
            collect(ShapeKind::Capsule { half_height: 0.1, radius: 0.02 }, Transform::from_translation(Vector3::new(0.0, 0.0, 0.12))).len(),
            1
        );
        // A cylinder on its end stands on four rim points; on its side it touches along a line (two points).
        let standing = collect(ShapeKind::Cylinder { half_height: 0.1, radius: 0.05 }, Transform::from_translation(Vector3::new(0.0, 0.0, 0.1)));
        assert_eq!(standing.len(), 4);
        let side = collect(ShapeKind::Cylinder { half_height: 0.1, radius: 0.05 }, Transform::new(lying, Vector3::new(0.0, 0.0, 0.05)));
        assert!(side.len() == 2 && side.iter().all(|p| p.feature < 2 && p.height.abs() < 1e-12), "{side:?}");
        // Tilted on its end: the lowest rim point and the rim points away from it (none within 30 degrees).
        let tilt = Rotation3::from_euler_angles(0.02, 0.0, 0.0).into_inner();
        let tilted = collect(ShapeKind::Cylinder { half_height: 0.1, radius: 0.05 }, Transform::new(tilt, Vector3::new(0.0, 0.0, 0.1)));
        let lowest = tilted.iter().find(|p| p.feature == 0).expect("the lowest rim point").surface;
        assert!(tilted.iter().filter(|p| p.feature >= 2).all(|p| (p.surface - lowest).norm() > 0.05 * 0.5), "{tilted:?}");
    }
}
