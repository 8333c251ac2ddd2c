//! Joint kinds, each with its coordinates, motion subspace (Featherstone Table 4.1), transform, integration,
//! difference and their Jacobians: the one place that knows what a kind of joint is (as Pinocchio's `JointModel`). The
//! algorithms ask a joint for its [`Dofs`] and never match on its kind, so a new kind of joint is added here.

use nalgebra::{DMatrixViewMut, Quaternion, UnitQuaternion, Vector3};

use crate::explog::{exp6, inverse_adjoint, jexp3, jexp6, jlog3, jlog6, log3, log6};
use crate::spatial::{spatial, Motion, Transform};
use crate::validate::{direction, finite};
use crate::{Error, Result};

/// The joint that moves a body relative to its parent, with its motion subspace from
/// [Featherstone 2008, Table 4.1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Joint {
    /// The base of a floating-base model: 7 configuration and 6 velocity coordinates.
    FreeFlyer,
    /// The base of a fixed-base model, or a rigid attachment: no coordinates.
    Fixed,
    /// Rotation about a unit axis of the joint frame.
    Revolute(Vector3<f64>),
    /// Translation along a unit axis of the joint frame.
    Prismatic(Vector3<f64>),
    /// Rotation by q about a unit axis of the joint frame with translation `pitch` q along it (m/rad).
    Helical {
        /// The unit axis of rotation and translation.
        axis: Vector3<f64>,
        /// Translation per radian (m/rad).
        pitch: f64,
    },
    /// A ball joint: any rotation about the joint frame's origin, a unit quaternion `[qx, qy, qz, qw]` in q (as
    /// the free flyer's) and the angular velocity in the child frame in v (Pinocchio's `JointModelSpherical`).
    Spherical,
}

/// How a joint moves, as the algorithms see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Dofs {
    /// The free-flyer base: velocity `[v; ω]` in its own frame.
    Free,
    /// No motion.
    Zero,
    /// One coordinate along the motion subspace S, in the joint's child frame.
    One(Motion),
    /// The ball joint: angular velocity ω in the child frame, S = [0; I].
    Ball,
}

impl Joint {
    /// Number of configuration coordinates: 7 for the free flyer, 4 for a ball joint (a quaternion).
    #[inline(always)]
    pub fn nq(&self) -> usize {
        match self.dofs() {
            Dofs::Free => 7,
            Dofs::Zero => 0,
            Dofs::One(_) => 1,
            Dofs::Ball => 4,
        }
    }

    /// Number of velocity coordinates (degrees of freedom).
    #[inline(always)]
    pub fn nv(&self) -> usize {
        match self.dofs() {
            Dofs::Free => 6,
            Dofs::Zero => 0,
            Dofs::One(_) => 1,
            Dofs::Ball => 3,
        }
    }

    /// The joint's degrees of freedom; S of a one-degree-of-freedom joint is Table 4.1's.
    #[inline(always)]
    pub(crate) fn dofs(&self) -> Dofs {
        match *self {
            Joint::FreeFlyer => Dofs::Free,
            Joint::Fixed => Dofs::Zero,
            Joint::Revolute(a) => Dofs::One(spatial(Vector3::zeros(), a)),
            Joint::Prismatic(a) => Dofs::One(spatial(a, Vector3::zeros())),
            Joint::Helical { axis, pitch } => Dofs::One(spatial(axis * pitch, axis)),
            Joint::Spherical => Dofs::Ball,
        }
    }

    /// S of a one-degree-of-freedom joint carried from its child frame by `pose` (`pose.act_motion(S)`,
    /// without the products by zero); zero for the other joints, whose motion the algorithms treat apart.
    #[inline(always)]
    pub(crate) fn subspace_in(&self, pose: &Transform) -> Motion {
        match *self {
            Joint::Revolute(a) => {
                let w = pose.rotation * a;
                spatial(pose.translation.cross(&w), w)
            }
            Joint::Prismatic(a) => spatial(pose.rotation * a, Vector3::zeros()),
            Joint::Helical { axis, pitch } => {
                let w = pose.rotation * axis;
                spatial(pose.translation.cross(&w) + w * pitch, w)
            }
            Joint::FreeFlyer | Joint::Fixed | Joint::Spherical => Motion::zeros(),
        }
    }

