//! The exponential and logarithm of SO(3) and SE(3) and their Jacobians: the free flyer's Lie group (Pinocchio's
//! `spatial/explog`). Twists are `[ρ; ω]`, linear first, as motions; the Jacobians are right Jacobians, as Pinocchio
//! differentiates: exp(ξ + δ) ≈ exp(ξ) exp(J_r(ξ) δ) and log(M exp(δ)) ≈ log(M) + J_r(log M)⁻¹ δ.
//!
//! Formulas from Solà, Deray & Atchuthan, "A micro Lie theory for state estimation in robotics" (arXiv:1812.01537,
//! 2018; [Solà]), its SO(3) Jacobians (eq. 143 and the closed forms beside it) and App. D for SE(3), and Barfoot &
//! Furgale, "Associating uncertainty with three-dimensional poses" (T-RO 2014; [Barfoot]), eq. 102, for the coupling
//! block Q of the SE(3) Jacobians.
//!
//! Every coefficient below is a trigonometric expression over a power of the angle θ whose closed form cancels as θ
//! goes to 0 (by up to ε/θ⁴ for d in `coupling`, whose term is O(θ³)); below `SERIES_BELOW` its Taylor series to θ⁶
//! replaces it. At the switch the truncation below and the cancellation above each cost the Jacobians a few ulps
//! (tested). Only J_r(ω)⁻¹ divides by a trigonometric function, as cot(θ/2): finite on the logarithm's range θ ≤ π,
//! 0 at π.

use nalgebra::{Matrix3, Matrix6, UnitQuaternion, Vector3};

use crate::spatial::{angular, linear, spatial, Motion};

/// The angle (rad) below which the coefficients are their Taylor series.
const SERIES_BELOW: f64 = 0.1;

/// c₀ + c₁ θ² + c₂ θ⁴ + c₃ θ⁶.
#[inline(always)]
fn series(theta2: f64, c: [f64; 4]) -> f64 {
    c[0] + theta2 * (c[1] + theta2 * (c[2] + theta2 * c[3]))
}

/// versin θ = 1 − cos θ, as 2 sin²(θ/2): without the cancellation of 1 − cos θ at small θ.
#[inline(always)]
fn versine(theta: f64) -> f64 {
    2.0 * (0.5 * theta).sin().powi(2)
}

/// (1 − cos θ)/θ² and (θ − sin θ)/θ³, the coefficients of ω̂ and ω̂² in the SO(3) Jacobians.
#[inline(always)]
fn rodrigues_coefficients(theta2: f64) -> (f64, f64) {
    if theta2 < SERIES_BELOW * SERIES_BELOW {
        (
            series(theta2, [1.0 / 2.0, -1.0 / 24.0, 1.0 / 720.0, -1.0 / 40320.0]),
            series(theta2, [1.0 / 6.0, -1.0 / 120.0, 1.0 / 5040.0, -1.0 / 362880.0]),
        )
    } else {
        let theta = theta2.sqrt();
        (versine(theta) / theta2, (theta - theta.sin()) / (theta2 * theta))
    }
}

/// 1/θ² − cot(θ/2)/(2θ), the coefficient of ω̂² in J_r(ω)⁻¹ (Pinocchio's `Jlog3`, whose `alpha` it is).
#[inline(always)]
fn inverse_coefficient(theta2: f64) -> f64 {
    if theta2 < SERIES_BELOW * SERIES_BELOW {
        series(theta2, [1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0])
    } else {
        let theta = theta2.sqrt();
        1.0 / theta2 - 1.0 / (2.0 * theta * (0.5 * theta).tan())
    }
}

/// The SO(3) left Jacobian V(ω) = 1 + (1 − cos θ)/θ² ω̂ + (θ − sin θ)/θ³ ω̂² [Solà, beside eq. 143]: exp of the twist
/// (ρ, ω) translates by V ρ. The right Jacobian is J_r(ω) = V(−ω) = V(ω)ᵀ [eq. 143].
fn left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let (a, b) = rodrigues_coefficients(w.norm_squared());
    let k = w.cross_matrix();
    Matrix3::identity() + k * a + k * k * b
}

