//! Mass-property algebra: mass, centre of mass and rotational inertia about the centre of mass, all
//! expressed in one frame.
//!
//! Composition uses the parallel-axis theorem. For two bodies with masses m1, m2, centres c1, c2 and
//! inertias I1, I2 (each about its own centre) the composite has m = m1 + m2, c = (m1 c1 + m2 c2) / m and
//!
//! ```text
//! I = I1 + I2 + (m1 m2 / m) (|d|² 1 − d dᵀ),   d = c1 − c2.
//! ```
//!
//! The shorthand `(m1 I1 + m2 I2) / (m1 + m2)` in Moll et al. (IROS 2006) is a mass-weighted average of
//! the two inertias: it has the wrong units (it is not scaled by mass) and omits the transfer term, so it
//! underestimates the inertia of any body whose parts do not share a centre. It is not used here.
//!
//! Subtraction solves `a = c + b` for `c`, so `(a + b) - b == a` up to rounding.

use std::ops::{Add, Sub};

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use crate::spatial::RigidInertia;
use crate::validate::{finite, finite_matrix, finite_vector, rotation};
use crate::{Error, Result};

/// Relative tolerance of the symmetry, positivity and triangle-inequality checks on an inertia.
const PHYSICAL_TOLERANCE: f64 = 1e-9;
/// Absolute round-off allowed on an inertia read from a file (kg m²): far below any real link's (a 1 g,
/// 1 mm cube has 1.7e-10), so a written-out zero inertia with 1e-35 terms is not refused.
const ROUND_OFF_INERTIA: f64 = 1e-15;

/// A body's mass (kg), centre of mass (m) and rotational inertia about its centre of mass (kg m²), all in one
/// frame. `+` composes bodies by the parallel-axis theorem (not the mass-weighted average of the inertias
/// written in [Moll 2006], which omits the transfer term); `-` is its exact inverse ([`MassProperties::checked_sub`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    mass: f64,
    com: Vector3<f64>,
    inertia: Matrix3<f64>,
}

/// `|d|² 1 − d dᵀ`: the inertia of a unit point mass at offset `d` about the origin.
#[inline]
fn point_inertia(d: &Vector3<f64>) -> Matrix3<f64> {
    let (xx, yy, zz) = (d.x * d.x, d.y * d.y, d.z * d.z);
    let (xy, xz, yz) = (d.x * d.y, d.x * d.z, d.y * d.z);
    Matrix3::new(yy + zz, -xy, -xz, -xy, xx + zz, -yz, -xz, -yz, xx + yy)
}

impl MassProperties {
    /// Validated constructor: `mass` finite and > 0, `com` finite, `inertia` (about the COM) symmetric,
    /// positive semi-definite and satisfying the triangle inequality of principal moments.
    pub fn new(mass: f64, com: Vector3<f64>, inertia: Matrix3<f64>) -> Result<Self> {
        if !(finite("mass", mass)? > 0.0) {
            return Err(Error::invalid("mass", format!("must be > 0, got {mass}")));
        }
        finite_vector("com", com)?;
        check_inertia("inertia", &inertia)?;
        Ok(Self { mass, com, inertia: symmetrised(&inertia) })
    }

    /// A body as a file writes it, checked only for finite values, mass >= 0 and a symmetric inertia
    /// (within `PHYSICAL_TOLERANCE`). Unlike `new` it admits what exporters write and Pinocchio loads: a
    /// massless body with a rotational inertia, an inertia that is not physical (see `inertia_problem`).
    pub(crate) fn as_written(mass: f64, com: Vector3<f64>, inertia: Matrix3<f64>) -> Result<Self> {
        if finite("mass", mass)? < 0.0 {
            return Err(Error::invalid("mass", format!("must be >= 0, got {mass}")));
        }
        finite_vector("com", com)?;
        finite_matrix("inertia", &inertia)?;
        let asymmetry = (inertia - inertia.transpose()).amax();
        if asymmetry > PHYSICAL_TOLERANCE * inertia.amax() {
            return Err(Error::invalid("inertia", format!("must be symmetric (|I - I^T| = {asymmetry:.3e})")));
        }
        Ok(Self { mass, com, inertia: symmetrised(&inertia) })
    }

