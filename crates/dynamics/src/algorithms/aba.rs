//! Articulated-body algorithm (Featherstone, Table 7.1): O(n) forward dynamics q̈ = M⁻¹(τ − C q̇ − g + Jᵀ f_ext).
//!
//! Worked in the world's axes about the base (`kinematics::base_centred_kinematics`), as Pinocchio's in world
//! coordinates: each body's rigid inertia moves to the world once, in its 10-parameter form, and articulated
//! inertias and bias forces then pass to the parent without a transform.

use nalgebra::{DVector, Matrix3, Matrix6x3, Vector3, Vector6};

use super::checks::{check_forces, check_state, finite_dynamics};
use super::kinematics::base_centred_root;
use super::world_pose;
use crate::joint::Dofs;
use crate::model::check_vector;
use crate::model::{Block6, Data, Model, BLOCK};
use crate::spatial::{
    add_reduced_inertia, cross_force, cross_motion, dot6, inertia_times_pair, spd_inverse6, Force, Inertia, Motion, RigidInertia, Transform,
};
use crate::{Error, Result};

/// Forward dynamics by the articulated-body algorithm [Featherstone 2008, Table 7.1], O(n):
/// q̈ = M⁻¹(τ − C q̇ − g + Jᵀ f_ext).
///
/// Joint accelerations for configuration `q`, velocity `v` and joint forces `tau`, with the model's
/// armature (`Model::armature`); `f_ext` as in `rnea`. Writes `data.ddq` and returns it. In the world's axes about the base's origin (see
/// `kinematics::base_centred_kinematics`), `data.centred_m_i` holds each body's pose, `data.rigid` its rigid
/// inertia, `data.centred_v` its velocity and `data.centred_a` its acceleration with gravity as a base
/// acceleration (§5.3).
///
/// # Examples
///
/// Forward and inverse dynamics undo each other, RNEA(q, q̇, ABA(q, q̇, τ)) = τ, here on a double pendulum (two 1 kg
/// links 0.4 m long, hinged about y; built in the hidden lines). Rotor inertia on the joints (`aba_with_armature`) adds
/// to M's diagonal: (M + diag(armature)) q̈ = τ − RNEA(q, q̇, 0).
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
/// let (q, v, tau) = ([0.3, -0.5], [1.0, 2.0], DVector::from_vec(vec![0.4, -0.1]));
/// let ddq = algorithms::aba(&model, &mut data, &q, &v, tau.as_slice(), None)?.clone();
/// let back = algorithms::rnea(&model, &mut data, &q, &v, ddq.as_slice(), None)?;
/// assert!((back - &tau).amax() < 1e-12);
///
/// let armature = [0.05, 0.02];
/// let ddq = algorithms::aba_with_armature(&model, &mut data, &q, &v, tau.as_slice(), None, &armature)?.clone();
/// let bias = algorithms::rnea(&model, &mut data, &q, &v, &[0.0; 2], None)?.clone();
/// let mass = algorithms::crba(&model, &mut data, &q)?.clone() + DMatrix::from_diagonal(&DVector::from_row_slice(&armature));
/// assert!((mass * ddq - (&tau - bias)).amax() < 1e-12);
/// let error = algorithms::aba_with_armature(&model, &mut data, &q, &v, tau.as_slice(), None, &[-0.05, 0.02]).unwrap_err();
/// assert_eq!(error.to_string(), "armature: element 0 is negative (-0.05)");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn aba<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>) -> Result<&'d DVector<f64>> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_forces(model, f_ext)?;
    aba_unchecked(model, data, q, v, tau, f_ext);
    finite_dynamics(model, data, data.ddq.as_slice())?;
    Ok(&data.ddq)
}

/// [`aba`] without its checks, for the crate's inner loops.
pub(crate) fn aba_unchecked<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>) -> &'d DVector<f64> {
    aba_with_armature_unchecked(model, data, q, v, tau, f_ext, model.armature())
}

