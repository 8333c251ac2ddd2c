//! Analytic derivatives of the contact dynamics and of impacts (`contact::contact_dynamics`, `contact::impact`;
//! Pinocchio's `computeConstraintDynamicsDerivatives` and `computeImpulseDynamicsDerivatives` for CONTACT_3D or
//! CONTACT_6D contacts in `LOCAL_WORLD_ALIGNED`), q on its tangent space.
//!
//! Both solve a KKT system [M −Jᵀ; J 0] [x; λ] = [a; b]. Differentiating its rows at the solution gives the same
//! system for the derivatives, with the rows' own partial derivatives as right-hand sides: those of inverse dynamics
//! (`rnea_derivatives` with the contact forces as external forces) and of the contacts' accelerations or velocities
//! (`kinematics_derivatives`). The solve reuses the KKT inverse's blocks of the forward solution (`contact::factor`),
//! whose q̈-by-τ block is ∂q̈/∂τ itself, as Pinocchio does. The contact forces are fixed in world axes, not in their
//! bodies, so a joint that turns a body also turns its forces against it: ∂τ/∂q gains −J_pᵀ [f]× J_ω (and −J_ωᵀ [n]×
//! J_ω for a torque n). The derivatives exist where the contacts are independent (J of full row rank); redundant
//! contacts are refused.
//!
//! Dense O(nv³ + r³) linear algebra for r constraint rows, in `ContactWorkspace` (`Data::contact`): nothing is
//! allocated once it is sized, apart from the outputs of the owning variants.

use nalgebra::{DMatrix, DVector, Vector3};

use super::checks::{check_output, check_state, finite_result};
use super::contact::{check_contacts, contact_solution, gemm, impact_solution, plain, with_workspace, ContactDim, ContactPoint};
use super::jacobian::Frame;
use super::kinematics_derivatives::{for_each_frame_derivative, FramePoint};
use super::rnea_derivatives::{column, derivatives_into, motion_derivatives};
use crate::model::{ContactWorkspace, Data, Model};
use crate::spatial::{angular, linear, spatial, Force, Motion};
use crate::{Error, Result};

/// `contact_dynamics`' solution and its derivatives (q on its tangent space; forces r = 3 or 6 per contact, world axes).
#[derive(Debug, Clone, PartialEq)]
pub struct ContactDynamicsDerivatives {
    /// q̈ (nv), as `contact_dynamics` gives it.
    pub ddq: DVector<f64>,
    /// The contact forces (r), as `contact_dynamics` gives them.
    pub forces: DVector<f64>,
    /// nv x nv each.
    pub ddq_dq: DMatrix<f64>,
    /// ∂q̈/∂q̇.
    pub ddq_dv: DMatrix<f64>,
    /// ∂q̈/∂τ.
    pub ddq_dtau: DMatrix<f64>,
    /// r x nv each.
    pub forces_dq: DMatrix<f64>,
    /// ∂λ/∂q̇.
    pub forces_dv: DMatrix<f64>,
    /// ∂λ/∂τ.
    pub forces_dtau: DMatrix<f64>,
}

/// `impact`'s solution and its derivatives with respect to q (tangent space) and the velocity before the impact.
#[derive(Debug, Clone, PartialEq)]
pub struct ImpactDerivatives {
    /// The velocity after the impact (nv), as `impact` gives it.
    pub velocity: DVector<f64>,
    /// The contact impulses (r), as `impact` gives them.
    pub impulses: DVector<f64>,
    /// nv x nv each.
    pub velocity_dq: DMatrix<f64>,
    /// ∂v⁺/∂v⁻.
    pub velocity_dv: DMatrix<f64>,
    /// r x nv each.
    pub impulses_dq: DMatrix<f64>,
    /// ∂Λ/∂v⁻.
    pub impulses_dv: DMatrix<f64>,
}