    /// Column `c` of S carried from the child frame by `pose`, for any joint with more than one: the free flyer's
    /// S is the identity in its own frame, the ball joint's [0; I].
    #[inline(always)]
    pub(crate) fn subspace_column_in(&self, pose: &Transform, c: usize) -> Motion {
        match self.dofs() {
            Dofs::Ball => {
                let w = pose.rotation.column(c).into_owned();
                spatial(pose.translation.cross(&w), w)
            }
            Dofs::Free => pose.act_motion(&Motion::ith(c, 1.0)),
            Dofs::One(_) | Dofs::Zero => self.subspace_in(pose),
        }
    }

    /// `pose` followed by the joint's transform for configuration `q` (its `nq` coordinates).
    #[inline(always)]
    pub(crate) fn after(&self, pose: Transform, q: &[f64]) -> Transform {
        match *self {
            Joint::Revolute(axis) => pose.rotated_about(&axis, q[0]),
            Joint::Prismatic(axis) => Transform::new(pose.rotation, pose.transform_point(&(axis * q[0]))),
            // The translation runs along the axis, which the rotation leaves in place: the two commute.
            Joint::Helical { axis, pitch } => {
                let turned = pose.rotated_about(&axis, q[0]);
                Transform::new(turned.rotation, pose.transform_point(&(axis * (pitch * q[0]))))
            }
            Joint::Fixed => pose,
            Joint::FreeFlyer => pose.compose(&Transform::from_quaternion(position(q), &unit_quaternion(&q[3..]))),
            Joint::Spherical => pose.compose(&Transform::from_quaternion(Vector3::zeros(), &unit_quaternion(q))),
        }
    }

    /// `q ⊕ v dt` on the joint's own coordinates `q` (nq) and velocity `v` (nv), into `out` (nq): the
    /// free-flyer base moves along the screw exp(v dt) in its own frame (Pinocchio's `integrate`), keeping
    /// the quaternion unit, and the ball joint turns by exp(ω dt) in its own frame; the other coordinates add.
    #[inline]
    pub(crate) fn integrate(&self, q: &[f64], v: &[f64], dt: f64, out: &mut [f64]) {
        match self.dofs() {
            Dofs::Free => {
                let rotation = unit_quaternion(&q[3..]);
                let (turn, shift) = exp6(&(Motion::from_column_slice(v) * dt));
                out[..3].copy_from_slice((position(q) + rotation * shift).as_slice());
                write_quaternion(&(rotation * turn), &mut out[3..]);
            }
            Dofs::Ball => {
                let turn = UnitQuaternion::from_scaled_axis(Vector3::from_column_slice(v) * dt);
                write_quaternion(&(unit_quaternion(q) * turn), out);
            }
            Dofs::Zero => {}
            Dofs::One(_) => out[0] = q[0] + v[0] * dt,
        }
    }

    /// `q1 ⊖ q0`: the velocity (nv) that `integrate` takes from `q0` to `q1` in unit time, into `out` (Pinocchio's
    /// `difference`): for the free flyer the SE(3) log of M0⁻¹ M1, in the base's own frame and of angle ≤ π, for the
    /// ball joint the SO(3) log of R0⁻¹ R1; the other coordinates subtract.
    #[inline]
    pub(crate) fn difference(&self, q0: &[f64], q1: &[f64], out: &mut [f64]) {
        match self.dofs() {
            Dofs::Free => {
                let (rotation, translation) = relative_pose(q0, q1);
                out.copy_from_slice(log6(&rotation, &translation).as_slice());
            }
            Dofs::Ball => out.copy_from_slice(log3(&relative_rotation(q0, q1)).as_slice()),
            Dofs::Zero => {}
            Dofs::One(_) => out[0] = q1[0] - q0[0],
        }
    }