/// `aba` for the mass matrix M + diag(armature) (one non-negative entry per velocity coordinate; the
/// free-flyer base's six are ignored) in place of the model's armature: each joint's D = Sᵀ I^A S +
/// armature, as Pinocchio's. The simulation adds the implicit servo and damping terms this way. The
/// joints' `data.u`, `data.d_inv` and the base's articulated inertia `data.inertia[0]` are then the
/// factors of M + diag(armature) = Lᵀ D L (L_ki = D_k⁻¹ U_kᵀ S_i for each ancestor i of k).
pub fn aba_with_armature<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>, armature: &[f64],
) -> Result<&'d DVector<f64>> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_forces(model, f_ext)?;
    check_vector("armature", armature, model.nv())?;
    if let Some(k) = armature.iter().position(|x| *x < 0.0) {
        return Err(Error::invalid("armature", format!("element {k} is negative ({})", armature[k])));
    }
    aba_with_armature_unchecked(model, data, q, v, tau, f_ext, armature);
    finite_dynamics(model, data, data.ddq.as_slice())?;
    Ok(&data.ddq)
}

/// [`aba_with_armature`] without its checks, for the crate's inner loops.
#[inline(always)]
pub(crate) fn aba_with_armature_unchecked<'d>(
    model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], tau: &[f64], f_ext: Option<&[Force]>, armature: &[f64],
) -> &'d DVector<f64> {
    let n = model.nbodies();
    // Pass 1: poses, velocities v_i = v_λ + S q̇, velocity-product accelerations c_i = v_λ × S q̇ and bias
    // forces v_i ×* I_i v_i − f_ext (eq. 7.34–7.36, world frame).
    for i in 0..n {
        let (pose, inertia) = place(model, data, q, i);
        let v_parent = if i == 0 { Motion::zeros() } else { data.centred_v[model.parent(i)] };
        let k = model.idx_v(i);
        let v_joint = match model.joint(i).dofs() {
            Dofs::Free => pose.act_motion(&Motion::from_column_slice(&v[k..k + 6])),
            Dofs::Zero => Motion::zeros(),
            Dofs::One(_) => data.s[i] * v[k],
            Dofs::Ball => ball_subspace(&pose) * Vector3::from_column_slice(&v[k..k + 3]),
        };
        data.centred_v[i] = v_parent + v_joint;
        data.c[i] = cross_motion(&v_parent, &v_joint);
        data.bias[i] = cross_force(&data.centred_v[i], &inertia.apply(&data.centred_v[i]));
        if let Some(f_ext) = f_ext {
            data.bias[i] -= pose.act_force(&f_ext[i]);
        }
    }
    // Pass 2: articulated inertias and bias forces, leaves to root (eq. 7.38–7.44). With w = U / D, the
    // parent gets I^A − U wᵀ and p^A + (I^A − U wᵀ) c + w u.
    for i in (1..n).rev() {
        let (k, p) = (model.idx_v(i), model.parent(i));
        let (s, c) = (data.s[i], data.c[i]);
        let (u, ia_c) = inertia_times_pair(&data.inertia[i], &s, &c);
        let mut pa = data.bias[i] + ia_c;
        let w = if model.joint(i).nv() == 1 {
            // One division per joint, off the accelerations' dependency chain.
            let d_inv = 1.0 / (dot6(&s, u.as_slice()) + armature[k]);
            let u_scalar = tau[k] - dot6(&s, data.bias[i].as_slice());
            let w = u * d_inv;
            pa += w * (u_scalar - dot6(&u, c.as_slice()));
            data.u[i] = u;
            data.d_inv[i] = d_inv;
            data.ddq[k] = u_scalar;
            w
        } else {
            Motion::zeros()
        };
        let (head, tail) = data.inertia.split_at_mut(i);
        if model.joint(i).dofs() == Dofs::Ball {
            // The same with three columns: U = I^A S (6 x 3), D = Sᵀ U + armature (3 x 3).
            let (s3, u3, d_inv) = ball_factors(&data.centred_m_i[i], &tail[0], &armature[k..k + 3]);
            let u_joint = Vector3::from_column_slice(&tau[k..k + 3]) - s3.tr_mul(&data.bias[i]);
            let w3 = u3 * d_inv;
            pa += w3 * (u_joint - u3.tr_mul(&c));
            head[p] += tail[0] - w3 * u3.transpose();
            data.ddq.rows_mut(k, 3).copy_from(&u_joint);
        } else {
            add_reduced_inertia(&mut head[p], &tail[0], &u, &w);
        }
        data.bias[p] += pa;
    }
    // Pass 3: accelerations, root to leaves (eq. 7.45–7.47).
    let gravity = model.gravity_bias();
    for i in 0..n {
        let k = model.idx_v(i);
        let a_prime = if i == 0 { gravity } else { data.centred_a[model.parent(i)] + data.c[i] };
        data.centred_a[i] = match model.joint(i).dofs() {
            Dofs::Free => {
                // The base's joint force, and its acceleration, are spatial vectors in its own frame.
                let pose = data.centred_m_i[i];
                let rhs = pose.act_force(&Force::from_column_slice(&tau[k..k + 6])) - data.bias[i];
                let a = data.inertia[i].cholesky().map(|c| c.solve(&rhs)).unwrap_or_else(|| Motion::repeat(f64::NAN));
                data.ddq.rows_mut(k, 6).copy_from(&pose.inv_act_motion(&(a - a_prime)));
                a
            }
            Dofs::Zero => a_prime,
            Dofs::One(_) => {
                let qdd = (data.ddq[k] - dot6(&data.u[i], a_prime.as_slice())) * data.d_inv[i];
                data.ddq[k] = qdd;
                a_prime + data.s[i] * qdd
            }
            Dofs::Ball => {
                let (s3, u3, d_inv) = ball_factors(&data.centred_m_i[i], &data.inertia[i], &armature[k..k + 3]);
                let qdd = d_inv * (data.ddq.fixed_rows::<3>(k) - u3.tr_mul(&a_prime));
                data.ddq.rows_mut(k, 3).copy_from(&qdd);
                a_prime + s3 * qdd
            }
        };
    }
    &data.ddq
}

