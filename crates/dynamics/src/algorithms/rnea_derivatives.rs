//! Analytic derivatives of inverse dynamics (Carpentier & Mansard, RSS 2018; Pinocchio's
//! `computeRNEADerivatives`): ∂τ/∂q and ∂τ/∂q̇ of τ = RNEA(q, q̇, q̈, f_ext), with q on its tangent space (the free
//! flyer perturbed as q ⊕ δq, δq in its own frame, as `integrate` moves it). ∂τ/∂q̈ is M (`crba`).
//!
//! Worked in the centred frame (`kinematics::base_centred_kinematics`). A change of joint j's coordinate moves j's
//! subtree rigidly about its motion S_j: the subtree's force turns with it (S_j ×* f, which leaves the subtree's own
//! joint torques Sᵀ f unchanged), and the velocities and accelerations it sees change by ∂v/∂q = v_λ × S_j and
//! ∂a/∂q = a_λ × S_j + v_λ × ∂v/∂q. Each body's force then changes by I ∂a + B ∂v (`RigidInertia::rate_matrix`),
//! summed over subtrees as composite I and B. O(n d) for n bodies of depth d; allocates nothing once sized.

use nalgebra::{DMatrix, Matrix6xX, Vector6};

use super::checks::{check_forces, check_output, check_state, finite_result};
use super::kinematics::base_centred_root;
use super::world_pose;
use crate::joint::Dofs;
use crate::model::Dense;
use crate::model::{reserve_square, Data, Model};
use crate::spatial::{cross_force, cross_motion, dot6, Force, Motion};
use crate::Result;

#[inline(always)]
pub(crate) fn column(m: &Matrix6xX<f64>, c: usize) -> Vector6<f64> {
    Vector6::from_column_slice(&m.as_slice()[6 * c..6 * c + 6])
}

#[inline(always)]
pub(crate) fn set_column(m: &mut Matrix6xX<f64>, c: usize, x: &Vector6<f64>) {
    m.as_mut_slice()[6 * c..6 * c + 6].copy_from_slice(x.as_slice());
}

/// ∂τ/∂q and ∂τ/∂q̇ (nv x nv) at configuration `q`, velocity `v` and acceleration `a`, with `f_ext` as in `rnea`
/// (forces fixed in their bodies' frames). Writes `data.derivatives.dtau_dq` and `dtau_dv` and returns them.
///
/// # Examples
///
/// ∂τ/∂q and ∂τ/∂q̇ of a double pendulum (two 1 kg links 0.4 m long, hinged about y; built in the hidden lines) against
/// central differences of `rnea`; `rnea_derivatives_into` writes the same numbers into the caller's slices.
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
/// let (dtau_dq, dtau_dv) = algorithms::rnea_derivatives(&model, &mut data, &q, &v, &a, None)?;
/// let (dtau_dq, dtau_dv) = (dtau_dq.clone(), dtau_dv.clone());
/// for k in 0..2 {
///     let plus = algorithms::rnea(&model, &mut data, &nudge(q, k, h), &v, &a, None)?.clone();
///     let by_q = (plus - algorithms::rnea(&model, &mut data, &nudge(q, k, -h), &v, &a, None)?) / (2.0 * h);
///     let plus = algorithms::rnea(&model, &mut data, &q, &nudge(v, k, h), &a, None)?.clone();
///     let by_v = (plus - algorithms::rnea(&model, &mut data, &q, &nudge(v, k, -h), &a, None)?) / (2.0 * h);
///     assert!((dtau_dq.column(k) - by_q).norm() < 1e-8 && (dtau_dv.column(k) - by_v).norm() < 1e-8);
/// }
/// let (mut into_q, mut into_v) = ([0.0; 4], [0.0; 4]);
/// algorithms::rnea_derivatives_into(&model, &mut data, &q, &v, &a, None, &mut into_q, &mut into_v)?;
/// assert!(into_q == dtau_dq.as_slice() && into_v == dtau_dv.as_slice());
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn rnea_derivatives<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>,
) -> Result<(&'d DMatrix<f64>, &'d DMatrix<f64>)> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    check_forces(model, f_ext)?;
    data.reserve_dense(model, &[Dense::RneaDerivatives])?;
    rnea_derivatives_unchecked(model, data, q, v, a, f_ext);
    let d = &data.derivatives;
    finite_result(d.dtau_dq.as_slice())?;
    finite_result(d.dtau_dv.as_slice())?;
    Ok((&d.dtau_dq, &d.dtau_dv))
}

/// [`rnea_derivatives`] without its checks, for the crate's inner loops.
pub(crate) fn rnea_derivatives_unchecked<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>,
) -> (&'d DMatrix<f64>, &'d DMatrix<f64>) {
    lend_squares(
        model,
        data,
        |d| [&mut d.derivatives.dtau_dq, &mut d.derivatives.dtau_dv],
        |data, [dq, dv]| {
            derivatives_into::<false>(model, data, q, v, a, f_ext, model.gravity_bias(), dq, dv);
        },
    );
    (&data.derivatives.dtau_dq, &data.derivatives.dtau_dv)
}

