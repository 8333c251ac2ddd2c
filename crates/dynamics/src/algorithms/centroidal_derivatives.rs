//! Analytic derivatives of the centroidal momentum h = [p; L_G] (`centroidal_momentum`) and of its rate ḣ
//! (`centroidal_momentum_rate`) (Carpentier & Mansard, RSS 2018; Pinocchio's `computeCentroidalDynamicsDerivatives`):
//! ∂h/∂q, ∂ḣ/∂q, ∂ḣ/∂q̇ and ∂ḣ/∂q̈ = ∂h/∂q̇ = A_G, with q on its tangent space as in `rnea_derivatives`. ḣ excludes
//! gravity, as `centroidal_momentum_rate` and Pinocchio do; with it ṗ would gain the constant weight and L̇_G nothing
//! (the weight acts at the COM), so the derivatives would be the same.
//!
//! The RNEA derivatives' forward pass, then one backward pass that sums each subtree's inertia I, rate matrix B,
//! momentum h and force f. A change of joint j's coordinate moves j's subtree rigidly along S_j: its momentum and
//! force turn with it (S_j ×* h, S_j ×* f), and the velocities and accelerations its bodies see change by ∂v/∂q and
//! ∂a/∂q, so that its momentum changes by I ∂v/∂q more and its force by I ∂a/∂q + B ∂v/∂q. A column needs only its
//! own subtree's sums: O(n) for n bodies, and nothing allocated once sized. The columns, about the centred frame's
//! origin O, are then taken about the COM, which moves as well.

use nalgebra::{Matrix6xX, Vector3};

use super::checks::{check_state, finite_result};
use super::rnea_derivatives::{column, forward_pass, set_column};
use crate::model::Dense;
use crate::model::{Data, Model};
use crate::spatial::{angular, cross_force, linear, spatial, Motion};
use crate::Result;