/// Body `i`'s pose, one-degree-of-freedom subspace S (zero for other joints) and rigid inertia in the world's axes about
/// the base at `q`, into `data` (its parent placed already), the articulated inertia starting from the rigid one.
#[inline(always)]
fn place(model: &Model, data: &mut Data, q: &[f64], i: usize) -> (Transform, RigidInertia) {
    let pose = place_pose(model, data, q, i);
    let inertia = pose.act_rigid_inertia(model.inertia(i));
    data.rigid[i] = inertia.matrix();
    data.inertia[i] = data.rigid[i];
    (pose, inertia)
}

/// Body `i`'s pose and one-degree-of-freedom subspace S (zero for other joints) at `q`, into `data` (its parent placed).
#[inline(always)]
fn place_pose(model: &Model, data: &mut Data, q: &[f64], i: usize) -> Transform {
    let pose = match i {
        0 => base_centred_root(model, q),
        _ => world_pose(model, i, &data.centred_m_i[model.parent(i)], q),
    };
    data.s[i] = match model.joint(i).dofs() {
        Dofs::One(_) => model.joint(i).subspace_in(&pose),
        _ => Motion::zeros(),
    };
    data.centred_m_i[i] = pose;
    pose
}

/// The poses and subspaces [`aba_with_armature`] leaves in `Data` (the world's axes about the base), at `q` from
/// `reference`'s at a configuration that differs from `q` in the coordinates of body `moved`'s joint alone (None: in
/// none that move a body about the base, which leaves `reference`'s): `moved`'s subtree placed again, O(subtree), or
/// every body for the root. `data` must hold `reference`'s poses but for the bodies in `written`, which are put back
/// first; the bodies placed this time are left there.
pub(crate) fn placement_update_unchecked(
    model: &Model, data: &mut Data, reference: &Data, q: &[f64], moved: Option<usize>, written: &mut Vec<usize>,
) {
    for &i in written.iter() {
        data.centred_m_i[i] = reference.centred_m_i[i];
        data.s[i] = reference.s[i];
    }
    written.clear();
    let Some(moved) = moved else { return };
    // The subtree, parents before children (as the model numbers them).
    for i in moved..model.nbodies() {
        if i == moved || written.binary_search(&model.parent(i)).is_ok() {
            place_pose(model, data, q, i);
            written.push(i);
        }
    }
}