/// Runs `kernel` on the nv x nv matrices of `data` that `outputs` picks, sized and lent out of `data` as slices (an
/// empty matrix in their place holds no allocation), and puts them back: an `_into` kernel writing `Data`'s own outputs.
pub(crate) fn lend_squares<const N: usize>(
    model: &Model, data: &mut Data, outputs: fn(&mut Data) -> [&mut DMatrix<f64>; N], kernel: impl FnOnce(&mut Data, [&mut [f64]; N]),
) {
    let mut lent = outputs(data).map(|matrix| {
        reserve_square(matrix, model.nv());
        std::mem::replace(matrix, DMatrix::zeros(0, 0))
    });
    kernel(data, lent.each_mut().map(|matrix| matrix.as_mut_slice()));
    for (matrix, output) in outputs(data).into_iter().zip(lent) {
        *matrix = output;
    }
}

/// `rnea_derivatives` into `dtau_dq` and `dtau_dv` (nv x nv each, column-major; every entry written) instead of
/// `Data`, which then holds no nv x nv matrix: O(n) workspace beyond the outputs.
#[allow(clippy::too_many_arguments)]
pub fn rnea_derivatives_into(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>, dtau_dq: &mut [f64], dtau_dv: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    check_forces(model, f_ext)?;
    check_output("dtau_dq", dtau_dq, model.nv() * model.nv())?;
    check_output("dtau_dv", dtau_dv, model.nv() * model.nv())?;
    data.reserve_dense(model, &[Dense::Workspace])?;
    derivatives_into::<false>(model, data, q, v, a, f_ext, model.gravity_bias(), dtau_dq, dtau_dv);
    finite_result(dtau_dq)?;
    finite_result(dtau_dv)
}

/// `rnea_derivatives` with the base accelerating at `base_acceleration` (the model's `gravity_bias`, or zero: the
/// derivatives of M(q) a alone, as an impact's need) into `dtau_dq` and `dtau_dv` (nv x nv each, column-major; every
/// entry written), for the callers that keep them elsewhere (`aba_derivatives_into`, the Python bindings' arrays);
/// with `POSES_KNOWN`, on the poses `aba` just left in `data` at `q`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn derivatives_into<const POSES_KNOWN: bool>(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64], f_ext: Option<&[Force]>, base_acceleration: Motion, dtau_dq: &mut [f64],
    dtau_dv: &mut [f64],
) {
    let n = model.nbodies();
    forward_pass_with::<POSES_KNOWN>(model, data, q, v, a, base_acceleration);
    let Data { centred_m_i: poses, derivatives: d, .. } = data;
    if let Some(f_ext) = f_ext {
        for i in 0..n {
            d.force[i] -= poses[i].act_force(&f_ext[i]);
        }
    }
    // Backward pass: each joint's subtree force derivatives, its rows τ_j = S_jᵀ f over its subtree's columns,
    // and its column in its descendants' rows (Alg. 1, backward pass).
    let nv = model.nv();
    dtau_dq.fill(0.0);
    dtau_dv.fill(0.0);
    for i in (0..n).rev() {
        let k = model.idx_v(i);
        let own = k..k + model.joint(i).nv();
        let (composite, rate) = (d.composite[i], d.rate[i]);
        for c in own.clone() {
            let s = column(&d.subspace, c);
            set_column(&mut d.df_da, c, &composite.apply(&s));
            set_column(&mut d.df_dq, c, &(rate.apply(&column(&d.dv_dq, c)) + composite.apply(&column(&d.da_dq, c))));
            set_column(&mut d.df_dv, c, &(rate.apply(&s) + composite.apply(&column(&d.da_dv, c))));
            set_column(&mut d.rate_subspace, c, &rate.transpose_apply(&s));
        }
        let (df_da, df_dq, df_dv, rate_s) = (d.df_da.as_slice(), d.df_dq.as_slice(), d.df_dv.as_slice(), d.rate_subspace.as_slice());
        for c in own.clone() {
            let (s, dv_dq, da_dq, da_dv) = (column(&d.subspace, c), column(&d.dv_dq, c), column(&d.da_dq, c), column(&d.da_dv, c));
            for columns in model.subtree_columns(i) {
                for col in columns.clone() {
                    let chunk = 6 * col..6 * col + 6;
                    if !own.contains(&col) {
                        // A descendant's torque: only the non-rigid change of its subtree's force counts.
                        dtau_dq[c * nv + col] = dot6(&da_dq, &df_da[chunk.clone()]) + dot6(&dv_dq, &rate_s[chunk.clone()]);
                        dtau_dv[c * nv + col] = dot6(&da_dv, &df_da[chunk.clone()]) + dot6(&s, &rate_s[chunk.clone()]);
                    }
                    dtau_dq[col * nv + c] = dot6(&s, &df_dq[chunk.clone()]);
                    dtau_dv[col * nv + c] = dot6(&s, &df_dv[chunk]);
                }
            }
        }
        let force = d.force[i];
        for c in own {
            let turned = column(&d.df_dq, c) + cross_force(&column(&d.subspace, c), &force);
            set_column(&mut d.df_dq, c, &turned);
        }
        if i > 0 {
            let p = model.parent(i);
            d.composite[p] += composite;
            d.rate[p] += rate;
            d.force[p] += force;
        }
    }
}