/// Dependent contacts (`factor` found constraint row `row` to depend on the rows before it): the caller's constraint
/// set is redundant, so its forces are not unique (`contact_dynamics` and `impact` take the minimum-norm ones; their
/// derivatives do not exist). Names the contact and the matrix, so that the caller knows which contact to drop.
fn dependent(contacts: &[ContactPoint], dim: ContactDim, row: usize) -> Error {
    let (k, d) = (row / dim.rows(), dim.rows());
    Error::invalid(
        "contacts",
        format!(
            "the contacts are not independent: row {} of {d} of contact {k} (body {}) depends on the rows before it (the contact \
             Gram matrix J M⁻¹ Jᵀ is singular there: a repeated contact, or one on a body that cannot move that way), so the \
             forces, and their derivatives, are not unique",
            row % d + 1,
            contacts[k].body
        ),
    )
}

/// The contact forces `w.forces` (world axes, at the points) as forces on their bodies fixed in the bodies' frames
/// (`rnea`'s f_ext) into `w.body_forces`, from the poses `motion_derivatives` leaves.
fn body_forces(data: &Data, w: &mut ContactWorkspace, contacts: &[ContactPoint], dim: ContactDim) {
    w.body_forces.fill(Force::zeros());
    for (contact, wrench) in contacts.iter().zip(w.forces.chunks_exact(dim.rows())) {
        let rotation = &data.centred_m_i[contact.body].rotation;
        let f = rotation.tr_mul(&Vector3::from_column_slice(&wrench[..3]));
        let n = if dim == ContactDim::Frame { rotation.tr_mul(&Vector3::from_column_slice(&wrench[3..])) } else { Vector3::zeros() };
        w.body_forces[contact.body] += spatial(f, contact.point.cross(&f) + n);
    }
}

/// ∂τ/∂q (`dtau_dq`, nv x nv column-major) of `rnea_derivatives`, whose external forces turn with their bodies, for
/// the same forces fixed in world axes instead: less J_pᵀ [f]× J_ω + J_ωᵀ [n]× J_ω per contact (a turn ω of the body
/// turns a body-fixed force f by ω × f), over the contact's support, after `motion_derivatives` at q.
fn hold_forces_in_world_axes(model: &Model, data: &Data, q: &[f64], contacts: &[ContactPoint], dim: ContactDim, forces: &[f64], dtau_dq: &mut [f64]) {
    let (nv, subspace) = (model.nv(), &data.derivatives.subspace);
    for (contact, wrench) in contacts.iter().zip(forces.chunks_exact(dim.rows())) {
        let f = Vector3::from_column_slice(&wrench[..3]);
        let n = if dim == ContactDim::Frame { Vector3::from_column_slice(&wrench[3..]) } else { Vector3::zeros() };
        let at = FramePoint::new(model, data, q, contact.body, &contact.point);
        at.support(model, |c, _| {
            let turn = angular(&column(subspace, c));
            let (change_f, change_n) = (f.cross(&turn), n.cross(&turn));
            at.support(model, |r, _| {
                let s = at.jacobian_column(subspace, r);
                dtau_dq[r + nv * c] -= linear(&s).dot(&change_f) + angular(&s).dot(&change_n);
            });
        });
    }
}

