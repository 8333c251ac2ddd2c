//! Second derivatives of the centre of mass c(q) and of the centroidal momentum h(q, v) = [p; L_G]
//! (`centroidal_momentum`), weighted: the q-Hessian of w · c and the (q, q), (q, v) Hessians of w · h, q on its
//! tangent space as in `rnea_derivatives`.
//!
//! In the centred frame, with S_e joint e's column and I_e, H_e the inertia and momentum of its subtree (`e` stands
//! for its body): a change of q_d moves the subtree of d's joint rigidly along S_d, so an inertia or momentum of a
//! subtree inside it turns (S_d ×* f - I S_d ×), the columns at and after it turn (∂S_e/∂q_d = S_d × S_e, Carpentier
//! & Mansard, RSS 2018, eq. 7) and the velocity B_e of e's parent changes by S_d × (B_e - B_d). The momentum about
//! the origin h_O = Σ_e I_e S_e v_e has ∂h_O/∂q_e = S_e ×* H_e - I_e (S_e × B_e) (Pinocchio's dhdq), and
//! w · h = Γ · h_O with the motion Γ = [w_lin + c × w_ang; w_ang], whose slope is the COM's. Each entry is then a few
//! cross products of subtree sums: O(nv²) and the depth of the tree.

use nalgebra::Vector3;

use super::checks::{check_output, check_state, finite_result};
use super::kinematic_hessian::is_ancestor;
use super::kinematics::base_centred_kinematics;
use super::rnea_derivatives::{column, set_column};
use crate::model::check_vector;
use crate::model::Dense;
use crate::model::{Data, Model};
use crate::spatial::{cross_force, cross_motion, linear, spatial, Force, Motion, RigidInertia};
use crate::validate::finite_vector;
use crate::Result;

/// Each coordinate's column (`data.derivatives.subspace`), each body's velocity (`velocity`, zero without `v`) and
/// its subtree's inertia (`composite`) and momentum (`momentum`), centred frame; returns the total mass and the COM.
fn subtree_sums(model: &Model, data: &mut Data, q: &[f64], v: Option<&[f64]>) -> (f64, Vector3<f64>) {
    data.derivatives.reserve(model);
    base_centred_kinematics(model, data, q);
    let Data { centred_m_i: poses, derivatives: d, .. } = data;
    let n = model.nbodies();
    for (i, pose) in poses.iter().enumerate().take(n) {
        let mut velocity = if i == 0 { Motion::zeros() } else { d.velocity[model.parent(i)] };
        let k = model.idx_v(i);
        for c in 0..model.joint(i).nv() {
            let s = model.joint(i).subspace_column_in(pose, c);
            set_column(&mut d.subspace, k + c, &s);
            if let Some(v) = v {
                velocity += s * v[k + c];
            }
        }
        d.velocity[i] = velocity;
        let inertia = pose.act_rigid_inertia(model.inertia(i));
        d.composite[i] = inertia;
        d.momentum[i] = inertia.apply(&velocity);
    }
    for i in (1..n).rev() {
        let (inertia, momentum, p) = (d.composite[i], d.momentum[i], model.parent(i));
        d.composite[p] += inertia;
        d.momentum[p] += momentum;
    }
    let whole = d.composite[0];
    (whole.mass, if whole.mass > 0.0 { whole.first_moment / whole.mass } else { Vector3::zeros() })
}

/// Calls `visit(coordinate, body)` for every velocity coordinate, body by body.
fn coordinates(model: &Model, mut visit: impl FnMut(usize, usize)) {
    for i in 0..model.nbodies() {
        let k = model.idx_v(i);
        for c in k..k + model.joint(i).nv() {
            visit(c, i);
        }
    }
}

/// The subtree inertia shared by the bodies that both coordinates move (the later one's, or none off one chain), and
/// whether d's joint is at or before e's.
fn shared(model: &Model, composite: &[RigidInertia], body_d: usize, body_e: usize) -> Option<(RigidInertia, bool)> {
    if is_ancestor(model, body_d, body_e) {
        Some((composite[body_e], true))
    } else if is_ancestor(model, body_e, body_d) {
        Some((composite[body_d], false))
    } else {
        None
    }
}

/// ∂(I_e S_e)/∂q_d, the slope of A_O's column e (I_e the subtree inertia of e's joint): the bodies both move turn, and
/// S_e with them if d's joint is at or before e's.
fn column_slope(model: &Model, composite: &[RigidInertia], s_d: &Motion, s_e: &Motion, body_d: usize, body_e: usize) -> Force {
    match shared(model, composite, body_d, body_e) {
        Some((inertia, true)) => cross_force(s_d, &inertia.apply(s_e)),
        Some((inertia, false)) => cross_force(s_d, &inertia.apply(s_e)) - inertia.apply(&cross_motion(s_d, s_e)),
        None => Force::zeros(),
    }
}