    /// What makes `inertia` (finite, symmetric) non-physical, beyond round-off: a negative principal
    /// moment, or one above the sum of the other two, by more than `PHYSICAL_TOLERANCE` of its largest
    /// entry plus `ROUND_OFF_INERTIA`. None for a physical inertia.
    pub fn inertia_problem(inertia: &Matrix3<f64>) -> Option<String> {
        check_inertia_scaled("inertia", inertia, inertia.amax() + ROUND_OFF_INERTIA / PHYSICAL_TOLERANCE).err().map(|e| e.to_string())
    }

    /// The identity of `+`: no mass.
    pub fn zero() -> Self {
        Self { mass: 0.0, com: Vector3::zeros(), inertia: Matrix3::zeros() }
    }

    /// A point mass `mass` (> 0) at `position`: no rotational inertia.
    pub fn point(mass: f64, position: Vector3<f64>) -> Result<Self> {
        finite_vector("position", position)?;
        Self::new(mass, position, Matrix3::zeros())
    }

    /// A solid box of uniform density with full edge lengths `size`, centred at `center` and rotated by
    /// `rotation`. Named `solid_box` in Rust and Python alike (`box` is a Rust keyword): "box" is the word the
    /// collision shapes, URDF and MuJoCo use for the same geometry, and "solid" says the mass fills it.
    pub fn solid_box(mass: f64, size: Vector3<f64>, center: Vector3<f64>, rotation: &Matrix3<f64>) -> Result<Self> {
        finite_vector("size", size)?;
        if size.iter().any(|&s| s < 0.0) {
            return Err(Error::invalid("size", "edge lengths must be >= 0"));
        }
        finite_vector("center", center)?;
        let s2 = size.component_mul(&size);
        let body = Matrix3::from_diagonal(&Vector3::new(s2.y + s2.z, s2.x + s2.z, s2.x + s2.y)) * (mass / 12.0);
        Self::new(mass, Vector3::zeros(), body)?.transformed(rotation, &center)
    }

    /// Point masses `masses[i]` at `positions[i]`; each mass must be > 0.
    pub fn from_points(masses: &[f64], positions: &[Vector3<f64>]) -> Result<Self> {
        if masses.len() != positions.len() {
            return Err(Error::invalid("positions", format!("has {} points but masses has {}", positions.len(), masses.len())));
        }
        if masses.is_empty() {
            return Err(Error::invalid("masses", "needs at least one point"));
        }
        masses.iter().zip(positions).try_fold(Self::zero(), |acc, (&m, &p)| Ok(acc + Self::point(m, p)?))
    }

    /// Mass (kg).
    pub fn mass(&self) -> f64 {
        self.mass
    }

    /// Centre of mass (m).
    pub fn com(&self) -> Vector3<f64> {
        self.com
    }

    /// Inertia about the centre of mass.
    pub fn inertia(&self) -> Matrix3<f64> {
        self.inertia
    }

    /// No mass and no rotational inertia.
    pub fn is_zero(&self) -> bool {
        self.mass == 0.0 && self.inertia == Matrix3::zeros()
    }

    /// Inertia about an arbitrary `point` (parallel-axis theorem).
    pub fn inertia_about(&self, point: &Vector3<f64>) -> Matrix3<f64> {
        self.inertia + point_inertia(&(self.com - point)) * self.mass
    }

    /// The same body expressed in the parent frame of the transform `x_parent = R x + t`.
    pub fn transformed(&self, rotation_matrix: &Matrix3<f64>, translation: &Vector3<f64>) -> Result<Self> {
        rotation("rotation", rotation_matrix)?;
        finite_vector("translation", *translation)?;
        Ok(self.transformed_unchecked(rotation_matrix, translation))
    }

    /// `transformed` for a rotation already known to be proper (the dynamics kernels' hot path).
    #[inline]
    pub fn transformed_unchecked(&self, rotation: &Matrix3<f64>, translation: &Vector3<f64>) -> Self {
        if self.is_zero() {
            return *self;
        }
        Self { mass: self.mass, com: rotation * self.com + translation, inertia: rotation * self.inertia * rotation.transpose() }
    }