/// Rows of the contacts' accelerations (the points' classical accelerations a + ω × v, or with `ContactDim::Frame` the
/// frames' spatial accelerations; world axes) differentiated with respect to q and q̇, into `rows` (r x 2nv
/// column-major: q's columns, then q̇'s), after `motion_derivatives` at the state (gravity in the base's acceleration
/// adds a constant and changes nothing).
fn acceleration_rows(model: &Model, data: &Data, q: &[f64], contacts: &[ContactPoint], dim: ContactDim, rows: &mut [f64]) {
    let (d, r, nv) = (dim.rows(), dim.rows() * contacts.len(), model.nv());
    rows.fill(0.0);
    for (k, contact) in contacts.iter().enumerate() {
        let at = FramePoint::new(model, data, q, contact.body, &contact.point);
        let (velocity, omega) = (linear(&at.velocity), angular(&at.velocity));
        for_each_frame_derivative(model, data, &at, Frame::LocalWorldAligned, |c, x| {
            let (dq, dv) = (c * r + d * k, (nv + c) * r + d * k);
            if dim == ContactDim::Frame {
                // The frame's spatial acceleration (`contact::contact_acceleration`).
                rows[dq..dq + 6].copy_from_slice(x.acceleration_dq.as_slice());
                rows[dv..dv + 6].copy_from_slice(x.acceleration_dv.as_slice());
            } else {
                // ∂(a + ω × v) = ∂a + ∂ω × v + ω × ∂v, with ∂/∂q̇ of (v, ω) the Jacobian's columns.
                let along_q = linear(&x.acceleration_dq) + angular(&x.velocity_dq).cross(&velocity) + omega.cross(&linear(&x.velocity_dq));
                let along_v = linear(&x.acceleration_dv) + angular(&x.jacobian).cross(&velocity) + omega.cross(&linear(&x.jacobian));
                rows[dq..dq + 3].copy_from_slice(along_q.as_slice());
                rows[dv..dv + 3].copy_from_slice(along_v.as_slice());
            }
        });
    }
}

/// The derivatives' solve with the KKT inverse's blocks the forward solve left (`contact::solve`): for the rows' partial derivatives A
/// (`w.rhs_top`, nv x m) and B (`w.rhs_rows`, r x m), x = −(M⁻¹ − M⁻¹ Jᵀ G) A − Gᵀ B into `x` and y = G A − S⁻¹ B into
/// `y` (m = x.len() / nv columns).
fn solve_derivatives(w: &ContactWorkspace, x: &mut [f64], y: &mut [f64]) {
    let (r, nv) = w.shape;
    let m = x.len() / nv;
    let (a, b) = (&w.rhs_top[..nv * m], &w.rhs_rows[..r * m]);
    gemm(x, nv, -1.0, &w.projected, a, plain(nv), 0.0);
    gemm(x, nv, -1.0, &w.gain_t, b, plain(r), 1.0);
    gemm(y, r, -1.0, &w.schur_inverse, b, plain(r), 0.0);
    gemm(y, r, 1.0, &w.gain, a, plain(nv), 1.0);
}

/// The constraint rows of `contacts` (3 or 6 each).
fn rows(contacts: &[ContactPoint], dim: ContactDim) -> usize {
    dim.rows() * contacts.len()
}