/// J_r(ω)⁻¹ = 1 + ½ ω̂ + (1/θ² − cot(θ/2)/(2θ)) ω̂² [Solà, beside eq. 143]; V(ω)⁻¹ is this at −ω.
fn right_jacobian_inverse(w: &Vector3<f64>) -> Matrix3<f64> {
    let k = w.cross_matrix();
    Matrix3::identity() + k * 0.5 + k * k * inverse_coefficient(w.norm_squared())
}

/// Q(ρ, φ) [Barfoot, eq. 102], the coupling block of the SE(3) left Jacobian [[V(φ), Q], [0, V(φ)]]:
/// Q = ½ ρ̂ + b (φ̂ρ̂ + ρ̂φ̂ + φ̂ρ̂φ̂) + c (φ̂²ρ̂ + ρ̂φ̂² − 3 φ̂ρ̂φ̂) + d (φ̂ρ̂φ̂² + φ̂²ρ̂φ̂), with b = (θ − sin θ)/θ³,
/// c = (θ² + 2 cos θ − 2)/(2θ⁴) (as θ² − 2 versin θ, which cancels less) and d = (2θ − 3 sin θ + θ cos θ)/(2θ⁵)
/// [Solà, App. D].
fn coupling(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let (_, b) = rodrigues_coefficients(theta2);
    let (c, d) = if theta2 < SERIES_BELOW * SERIES_BELOW {
        (
            series(theta2, [1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0]),
            series(theta2, [1.0 / 120.0, -1.0 / 2520.0, 1.0 / 120960.0, -1.0 / 9979200.0]),
        )
    } else {
        let theta = theta2.sqrt();
        let (sin, cos) = theta.sin_cos();
        ((theta2 - 2.0 * versine(theta)) / (2.0 * theta2 * theta2), (2.0 * theta - 3.0 * sin + theta * cos) / (2.0 * theta2 * theta2 * theta))
    };
    let (r, f) = (rho.cross_matrix(), phi.cross_matrix());
    let (fr, rf) = (f * r, r * f);
    let frf = fr * f;
    r * 0.5 + (fr + rf + frf) * b + (f * fr + rf * f - frf * 3.0) * c + (frf * f + f * frf) * d
}

/// [[A, B], [0, A]], the shape of every SE(3) Jacobian here.
fn upper_block_triangular(diagonal: &Matrix3<f64>, corner: &Matrix3<f64>) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(diagonal);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(corner);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(diagonal);
    m
}

/// exp of the twist ξ = [ρ; ω]: the rigid transform (exp(ω), V(ω) ρ) [Solà, App. D], as (rotation, translation).
pub(crate) fn exp6(xi: &Motion) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let w = angular(xi);
    (UnitQuaternion::from_scaled_axis(w), left_jacobian(&w) * linear(xi))
}

/// log of a unit quaternion: the rotation vector of angle θ ∈ [0, π], the quaternion taken with w ≥ 0
/// (Pinocchio's `quaternion::log3`): 2 atan2(|u|, w) u/|u| for its vector part u. atan2(|u|, w)/|u| is well
/// conditioned down to |u| = 0, where it tends to 1/w; only 0/0 needs the series.
pub(crate) fn log3(r: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (u, w) = if r.w < 0.0 { (-r.imag(), -r.w) } else { (r.imag(), r.w) };
    let n2 = u.norm_squared();
    let scale = if n2 < f64::EPSILON {
        2.0 / w * (1.0 - n2 / (3.0 * w * w))
    } else {
        let n = n2.sqrt();
        2.0 * n.atan2(w) / n
    };
    u * scale
}

/// The right Jacobian of exp on SO(3), J_r(ω) = V(−ω) (Pinocchio's `Jexp3`): the ball joint's.
pub(crate) fn jexp3(w: &Vector3<f64>) -> Matrix3<f64> {
    left_jacobian(&-w)
}

