//! Spatial algebra (Featherstone, *Rigid Body Dynamics Algorithms*, ch. 2), in Pinocchio's layout:
//! spatial vectors are `[linear; angular]`, motion `[v; ω]` and force `[f; n]`, each expressed in a body
//! frame; a `Transform` maps child to parent coordinates, `x_parent = R x_child + p`.
//!
//! Every operation here is `#[inline(always)]`: left to itself the compiler kept some out of line, and
//! passing 6-vectors and transforms through memory cost ABA and CRBA on small models up to a quarter of
//! their time (measured with criterion and callgrind).

use nalgebra::{Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

/// A spatial motion vector `[v; ω]` (m/s, rad/s): a body's velocity, or an acceleration, about a frame's origin.
pub type Motion = Vector6<f64>;
/// A spatial force vector `[f; n]` (N, N m): a force and its moment about a frame's origin.
pub type Force = Vector6<f64>;
/// A spatial inertia (rigid or articulated) acting on motions `[v; ω]` and giving forces `[f; n]`.
pub type Inertia = Matrix6<f64>;

#[inline(always)]
pub(crate) fn linear(x: &Vector6<f64>) -> Vector3<f64> {
    x.fixed_rows::<3>(0).into_owned()
}

#[inline(always)]
pub(crate) fn angular(x: &Vector6<f64>) -> Vector3<f64> {
    x.fixed_rows::<3>(3).into_owned()
}

#[inline(always)]
pub(crate) fn spatial(linear: Vector3<f64>, angular: Vector3<f64>) -> Vector6<f64> {
    Vector6::new(linear.x, linear.y, linear.z, angular.x, angular.y, angular.z)
}

/// `v × m` (eq. 2.31): the derivative of motion `m` moving with velocity `v`.
#[inline(always)]
pub(crate) fn cross_motion(v: &Motion, m: &Motion) -> Motion {
    let (vl, w) = (linear(v), angular(v));
    spatial(w.cross(&linear(m)) + vl.cross(&angular(m)), w.cross(&angular(m)))
}

/// `v ×* f` (eq. 2.32): the derivative of force `f` moving with velocity `v`.
#[inline(always)]
pub(crate) fn cross_force(v: &Motion, f: &Force) -> Force {
    let (vl, w, fl) = (linear(v), angular(v), linear(f));
    spatial(w.cross(&fl), w.cross(&angular(f)) + vl.cross(&fl))
}

/// A rigid transform: the pose of a child frame in its parent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// R: the child's axes in parent coordinates.
    pub rotation: Matrix3<f64>,
    /// t: the child's origin in parent coordinates (m).
    pub translation: Vector3<f64>,
}

impl Default for Transform {
    fn default() -> Self {
        Self::identity()
    }
}

impl Transform {
    /// The pose (R, t), unchecked: R is taken to be a rotation.
    pub fn new(rotation: Matrix3<f64>, translation: Vector3<f64>) -> Self {
        Self { rotation, translation }
    }

    /// The child frame coincides with the parent.
    pub fn identity() -> Self {
        Self { rotation: Matrix3::identity(), translation: Vector3::zeros() }
    }

    /// A pure translation by `translation` (m).
    pub fn from_translation(translation: Vector3<f64>) -> Self {
        Self { rotation: Matrix3::identity(), translation }
    }

    /// Rotation about the unit `axis` by `angle` (Rodrigues).
    #[inline(always)]
    pub fn rotation_about(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
        let (s, c) = angle.sin_cos();
        let (x, y, z) = (axis.x, axis.y, axis.z);
        let t = 1.0 - c;
        let (tx, ty, tz) = (t * x, t * y, t * z);
        let (sx, sy, sz) = (s * x, s * y, s * z);
        Matrix3::new(tx * x + c, tx * y - sz, tx * z + sy, tx * y + sz, ty * y + c, ty * z - sx, tx * z - sy, ty * z + sx, tz * z + c)
    }

    /// The pose with rotation `rotation` and origin `translation`.
    pub fn from_quaternion(translation: Vector3<f64>, rotation: &UnitQuaternion<f64>) -> Self {
        Self { rotation: rotation.to_rotation_matrix().into_inner(), translation }
    }