    /// ∂(q ⊕ v dt)/∂q and ∂(q ⊕ v dt)/∂v (nv x nv each) on the tangent spaces, into `dq` and `dv` (Pinocchio's
    /// `dIntegrate` at v dt, ARG0 and dt times ARG1): for the free flyer Ad(exp(v dt))⁻¹, which carries a
    /// perturbation of q into the frame of q ⊕ v dt, and dt J_r(v dt); their SO(3) blocks for the ball joint, exp(ω
    /// dt)ᵀ and dt J_r(ω dt); 1 and dt for one coordinate. Neither depends
    /// on q: each joint's configurations form a group, whose ⊕ is its product on the right.
    pub(crate) fn integrate_jacobians(&self, v: &[f64], dt: f64, dq: &mut DMatrixViewMut<'_, f64>, dv: &mut DMatrixViewMut<'_, f64>) {
        match self.dofs() {
            Dofs::Free => {
                let step = Motion::from_column_slice(v) * dt;
                let (turn, shift) = exp6(&step);
                dq.copy_from(&inverse_adjoint(&turn, &shift));
                dv.copy_from(&(jexp6(&step) * dt));
            }
            Dofs::Ball => {
                let step = Vector3::from_column_slice(v) * dt;
                dq.copy_from(&UnitQuaternion::from_scaled_axis(step).to_rotation_matrix().into_inner().transpose());
                dv.copy_from(&(jexp3(&step) * dt));
            }
            Dofs::Zero => {}
            Dofs::One(_) => {
                dq[(0, 0)] = 1.0;
                dv[(0, 0)] = dt;
            }
        }
    }

    /// ∂(q1 ⊖ q0)/∂q0 and ∂(q1 ⊖ q0)/∂q1 (nv x nv each) on the tangent spaces, into `d0` and `d1` (Pinocchio's
    /// `dDifference`, ARG0 and ARG1): for the free flyer −J_r(ξ)⁻¹ Ad(M0⁻¹ M1)⁻¹ and J_r(ξ)⁻¹ at ξ = log(M0⁻¹ M1)
    /// (perturbing M0 by δ perturbs M0⁻¹ M1 by −Ad(M0⁻¹ M1)⁻¹ δ on its right); for the ball joint the SO(3) blocks
    /// −J_r(ω)⁻¹ (R0⁻¹ R1)ᵀ and J_r(ω)⁻¹ at ω = log(R0⁻¹ R1); −1 and 1 for one coordinate.
    pub(crate) fn difference_jacobians(&self, q0: &[f64], q1: &[f64], d0: &mut DMatrixViewMut<'_, f64>, d1: &mut DMatrixViewMut<'_, f64>) {
        match self.dofs() {
            Dofs::Free => {
                let (rotation, translation) = relative_pose(q0, q1);
                let jlog = jlog6(&log6(&rotation, &translation));
                d0.copy_from(&(-jlog * inverse_adjoint(&rotation, &translation)));
                d1.copy_from(&jlog);
            }
            Dofs::Ball => {
                let rotation = relative_rotation(q0, q1);
                let jlog = jlog3(&log3(&rotation));
                d0.copy_from(&(-jlog * rotation.to_rotation_matrix().into_inner().transpose()));
                d1.copy_from(&jlog);
            }
            Dofs::Zero => {}
            Dofs::One(_) => {
                d0[(0, 0)] = -1.0;
                d1[(0, 0)] = 1.0;
            }
        }
    }

    /// The configuration coordinates that are lengths (m): the base's position, a prismatic joint's.
    pub(crate) fn length_coordinates(&self) -> std::ops::Range<usize> {
        match self {
            Joint::FreeFlyer => 0..3,
            Joint::Prismatic(_) => 0..1,
            Joint::Revolute(_) | Joint::Helical { .. } | Joint::Fixed | Joint::Spherical => 0..0,
        }
    }

    /// The coordinates that hold a unit quaternion `[qx, qy, qz, qw]`: the free flyer's and the ball joint's.
    pub fn quaternion_coordinates(&self) -> Option<std::ops::Range<usize>> {
        match self {
            Joint::FreeFlyer => Some(3..7),
            Joint::Spherical => Some(0..4),
            Joint::Revolute(_) | Joint::Prismatic(_) | Joint::Helical { .. } | Joint::Fixed => None,
        }
    }