/// The forward pass of the derivative algorithms (Carpentier & Mansard, Alg. 1, forward pass; Pinocchio's
/// `computeForwardKinematicsDerivatives`), in the centred frame: each body's pose (`data.centred_m_i`), velocity and
/// acceleration (joint accelerations `a`, None for zero; the base accelerating with `base_acceleration`), and each velocity coordinate's column of S, ∂v/∂q,
/// ∂a/∂q and ∂a/∂q̇ in `data.derivatives` (sized here).
#[inline(always)]
pub(crate) fn motion_derivatives(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>, base_acceleration: Motion) {
    motion_derivatives_with::<false>(model, data, q, v, a, base_acceleration);
}

/// `motion_derivatives`; with `POSES_KNOWN`, the poses `data.centred_m_i` already holds at `q` (left by `aba`) are
/// taken as they are instead of composed again.
#[inline(always)]
fn motion_derivatives_with<const POSES_KNOWN: bool>(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>, base_acceleration: Motion,
) {
    data.derivatives.reserve(model);
    let Data { centred_m_i: poses, derivatives: d, .. } = data;
    for i in 0..model.nbodies() {
        let (pose, v_parent, a_parent) = match i {
            0 => (if POSES_KNOWN { poses[0] } else { base_centred_root(model, q) }, Motion::zeros(), base_acceleration),
            _ => {
                let p = model.parent(i);
                (if POSES_KNOWN { poses[i] } else { world_pose(model, i, &poses[p], q) }, d.velocity[p], d.acceleration[p])
            }
        };
        poses[i] = pose;
        let k = model.idx_v(i);
        let columns = k..k + model.joint(i).nv();
        match model.joint(i).dofs() {
            Dofs::Free | Dofs::Ball => {
                for c in 0..model.joint(i).nv() {
                    set_column(&mut d.subspace, k + c, &model.joint(i).subspace_column_in(&pose, c));
                }
            }
            Dofs::Zero => {}
            Dofs::One(_) => set_column(&mut d.subspace, k, &model.joint(i).subspace_in(&pose)),
        }
        let (mut v_joint, mut a_joint) = (Motion::zeros(), Motion::zeros());
        for c in columns.clone() {
            let s = column(&d.subspace, c);
            v_joint += s * v[c];
            if let Some(a) = a {
                a_joint += s * a[c];
            }
        }
        let velocity = v_parent + v_joint;
        d.velocity[i] = velocity;
        d.acceleration[i] = a_parent + a_joint + cross_motion(&v_parent, &v_joint);
        for c in columns {
            let s = column(&d.subspace, c);
            let dv_dq = cross_motion(&v_parent, &s);
            set_column(&mut d.dv_dq, c, &dv_dq);
            set_column(&mut d.da_dq, c, &(cross_motion(&a_parent, &s) + cross_motion(&v_parent, &dv_dq)));
            set_column(&mut d.da_dv, c, &(cross_motion(&velocity, &s) + dv_dq));
        }
    }
}

/// `motion_derivatives`, then each body's momentum I v and force I a + v ×* I v, its inertia and `rate_matrix` (the
/// backward passes of the RNEA and centroidal derivatives sum them over subtrees; Alg. 1, forward pass, last line).
/// Inlined: out of line, both derivatives took 5% more instructions (callgrind, trees of 64 and 512 bodies).
#[inline(always)]
pub(crate) fn forward_pass(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64], base_acceleration: Motion) {
    forward_pass_with::<false>(model, data, q, v, a, base_acceleration);
}

/// `forward_pass`, the poses known with `POSES_KNOWN` (`motion_derivatives_with`).
#[inline(always)]
fn forward_pass_with<const POSES_KNOWN: bool>(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64], base_acceleration: Motion) {
    motion_derivatives_with::<POSES_KNOWN>(model, data, q, v, Some(a), base_acceleration);
    let Data { centred_m_i: poses, derivatives: d, .. } = data;
    for (i, pose) in poses.iter().enumerate().take(model.nbodies()) {
        let velocity = d.velocity[i];
        let inertia = pose.act_rigid_inertia(model.inertia(i));
        let momentum = inertia.apply(&velocity);
        d.momentum[i] = momentum;
        d.force[i] = inertia.apply(&d.acceleration[i]) + cross_force(&velocity, &momentum);
        d.composite[i] = inertia;
        d.rate[i] = inertia.rate_matrix(&velocity);
    }
}