    /// `self ∘ other`: the pose of `other`'s child in `self`'s parent.
    #[inline(always)]
    pub fn compose(&self, other: &Transform) -> Transform {
        Transform { rotation: self.rotation * other.rotation, translation: self.rotation * other.translation + self.translation }
    }

    /// The parent's pose in the child: (Rᵀ, −Rᵀ t).
    #[inline(always)]
    pub fn inverse(&self) -> Transform {
        let rt = self.rotation.transpose();
        Transform { rotation: rt, translation: -(rt * self.translation) }
    }

    /// A point from child to parent coordinates: R x + t.
    #[inline(always)]
    pub fn transform_point(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x + self.translation
    }

    /// Motion from child to parent coordinates, X m [Featherstone 2008, eq. 2.24].
    #[inline(always)]
    pub fn act_motion(&self, m: &Motion) -> Motion {
        let w = self.rotation * angular(m);
        spatial(self.rotation * linear(m) + self.translation.cross(&w), w)
    }

    /// Motion from parent to child coordinates.
    #[inline(always)]
    pub fn inv_act_motion(&self, m: &Motion) -> Motion {
        let (v, w) = (linear(m), angular(m));
        let rt = self.rotation.transpose();
        spatial(rt * (v - self.translation.cross(&w)), rt * w)
    }

    /// Force from child to parent coordinates, X* f (the dual of `act_motion`).
    #[inline(always)]
    pub fn act_force(&self, f: &Force) -> Force {
        let fl = self.rotation * linear(f);
        spatial(fl, self.rotation * angular(f) + self.translation.cross(&fl))
    }

    /// Force from parent to child coordinates.
    #[inline(always)]
    pub fn inv_act_force(&self, f: &Force) -> Force {
        let (fl, n) = (linear(f), angular(f));
        let rt = self.rotation.transpose();
        spatial(rt * fl, rt * (n - self.translation.cross(&fl)))
    }
}

/// `(I x, I y)` for a 6x6 inertia, in one pass over I written over fixed arrays, so that it compiles to
/// straight vector code (nalgebra's generic product does not, and these products dominate ABA and Minv).
/// The linear and angular halves of x and y are summed apart: ABA's backward pass is a chain of these
/// products, so their latency counts.
#[inline(always)]
pub(crate) fn inertia_times_pair(inertia: &Inertia, x: &Vector6<f64>, y: &Vector6<f64>) -> (Vector6<f64>, Vector6<f64>) {
    let entries: &[f64; 36] = inertia.as_slice().try_into().expect("6x6");
    let mut sums = [[0.0; 6]; 4];
    for (c, column) in entries.chunks_exact(6).enumerate() {
        let half = c / 3;
        for r in 0..6 {
            sums[half][r] += column[r] * x[c];
            sums[2 + half][r] += column[r] * y[c];
        }
    }
    let add = |a: &[f64; 6], b: &[f64; 6]| Vector6::from_fn(|r, _| a[r] + b[r]);
    (add(&sums[0], &sums[1]), add(&sums[2], &sums[3]))
}

/// `a · b` for 6-vectors, summed pairwise (a shorter dependency chain than left to right).
#[inline(always)]
pub(crate) fn dot6(a: &Vector6<f64>, b: &[f64]) -> f64 {
    (a[0] * b[0] + a[1] * b[1]) + (a[2] * b[2] + a[3] * b[3]) + (a[4] * b[4] + a[5] * b[5])
}

