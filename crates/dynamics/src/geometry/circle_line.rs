//! Closest points between a circle and a line in 3D, and the rotation that brings a point closest to a line.
//!
//! Method: the distance from any point to the line is the length of its projection onto the plane
//! perpendicular to the line direction `d`, measured from the line's trace. Projected along `d`, the circle
//! becomes an axis-aligned ellipse, so the problem reduces to the distance from a point to an ellipse in 2D.
//! With `n` the circle normal, `u = n × d / |n × d|` (in the circle's plane and perpendicular to `d`),
//! `v = n × u` and `e2 = d × u`, the circle point `X(θ) = C + r (cos θ u + sin θ v)` projects to
//! `(r cos θ, r β sin θ)` in the basis `(u, e2)`, with `β = n · d`: semi-axes `r ≥ r |β|`.
//!
//! Reflecting the query into the first quadrant leaves exactly one closest point there (Eberly). It is the root
//! of `g(φ)`, the derivative of half the squared distance, which changes sign once on `[0, π/2]`; a Halley
//! iteration safeguarded by bisection finds it to full precision, typically in three or four steps. Angles are
//! carried as unit vectors `(cos φ, sin φ)` and steps applied as rotations, so the iteration needs no
//! trigonometric calls and one division per step. Queries on the ellipse's major axis, or a flat
//! ellipse (line parallel to the circle's plane), have closed-form and possibly mirrored minimisers; a line
//! along the circle's axis sees every circle point at the same distance.
//!
//! The distance is evaluated in the 2D frame relative to the circle centre, so it keeps full precision relative
//! to the problem's scale (radius plus the centre's offset from the line) even far from the origin. That needs
//! `u` perpendicular to `d` to a few ε, not merely to `ε / |n × d|`, or the line-parallel part of the offset,
//! which may dwarf the scale, leaks into the projection: `u` is formed as `n × (d ∓ n)`, which stays well
//! conditioned as `d` approaches `±n`. Problems far from unit size are first rescaled by a power of two, so
//! that no square underflows or overflows. Projected coordinates within a few ε (of the scale, or of the
//! inputs' coordinates) of a degenerate value, and `|β|` within a few ε of 0 or 1, are snapped to it, so that
//! mirror-symmetric and equidistant configurations built in rounded coordinates are recognised; this moves the
//! distance by at most that rounding level.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

use nalgebra::Vector3;

use crate::{validate, Error, Result};

const EPS: f64 = f64::EPSILON;

/// Relative rounding level of the projected problem (a few ε per dot product, with margin): a coordinate or
/// an axis ratio within it of a degenerate value is treated as degenerate, which moves the distance by at most
/// this fraction of the problem's scale.
const ROUNDING: f64 = 16.0 * EPS;

/// How far, per unit of the inputs' coordinates, their rounding can move a line off a degenerate position: a
/// point is only known to ε/2 per coordinate, so to about ε |X|; this leaves a margin of two. Applied to the
/// sum of the largest coordinates of both points, snapping within it moves the distance by at most 8 ε |X|,
/// the inputs' own uncertainty.
const COORDINATE_ROUNDING: f64 = 2.0 * EPS;

/// Halley iterations are bounded; bisection alone resolves the angle to rounding in about 55 steps.
const MAX_ITERATIONS: usize = 100;

/// A circle in 3D: centre, unit normal and radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    /// Centre of the circle.
    pub center: Vector3<f64>,
    /// Unit normal of the circle's plane; its sign does not matter to `circle_line`.
    pub normal: Vector3<f64>,
    /// Non-negative; zero makes the circle a point.
    pub radius: f64,
}

impl Circle {
    /// Validates the inputs and normalises `normal`. Errors name `center`, `normal` (non-finite or zero) or
    /// `radius` (non-finite or negative); a zero radius is a point.
    pub fn new(center: Vector3<f64>, normal: Vector3<f64>, radius: f64) -> Result<Circle> {
        let center = validate::finite_vector("center", center)?;
        let normal = validate::direction("normal", normal)?;
        let radius = validate::finite("radius", radius)?;
        if radius < 0.0 {
            return Err(Error::invalid("radius", format!("must be non-negative, got {radius}")));
        }
        Ok(Circle { center, normal, radius })
    }
}