    /// Equality within `rtol` relative to each quantity's magnitude plus `atol`.
    pub fn is_close(&self, other: &Self, rtol: f64, atol: f64) -> bool {
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= atol + rtol * scale;
        let mass_scale = self.mass.abs().max(other.mass.abs());
        let com_scale = self.com.amax().max(other.com.amax());
        let inertia_scale = self.inertia.amax().max(other.inertia.amax());
        close(self.mass, other.mass, mass_scale)
            && self.com.iter().zip(other.com.iter()).all(|(&a, &b)| close(a, b, com_scale))
            && self.inertia.iter().zip(other.inertia.iter()).all(|(&a, &b)| close(a, b, inertia_scale))
    }

    /// `self − other`, the exact inverse of `+`. Removing a body from itself gives `zero()`; removing
    /// more mass than there is, or leaving a non-physical inertia, is an error.
    pub fn checked_sub(&self, other: &Self) -> Result<Self> {
        if other.is_zero() {
            return Ok(*self);
        }
        if self.is_close(other, 1e-12, 0.0) {
            return Ok(Self::zero());
        }
        let mass = self.mass - other.mass;
        if !(mass > PHYSICAL_TOLERANCE * self.mass) {
            return Err(Error::invalid("other", format!("subtracting mass {} from {} leaves no positive mass", other.mass, self.mass)));
        }
        let com = (self.com * self.mass - other.com * other.mass) / mass;
        let inertia = self.inertia - other.inertia - point_inertia(&(com - other.com)) * (mass * other.mass / self.mass);
        check_inertia_scaled("other", &inertia, self.inertia.amax())
            .map_err(|e| Error::invalid("other", format!("the difference is not a physical body ({e})")))?;
        Ok(Self { mass, com, inertia: symmetrised(&inertia) })
    }
}

impl RigidInertia {
    /// The inertia of `body` about its frame's origin (parallel axes: I_O = I_c − m ĉĉ).
    pub fn from_body(body: &MassProperties) -> Self {
        let (m, c) = (body.mass(), body.com().cross_matrix());
        Self { mass: m, first_moment: body.com() * m, rotational: body.inertia() - m * c * c }
    }
}

impl Add for MassProperties {
    type Output = MassProperties;

    #[inline]
    fn add(self, other: Self) -> Self {
        if self.is_zero() {
            return other;
        }
        if other.is_zero() {
            return self;
        }
        let mass = self.mass + other.mass;
        if mass == 0.0 {
            // Massless bodies with rotational inertia (Pinocchio keeps those): no centre of mass to move.
            return Self { mass, com: self.com, inertia: self.inertia + other.inertia };
        }
        let inverse = 1.0 / mass;
        let com = (self.com * self.mass + other.com * other.mass) * inverse;
        let offset = self.com - other.com;
        let transfer = point_inertia(&offset) * (self.mass * other.mass * inverse);
        Self { mass, com, inertia: self.inertia + other.inertia + transfer }
    }
}

impl Sub for MassProperties {
    type Output = Result<MassProperties>;

    fn sub(self, other: Self) -> Result<Self> {
        self.checked_sub(&other)
    }
}

impl std::iter::Sum for MassProperties {
    fn sum<I: Iterator<Item = Self>>(iter: I) -> Self {
        iter.fold(Self::zero(), |acc, x| acc + x)
    }
}

fn symmetrised(m: &Matrix3<f64>) -> Matrix3<f64> {
    (m + m.transpose()) * 0.5
}

fn check_inertia(argument: &'static str, inertia: &Matrix3<f64>) -> Result<()> {
    finite_matrix(argument, inertia)?;
    check_inertia_scaled(argument, inertia, inertia.amax())
}