/// Adds `scale` times the q-Hessian of `weights` · c (`[e, d]`, row-major nv x nv) to `out` from `subtree_sums`' columns
/// and inertias, c = Σ_i m_i c_i / m: its gradient's entry e is w · lin(I_e S_e) / m.
fn add_com_hessian(model: &Model, data: &Data, mass: f64, weights: &Vector3<f64>, out: &mut [f64]) {
    let (nv, d) = (model.nv(), &data.derivatives);
    coordinates(model, |e, body_e| {
        let s_e = column(&d.subspace, e);
        coordinates(model, |c, body_c| {
            let slope = column_slope(model, &d.composite, &column(&d.subspace, c), &s_e, body_c, body_e);
            out[e * nv + c] += weights.dot(&linear(&slope)) / mass;
        });
    });
}

/// The q-Hessian `hessian` (nv x nv, row-major, `[e, d]` the slope along q_d of the gradient's entry e) and the
/// gradient `gradient` (nv) of `weights` · the centre of mass (world; zeros for a massless model).
///
/// # Examples
///
/// The q-Hessian of a weighted centre of mass w · c(q), on a double pendulum (two 1 kg links 0.4 m long, hinged about
/// y; built in the hidden lines): the gradient is w · J_c (`center_of_mass_jacobian`), and the Hessian's entries
/// `[e, d]` (row-major) its slopes, checked here against central differences.
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
/// let (q, nv, h, weights) = ([0.3, -0.5], 2, 1e-6, Vector3::new(1.0, -2.0, 0.5));
/// let (mut hessian, mut gradient) = (vec![0.0; nv * nv], vec![0.0; nv]);
/// algorithms::center_of_mass_hessian(&model, &mut data, &q, &weights, &mut hessian, &mut gradient)?;
/// let mut gradient_at = |q: &[f64]| -> legkit_dynamics::Result<_> { Ok(weights.transpose() * algorithms::center_of_mass_jacobian(&model, &mut data, q)?) };
/// assert!((DVector::from_vec(gradient).transpose() - gradient_at(&q)?).norm() < 1e-12);
/// for d in 0..nv {
///     let slope = (gradient_at(&nudge(q, d, h))? - gradient_at(&nudge(q, d, -h))?) / (2.0 * h);
///     (0..nv).for_each(|e| assert!((hessian[e * nv + d] - slope[e]).abs() < 1e-8));
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn center_of_mass_hessian(
    model: &Model, data: &mut Data, q: &[f64], weights: &Vector3<f64>, hessian: &mut [f64], gradient: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[])?;
    finite_vector("weights", *weights)?;
    check_output("hessian", hessian, model.nv() * model.nv())?;
    check_output("gradient", gradient, model.nv())?;
    data.reserve_dense(model, &[Dense::Workspace])?;
    let (mass, _) = subtree_sums(model, data, q, None);
    hessian.fill(0.0);
    gradient.fill(0.0);
    if mass <= 0.0 {
        return Ok(());
    }
    let d = &data.derivatives;
    coordinates(model, |e, body_e| gradient[e] = weights.dot(&linear(&d.composite[body_e].apply(&column(&d.subspace, e)))) / mass);
    add_com_hessian(model, data, mass, weights, hessian);
    finite_result(hessian)?;
    finite_result(gradient)
}