/// The inverse of a symmetric positive definite 6x6 matrix (an articulated-body inertia) by its Cholesky factor,
/// S⁻¹ = L⁻ᵀ L⁻¹, in loops the compiler unrolls (nalgebra's `Cholesky::inverse` solves against the identity column by
/// column, and took 1.8 times as long in `aba_derivatives`); all NaN if the matrix is not positive definite.
pub fn spd_inverse6(m: &Inertia) -> Inertia {
    let mut l = Inertia::zeros();
    for j in 0..6 {
        let mut pivot = m[(j, j)];
        for k in 0..j {
            pivot -= l[(j, k)] * l[(j, k)];
        }
        if !(pivot > 0.0) {
            return Inertia::repeat(f64::NAN);
        }
        let diagonal = pivot.sqrt();
        l[(j, j)] = diagonal;
        for i in j + 1..6 {
            let mut x = m[(i, j)];
            for k in 0..j {
                x -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = x / diagonal;
        }
    }
    let mut inverse_l = Inertia::zeros();
    for j in 0..6 {
        inverse_l[(j, j)] = 1.0 / l[(j, j)];
        for i in j + 1..6 {
            let mut x = 0.0;
            for k in j..i {
                x += l[(i, k)] * inverse_l[(k, j)];
            }
            inverse_l[(i, j)] = -x / l[(i, i)];
        }
    }
    inverse_l.tr_mul(&inverse_l)
}

/// `parent += I − u wᵀ`: an articulated inertia less a joint's rank-one part (I^A − U D⁻¹ Uᵀ with w = U / D),
/// added to its parent's without storing it.
#[inline(always)]
pub(crate) fn add_reduced_inertia(parent: &mut Inertia, inertia: &Inertia, u: &Vector6<f64>, w: &Vector6<f64>) {
    let (parent, entries, u) = (&mut parent.data.0, &inertia.data.0, &u.data.0[0]);
    // Whole fixed-size columns, which the compiler vectorises.
    for ((p, column), &wc) in parent.iter_mut().zip(entries).zip(w.iter()) {
        *p = std::array::from_fn(|r| p[r] + (column[r] - u[r] * wc));
    }
}

/// `R S Rᵀ` for a symmetric `S`: the six distinct entries only.
#[inline(always)]
fn rotate_symmetric(r: &Matrix3<f64>, s: &Matrix3<f64>) -> Matrix3<f64> {
    // Bodies are mostly modelled along their frame's axes, where S is diagonal and R S scales R's columns.
    let diagonal = s[(0, 1)] == 0.0 && s[(0, 2)] == 0.0 && s[(1, 2)] == 0.0;
    let t = if diagonal {
        Matrix3::from_fn(|i, j| r[(i, j)] * s[(j, j)])
    } else {
        Matrix3::from_fn(|i, j| r[(i, 0)] * s[(0, j)] + r[(i, 1)] * s[(1, j)] + r[(i, 2)] * s[(2, j)])
    };
    let entry = |i: usize, j: usize| t[(i, 0)] * r[(j, 0)] + t[(i, 1)] * r[(j, 1)] + t[(i, 2)] * r[(j, 2)];
    let (xx, yy, zz, xy, xz, yz) = (entry(0, 0), entry(1, 1), entry(2, 2), entry(0, 1), entry(0, 2), entry(1, 2));
    Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
}

/// A rigid body's spatial inertia in its 10-parameter form (eq. 2.63 about the frame origin O): mass m,
/// first moment h = m c and rotational inertia about O, I_O = I_c − m ĉĉ. Rigid inertias add, and move
/// between frames, at a fraction of the cost of their 6x6 matrices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidInertia {
    /// m (kg).
    pub mass: f64,
    /// h = m c (kg m), c the centre of mass in the frame.
    pub first_moment: Vector3<f64>,
    /// I_O, the rotational inertia about the frame's origin (kg m²).
    pub rotational: Matrix3<f64>,
}

impl RigidInertia {
    /// No mass: the identity of addition.
    pub fn zeros() -> Self {
        Self { mass: 0.0, first_moment: Vector3::zeros(), rotational: Matrix3::zeros() }
    }

    /// `I m = [m v − h × ω; I_O ω + h × v]` for a motion `m = [v; ω]`.
    #[inline(always)]
    pub fn apply(&self, motion: &Motion) -> Force {
        let (v, w, h) = (linear(motion), angular(motion), &self.first_moment);
        spatial(v * self.mass - h.cross(&w), self.rotational * w + h.cross(&v))
    }