/// The ball joint's S = X [0; I] at `pose` (6 x 3, the centred frame).
#[inline(always)]
pub(crate) fn ball_subspace(pose: &Transform) -> Matrix6x3<f64> {
    let mut s = Matrix6x3::zeros();
    s.fixed_view_mut::<3, 3>(0, 0).copy_from(&(pose.translation.cross_matrix() * pose.rotation));
    s.fixed_view_mut::<3, 3>(3, 0).copy_from(&pose.rotation);
    s
}

/// A ball joint's S, U = I^A S and D⁻¹ = (Sᵀ U + diag(armature))⁻¹ (eq. 7.43 with three columns) at `pose`, from its
/// articulated inertia, which `Data` keeps: recomputed where needed rather than stored per joint. D is not positive
/// definite only for a massless subtree, whose accelerations are then NaN as the one-coordinate joints'.
#[inline(always)]
pub(crate) fn ball_factors(pose: &Transform, inertia: &Inertia, armature: &[f64]) -> (Matrix6x3<f64>, Matrix6x3<f64>, Matrix3<f64>) {
    let s = ball_subspace(pose);
    let u = inertia * s;
    let d = s.tr_mul(&u) + Matrix3::from_diagonal(&Vector3::from_column_slice(armature));
    let d_inv = d.cholesky().map_or_else(|| Matrix3::repeat(f64::NAN), |c| c.inverse());
    (s, u, d_inv)
}

/// The factors of M + diag(armature) that `aba_with_armature` leaves in `Data` (centred frame): each body's pose,
/// articulated inertia, joint subspace, U = I^A S and D⁻¹.
pub(crate) struct Factors<'a> {
    pub poses: &'a [Transform],
    pub inertia: &'a [Inertia],
    pub s: &'a [Motion],
    pub u: &'a [Vector6<f64>],
    pub d_inv: &'a [f64],
}