/// ∂h/∂q, ∂ḣ/∂q, ∂ḣ/∂q̇ and ∂ḣ/∂q̈ = A_G (6 x nv each, rows `[linear; angular about the COM]` in world axes) at
/// configuration `q`, velocity `v` and acceleration `a`. Writes the first three to `data.derivatives.dh_dq`,
/// `dhdot_dq` and `dhdot_dv`, A_G to `data.centroidal_map`, and returns them.
///
/// # Examples
///
/// ∂h/∂q and ∂ḣ/∂q̇ of a double pendulum's centroidal momentum (two 1 kg links 0.4 m long, hinged about y; built in the
/// hidden lines) against central differences of `centroidal_momentum` and `centroidal_momentum_rate`; ∂ḣ/∂q̈ is A_G.
///
/// ```
/// # use legkit_dynamics::{algorithms, Data, Joint, JointLimits, MassProperties, Model, Transform};
/// # use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector6};
/// # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, -0.2), &Matrix3::identity())?;
/// # let mut model = Model::new(false, MassProperties::zero(), "base");
/// # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "upper", JointLimits::NONE)?;
/// # let elbow = Transform::from_translation(Vector3::new(0.0, 0.0, -0.4));
/// # model.add_body(1, Joint::Revolute(Vector3::y()), elbow, link, "lower", JointLimits::NONE)?;
/// # let mut data = Data::new(&model);
/// # let nudge = |x: [f64; 2], k: usize, step: f64| { let mut x = x; x[k] += step; x };
/// let (q, v, a, h) = ([0.3, -0.5], [1.0, 2.0], [-3.0, 0.5], 1e-6);
/// let (dh_dq, _, dhdot_dv, dhdot_da) = algorithms::centroidal_derivatives(&model, &mut data, &q, &v, &a)?;
/// let (dh_dq, dhdot_dv, dhdot_da) = (dh_dq.clone(), dhdot_dv.clone(), dhdot_da.clone());
/// assert!((dhdot_da - algorithms::centroidal_map(&model, &mut data, &q)?).amax() < 1e-12);
/// for k in 0..2 {
///     let plus = algorithms::centroidal_momentum(&model, &mut data, &nudge(q, k, h), &v)?;
///     let minus = algorithms::centroidal_momentum(&model, &mut data, &nudge(q, k, -h), &v)?;
///     assert!((dh_dq.column(k) - (plus - minus) / (2.0 * h)).norm() < 1e-8);
///     let plus = algorithms::centroidal_momentum_rate(&model, &mut data, &q, &nudge(v, k, h), &a)?;
///     let minus = algorithms::centroidal_momentum_rate(&model, &mut data, &q, &nudge(v, k, -h), &a)?;
///     assert!((dhdot_dv.column(k) - (plus - minus) / (2.0 * h)).norm() < 1e-8);
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
#[allow(clippy::type_complexity)]
pub fn centroidal_derivatives<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64],
) -> Result<(&'d Matrix6xX<f64>, &'d Matrix6xX<f64>, &'d Matrix6xX<f64>, &'d Matrix6xX<f64>)> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    data.reserve_dense(model, &[Dense::Workspace])?;
    forward_pass(model, data, q, v, a, Motion::zeros());
    let Data { derivatives: d, centroidal_map, .. } = data;
    // Backward pass: each joint's columns about O from its subtree's sums (Pinocchio's dHdq, dFdq, dFdv, dFda).
    for i in (0..model.nbodies()).rev() {
        let (inertia, rate, momentum, force) = (d.composite[i], d.rate[i], d.momentum[i], d.force[i]);
        let k = model.idx_v(i);
        for c in k..k + model.joint(i).nv() {
            let (s, dv_dq) = (column(&d.subspace, c), column(&d.dv_dq, c));
            // ∂h/∂q = S ×* h + I ∂v/∂q: the subtree's momentum turned, and its bodies' velocities changed.
            set_column(&mut d.dh_dq, c, &(cross_force(&s, &momentum) + inertia.apply(&dv_dq)));
            // ∂ḣ/∂q = S ×* f + I ∂a/∂q + B ∂v/∂q (the RNEA derivatives' subtree force, turned).
            let df_dq = cross_force(&s, &force) + inertia.apply(&column(&d.da_dq, c)) + rate.apply(&dv_dq);
            set_column(&mut d.dhdot_dq, c, &df_dq);
            // ∂ḣ/∂q̇ = I ∂a/∂q̇ + B S, and ∂ḣ/∂q̈ = ∂h/∂q̇ = I S (CRBA's column, eq. 6.17's F).
            set_column(&mut d.dhdot_dv, c, &(inertia.apply(&column(&d.da_dv, c)) + rate.apply(&s)));
            set_column(centroidal_map, c, &inertia.apply(&s));
        }
        if i > 0 {
            let p = model.parent(i);
            d.composite[p] += inertia;
            d.rate[p] += rate;
            d.momentum[p] += momentum;
            d.force[p] += force;
        }
    }
    let whole = d.composite[0];
    let (com, per_mass) = if whole.mass > 0.0 { (whole.first_moment / whole.mass, 1.0 / whole.mass) } else { (Vector3::zeros(), 0.0) };
    let (p, p_dot) = (linear(&d.momentum[0]), linear(&d.force[0]));
    // About the COM: L_G = L_O − c × p, so ∂L_G = ∂L_O − c × ∂p + p × ∂c, where ∂c/∂q = A_G's linear rows / m and q̇,
    // q̈ leave the COM in place.
    let zero = Vector3::zeros();
    for c in 0..model.nv() {
        let dc_dq = linear(&column(centroidal_map, c)) * per_mass;
        for (matrix, moving) in [(&mut d.dh_dq, p), (&mut d.dhdot_dq, p_dot), (&mut d.dhdot_dv, zero), (&mut *centroidal_map, zero)] {
            let f = column(matrix, c);
            set_column(matrix, c, &spatial(linear(&f), angular(&f) - com.cross(&linear(&f)) + moving.cross(&dc_dq)));
        }
    }
    let d = &data.derivatives;
    for matrix in [&d.dh_dq, &d.dhdot_dq, &d.dhdot_dv, &data.centroidal_map] {
        finite_result(matrix.as_slice())?;
    }
    Ok((&d.dh_dq, &d.dhdot_dq, &d.dhdot_dv, &data.centroidal_map))
}