/// The Hessians `qq` (`[e, d]` the slope along q_d of the q-gradient's entry e) and `qv` (`[d, e]` = ∂²/∂q_d ∂v_e),
/// nv x nv row-major, and the q-gradient `gradient` (nv) of `weights` · h(q, v), h the centroidal momentum
/// [linear; angular about the COM] (`centroidal_momentum`); linear in v, so vv is zero.
///
/// # Examples
///
/// A weighted centroidal momentum w · h(q, q̇) is linear in q̇, w · A_G(q) q̇: its mixed Hessian `qv` (`[d, e]`,
/// ∂²/∂q_d ∂q̇_e) is the q-slope of w · A_G, and its q-gradient that slope times q̇.
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
/// let (q, v, nv, h) = ([0.3, -0.5], [1.0, 2.0], 2, 1e-6);
/// let weights = [1.0, -2.0, 0.5, 0.3, 0.2, -1.0];
/// let (mut qq, mut qv, mut gradient) = (vec![0.0; nv * nv], vec![0.0; nv * nv], vec![0.0; nv]);
/// algorithms::centroidal_momentum_hessian(&model, &mut data, &q, &v, &weights, &mut qq, &mut qv, &mut gradient)?;
/// let w = Vector6::from_row_slice(&weights);
/// let mut weighted_map = |q: &[f64]| -> legkit_dynamics::Result<_> { Ok(w.transpose() * algorithms::centroidal_map(&model, &mut data, q)?) };
/// for d in 0..nv {
///     let slope = (weighted_map(&nudge(q, d, h))? - weighted_map(&nudge(q, d, -h))?) / (2.0 * h);
///     (0..nv).for_each(|e| assert!((qv[d * nv + e] - slope[e]).abs() < 1e-8));
///     assert!((gradient[d] - (slope * DVector::from_row_slice(&v))[0]).abs() < 1e-8);
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn centroidal_momentum_hessian(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], weights: &[f64; 6], qq: &mut [f64], qv: &mut [f64], gradient: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[("v", v)])?;
    check_vector("weights", weights, 6)?;
    let nv = model.nv();
    check_output("qq", qq, nv * nv)?;
    check_output("qv", qv, nv * nv)?;
    check_output("gradient", gradient, nv)?;
    data.reserve_dense(model, &[Dense::Workspace])?;
    let (mass, com) = subtree_sums(model, data, q, Some(v));
    qq.fill(0.0);
    qv.fill(0.0);
    gradient.fill(0.0);
    if mass <= 0.0 {
        return Ok(());
    }
    let (w_lin, w_ang) = (Vector3::new(weights[0], weights[1], weights[2]), Vector3::new(weights[3], weights[4], weights[5]));
    let gamma = spatial(w_lin + com.cross(&w_ang), w_ang);
    let momentum = linear(&data.derivatives.momentum[0]);
    // Γ's slope along q_e is [J_c,e × w_ang; 0]: its share of the curvature is the COM's, weighted by w_ang × p.
    add_com_hessian(model, data, mass, &w_ang.cross(&momentum), qq);
    let Data { derivatives: d, com_jacobian, .. } = data;
    let parent_velocity = |body: usize| if body == 0 { Motion::zeros() } else { d.velocity[model.parent(body)] };
    // Per coordinate e: ∂h_O/∂q_e = S_e ×* H_e - I_e (S_e × B_e), the COM's column J_c,e and the gradient.
    coordinates(model, |e, body_e| {
        let s_e = column(&d.subspace, e);
        let slope = cross_force(&s_e, &d.momentum[body_e]) - d.composite[body_e].apply(&cross_motion(&s_e, &parent_velocity(body_e)));
        let com_e = linear(&d.composite[body_e].apply(&s_e)) / mass;
        set_column(&mut d.origin_momentum_dq, e, &slope);
        com_jacobian.set_column(e, &com_e);
        gradient[e] = com_e.cross(&w_ang).dot(&momentum) + gamma.dot(&slope);
    });
    coordinates(model, |e, body_e| {
        let (s_e, before_e) = (column(&d.subspace, e), parent_velocity(body_e));
        let (slope_e, com_e) = (column(&d.origin_momentum_dq, e), com_jacobian.column(e).into_owned());
        let momentum_e = linear(&d.composite[body_e].apply(&s_e)); // ∂p/∂v_e
        coordinates(model, |c, body_c| {
            let s_c = column(&d.subspace, c);
            let com_c = com_jacobian.column(c).into_owned();
            qv[c * nv + e] = com_c.cross(&w_ang).dot(&momentum_e) + gamma.dot(&column_slope(model, &d.composite, &s_c, &s_e, body_c, body_e));
            // ∂²h_O/∂q_e ∂q_c: the slope along q_c of S_e ×* H_e - I_e (S_e × B_e).
            let mut second = Force::zeros();
            if let Some((inertia, c_before_e)) = shared(model, &d.composite, body_c, body_e) {
                let later = if c_before_e { body_e } else { body_c };
                let before_c = parent_velocity(body_c);
                let turned_momentum = cross_force(&s_c, &d.momentum[later]) - inertia.apply(&cross_motion(&s_c, &before_c));
                let relative = cross_motion(&s_e, &before_e);
                second += cross_force(&s_e, &turned_momentum) - cross_force(&s_c, &inertia.apply(&relative))
                    + inertia.apply(&cross_motion(&s_c, &relative));
                if c_before_e {
                    let ds = cross_motion(&s_c, &s_e);
                    second += cross_force(&ds, &d.momentum[body_e]) - d.composite[body_e].apply(&cross_motion(&ds, &before_e));
                    if body_c != body_e {
                        let d_before = cross_motion(&s_c, &(before_e - before_c));
                        second -= d.composite[body_e].apply(&cross_motion(&s_e, &d_before));
                    }
                }
            }
            qq[e * nv + c] +=
                com_e.cross(&w_ang).dot(&linear(&column(&d.origin_momentum_dq, c))) + com_c.cross(&w_ang).dot(&linear(&slope_e)) + gamma.dot(&second);
        });
    });
    finite_result(qq)?;
    finite_result(qv)?;
    finite_result(gradient)
}