    /// The kind's name, as the Python API spells it.
    pub fn kind(&self) -> &'static str {
        match self {
            Joint::FreeFlyer => "free_flyer",
            Joint::Fixed => "fixed",
            Joint::Revolute(_) => "revolute",
            Joint::Prismatic(_) => "prismatic",
            Joint::Helical { .. } => "helical",
            Joint::Spherical => "spherical",
        }
    }

    /// The joint's axis (joint frame), if it has one.
    pub fn axis(&self) -> Option<Vector3<f64>> {
        match *self {
            Joint::Revolute(a) | Joint::Prismatic(a) | Joint::Helical { axis: a, .. } => Some(a),
            Joint::FreeFlyer | Joint::Fixed | Joint::Spherical => None,
        }
    }

    /// The joint as a body's joint below the base: its axis normalised; a zero or non-finite axis, a
    /// non-finite pitch or a free flyer are errors.
    pub(crate) fn checked_below_base(self) -> Result<Joint> {
        Ok(match self {
            Joint::Revolute(axis) => Joint::Revolute(direction("axis", axis)?),
            Joint::Prismatic(axis) => Joint::Prismatic(direction("axis", axis)?),
            Joint::Helical { axis, pitch } => Joint::Helical { axis: direction("axis", axis)?, pitch: finite("pitch", pitch)? },
            Joint::Fixed | Joint::Spherical => self,
            Joint::FreeFlyer => return Err(Error::invalid("joint", "a free-flyer joint can only be the base")),
        })
    }
}

/// The orientation stored as `[qx, qy, qz, qw]` from `q[0]` (the free flyer's from `q[3]`).
#[inline(always)]
fn unit_quaternion(q: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]))
}

/// Writes `rotation` as `[qx, qy, qz, qw]` into `out[..4]`.
#[inline(always)]
fn write_quaternion(rotation: &UnitQuaternion<f64>, out: &mut [f64]) {
    out[..4].copy_from_slice(&[rotation.i, rotation.j, rotation.k, rotation.w]);
}

/// The free flyer's position from its coordinates.
#[inline(always)]
fn position(q: &[f64]) -> Vector3<f64> {
    Vector3::from_column_slice(&q[..3])
}

/// M0⁻¹ M1 for the free-flyer configurations `q0` and `q1`, as (rotation, translation).
fn relative_pose(q0: &[f64], q1: &[f64]) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let inverse = unit_quaternion(&q0[3..]).inverse();
    (inverse * unit_quaternion(&q1[3..]), inverse * (position(q1) - position(q0)))
}