    /// The 6x6 matrix `[m 1, −ĥ; ĥ, I_O]`.
    #[inline(always)]
    pub fn matrix(&self) -> Inertia {
        let (m, h, i) = (self.mass, &self.first_moment, &self.rotational);
        Inertia::new(
            m,
            0.0,
            0.0,
            0.0,
            h.z,
            -h.y,
            0.0,
            m,
            0.0,
            -h.z,
            0.0,
            h.x,
            0.0,
            0.0,
            m,
            h.y,
            -h.x,
            0.0,
            0.0,
            -h.z,
            h.y,
            i[(0, 0)],
            i[(0, 1)],
            i[(0, 2)],
            h.z,
            0.0,
            -h.x,
            i[(1, 0)],
            i[(1, 1)],
            i[(1, 2)],
            -h.y,
            h.x,
            0.0,
            i[(2, 0)],
            i[(2, 1)],
            i[(2, 2)],
        )
    }
}

/// The matrix B(v) = v ×* I − I v× + (I v)×̄ of a rigid body of inertia I moving with velocity v, where
/// (h)×̄ m = m ×* h: when the body's velocity changes by δv and its acceleration by δa − v × δv, its net force
/// I a + v ×* I v changes by I δa + B δv (Carpentier & Mansard, RSS 2018, the Ẏ + h×̄ of their backward pass).
/// For I = [m 1, −ĥ; ĥ, I_O] and v = [u; ω] it is [0, −2p̂; 0, C] with p = m u + ω × h the linear momentum and
/// C = ω̂ I_O − I_O ω̂ − (ûĥ + ĥû) − L̂, L = I_O ω + h × u: only its angular columns, 12 numbers, which add.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RateMatrix {
    pub momentum: Vector3<f64>,
    pub angular: Matrix3<f64>,
}

impl RateMatrix {
    pub fn zeros() -> Self {
        Self { momentum: Vector3::zeros(), angular: Matrix3::zeros() }
    }

    /// B x.
    #[inline(always)]
    pub fn apply(&self, x: &Motion) -> Force {
        let w = angular(x);
        spatial(-2.0 * self.momentum.cross(&w), self.angular * w)
    }

    /// Bᵀ x (its linear half is zero).
    #[inline(always)]
    pub fn transpose_apply(&self, x: &Motion) -> Vector6<f64> {
        spatial(Vector3::zeros(), 2.0 * self.momentum.cross(&linear(x)) + self.angular.tr_mul(&angular(x)))
    }

    /// The full 6x6 matrix.
    pub fn matrix(&self) -> Matrix6<f64> {
        let mut b = Matrix6::zeros();
        b.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-2.0 * self.momentum.cross_matrix()));
        b.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.angular);
        b
    }
}

impl std::ops::AddAssign for RateMatrix {
    #[inline(always)]
    fn add_assign(&mut self, other: Self) {
        self.momentum += other.momentum;
        self.angular += other.angular;
    }
}

impl RigidInertia {
    /// B(v) (see `RateMatrix`) of this body moving with velocity `v`.
    #[inline(always)]
    pub(crate) fn rate_matrix(&self, v: &Motion) -> RateMatrix {
        let (u, w, h, i) = (linear(v), angular(v), &self.first_moment, &self.rotational);
        let momentum = u * self.mass + w.cross(h);
        let spin = i * w + h.cross(&u);
        let w_hat = w.cross_matrix();
        // ûĥ + ĥû = h uᵀ + u hᵀ − 2 (u·h) 1.
        let symmetric = h * u.transpose() + u * h.transpose() - Matrix3::identity() * (2.0 * u.dot(h));
        RateMatrix { momentum, angular: w_hat * i - i * w_hat - symmetric - spin.cross_matrix() }
    }
}

impl std::ops::AddAssign for RigidInertia {
    #[inline(always)]
    fn add_assign(&mut self, other: Self) {
        self.mass += other.mass;
        self.first_moment += other.first_moment;
        self.rotational += other.rotational;
    }
}