/// `contact_dynamics` (q̈ and the contact forces at configuration `q`, velocity `v`, joint forces `tau`, the
/// `contacts` held still) and its derivatives with respect to q, q̇ and τ. An error if M is singular or the contacts are
/// not independent.
///
/// # Examples
///
/// The box of `contact_dynamics`' example (2 kg, 0.3 x 0.2 x 0.1 m, floating; built in the hidden lines) pivoting on a
/// corner: whatever τ, the corner stays put, J ∂q̈/∂τ = 0 (J its linear Jacobian, world axes); ∂q̈/∂q̇ is checked against
/// central differences; `contact_dynamics_derivatives_into` writes the same numbers into the caller's slices.
///
/// ```
/// # use legkit_dynamics::algorithms::{self, ContactDim, ContactPoint};
/// # use legkit_dynamics::{Data, MassProperties, Model};
/// # use nalgebra::{DVector, Matrix3, Vector3};
/// # let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
/// # let model = Model::new(true, body, "box");
/// # let mut data = Data::new(&model);
/// use legkit_dynamics::algorithms::Frame;
/// let (q, v, tau, h) = ([0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 1.0], [0.025, 0.0, 0.075, 0.0, 0.5, 0.0], [0.0; 6], 1e-6);
/// let corner = [ContactPoint { body: 0, point: Vector3::new(0.15, 0.1, -0.05) }];
/// let d = algorithms::contact_dynamics_derivatives(&model, &mut data, &q, &v, &tau, &corner, ContactDim::Point)?;
/// let j = algorithms::jacobian(&model, &mut data, &q, 0, &corner[0].point, Frame::LocalWorldAligned)?.fixed_rows::<3>(0).into_owned();
/// assert!((&j * &d.ddq_dtau).amax() < 1e-12);
/// for k in 0..6 {
///     let nudge = |step: f64| { let mut v = v; v[k] += step; v };
///     let plus = algorithms::contact_dynamics(&model, &mut data, &q, &nudge(h), &tau, &corner, ContactDim::Point)?.ddq;
///     let minus = algorithms::contact_dynamics(&model, &mut data, &q, &nudge(-h), &tau, &corner, ContactDim::Point)?.ddq;
///     assert!((d.ddq_dv.column(k) - (plus - minus) / (2.0 * h)).norm() < 1e-7);
/// }
/// // ∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂τ (nv x nv each) and the forces' (3 x nv each), column-major.
/// let (mut ddq_d, mut forces_d) = (vec![0.0; 3 * 6 * 6], vec![0.0; 3 * 3 * 6]);
/// algorithms::contact_dynamics_derivatives_into(&model, &mut data, &q, &v, &tau, &corner, ContactDim::Point, &mut ddq_d, &mut forces_d)?;
/// assert!(ddq_d[2 * 36..] == *d.ddq_dtau.as_slice() && forces_d[2 * 18..] == *d.forces_dtau.as_slice());
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn contact_dynamics_derivatives(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<ContactDynamicsDerivatives> {
    let (ddq, forces, [ddq_dq, ddq_dv, ddq_dtau], [forces_dq, forces_dv, forces_dtau]) =
        owned(model, data, rows(contacts, dim), |data, ddq_d, forces_d| {
            contact_dynamics_derivatives_into(model, data, q, v, tau, contacts, dim, ddq_d, forces_d)
        })?;
    Ok(ContactDynamicsDerivatives { ddq, forces, ddq_dq, ddq_dv, ddq_dtau, forces_dq, forces_dv, forces_dtau })
}

/// `contact_dynamics_derivatives` into `ddq_d` (3 nv x nv, column-major, one after the other: ∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂τ)
/// and `forces_d` (3 r x nv: the forces' by q, q̇ and τ; r = 3 or 6 per contact); q̈ and the forces are left in
/// `data.contact`. Allocates nothing once `data` is sized for the contacts (`TooLarge` naming them if it cannot be).
#[allow(clippy::too_many_arguments)]
pub fn contact_dynamics_derivatives_into(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], contacts: &[ContactPoint], dim: ContactDim, ddq_d: &mut [f64],
    forces_d: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_contacts(model, contacts)?;
    let (nv, r) = (model.nv(), rows(contacts, dim));
    check_output("ddq_d", ddq_d, 3 * nv * nv)?;
    check_output("forces_d", forces_d, 3 * r * nv)?;
    with_workspace(data, |data, w| {
        if let Some(row) = contact_solution(model, data, w, q, v, tau, contacts, dim)? {
            return Err(dependent(contacts, dim, row));
        }
        // The rows' partial derivatives: M q̈ + h − Jᵀλ − τ (inverse dynamics with the forces applied) and J q̈ + γ.
        body_forces(data, w, contacts, dim);
        let (dtau_dq, dtau_dv) = w.rhs_top.split_at_mut(nv * nv);
        derivatives_into::<false>(model, data, q, v, &w.solution, Some(&w.body_forces), model.gravity_bias(), dtau_dq, dtau_dv);
        hold_forces_in_world_axes(model, data, q, contacts, dim, &w.forces, dtau_dq);
        acceleration_rows(model, data, q, contacts, dim, &mut w.rhs_rows);
        // q's and q̇'s columns side by side, straight into the outputs; the τ block is the KKT inverse's own.
        let (ddq_dx, ddq_dtau) = ddq_d.split_at_mut(2 * nv * nv);
        let (forces_dx, forces_dtau) = forces_d.split_at_mut(2 * r * nv);
        solve_derivatives(w, ddq_dx, forces_dx);
        ddq_dtau.copy_from_slice(&w.projected);
        forces_dtau.iter_mut().zip(&w.gain).for_each(|(out, g)| *out = -g);
        Ok(())
    })?;
    finite_result(ddq_d)?;
    finite_result(forces_d)
}