/// Symmetric, and `Σ = ½ tr(I) 1 − I` positive semi-definite: Σ is the second moment of the mass
/// distribution, and Σ ⪰ 0 is exactly "I ⪰ 0 and each principal moment ≤ the sum of the other two".
/// `scale` sets the tolerance (the magnitude of the inertias the value was computed from).
fn check_inertia_scaled(argument: &'static str, inertia: &Matrix3<f64>, scale: f64) -> Result<()> {
    let tolerance = PHYSICAL_TOLERANCE * scale;
    let asymmetry = (inertia - inertia.transpose()).amax();
    if asymmetry > tolerance {
        return Err(Error::invalid(argument, format!("must be symmetric (|I - I^T| = {asymmetry:.3e})")));
    }
    let principal = SymmetricEigen::new(symmetrised(inertia)).eigenvalues;
    if principal.min() < -tolerance {
        return Err(Error::invalid(argument, format!("must be positive semi-definite (principal moments {principal:?})")));
    }
    let trace = principal.sum();
    if principal.iter().any(|&moment| moment > trace - moment + tolerance) {
        return Err(Error::invalid(
            argument,
            format!("principal moments [{:.6e}, {:.6e}, {:.6e}] violate the triangle inequality", principal[0], principal[1], principal[2]),
        ));
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn random_rotation(rng: &mut StdRng) -> Matrix3<f64> {
        let axis = Unit::new_normalize(Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0) + 1e-3));
        Rotation3::from_axis_angle(&axis, rng.random_range(-3.0..3.0)).into_inner()
    }

    fn random_body(rng: &mut StdRng) -> MassProperties {
        let size = Vector3::new(rng.random_range(0.0..2.0), rng.random_range(0.0..2.0), rng.random_range(0.0..2.0));
        let center = Vector3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0));
        MassProperties::solid_box(rng.random_range(0.1..10.0), size, center, &random_rotation(rng)).unwrap()
    }

    /// Brute force: Σ m (|r − c|² 1 − (r − c)(r − c)ᵀ) over the points (also the URDF tests' point clouds).
    pub(crate) fn brute_force(masses: &[f64], points: &[Vector3<f64>]) -> (f64, Vector3<f64>, Matrix3<f64>) {
        let m: f64 = masses.iter().sum();
        let c = masses.iter().zip(points).map(|(&mi, p)| p * mi).sum::<Vector3<f64>>() / m;
        let mut inertia = Matrix3::zeros();
        for (&mi, p) in masses.iter().zip(points) {
            let r = p - c;
            inertia += (Matrix3::identity() * r.dot(&r) - r * r.transpose()) * mi;
        }
        (m, c, inertia)
    }

    #[test]
    fn addition_commutes_associates_and_subtraction_inverts_it() {
        let mut rng = StdRng::seed_from_u64(1);
        for _ in 0..500 {
            let (a, b, c) = (random_body(&mut rng), random_body(&mut rng), random_body(&mut rng));
            assert!((a + b).is_close(&(b + a), 1e-12, 0.0));
            assert!(((a + b) + c).is_close(&(a + (b + c)), 1e-10, 0.0));
            assert!(((a + b) - b).unwrap().is_close(&a, 1e-9, 0.0));
        }
    }

    #[test]
    fn from_points_matches_brute_force() {
        let mut rng = StdRng::seed_from_u64(2);
        for n in 1..30 {
            let masses: Vec<f64> = (0..n).map(|_| rng.random_range(0.01..5.0)).collect();
            let points: Vec<Vector3<f64>> =
                (0..n).map(|_| Vector3::new(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0))).collect();
            let (m, c, inertia) = brute_force(&masses, &points);
            let expected = MassProperties::new(m, c, inertia).unwrap();
            assert!(MassProperties::from_points(&masses, &points).unwrap().is_close(&expected, 1e-11, 1e-12));
        }
    }

    #[test]
    fn transform_commutes_with_addition_and_inverts() {
        let mut rng = StdRng::seed_from_u64(3);
        for _ in 0..200 {
            let (a, b) = (random_body(&mut rng), random_body(&mut rng));
            let r = random_rotation(&mut rng);
            let t = Vector3::new(rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0));
            let sum_then_move = (a + b).transformed(&r, &t).unwrap();
            let move_then_sum = a.transformed(&r, &t).unwrap() + b.transformed(&r, &t).unwrap();
            assert!(sum_then_move.is_close(&move_then_sum, 1e-10, 0.0));
            let back = a.transformed(&r, &t).unwrap().transformed(&r.transpose(), &(-r.transpose() * t)).unwrap();
            assert!(back.is_close(&a, 1e-10, 1e-14));
        }
    }

    #[test]
    fn inertia_about_a_point_matches_brute_force() {
        let masses = [1.0, 2.0, 0.5];
        let points = [Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 2.0, -1.0), Vector3::new(-1.0, 1.0, 3.0)];
        let body = MassProperties::from_points(&masses, &points).unwrap();
        let pivot = Vector3::new(0.3, -0.2, 0.7);
        let shifted: Vec<Vector3<f64>> = points.iter().map(|p| p - pivot).collect();
        let mut about = Matrix3::zeros();
        for (&mi, r) in masses.iter().zip(&shifted) {
            about += (Matrix3::identity() * r.dot(r) - r * r.transpose()) * mi;
        }
        assert!((body.inertia_about(&pivot) - about).amax() < 1e-12);
    }

    #[test]
    fn the_papers_mass_weighted_average_is_not_the_composite_inertia() {
        let a = MassProperties::point(1.0, Vector3::new(-1.0, 0.0, 0.0)).unwrap();
        let b = MassProperties::point(1.0, Vector3::new(1.0, 0.0, 0.0)).unwrap();
        // Two unit point masses 2 m apart: I_yy = I_zz = 2 about the midpoint; the average gives 0.
        let composite = (a + b).inertia();
        assert_eq!(composite, Matrix3::from_diagonal(&Vector3::new(0.0, 2.0, 2.0)));
        let average = (a.inertia() * a.mass() + b.inertia() * b.mass()) / (a.mass() + b.mass());
        assert_eq!(average, Matrix3::zeros());
    }

    #[test]
    fn a_moved_bodys_rigid_inertia_is_its_rigid_inertia_moved() {
        let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::new(0.1, 0.2, -0.3), &Matrix3::identity()).unwrap();
        let x = crate::Transform::new(Rotation3::from_euler_angles(0.3, -1.2, 2.0).into_inner(), Vector3::new(0.4, -0.7, 1.1));
        // X* I X⁻¹ (eq. 2.66, `act_rigid_inertia`) of the body's inertia is the inertia of the transformed body.
        let moved = RigidInertia::from_body(&body.transformed(&x.rotation, &x.translation).unwrap());
        assert!((x.act_rigid_inertia(&RigidInertia::from_body(&body)).matrix() - moved.matrix()).amax() < 1e-13);
        // A centred, axis-aligned body's rotational inertia about the origin is exactly diagonal (the diagonal
        // shortcut of `rotate_symmetric`).
        let centred =
            RigidInertia::from_body(&MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap());
        let r = &centred.rotational;
        assert!(r[(0, 1)] == 0.0 && r[(0, 2)] == 0.0 && r[(1, 2)] == 0.0);
    }

    #[test]
    fn zero_is_the_identity_and_self_subtraction_gives_it() {
        let mut rng = StdRng::seed_from_u64(4);
        let a = random_body(&mut rng);
        assert_eq!(MassProperties::zero() + a, a);
        assert_eq!(a + MassProperties::zero(), a);
        assert!((a - a).unwrap().is_zero());
        assert_eq!((a - MassProperties::zero()).unwrap(), a);
        assert_eq!([a, a, a].into_iter().sum::<MassProperties>(), a + a + a);
    }

    #[test]
    fn bad_input_names_the_argument() {
        let i = Matrix3::identity();
        let arg = |r: Result<MassProperties>| r.unwrap_err().argument();
        assert_eq!(arg(MassProperties::new(f64::NAN, Vector3::zeros(), i)), "mass");
        assert_eq!(arg(MassProperties::new(-1.0, Vector3::zeros(), i)), "mass");
        assert_eq!(arg(MassProperties::new(0.0, Vector3::zeros(), i)), "mass");
        assert_eq!(arg(MassProperties::new(1.0, Vector3::new(f64::INFINITY, 0.0, 0.0), i)), "com");
        let mut skew = i;
        skew[(0, 1)] = 0.5;
        assert_eq!(arg(MassProperties::new(1.0, Vector3::zeros(), skew)), "inertia");
        assert_eq!(arg(MassProperties::new(1.0, Vector3::zeros(), -i)), "inertia");
        let triangle = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 3.0));
        assert_eq!(arg(MassProperties::new(1.0, Vector3::zeros(), triangle)), "inertia");
        let small = MassProperties::point(1.0, Vector3::zeros()).unwrap();
        let big = MassProperties::point(2.0, Vector3::zeros()).unwrap();
        assert_eq!(arg(small - big), "other");
        let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        assert_eq!(arg(small.transformed(&reflection, &Vector3::zeros())), "rotation");
        // A point mass cannot be removed from a different place of a point mass: the rest would need
        // negative inertia.
        let other_place = MassProperties::point(1.0, Vector3::new(1.0, 0.0, 0.0)).unwrap();
        assert_eq!(arg(big - other_place), "other");
    }
}