/// R0⁻¹ R1 for the ball-joint configurations `q0` and `q1`.
fn relative_rotation(q0: &[f64], q1: &[f64]) -> UnitQuaternion<f64> {
    unit_quaternion(q0).inverse() * unit_quaternion(q1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds() -> [Joint; 6] {
        let axis = Vector3::new(0.3, -0.4, 0.5).normalize();
        [Joint::FreeFlyer, Joint::Fixed, Joint::Revolute(axis), Joint::Prismatic(axis), Joint::Helical { axis, pitch: 0.07 }, Joint::Spherical]
    }

    fn sample_q(joint: &Joint) -> Vec<f64> {
        let r = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.9);
        match joint.dofs() {
            Dofs::Free => vec![0.1, -0.4, 0.25, r.i, r.j, r.k, r.w],
            Dofs::Ball => vec![r.i, r.j, r.k, r.w],
            _ => vec![0.8; joint.nq()],
        }
    }

    /// S = d/dε X_J(q + ε) X_J(q)⁻¹, by central differences, in the child frame (Table 4.1's definition).
    #[test]
    fn subspace_is_the_derivative_of_the_transform() {
        for joint in kinds() {
            let Dofs::One(s) = joint.dofs() else { continue };
            let (q, eps) = (sample_q(&joint), 1e-6);
            let x = joint.after(Transform::identity(), &q);
            let (plus, minus) = (joint.after(Transform::identity(), &[q[0] + eps]), joint.after(Transform::identity(), &[q[0] - eps]));
            // In the child frame: Xᵀ dX.
            let rotation_rate = x.rotation.transpose() * (plus.rotation - minus.rotation) / (2.0 * eps);
            let velocity = x.rotation.transpose() * (plus.translation - minus.translation) / (2.0 * eps);
            let w = Vector3::new(rotation_rate[(2, 1)], rotation_rate[(0, 2)], rotation_rate[(1, 0)]);
            // The child origin's velocity, expressed at that origin (which moves with it).
            let expected = spatial(velocity, w);
            assert!((s - expected).amax() < 1e-8, "{joint:?}: {s:?} vs {expected:?}");
        }
    }

    #[test]
    fn after_composes_and_subspace_in_carries() {
        let pose = Transform::new(Transform::rotation_about(&Vector3::new(1.0, 2.0, 0.5).normalize(), 0.6), Vector3::new(0.2, -0.3, 0.4));
        for joint in kinds() {
            let q = sample_q(&joint);
            let (got, expected) = (joint.after(pose, &q), pose.compose(&joint.after(Transform::identity(), &q)));
            assert!((got.rotation - expected.rotation).amax() < 1e-15 && (got.translation - expected.translation).amax() < 1e-15, "{joint:?}");
            let carried = match joint.dofs() {
                Dofs::One(s) => pose.act_motion(&s),
                Dofs::Free | Dofs::Zero | Dofs::Ball => Motion::zeros(),
            };
            assert!((joint.subspace_in(&pose) - carried).amax() < 1e-15, "{joint:?}");
            if joint == Joint::Spherical {
                for c in 0..3 {
                    let expected = pose.act_motion(&spatial(Vector3::zeros(), Vector3::ith(c, 1.0)));
                    assert!((joint.subspace_column_in(&pose, c) - expected).amax() < 1e-15);
                }
            }
        }
    }

    #[test]
    fn integration_moves_along_the_subspace() {
        for joint in kinds() {
            let q = sample_q(&joint);
            let v = vec![0.3; joint.nv()];
            let mut out = vec![0.0; joint.nq()];
            joint.integrate(&q, &v, 1e-3, &mut out);
            if let Dofs::One(_) = joint.dofs() {
                assert_eq!(out[0], q[0] + 0.3e-3);
            }
            if joint == Joint::FreeFlyer {
                // The twist integrated over dt, in the base frame: translation R V(ω dt) ν dt.
                let turned = unit_quaternion(&out[3..]);
                assert!((turned.norm() - 1.0).abs() < 1e-15);
                let expected = unit_quaternion(&q[3..]) * UnitQuaternion::from_scaled_axis(Vector3::repeat(0.3e-3));
                assert!(turned.angle_to(&expected) < 1e-15);
            }
            if joint == Joint::Spherical {
                // ω in the child frame: R exp(ω dt), and back by the difference.
                let expected = unit_quaternion(&q) * UnitQuaternion::from_scaled_axis(Vector3::repeat(0.3e-3));
                assert!(unit_quaternion(&out).angle_to(&expected) < 1e-15);
                let mut back = [0.0; 3];
                joint.difference(&q, &out, &mut back);
                assert!(back.iter().all(|x| (x - 0.3e-3).abs() < 1e-15), "{back:?}");
            }
        }
    }

    #[test]
    fn below_the_base_axes_are_normalised_and_bad_joints_refused() {
        let helical = Joint::Helical { axis: Vector3::new(0.0, 0.0, 2.0), pitch: 0.1 }.checked_below_base().unwrap();
        assert_eq!(helical, Joint::Helical { axis: Vector3::z(), pitch: 0.1 });
        assert_eq!(Joint::FreeFlyer.checked_below_base().unwrap_err().argument(), "joint");
        assert_eq!(Joint::Revolute(Vector3::zeros()).checked_below_base().unwrap_err().argument(), "axis");
        assert_eq!(Joint::Helical { axis: Vector3::x(), pitch: f64::NAN }.checked_below_base().unwrap_err().argument(), "pitch");
    }
}