impl Transform {
    /// A rigid inertia from child to parent coordinates: h' = R h + m p and
    /// I'_O = R I_O Rᵀ − (ĥ_r p̂ + p̂ ĥ_r) − m p̂p̂ (parallel axes, with h_r = R h); with â b̂ = b aᵀ − (a·b) 1
    /// the shift is (2 h_r·p + m p·p) 1 − p h'ᵀ − h_r pᵀ.
    #[inline(always)]
    pub fn act_rigid_inertia(&self, inertia: &RigidInertia) -> RigidInertia {
        let (m, p) = (inertia.mass, &self.translation);
        let h = self.rotation * inertia.first_moment;
        let moment = h + p * m;
        let diagonal = h.dot(p) + moment.dot(p);
        let r = rotate_symmetric(&self.rotation, &inertia.rotational);
        let entry = |i: usize, j: usize| r[(i, j)] - p[i] * moment[j] - h[i] * p[j];
        let (xy, xz, yz) = (entry(0, 1), entry(0, 2), entry(1, 2));
        let rotational = Matrix3::new(entry(0, 0) + diagonal, xy, xz, xy, entry(1, 1) + diagonal, yz, xz, yz, entry(2, 2) + diagonal);
        RigidInertia { mass: m, first_moment: moment, rotational }
    }

    /// `self` followed by a rotation by `angle` about the unit `axis` of the child frame: the rotation
    /// becomes R Rot(axis, angle). About a coordinate axis this mixes two columns of R.
    #[inline(always)]
    pub fn rotated_about(&self, axis: &Vector3<f64>, angle: f64) -> Transform {
        let r = &self.rotation;
        // Columns j and k of R turned by the angle about the third coordinate axis.
        let mix = |j: usize, k: usize| {
            let (s, c) = angle.sin_cos();
            let (cj, ck) = (r.column(j), r.column(k));
            let mut out = *r;
            out.set_column(j, &(cj * c + ck * s));
            out.set_column(k, &(ck * c - cj * s));
            out
        };
        let rotation = match (axis.x, axis.y, axis.z) {
            (1.0, 0.0, 0.0) => mix(1, 2),
            (0.0, 1.0, 0.0) => mix(2, 0),
            (0.0, 0.0, 1.0) => mix(0, 1),
            _ => r * Transform::rotation_about(axis, angle),
        };
        Transform { rotation, translation: self.translation }
    }