/// Runs an `_into` variant on outputs of N nv x nv and N r x nv matrices it allocates, and returns the solution it
/// leaves in `data.contact` with those matrices.
#[allow(clippy::type_complexity)]
fn owned<const N: usize>(
    model: &Model, data: &mut Data, r: usize, kernel: impl FnOnce(&mut Data, &mut [f64], &mut [f64]) -> Result<()>,
) -> Result<(DVector<f64>, DVector<f64>, [DMatrix<f64>; N], [DMatrix<f64>; N])> {
    let nv = model.nv();
    let (mut generalized, mut per_row) = (vec![0.0; N * nv * nv], vec![0.0; N * r * nv]);
    kernel(data, &mut generalized, &mut per_row)?;
    let blocks =
        |buffer: &[f64], rows: usize| std::array::from_fn(|i| DMatrix::from_column_slice(rows, nv, &buffer[i * rows * nv..(i + 1) * rows * nv]));
    let w = &data.contact;
    Ok((DVector::from_column_slice(&w.solution), DVector::from_column_slice(&w.forces), blocks(&generalized, nv), blocks(&per_row, r)))
}

/// `impact` (the velocity after a perfectly inelastic impact at the contacts, and its impulses, at configuration `q`
/// and velocity `v` before it) and its derivatives with respect to q and that velocity.
///
/// # Examples
///
/// An impact on the box's corner leaves it still whatever the velocity before (J ∂v⁺/∂v = 0), and its derivatives carry
/// the velocity after, as `impact` gives it:
///
/// ```
/// # use legkit_dynamics::algorithms::{self, ContactDim, ContactPoint};
/// # use legkit_dynamics::{Data, MassProperties, Model};
/// # use nalgebra::{DVector, Matrix3, Vector3};
/// # let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
/// # let model = Model::new(true, body, "box");
/// # let mut data = Data::new(&model);
/// use legkit_dynamics::algorithms::Frame;
/// let (q, v) = ([0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 1.0], [0.3, -0.1, -1.0, 0.2, 0.5, 0.0]);
/// let corner = [ContactPoint { body: 0, point: Vector3::new(0.15, 0.1, -0.05) }];
/// let d = algorithms::impact_derivatives(&model, &mut data, &q, &v, &corner, ContactDim::Point)?;
/// let j = algorithms::jacobian(&model, &mut data, &q, 0, &corner[0].point, Frame::LocalWorldAligned)?.fixed_rows::<3>(0).into_owned();
/// assert!((&j * &d.velocity_dv).amax() < 1e-12 && (&j * &d.velocity).amax() < 1e-12);
/// let (after, impulses) = algorithms::impact(&model, &mut data, &q, &v, &corner, ContactDim::Point)?;
/// assert!((after - &d.velocity).amax() < 1e-12 && (impulses - &d.impulses).amax() < 1e-12);
/// // ∂v⁺/∂q, ∂v⁺/∂v (nv x nv each) and the impulses' (3 x nv each), column-major.
/// let (mut velocity_d, mut impulses_d) = (vec![0.0; 2 * 6 * 6], vec![0.0; 2 * 3 * 6]);
/// algorithms::impact_derivatives_into(&model, &mut data, &q, &v, &corner, ContactDim::Point, &mut velocity_d, &mut impulses_d)?;
/// assert!(velocity_d[36..] == *d.velocity_dv.as_slice() && impulses_d[18..] == *d.impulses_dv.as_slice());
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn impact_derivatives(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<ImpactDerivatives> {
    let (velocity, impulses, [velocity_dq, velocity_dv], [impulses_dq, impulses_dv]) =
        owned(model, data, rows(contacts, dim), |data, velocity_d, impulses_d| {
            impact_derivatives_into(model, data, q, v, contacts, dim, velocity_d, impulses_d)
        })?;
    Ok(ImpactDerivatives { velocity, impulses, velocity_dq, velocity_dv, impulses_dq, impulses_dv })
}

/// `impact_derivatives` into `velocity_d` (2 nv x nv, column-major: ∂v⁺/∂q, ∂v⁺/∂v) and `impulses_d` (2 r x nv); v⁺
/// and the impulses are left in `data.contact`. Allocates nothing once `data` is sized for the contacts.
#[allow(clippy::too_many_arguments)]
pub fn impact_derivatives_into(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint], dim: ContactDim, velocity_d: &mut [f64], impulses_d: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[("v", v)])?;
    check_contacts(model, contacts)?;
    let (nv, r) = (model.nv(), rows(contacts, dim));
    check_output("velocity_d", velocity_d, 2 * nv * nv)?;
    check_output("impulses_d", impulses_d, 2 * r * nv)?;
    with_workspace(data, |data, w| {
        // M (v⁺ − v) − Jᵀ Λ = 0, J v⁺ = 0.
        if let Some(row) = impact_solution(model, data, w, q, v, contacts, dim)? {
            return Err(dependent(contacts, dim, row));
        }
        // ∂(J v⁺)/∂q: the contacts' velocities at v⁺.
        motion_derivatives(model, data, q, &w.solution, None, Motion::zeros());
        let d = dim.rows();
        w.rhs_rows[..r * nv].fill(0.0);
        for (k, contact) in contacts.iter().enumerate() {
            let at = FramePoint::new(model, data, q, contact.body, &contact.point);
            let rows = &mut w.rhs_rows;
            for_each_frame_derivative(model, data, &at, Frame::LocalWorldAligned, |c, x| {
                rows[c * r + d * k..c * r + d * k + d].copy_from_slice(&x.velocity_dq.as_slice()[..d]);
            });
        }
        // ∂(M (v⁺ − v) − Jᵀ Λ)/∂q: inverse dynamics at rest, accelerating by the change, without gravity.
        w.change.iter_mut().zip(w.solution.iter().zip(v)).for_each(|(x, (after, before))| *x = after - before);
        body_forces(data, w, contacts, dim);
        let (dq, scratch) = w.rhs_top.split_at_mut(nv * nv);
        derivatives_into::<false>(model, data, q, &w.zeros, &w.change, Some(&w.body_forces), Motion::zeros(), dq, scratch);
        hold_forces_in_world_axes(model, data, q, contacts, dim, &w.forces, dq);
        let (velocity_dq, velocity_dv) = velocity_d.split_at_mut(nv * nv);
        let (impulses_dq, impulses_dv) = impulses_d.split_at_mut(r * nv);
        solve_derivatives(w, velocity_dq, impulses_dq);
        // Along v: M ∂v⁺ − Jᵀ ∂Λ = M, so ∂Λ = −S⁻¹ J and ∂v⁺ = I + M⁻¹ Jᵀ ∂Λ.
        gemm(impulses_dv, r, -1.0, &w.schur_inverse, &w.jacobian, plain(r), 0.0);
        gemm(velocity_dv, nv, 1.0, &w.minv_jt, impulses_dv, plain(r), 0.0);
        for i in 0..nv {
            velocity_dv[i + nv * i] += 1.0;
        }
        Ok(())
    })?;
    finite_result(velocity_d)?;
    finite_result(impulses_d)
}