/// J_r(ω)⁻¹ at the log ω of a rotation R: Pinocchio's `Jlog3(R)`, log(R exp(δ)) ≈ ω + J_r(ω)⁻¹ δ.
pub(crate) fn jlog3(w: &Vector3<f64>) -> Matrix3<f64> {
    right_jacobian_inverse(w)
}

/// log of the rigid transform (r, p): the twist [V(ω)⁻¹ p; ω], ω = log3(r) [Solà, App. D] (Pinocchio's `log6`).
pub(crate) fn log6(r: &UnitQuaternion<f64>, p: &Vector3<f64>) -> Motion {
    let w = log3(r);
    spatial(right_jacobian_inverse(&-w) * p, w)
}

/// The right Jacobian of exp on SE(3), J_r(ξ) = J_l(−ξ) = [[J_r(ω), Q(−ρ, −ω)], [0, J_r(ω)]] [Solà, App. D]
/// (Pinocchio's `Jexp6`). Finite at every angle.
pub(crate) fn jexp6(xi: &Motion) -> Matrix6<f64> {
    let (rho, w) = (linear(xi), angular(xi));
    upper_block_triangular(&left_jacobian(&-w), &coupling(&-rho, &-w))
}

/// J_r(ξ)⁻¹ = [[J_r(ω)⁻¹, −J_r(ω)⁻¹ Q(−ρ, −ω) J_r(ω)⁻¹], [0, J_r(ω)⁻¹]] [Solà, App. D, inverted blockwise] at the
/// log ξ of a transform M: Pinocchio's `Jlog6(M)`, log(M exp(δ)) ≈ ξ + J_r(ξ)⁻¹ δ.
pub(crate) fn jlog6(xi: &Motion) -> Matrix6<f64> {
    let (rho, w) = (linear(xi), angular(xi));
    let inverse = right_jacobian_inverse(&w);
    upper_block_triangular(&inverse, &(-inverse * coupling(&-rho, &-w) * inverse))
}

/// The motion transform of (r, p)⁻¹, [[Rᵀ, −Rᵀ p̂], [0, Rᵀ]]: a twist of (r, p)'s parent frame in its own
/// (Pinocchio's `toActionMatrixInverse`).
pub(crate) fn inverse_adjoint(r: &UnitQuaternion<f64>, p: &Vector3<f64>) -> Matrix6<f64> {
    let rt = r.to_rotation_matrix().into_inner().transpose();
    upper_block_triangular(&rt, &(-rt * p.cross_matrix()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;

    /// The series and the closed forms meet at `SERIES_BELOW` to a few ulps in every Jacobian block: neither the
    /// truncation below nor the cancellation above shows.
    #[test]
    fn series_and_closed_forms_agree_at_the_switch() {
        let (rho, axis) = (Vector3::new(0.3, -1.2, 0.7), Vector3::new(1.0, 2.0, -2.0) / 3.0);
        let (below, above) = (axis * SERIES_BELOW * (1.0 - 1e-15), axis * SERIES_BELOW * (1.0 + 1e-15));
        assert!(below.norm_squared() < SERIES_BELOW.powi(2) && above.norm_squared() >= SERIES_BELOW.powi(2));
        assert!((left_jacobian(&below) - left_jacobian(&above)).amax() < 1e-15);
        assert!((right_jacobian_inverse(&below) - right_jacobian_inverse(&above)).amax() < 1e-15);
        assert!((coupling(&rho, &below) - coupling(&rho, &above)).amax() < 2e-15);
    }

    #[test]
    fn log_inverts_exp_and_jlog_inverts_jexp() {
        for xi in [Vector6::new(0.3, -0.2, 0.5, 0.4, -1.1, 0.8), Vector6::new(0.3, -0.2, 0.5, 1e-9, 0.0, -2e-9), Vector6::zeros()] {
            let (r, p) = exp6(&xi);
            assert!((log6(&r, &p) - xi).amax() < 1e-15, "{xi}");
            assert!((jlog6(&xi) * jexp6(&xi) - Matrix6::identity()).amax() < 1e-15, "{xi}");
        }
    }
}