    /// Whether the rotation is exactly the identity (a placement that only translates).
    #[inline(always)]
    pub fn is_translation(&self) -> bool {
        let r = &self.rotation;
        let off_diagonal = [r[(1, 0)], r[(2, 0)], r[(0, 1)], r[(2, 1)], r[(0, 2)], r[(1, 2)]];
        r[(0, 0)] == 1.0 && r[(1, 1)] == 1.0 && r[(2, 2)] == 1.0 && off_diagonal.iter().all(|&x| x == 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn sample_transform() -> Transform {
        Transform::new(Rotation3::from_euler_angles(0.3, -1.2, 2.0).into_inner(), Vector3::new(0.4, -0.7, 1.1))
    }

    /// A rigid inertia off its frame's origin and axes: the identities tested hold for any mass, first moment and
    /// symmetric rotational inertia.
    fn sample_inertia() -> RigidInertia {
        let rotational = Matrix3::new(0.45, -0.04, 0.06, -0.04, 0.3, 0.12, 0.06, 0.12, 0.12);
        RigidInertia { mass: 2.0, first_moment: Vector3::new(0.2, 0.4, -0.6), rotational }
    }

    /// The 6x6 matrix of `v ×` (eq. 2.31), `[ω̂, v̂; 0, ω̂]`; `v ×*` is minus its transpose.
    fn motion_cross_matrix(v: &Motion) -> Matrix6<f64> {
        let (vl, w) = (linear(v).cross_matrix(), angular(v).cross_matrix());
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&w);
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&vl);
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&w);
        m
    }

    /// The 6x6 motion transform written out (eq. 2.24, reordered to [linear; angular]).
    fn motion_matrix(x: &Transform) -> Matrix6<f64> {
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&x.rotation);
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(x.translation.cross_matrix() * x.rotation));
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&x.rotation);
        m
    }

    #[test]
    fn actions_match_their_six_by_six_matrices() {
        let x = sample_transform();
        let xm = motion_matrix(&x);
        let xf = xm.try_inverse().unwrap().transpose();
        let m = Motion::new(0.1, -0.2, 0.3, 0.7, 0.5, -0.4);
        let f = Force::new(-1.0, 2.0, 0.5, 0.3, -0.1, 0.9);
        assert!((x.act_motion(&m) - xm * m).amax() < 1e-14);
        assert!((x.inv_act_motion(&x.act_motion(&m)) - m).amax() < 1e-14);
        assert!((x.act_force(&f) - xf * f).amax() < 1e-14);
        assert!((x.inv_act_force(&x.act_force(&f)) - f).amax() < 1e-14);
        let rigid = sample_inertia();
        let i = rigid.matrix();
        // X* I X⁻¹ (eq. 2.66) is the inertia of the transformed body (checked against `MassProperties::transformed`
        // in mass.rs); act_rigid_inertia gives it.
        let act = |inertia: &Inertia| xf * inertia * xm.try_inverse().unwrap();
        let acted = x.act_rigid_inertia(&rigid);
        assert!((acted.matrix() - act(&i)).amax() < 1e-13);
        let m = Motion::new(0.1, -0.2, 0.3, 0.7, 0.5, -0.4);
        assert!((acted.apply(&m) - act(&i) * m).amax() < 1e-13);
        let mut sum = rigid;
        sum += acted;
        assert!((sum.matrix() - (i + acted.matrix())).amax() < 1e-15);
        // A body whose rotational inertia about the frame origin is diagonal (centred, axis-aligned) takes
        // the diagonal shortcut of `rotate_symmetric`.
        let centred = RigidInertia { mass: 2.0, first_moment: Vector3::zeros(), rotational: Matrix3::from_diagonal(&Vector3::new(0.1, 0.2, 0.3)) };
        assert!((x.act_rigid_inertia(&centred).matrix() - act(&centred.matrix())).amax() < 1e-13);
    }

    #[test]
    fn rate_matrix_is_the_written_out_product() {
        let inertia = sample_transform().act_rigid_inertia(&sample_inertia());
        let v = Motion::new(0.3, 0.1, -0.2, 0.5, -0.6, 0.2);
        let (i, cross) = (inertia.matrix(), motion_cross_matrix(&v));
        // v ×* I − I v× + (I v)×̄, with (h)×̄ m = m ×* h written column by column.
        let h = inertia.apply(&v);
        let h_bar = Matrix6::from_fn(|r, c| cross_force(&Motion::ith(c, 1.0), &h)[r]);
        let expected = -(cross.transpose() * i) - i * cross + h_bar;
        let rate = inertia.rate_matrix(&v);
        assert!((rate.matrix() - expected).amax() < 1e-14);
        let x = Motion::new(-0.4, 0.8, 0.1, 0.2, 0.3, -0.9);
        assert!((rate.apply(&x) - expected * x).amax() < 1e-14);
        assert!((rate.transpose_apply(&x) - expected.transpose() * x).amax() < 1e-14);
    }

    #[test]
    fn rotated_about_composes_with_the_axis_rotation() {
        let x = sample_transform();
        let general = Vector3::new(0.3, -0.4, 0.5).normalize();
        for axis in [Vector3::x(), Vector3::y(), Vector3::z(), -Vector3::y(), general] {
            let expected = x.compose(&Transform::new(Transform::rotation_about(&axis, 0.7), Vector3::zeros()));
            let got = x.rotated_about(&axis, 0.7);
            assert!((got.rotation - expected.rotation).amax() < 1e-15 && got.translation == expected.translation, "{axis:?}");
        }
    }

    #[test]
    fn cross_products_match_their_matrices_and_power_is_invariant() {
        let v = Motion::new(0.3, 0.1, -0.2, 0.5, -0.6, 0.2);
        let m = Motion::new(-0.4, 0.8, 0.1, 0.2, 0.3, -0.9);
        let f = Force::new(1.0, -0.5, 0.25, 0.1, 0.4, -0.3);
        // v ×* = −(v ×)ᵀ, so (v × m)·f + m·(v ×* f) = 0.
        assert!((cross_motion(&v, &m).dot(&f) + m.dot(&cross_force(&v, &f))).abs() < 1e-15);
        assert!(cross_motion(&v, &v).amax() < 1e-15);
        let x = sample_transform();
        assert!((x.act_motion(&m).dot(&x.act_force(&f)) - m.dot(&f)).abs() < 1e-14);
    }
}
