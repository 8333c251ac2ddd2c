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
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::FRAC_PI_2;

    type V = Vector3<f64>;

    /// The angles of the near-degenerate variants of every degenerate configuration.
    const NEAR: [f64; 3] = [1e-6, 1e-8, 1e-10];

    /// Radius plus the centre's distance from the line: the size every absolute tolerance is relative to.
    fn scale(circle: &Circle, line: &Line) -> f64 {
        let w = line.point - circle.center;
        circle.radius + (w - line.direction * w.dot(&line.direction)).norm() + 1e-300
    }

    fn unit(rng: &mut StdRng) -> V {
        loop {
            let v = V::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let norm = v.norm();
            if (0.1..=1.0).contains(&norm) {
                return v / norm;
            }
        }
    }

    fn point(rng: &mut StdRng, half_width: f64) -> V {
        V::from_fn(|_, _| rng.random_range(-half_width..half_width))
    }

    /// A unit vector perpendicular to the unit `v`, built differently from the kernel's frame.
    fn perp(v: &V) -> V {
        let t = if v.x.abs() < 0.6 { V::x() } else { V::y() };
        (t - v * t.dot(v)).normalize()
    }

    /// A random unit vector perpendicular to the unit `v` (to a few ε: the rejected draws would amplify the
    /// rounding of the projection).
    fn random_perp(rng: &mut StdRng, v: &V) -> V {
        loop {
            let t = unit(rng);
            let t = t - v * t.dot(v);
            if t.norm() > 0.5 {
                return t.normalize();
            }
        }
    }

    /// Rotates `v` by `angle` about the unit `axis` (Rodrigues).
    fn rotate(v: &V, axis: &V, angle: f64) -> V {
        v * angle.cos() + axis.cross(v) * angle.sin() + axis * axis.dot(v) * (1.0 - angle.cos())
    }

    fn circle(center: V, normal: V, radius: f64) -> Circle {
        Circle::new(center, normal, radius).unwrap()
    }

    fn line(point: V, direction: V) -> Line {
        Line::new(point, direction).unwrap()
    }

    /// The sampled local minima of `f` over consecutive `angles`, best first. A circle-line distance has at
    /// most two local minima per turn; keeping four only matters when it is flat to rounding.
    fn local_minima(f: &impl Fn(f64) -> f64, angles: impl Iterator<Item = f64>) -> Vec<(f64, f64)> {
        let samples: Vec<(f64, f64)> = angles.map(|t| (t, f(t))).collect();
        let mut minima: Vec<(f64, f64)> = samples.windows(3).filter(|w| w[1].1 <= w[0].1 && w[1].1 <= w[2].1).map(|w| w[1]).collect();
        minima.sort_by(|a, b| a.1.total_cmp(&b.1));
        minima.truncate(4);
        minima
    }

    /// Brute-force global minimum of `f` over one turn: 4096 samples, then repeated 4-fold zooms of ±2 steps
    /// around every retained local minimum down to below the resolution of f64 angles. Zooming by sampling
    /// rather than golden-section search also separates two minima closer than a sample step (near-tangent
    /// lines).
    fn minimise(f: impl Fn(f64) -> f64) -> f64 {
        const SAMPLES: i32 = 4096;
        let mut step = 2.0 * PI / SAMPLES as f64;
        let mut minima = local_minima(&f, (-1..=SAMPLES).map(|i| i as f64 * step));
        while step > 1e-16 {
            step /= 4.0;
            let zoomed = minima.iter().flat_map(|&(t, _)| (-8..=8).map(move |j| t + j as f64 * step));
            minima = local_minima(&f, zoomed.collect::<Vec<_>>().into_iter());
        }
        minima[0].1
    }

    /// Brute-force distance between a circle and a line, over the circle parametrised in a test-built frame.
    fn reference(circle: &Circle, line: &Line) -> f64 {
        let e1 = perp(&circle.normal);
        let e2 = circle.normal.cross(&e1);
        // The offset from the line is linear in (cos θ, sin θ) once projected perpendicular to the line; plain
        // arrays keep the sampling fast in debug builds.
        let project = |v: V| -> [f64; 3] { (v - line.direction * v.dot(&line.direction)).into() };
        let (w, a, b) = (project(circle.center - line.point), project(e1 * circle.radius), project(e2 * circle.radius));
        minimise(|t| {
            let (sin, cos) = t.sin_cos();
            (0..3).map(|i| (w[i] + cos * a[i] + sin * b[i]).powi(2)).sum::<f64>().sqrt()
        })
    }

    /// Checks `circle_line(circle, line)` against the brute-force distance of the `exact` problem, and that the
    /// returned points lie on the circle and the line and realise the distance. Tolerance: 1e-12 of the scale
    /// (kernel and reference both round at ~1e-15 of it) plus `representation`, the error already in the inputs
    /// (for shifted coordinates, rounding of the shifted inputs moves the answer by a few ε |shift|). Points
    /// are also allowed the rounding of their own absolute coordinates, a few ε of the inputs' magnitude.
    fn check_against(circle: &Circle, line: &Line, exact: (&Circle, &Line), representation: f64) -> CircleLine {
        let result = circle_line(circle, line);
        let tol = 1e-12 * scale(exact.0, exact.1) + representation;
        let expected = reference(exact.0, exact.1);
        assert!(
            (result.distance - expected).abs() <= tol,
            "distance {} vs reference {expected} (tol {tol:.1e}) for {circle:?} {line:?}",
            result.distance
        );
        assert!(result.count == 1 || result.count == 2);
        if result.count == 1 {
            assert_eq!(result.circle_points[0], result.circle_points[1]);
            assert_eq!(result.line_points[0], result.line_points[1]);
        }
        let tol = tol + 4.0 * EPS * (circle.center.amax() + line.point.amax());
        for (x, l) in result.circle_points.iter().zip(&result.line_points) {
            let radial = x - circle.center;
            assert!((radial.norm() - circle.radius).abs() <= tol, "off the circle: {result:?}");
            assert!(radial.dot(&circle.normal).abs() <= tol, "off the circle's plane: {result:?}");
            assert!((l - line.point).cross(&line.direction).norm() <= tol, "off the line: {result:?}");
            assert!(((x - l).norm() - result.distance).abs() <= tol, "points do not realise the distance: {result:?}");
        }
        result
    }

    fn check(circle: &Circle, line: &Line) -> CircleLine {
        check_against(circle, line, (circle, line), 0.0)
    }

    /// The same problem shifted far from the origin must give the unshifted distance.
    fn check_shifted(circle: &Circle, line: &Line, shift: V) {
        let far_circle = Circle { center: circle.center + shift, ..*circle };
        let far_line = Line { point: line.point + shift, ..*line };
        check_against(&far_circle, &far_line, (circle, line), 8.0 * EPS * shift.norm());
    }

    /// Near-degenerate variants of `line`: its direction tilted, and its point shifted by `angle · scale`.
    fn perturbed(rng: &mut StdRng, circle: &Circle, line: &Line) -> Vec<Line> {
        let size = scale(circle, line);
        NEAR.iter()
            .flat_map(|&angle| {
                let tilt = random_perp(rng, &line.direction);
                let shift = random_perp(rng, &line.direction) * angle * size;
                [Line { direction: rotate(&line.direction, &tilt, angle), ..*line }, Line { point: line.point + shift, ..*line }]
            })
            .collect()
    }

    fn random_circle(rng: &mut StdRng) -> Circle {
        circle(point(rng, 1.0), unit(rng), rng.random_range(0.5..2.0))
    }

    /// One instance of every degenerate configuration, each with its expected count when exact.
    fn degenerate_cases(rng: &mut StdRng) -> Vec<(&'static str, Circle, Line, Option<usize>)> {
        let c = random_circle(rng);
        let (n, r) = (c.normal, c.radius);
        let m1 = random_perp(rng, &n);
        let m2 = n.cross(&m1);
        let t = rng.random_range(-1.0..1.0);
        let d = unit(rng);
        let off_axis = if d.dot(&n).abs() > 0.9 { m1 } else { d };
        let cusp_tilt: f64 = 0.7;
        let cusp_direction = n * cusp_tilt.cos() + m2 * cusp_tilt.sin();
        vec![
            ("zero radius", circle(c.center, n, 0.0), line(point(rng, 2.0), unit(rng)), Some(1)),
            ("along axis", c, line(c.center + n * t, n), Some(1)),
            ("along axis, reversed", c, line(c.center + n * t, -n), Some(1)),
            ("parallel to axis inside", c, line(c.center + m1 * (0.3 * r) + n * t, n), Some(1)),
            ("parallel to axis on circle", c, line(c.center + m1 * r + n * t, n), Some(1)),
            ("parallel to axis outside", c, line(c.center + m1 * (2.0 * r) + n * t, n), Some(1)),
            ("through centre", c, line(c.center + off_axis * t, off_axis), Some(2)),
            ("in plane crossing", c, line(c.center + m2 * (0.6 * r) + m1 * t, m1), Some(2)),
            ("in plane through centre", c, line(c.center + m1 * t, m1), Some(2)),
            ("in plane outside", c, line(c.center + m2 * (1.5 * r) + m1 * t, m1), Some(1)),
            ("in plane tangent", c, line(c.center + m2 * r + m1 * t, m1), None),
            ("parallel to plane crossing", c, line(c.center + n * 0.4 + m2 * (0.5 * r) + m1 * t, m1), Some(2)),
            ("parallel to plane outside", c, line(c.center + n * 0.4 + m2 * (1.5 * r) + m1 * t, m1), Some(1)),
            ("tangent", c, line(c.center + m1 * r + (m2 + n * 0.7) * t, m2 + n * 0.7), Some(1)),
            ("tangent, steep", c, line(c.center + m1 * r, (m2 * 0.01 + n).normalize()), Some(1)),
            // Through the centre of curvature of the projected ellipse's vertex, the evolute's cusp, where the
            // closest point is about to split into a mirrored pair and the root of g is a triple one.
            ("evolute cusp", c, line(c.center + m1 * (r * cusp_tilt.sin().powi(2)) + cusp_direction * t, cusp_direction), None),
        ]
    }

    #[test]
    fn random_configurations_match_brute_force() {
        let mut rng = StdRng::seed_from_u64(1);
        for _ in 0..2500 {
            // Radii and offsets over several orders of magnitude relative to each other.
            let radius = 10f64.powf(rng.random_range(-2.0..1.0));
            let circle = circle(point(&mut rng, 10.0), unit(&mut rng), radius);
            let offset = 10f64.powf(rng.random_range(-2.0..1.5));
            let line = line(circle.center + point(&mut rng, offset), unit(&mut rng));
            let result = check(&circle, &line);
            assert!(!result.equidistant);
        }
    }

    #[test]
    fn extreme_radius_to_offset_ratios_match_brute_force() {
        let mut rng = StdRng::seed_from_u64(9);
        for _ in 0..1000 {
            // Radius and offset each over 18 orders of magnitude: a line through a huge circle's centre, a
            // tiny circle far from the line, and everything between.
            let radius = 10f64.powf(rng.random_range(-9.0..9.0));
            let circle = circle(point(&mut rng, 10.0), unit(&mut rng), radius);
            let offset = 10f64.powf(rng.random_range(-9.0..9.0));
            let line = line(circle.center + point(&mut rng, offset), unit(&mut rng));
            check(&circle, &line);
            for near in perturbed(&mut rng, &circle, &line) {
                check(&circle, &near);
            }
        }
    }

    #[test]
    fn degenerate_configurations_and_their_near_versions() {
        let mut rng = StdRng::seed_from_u64(2);
        for _ in 0..20 {
            for (name, circle, line, count) in degenerate_cases(&mut rng) {
                let result = check(&circle, &line);
                if let Some(count) = count {
                    assert_eq!(result.count, count, "{name}: {result:?}");
                }
                let equidistant = name.starts_with("zero radius") || name.starts_with("along axis");
                assert_eq!(result.equidistant, equidistant, "{name}: {result:?}");
                for near in perturbed(&mut rng, &circle, &line) {
                    check(&circle, &near);
                }
            }
        }
    }

    #[test]
    fn exact_values_of_degenerate_configurations() {
        let mut rng = StdRng::seed_from_u64(3);
        for (name, circle, line, _) in degenerate_cases(&mut rng) {
            let result = circle_line(&circle, &line);
            let r = circle.radius;
            let expected = match name {
                "along axis" | "along axis, reversed" => r,
                "parallel to axis inside" => 0.7 * r,
                "parallel to axis outside" => r,
                "in plane outside" => 0.5 * r,
                "parallel to plane crossing" => 0.4,
                "zero radius" => scale(&circle, &line),
                n if n.contains("tangent") || n.contains("crossing") || n.contains("on circle") => 0.0,
                _ => continue,
            };
            assert!((result.distance - expected).abs() <= 1e-14 * (1.0 + r), "{name}: {result:?}");
        }
    }

    /// The rounding of the inputs' own coordinates, which moves the answer by a few ε of their magnitude
    /// whatever the scale (as in the Python suite's tolerance).
    fn input_rounding(circle: &Circle, line: &Line) -> f64 {
        8.0 * EPS * (circle.center.norm().max(line.point.norm()) + circle.radius)
    }

    /// Line direction equal to the normal up to rounding or to a small tilt, normals near a coordinate axis
    /// (found by the Python suite): fl(n × d) was rounding noise, so the frame left the circle's plane and tilted
    /// toward the line, moving the circle points off the plane and the distance by a fraction of the scale.
    #[test]
    fn line_nearly_parallel_to_the_normal() {
        let v = |x, y, z| V::new(x, y, z);
        // Circle points 1.1e-11, 8.4e-10 and 2.2e-12 off the plane (radius 1; the second is the axis).
        let cases = [
            (
                v(1.465934043551448e-05, 0.9999999998925518, 1.0744816147933989e-10),
                v(-0.9999999997851037, 1.465934043551448e-05, -1.465934043551448e-05),
                v(2.915357960347044e-05, 1.9887374693686057, 2.136861847716919e-10),
            ),
            (
                v(7.775179140127354e-11, 1.117682001393307e-10, -0.0009999999999999907),
                V::zeros(),
                v(1.5550358280254707e-07, 2.235364002786614e-07, -1.9999999999999813),
            ),
            (
                v(5.135579277246771e-05, 9.950184849665618e-05, -0.9999999937309825),
                V::zeros(),
                v(0.0007847304159295114, 0.0015204151808634282, -15.280270611083305),
            ),
        ];
        for (normal, point, direction) in cases {
            let (c, l) = (circle(V::zeros(), normal, 1.0), line(point, direction));
            check_against(&c, &l, (&c, &l), input_rounding(&c, &l));
        }

        // The axis, given through a normal with a 1e-32 component: not recognised as equidistant, at distance
        // 0.99999999999932.
        let normal = v(0.00012600806401593902, 4.173049432566246e-32, -0.9999999920609839);
        let axis = line(normal, v(0.0019254373294128571, 6.376532500278581e-31, -15.280270585565274));
        let result = check(&circle(V::zeros(), normal, 1.0), &axis);
        assert!(result.equidistant, "{result:?}");
        assert!((result.distance - 1.0).abs() <= 1e-15, "{result:?}");

        // Radius 0 with directions equal up to an ulp and 1e-69 or 1e-39 x components: distances 2.3% and 2e-7
        // off, disagreeing with the returned points.
        for (normal, point, direction, expected) in [
            (
                v(1.3750669035920504e-69, 6.216527089015008e-08, 0.9999999999999981),
                v(0.0, 0.0, 1.0),
                v(1.463751099515076e-69, 6.617458639969246e-08, 1.0644944589178573),
                6.216527089015006e-08,
            ),
            (
                v(8.540973236015979e-39, 1.9561755098827145e-05, 0.9258185579077083),
                v(0.0, 0.0, 1.94911792695584),
                v(6.1841935151886e-39, 1.416392203616174e-05, 0.6703499664313196),
                4.118319643915983e-05,
            ),
        ] {
            let (c, l) = (circle(V::zeros(), normal, 0.0), line(point, direction));
            let result = check_against(&c, &l, (&c, &l), input_rounding(&c, &l));
            assert!(result.equidistant, "{result:?}");
            assert!((result.distance - expected).abs() <= input_rounding(&c, &l), "{result:?}");
        }
    }

    /// An axis line given by a point in coordinates much larger than the scene (found by the Python suite:
    /// centre (0, 8, 0), radius 0.125, line point 0.03 from it): rounding that point moves the line off the axis
    /// by about ε times its coordinates, which the equidistance test must accept.
    #[test]
    fn axis_through_a_rounded_point_far_from_the_origin() {
        let mut rng = StdRng::seed_from_u64(10);
        for _ in 0..2000 {
            let radius = 10f64.powf(rng.random_range(-3.0..1.0));
            let c = circle(point(&mut rng, 10.0), unit(&mut rng), radius);
            let along = c.normal * rng.random_range(-0.1..0.1);
            let axis = line(c.center + along, c.normal * rng.random_range(0.5..2.0));
            let result = check_against(&c, &axis, (&c, &axis), input_rounding(&c, &axis));
            assert!(result.equidistant, "{c:?} {axis:?}: {result:?}");
        }
    }

    #[test]
    fn both_minimisers_realise_the_distance() {
        let mut rng = StdRng::seed_from_u64(4);
        for _ in 0..200 {
            let c = random_circle(&mut rng);
            let m = random_perp(&mut rng, &c.normal);
            let d = unit(&mut rng);
            for line in [line(c.center + d * 0.3, d), line(c.center + c.normal.cross(&m) * (0.9 * c.radius), m)] {
                let result = check(&c, &line);
                assert_eq!(result.count, 2, "{result:?}");
                assert!((result.circle_points[0] - result.circle_points[1]).norm() > 1e-3 * c.radius);
            }
        }
    }

    #[test]
    fn large_coordinates_keep_the_unshifted_distance() {
        let mut rng = StdRng::seed_from_u64(5);
        for magnitude in [1e6, 1e9] {
            let shift = V::new(1.0, -0.7, 0.3) * magnitude;
            for _ in 0..10 {
                for (_, circle, line, _) in degenerate_cases(&mut rng) {
                    check_shifted(&circle, &line, shift);
                    for near in perturbed(&mut rng, &circle, &line) {
                        check_shifted(&circle, &near, shift);
                    }
                }
            }
            for _ in 0..200 {
                let circle = random_circle(&mut rng);
                let line = line(point(&mut rng, 3.0), unit(&mut rng));
                check_shifted(&circle, &line, shift);
            }
        }
    }

    /// Scenes scaled by powers of two, which round nothing, down to 1e-301 and up to 1e289: the answer must scale
    /// with them (found by the Python suite: a point 4.7e-160 from a rotation axis along the line got a distance
    /// 1e-6 off, its squared radius having underflowed). Also a radius too far below the scene for its inverse.
    #[test]
    fn extreme_scales_scale_the_answer() {
        let y = 4.6547511301852685e-160;
        let on_axis = line(V::zeros(), V::z());
        assert_eq!(rotation_toward_line(&on_axis, &V::new(0.0, y, 0.0), &on_axis), (0.0, y));

        let mut rng = StdRng::seed_from_u64(11);
        let mut scenes: Vec<(Circle, Line)> = (0..200).map(|_| (random_circle(&mut rng), line(point(&mut rng, 2.0), unit(&mut rng)))).collect();
        scenes.extend(degenerate_cases(&mut rng).into_iter().map(|(_, c, l, _)| (c, l)));
        for (c, l) in scenes {
            let base = circle_line(&c, &l);
            let axis = line(point(&mut rng, 2.0), unit(&mut rng));
            let p = point(&mut rng, 2.0);
            let (base_theta, base_distance) = rotation_toward_line(&axis, &p, &l);
            for factor in [2f64.powi(-540), 2f64.powi(-1000), 2f64.powi(540), 2f64.powi(960)] {
                let scaled = |l: &Line| Line { point: l.point * factor, ..*l };
                let result = circle_line(&Circle { center: c.center * factor, radius: c.radius * factor, ..c }, &scaled(&l));
                let tol = 1e-12 * scale(&c, &l) * factor;
                assert!((result.distance - base.distance * factor).abs() <= tol, "factor {factor:e}: {result:?} vs {base:?}");
                assert_eq!((result.count, result.equidistant), (base.count, base.equidistant));
                for (x, base_x) in result.circle_points.iter().zip(&base.circle_points) {
                    assert!((x - base_x * factor).amax() <= tol, "factor {factor:e}: {result:?} vs {base:?}");
                }
                let (theta, distance) = rotation_toward_line(&scaled(&axis), &(p * factor), &scaled(&l));
                assert!((theta - base_theta).abs() <= 1e-12, "factor {factor:e}: {theta} vs {base_theta}");
                let size = base_distance + (p - axis.point).norm();
                assert!((distance - base_distance * factor).abs() <= 1e-12 * size * factor);
            }

            let point_distance = circle_line(&circle(c.center, c.normal, 0.0), &l).distance;
            for radius in [1e-300, 1e-320] {
                let result = circle_line(&circle(c.center, c.normal, radius), &l);
                let tol = radius + 1e-15 * point_distance;
                assert!((result.distance - point_distance).abs() <= tol, "{result:?}");
            }
        }
    }

    /// Rotating `point` about `axis` by θ, by Rodrigues' formula.
    fn rotated(axis: &Line, point: &V, theta: f64) -> V {
        axis.point + rotate(&(point - axis.point), &axis.direction, theta)
    }

    fn distance_to(line: &Line, x: &V) -> f64 {
        let w = x - line.point;
        (w - line.direction * w.dot(&line.direction)).norm()
    }

    /// Checks `rotation_toward_line` against a brute-force search over rotations; returns θ.
    fn check_rotation(axis: &Line, point: &V, line: &Line) -> f64 {
        let (theta, distance) = rotation_toward_line(axis, point, line);
        let f = |t: f64| distance_to(line, &rotated(axis, point, t));
        let expected = minimise(f);
        let relative = point - axis.point;
        let radial = relative - axis.direction * relative.dot(&axis.direction);
        let radius = radial.norm();
        let tol = 1e-12 * (radius + distance_to(line, &(point - radial)));
        assert!(theta > -PI && theta <= PI, "theta {theta} out of range");
        assert!((distance - expected).abs() <= tol, "distance {distance} vs {expected}");
        assert!(f(theta) - expected <= tol + 1e-12 * radius, "theta {theta} does not realise the distance");
        theta
    }

    #[test]
    fn rotation_matches_brute_force() {
        let mut rng = StdRng::seed_from_u64(6);
        for _ in 0..500 {
            let axis = line(point(&mut rng, 2.0), unit(&mut rng));
            check_rotation(&axis, &point(&mut rng, 2.0), &line(point(&mut rng, 2.0), unit(&mut rng)));
        }
    }

    #[test]
    fn rotation_tie_prefers_lowest_z_then_smallest_angle() {
        let axis = line(V::zeros(), V::x());
        let start = V::new(0.0, 1.0, 0.0);
        // Line through the centre along (1, 0, 1): minimisers at z = ±1, the lower one is a -π/2 rotation.
        let theta = check_rotation(&axis, &start, &line(V::zeros(), V::new(1.0, 0.0, 1.0)));
        assert!((theta + FRAC_PI_2).abs() < 1e-12, "{theta}");
        // Line along (1, 1, 0): minimisers at y = ±1, both at z = 0; the unrotated point wins.
        assert_eq!(check_rotation(&axis, &start, &line(V::zeros(), V::new(1.0, 1.0, 0.0))), 0.0);

        let mut rng = StdRng::seed_from_u64(7);
        for _ in 0..200 {
            let axis = line(point(&mut rng, 2.0), unit(&mut rng));
            let p = point(&mut rng, 2.0);
            let center = axis.point + axis.direction * (p - axis.point).dot(&axis.direction);
            let theta = check_rotation(&axis, &p, &line(center + V::new(0.1, 0.2, 0.3), V::new(0.1, 0.2, 0.3)));
            // The minimisers are antipodal about the centre, so the chosen one lies below it.
            assert!(rotated(&axis, &p, theta).z <= center.z + 1e-9, "theta {theta}");
        }
    }

    #[test]
    fn rotation_is_zero_when_every_angle_is_equally_close() {
        let mut rng = StdRng::seed_from_u64(8);
        for _ in 0..100 {
            let axis = line(point(&mut rng, 5.0), unit(&mut rng));
            let on_axis = axis.point + axis.direction * rng.random_range(-3.0..3.0);
            assert_eq!(check_rotation(&axis, &on_axis, &line(point(&mut rng, 2.0), unit(&mut rng))), 0.0);
            assert_eq!(check_rotation(&axis, &point(&mut rng, 2.0), &line(axis.point, -axis.direction)), 0.0);
        }
    }

    /// `line_nearly_parallel_to_the_normal`'s radius-0 case as a rotation axis: the distance was 6.07e-8 for a
    /// point on the axis, and for a point at 1 from it θ was 2.3% short, leaving the point 1.4e-9 from the line.
    #[test]
    fn rotation_about_an_axis_nearly_parallel_to_the_line() {
        let direction = V::new(1.3750669035920504e-69, 6.216527089015008e-08, 0.9999999999999981);
        let target = line(V::new(0.0, 0.0, 1.0), V::new(1.463751099515076e-69, 6.617458639969246e-08, 1.0644944589178573));
        let (theta, distance) = rotation_toward_line(&line(V::zeros(), direction), &V::zeros(), &target);
        assert_eq!(theta, 0.0);
        assert!((distance - 6.216527089015006e-08).abs() <= 8.0 * EPS, "{distance}");

        let axis = line(V::x(), direction);
        let theta = check_rotation(&axis, &V::zeros(), &target);
        assert!((theta - 6.21653e-08).abs() <= 1e-12, "{theta}");
    }

    #[test]
    fn invalid_inputs_name_the_argument() {
        let (o, z) = (V::zeros(), V::z());
        let nan = V::new(f64::NAN, 0.0, 0.0);
        let argument = |e: Error| e.argument();
        assert_eq!(Circle::new(nan, z, 1.0).map_err(argument), Err("center"));
        assert_eq!(Circle::new(o, o, 1.0).map_err(argument), Err("normal"));
        assert_eq!(Circle::new(o, nan, 1.0).map_err(argument), Err("normal"));
        assert_eq!(Circle::new(o, z, -1.0).map_err(argument), Err("radius"));
        assert_eq!(Circle::new(o, z, f64::NAN).map_err(argument), Err("radius"));
        assert_eq!(Circle::new(o, z, f64::INFINITY).map_err(argument), Err("radius"));
        assert_eq!(Line::new(nan, z).map_err(argument), Err("line_point"));
        assert_eq!(Line::new(o, o).map_err(argument), Err("line_direction"));
        assert_eq!(Line::new(o, nan).map_err(argument), Err("line_direction"));
        let c = Circle::new(o, V::new(0.0, 0.0, 2.0), 1.0).unwrap();
        assert_eq!(c.normal, z);
        assert_eq!(Line::new(o, V::new(3.0, 0.0, 0.0)).unwrap().direction, V::x());
    }
}