/// An infinite line in 3D: a point on it and a unit direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// Any point of the line.
    pub point: Vector3<f64>,
    /// Unit direction; its sign does not matter to `circle_line`.
    pub direction: Vector3<f64>,
}

impl Line {
    /// Validates the inputs and normalises `direction`. Errors name `line_point` (non-finite) or
    /// `line_direction` (non-finite or zero).
    pub fn new(point: Vector3<f64>, direction: Vector3<f64>) -> Result<Line> {
        Self::named(point, direction, ("line_point", "line_direction"))
    }

    /// `new` for a rotation axis: errors name `axis_point` or `axis_direction`.
    pub fn axis(point: Vector3<f64>, direction: Vector3<f64>) -> Result<Line> {
        Self::named(point, direction, ("axis_point", "axis_direction"))
    }

    fn named(point: Vector3<f64>, direction: Vector3<f64>, (point_name, direction_name): (&'static str, &'static str)) -> Result<Line> {
        let point = validate::finite_vector(point_name, point)?;
        let direction = validate::direction(direction_name, direction)?;
        Ok(Line { point, direction })
    }
}

/// Closest points between a circle and a line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleLine {
    /// Minimum distance between the circle and the line.
    pub distance: f64,
    /// Number of distinct minimisers, 1 or 2 (two for mirror-symmetric configurations such as a line through
    /// the centre or crossing the circle in its plane).
    pub count: usize,
    /// The minimising circle points; when `count == 1` the second equals the first.
    pub circle_points: [Vector3<f64>; 2],
    /// The line point closest to each circle point.
    pub line_points: [Vector3<f64>; 2],
    /// Every circle point is at the same distance (the line is the circle's axis, or the radius is zero), to
    /// rounding; the reported minimiser is then the circle point at θ = 0 of the internal frame, `count == 1`.
    pub equidistant: bool,
}

/// Results stored column by column, row `i` of each (a structure of arrays): what a batch of queries fills,
/// the Python binding's output arrays and the batch benchmark alike.
pub struct CircleLineColumns<'a> {
    /// One number a row: [`CircleLine::distance`].
    pub distance: &'a mut [f64],
    /// One number a row: [`CircleLine::count`].
    pub count: &'a mut [i64],
    /// Six numbers a row: the two minimising circle points.
    pub circle_points: &'a mut [f64],
    /// Six numbers a row: the line point closest to each circle point.
    pub line_points: &'a mut [f64],
    /// One flag a row: [`CircleLine::equidistant`].
    pub equidistant: &'a mut [bool],
}

impl CircleLineColumns<'_> {
    /// Stores `result` as row `i`.
    pub fn set(&mut self, i: usize, result: &CircleLine) {
        self.distance[i] = result.distance;
        self.count[i] = result.count as i64;
        self.equidistant[i] = result.equidistant;
        for k in 0..2 {
            self.circle_points[6 * i + 3 * k..6 * i + 3 * k + 3].copy_from_slice(result.circle_points[k].as_slice());
            self.line_points[6 * i + 3 * k..6 * i + 3 * k + 3].copy_from_slice(result.line_points[k].as_slice());
        }
    }
}

/// The minimisers in the circle's own frame, before they are mapped to 3D points.
struct Solution {
    /// In-plane unit vectors: a circle point is `C + r (cos θ u + sin θ v)`.
    u: Vector3<f64>,
    v: Vector3<f64>,
    distance: f64,
    count: usize,
    /// `(cos θ, sin θ)` of each minimiser; the second repeats the first when `count == 1`.
    angles: [(f64, f64); 2],
    equidistant: bool,
}