/// Solves (M + diag(armature)) x = b in place (a ball joint's D from the model's armature, `ball_factors`) for every column b of `columns` (column-major, nv rows each) with
/// `factors`: Table 7.1's passes 2 and 3 with q̇ = 0 and no gravity, O(n) per column, so M⁻¹ B costs O(n nv) for
/// nv columns where a dense product costs O(nv³). Columns go `BLOCK` at a time; `rows` (nv) holds a block row by row
/// and `forces` and `accelerations` (one per body) its bias forces and accelerations.
pub(crate) fn solve_columns(
    model: &Model, factors: &Factors<'_>, columns: &mut [f64], rows: &mut [[f64; BLOCK]], forces: &mut [Block6], accelerations: &mut [Block6],
) {
    let (n, nv) = (model.nbodies(), model.nv());
    if nv == 0 {
        return;
    }
    let base_inverse = match model.joint(0).dofs() {
        Dofs::Free => spd_inverse6(&factors.inertia[0]),
        _ => Inertia::zeros(),
    };
    let count = columns.len() / nv;
    // Each pass leaves every body's bias force zero for the next block.
    forces.fill([[0.0; BLOCK]; 6]);
    for start in (0..count).step_by(BLOCK) {
        let width = BLOCK.min(count - start);
        let block = &mut columns[start * nv..(start + width) * nv];
        for (k, row) in rows.iter_mut().enumerate() {
            *row = std::array::from_fn(|c| if c < width { block[c * nv + k] } else { 0.0 });
        }
        // Pass 2 on the bias forces alone (eq. 7.41–7.44): u = b − Sᵀ p^A, and p^A + U D⁻¹ u to the parent.
        for i in (1..n).rev() {
            let (head, tail) = forces.split_at_mut(i);
            let (to, from) = (&mut head[model.parent(i)], &mut tail[0]);
            if model.joint(i).nv() == 1 {
                let k = model.idx_v(i);
                let (s, w) = (&factors.s[i], factors.u[i] * factors.d_inv[i]);
                let mut u = rows[k];
                for r in 0..6 {
                    for c in 0..BLOCK {
                        u[c] -= s[r] * from[r][c];
                    }
                }
                for r in 0..6 {
                    for c in 0..BLOCK {
                        to[r][c] += from[r][c] + w[r] * u[c];
                    }
                }
                rows[k] = u;
            } else if model.joint(i).dofs() == Dofs::Ball {
                let k = model.idx_v(i);
                let (s3, u3, d_inv) = ball_factors(&factors.poses[i], &factors.inertia[i], &model.armature()[k..k + 3]);
                let w3 = u3 * d_inv;
                for c in 0..BLOCK {
                    let f = Force::from_fn(|r, _| from[r][c]);
                    let u = Vector3::from_fn(|r, _| rows[k + r][c]) - s3.tr_mul(&f);
                    let passed = f + w3 * u;
                    for r in 0..6 {
                        to[r][c] += passed[r];
                    }
                    for r in 0..3 {
                        rows[k + r][c] = u[r];
                    }
                }
            } else {
                for r in 0..6 {
                    for c in 0..BLOCK {
                        to[r][c] += from[r][c];
                    }
                }
            }
            *from = [[0.0; BLOCK]; 6];
        }
        // Pass 3 (eq. 7.45–7.47).
        accelerations[0] = [[0.0; BLOCK]; 6];
        if let Dofs::Free = model.joint(0).dofs() {
            let pose = factors.poses[0];
            for c in 0..BLOCK {
                let rhs = pose.act_force(&Force::from_fn(|r, _| rows[r][c])) - Force::from_fn(|r, _| forces[0][r][c]);
                let acceleration = base_inverse * rhs;
                let ddq = pose.inv_act_motion(&acceleration);
                for r in 0..6 {
                    accelerations[0][r][c] = acceleration[r];
                    rows[r][c] = ddq[r];
                }
            }
        }
        forces[0] = [[0.0; BLOCK]; 6];
        for i in 1..n {
            let (head, tail) = accelerations.split_at_mut(i);
            let (from, to) = (&head[model.parent(i)], &mut tail[0]);
            if model.joint(i).nv() == 1 {
                let k = model.idx_v(i);
                let (s, u, d_inv) = (&factors.s[i], &factors.u[i], factors.d_inv[i]);
                let mut qdd = rows[k];
                for r in 0..6 {
                    for c in 0..BLOCK {
                        qdd[c] -= u[r] * from[r][c];
                    }
                }
                qdd = qdd.map(|x| x * d_inv);
                for r in 0..6 {
                    for c in 0..BLOCK {
                        to[r][c] = from[r][c] + s[r] * qdd[c];
                    }
                }
                rows[k] = qdd;
            } else if model.joint(i).dofs() == Dofs::Ball {
                let k = model.idx_v(i);
                let (s3, u3, d_inv) = ball_factors(&factors.poses[i], &factors.inertia[i], &model.armature()[k..k + 3]);
                for c in 0..BLOCK {
                    let a = Motion::from_fn(|r, _| from[r][c]);
                    let qdd = d_inv * (Vector3::from_fn(|r, _| rows[k + r][c]) - u3.tr_mul(&a));
                    let a = a + s3 * qdd;
                    for r in 0..6 {
                        to[r][c] = a[r];
                    }
                    for r in 0..3 {
                        rows[k + r][c] = qdd[r];
                    }
                }
            } else {
                *to = *from;
            }
        }
        for (k, row) in rows.iter().enumerate() {
            for c in 0..width {
                block[c * nv + k] = row[c];
            }
        }
    }
}