/// The closest points between `circle` and `line`: the distance, its one or two minimisers, and whether every
/// circle point is equidistant. Accurate to rounding relative to the problem's scale in every configuration.
pub fn circle_line(circle: &Circle, line: &Line) -> CircleLine {
    let w = line.point - circle.center;
    let magnitude = circle.center.amax() + line.point.amax();
    let solution = solve(&circle.normal, circle.radius, &line.direction, &w, magnitude);
    let points = |(cos, sin): (f64, f64)| {
        let radial = (solution.u * cos + solution.v * sin) * circle.radius;
        // Projecting the offset from the line point, not the absolute circle point, keeps large coordinates out
        // of the subtraction.
        let t = (radial - w).dot(&line.direction);
        (circle.center + radial, line.point + line.direction * t)
    };
    let (x0, l0) = points(solution.angles[0]);
    let (x1, l1) = points(solution.angles[1]);
    CircleLine {
        distance: solution.distance,
        count: solution.count,
        circle_points: [x0, x1],
        line_points: [l0, l1],
        equidistant: solution.equidistant,
    }
}

/// The angle θ (radians, right-hand rule about `axis.direction`, in (-π, π]) by which rotating `point` about
/// the `axis` line brings it closest to `line`, and that closest distance.
///
/// θ = 0 when every rotation is equally close: the point lies on the axis (to the rounding of its coordinates)
/// or the axis is the line (to the rounding of the projected problem, as for `CircleLine::equidistant`). When two
/// rotations tie, the one whose rotated point has the lowest z wins; if z also ties (within 1e-12 of the
/// rotation radius), the smaller |θ|.
pub fn rotation_toward_line(axis: &Line, point: &Vector3<f64>, line: &Line) -> (f64, f64) {
    let n = axis.direction;
    let relative = point - axis.point;
    let along = relative.dot(&n);
    let radial = relative - n * along;
    let radius = norm(&radial);
    // A point on the axis, given in rounded coordinates, leaves a radial residue at the rounding level of those
    // coordinates; at that radius the angle would be pure noise, so it counts as on the axis.
    let radius = if radius <= 8.0 * EPS * (point.amax() + axis.point.amax()) { 0.0 } else { radius };
    // The line's offset from the rotation centre `axis.point + along n`, formed without rounding the centre's
    // absolute coordinates.
    let w = (line.point - axis.point) - n * along;
    // `point` enters w only along n, which cannot move the line off the axis.
    let magnitude = axis.point.amax() + line.point.amax();
    let solution = solve(&n, radius, &line.direction, &w, magnitude);
    if solution.equidistant {
        return (0.0, solution.distance);
    }
    let start = radial / radius;
    // Angles are measured between in-plane directions, never between absolute points, to keep precision.
    let rotation = |(cos, sin): (f64, f64)| {
        let direction = solution.u * cos + solution.v * sin;
        let theta = n.dot(&start.cross(&direction)).atan2(start.dot(&direction));
        (if theta <= -PI { PI } else { theta }, direction.z)
    };
    let (theta, z) = rotation(solution.angles[0]);
    if solution.count == 2 {
        let (other_theta, other_z) = rotation(solution.angles[1]);
        let other_wins = if (z - other_z).abs() <= 1e-12 { other_theta.abs() < theta.abs() } else { other_z < z };
        if other_wins {
            return (other_theta, solution.distance);
        }
    }
    (theta, solution.distance)
}

/// Closest points of the circle with unit normal `n` and radius `r` to the line with unit direction `d` whose
/// point is at `w` from the circle's centre; `magnitude` is the size of the absolute coordinates `w` was formed
/// from, whose rounding it carries.
fn solve(n: &Vector3<f64>, r: f64, d: &Vector3<f64>, w: &Vector3<f64>, magnitude: f64) -> Solution {
    let size = r.max(w.amax());
    if size == 0.0 || (1e-100..=1e100).contains(&size) {
        return solve_in_range(n, r, d, w, magnitude);
    }
    // Rescaling by a power of two is exact. Clamping the exponent keeps the factor finite, and still brings any
    // finite size within 2^±74 of 1.
    let factor = 2f64.powi((-size.log2().round()).clamp(-1000.0, 1000.0) as i32);
    let mut solution = solve_in_range(n, r * factor, d, &(w * factor), magnitude * factor);
    solution.distance /= factor;
    solution
}

/// `solve` for a problem whose size (largest of `r` and the coordinates of `w`) is within 1e±100 of 1, where
/// the squares of the distance and of everything down to its rounding level neither overflow nor underflow.
fn solve_in_range(n: &Vector3<f64>, r: f64, d: &Vector3<f64>, w: &Vector3<f64>, magnitude: f64) -> Solution {
    let beta = n.dot(d);
    // n × d = n × (d ∓ n), taking the sign of β. fl(n × d) has an absolute error of O(ε), so when d is
    // nearly ±n its direction is rounding noise: u then leaves the circle's plane and, worse, tilts toward d,
    // mixing the line-parallel part of w (possibly far larger than the scale) into the projected coordinates.
    // d ∓ n is rounded only relative to itself and at least 45° from n (cos² = (1 - |β|) / 2), so its cross
    // product with n, and u, are accurate to a few ε in direction however close d is to ±n.
    let cross = n.cross(&(d - n * 1f64.copysign(beta)));
    // Below this |n × d| ≤ 1e-100, so any in-plane u is perpendicular to d to far below rounding.
    let u = if cross.norm_squared() > 1e-200 { cross } else { perpendicular(n) }.normalize();
    let v = n.cross(&u);
    let e2 = d.cross(&u);
    let (p1, p2) = (w.dot(&u), w.dot(&e2));
    // Below this a projected coordinate is indistinguishable from zero, given the rounding of the projection
    // and of the coordinates w came from.
    let tol = ROUNDING * (r + w.amax()) + COORDINATE_ROUNDING * magnitude;
    // |β| within rounding of 0 is a flat ellipse (line parallel to the plane) and of 1 a circle.
    let k = if beta.abs() <= ROUNDING { 0.0 } else { beta.abs().min(1.0) };

    if r == 0.0 || (1.0 - k <= ROUNDING && p1.abs().max(p2.abs()) <= tol) {
        return Solution { u, v, distance: (r - p1).hypot(p2), count: 1, angles: [(1.0, 0.0); 2], equidistant: true };
    }

    let (y0, y1) = (p1.abs(), p2.abs());
    let (c, s, count) = closest_on_ellipse(r, k, y0, if y1 <= tol { 0.0 } else { y1 });
    // Undo the reflection into the first quadrant; the second coordinate of the ellipse carries sign(β).
    let cos = c.copysign(p1);
    let sin = if (p2 < 0.0) != (beta < 0.0) { -s } else { s };
    Solution {
        u,
        v,
        // Plain sqrt rather than hypot (a sixth of the query's cost): `solve` keeps the squares in range.
        distance: ((r * c - y0).powi(2) + (r * k * s - y1).powi(2)).sqrt(),
        count,
        angles: [(cos, sin), (cos, if count == 2 { -sin } else { sin })],
        equidistant: false,
    }
}

/// Closest point `(r c, r k s)` of the ellipse with semi-axes `r ≥ r k` (`1 ≥ k ≥ 0`) to the query
/// `(y0, y1)`, both non-negative, as `(c, s)` on the unit circle with the number of mirrored minimisers
/// `(c, ±s)`. The query is not divided by `r`, which would overflow for a radius far below the query's size.
#[inline]
fn closest_on_ellipse(r: f64, k: f64, y0: f64, y1: f64) -> (f64, f64, usize) {
    // r (1 - k²), without cancellation when k is close to 1.
    let e = r * ((1.0 - k) * (1.0 + k));
    if y1 == 0.0 || k == 0.0 {
        // On the major axis (or any query to a flat ellipse): inside the evolute's cusp at x = e the normal foot
        // leaves the vertex and splits into a mirrored pair.
        if y0 < e {
            let c = y0 / e;
            return (c, ((1.0 - c) * (1.0 + c)).sqrt(), 2);
        }
        return (1.0, 0.0, 1);
    }
    if y0 == 0.0 {
        // On the minor axis the co-vertex is always closest, since b ≤ a.
        return (0.0, 1.0, 1);
    }
    let (c, s) = halley(e, y0, k * y1);
    (c, s, 1)
}

/// The root in (0, π/2) of `g = s (y0 - e c) - y1 c` (`y1` here standing for the query's `k y1`), negative at 0
/// and positive at π/2, by Halley steps (g'' costs a few multiplications more than g') kept inside a shrinking
/// bracket, bisecting whenever a step would leave it. From the bracket's midpoint typical queries take three or
/// four steps.
#[inline]
fn halley(e: f64, y0: f64, y1: f64) -> (f64, f64) {
    // g is linear in (e, y0, y1); scaling them to sum 1 keeps the squares in the step far from overflow.
    let m = 1.0 / (e + y0 + y1);
    let (e, y0, y1) = (e * m, y0 * m, y1 * m);
    let mut lo = (1.0, 0.0);
    let mut hi = (0.0, 1.0);
    let (mut c, mut s) = (FRAC_1_SQRT_2, FRAC_1_SQRT_2);
    for _ in 0..MAX_ITERATIONS {
        let g = s * (y0 - e * c) - y1 * c;
        // Once g is within its own rounding error the root is located as well as the data allow.
        if g.abs() <= 4.0 * EPS * (s * (y0 + e * c) + y1 * c) {
            break;
        }
        if g < 0.0 {
            lo = (c, s);
        } else {
            hi = (c, s);
        }
        let g1 = e * (s * s - c * c) + y0 * c + y1 * s;
        let g2 = 4.0 * e * s * c - y0 * s + y1 * c;
        // Halley's step δ = -2 g g1 / (2 g1² - g g2) = 2 num / den, applied as the rotation by 2 atan(δ/2):
        // its unit vector (1 - t², 2t) / (1 + t²), t = num / den, costs one division and no square root, and
        // its O(δ³) angle error keeps the cubic convergence. Near an inflection of g (g1 → 0, e.g. at the
        // starting midpoint for a query near the centre) Halley's step shrinks to nothing instead of growing,
        // so there Newton's step (num = -g, den = 2 g1) is taken and left to the bracket test.
        let (num, den) = if g1 > 0.0 && (g * g2).abs() <= g1 * g1 { (-g * g1, 2.0 * g1 * g1 - g * g2) } else { (-g, 2.0 * g1) };
        let inverse = 1.0 / (den * den + num * num);
        let (a, b) = ((den - num) * (den + num) * inverse, 2.0 * num * den * inverse);
        let step = (a * c - b * s, a * s + b * c);
        let inside = cross(lo, step) > 0.0 && cross(step, hi) > 0.0;
        // Converged (|δ| ≤ 4ε) only if the step heads for a minimum (g' > 0), not toward a maximum.
        if g1 > 0.0 && num.abs() <= 2.0 * EPS * den {
            if inside {
                (c, s) = step;
            }
            break;
        }
        (c, s) = if inside { step } else { normalise(lo.0 + hi.0, lo.1 + hi.1) };
        if cross(lo, hi) <= 4.0 * EPS {
            break;
        }
    }
    (c, s)
}

/// `|v|`, scaling `v` by its largest coordinate when the sum of squares would underflow (losing precision) or
/// overflow, as nalgebra's `norm` does not.
fn norm(v: &Vector3<f64>) -> f64 {
    let squared = v.norm_squared();
    if (1e-200..=1e200).contains(&squared) {
        return squared.sqrt();
    }
    let largest = v.amax();
    if largest == 0.0 {
        0.0
    } else {
        (v / largest).norm() * largest
    }
}

#[inline]
fn normalise(c: f64, s: f64) -> (f64, f64) {
    let inverse = 1.0 / (c * c + s * s).sqrt();
    (c * inverse, s * inverse)
}

/// Sine of the angle from `a` to `b`, both unit vectors.
#[inline]
fn cross(a: (f64, f64), b: (f64, f64)) -> f64 {
    a.0 * b.1 - a.1 * b.0
}

/// A vector perpendicular to the unit `n`, crossing it with the basis axis least aligned with it so the cross
/// product cannot cancel.
#[inline]
fn perpendicular(n: &Vector3<f64>) -> Vector3<f64> {
    let a = n.abs();
    let axis = if a.x <= a.y && a.x <= a.z {
        Vector3::x()
    } else if a.y <= a.z {
        Vector3::y()
    } else {
        Vector3::z()
    };
    n.cross(&axis)
}

#[cfg(test)]
mod tests;
