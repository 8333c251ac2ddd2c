//! Analytic derivatives of the contact dynamics and of impacts (`contact::contact_dynamics`, `contact::impact`;
//! Pinocchio's `computeConstraintDynamicsDerivatives` and `computeImpulseDynamicsDerivatives` for 3-D contacts in
//! `LOCAL_WORLD_ALIGNED`), q on its tangent space.
//!
//! Both solve a KKT system [M −Jᵀ; J 0] [x; λ] = [a; b]. Differentiating its rows at the solution gives the same
//! system for the derivatives, with the rows' own partial derivatives as right-hand sides: those of inverse dynamics
//! (`rnea_derivatives` with the contact forces as external forces) and of the contact points' accelerations or
//! velocities (`kinematics_derivatives`). The contact forces are fixed in world axes, not in their bodies, so a joint
//! that turns a body also turns its forces against it: ∂τ/∂q gains −J_pᵀ [λ]× J_ω. The derivatives exist where the
//! contacts are independent (J of full row rank); redundant contacts are refused.
//!
//! Dense O(nv³ + k³) linear algebra, allocating its k-dependent matrices on each call, as `contact.rs`.

use nalgebra::{DMatrix, DVector, Vector3};

use super::contact::{check_contacts, constraint, kkt, Constraint, ContactPoint, Dependent, Kkt};
use super::jacobian::Frame;
use super::kinematics_derivatives::{for_each_frame_derivative, FramePoint};
use super::rnea;
use super::rnea_derivatives::{derivatives_with_base_acceleration, motion_derivatives, rnea_derivatives};
use crate::model::{Data, Model};
use crate::spatial::{angular, linear, spatial, Force, Motion};
use crate::{Error, Result};

/// `contact_dynamics`' solution and its derivatives (q on its tangent space; forces 3 per contact, world axes).
#[derive(Debug, Clone, PartialEq)]
pub struct ContactDynamicsDerivatives {
    pub ddq: DVector<f64>,
    pub forces: DVector<f64>,
    /// nv x nv each.
    pub ddq_dq: DMatrix<f64>,
    pub ddq_dv: DMatrix<f64>,
    pub ddq_dtau: DMatrix<f64>,
    /// 3k x nv each.
    pub forces_dq: DMatrix<f64>,
    pub forces_dv: DMatrix<f64>,
    pub forces_dtau: DMatrix<f64>,
}

/// `impact`'s solution and its derivatives with respect to q (tangent space) and the velocity before the impact.
#[derive(Debug, Clone, PartialEq)]
pub struct ImpactDerivatives {
    pub velocity: DVector<f64>,
    pub impulses: DVector<f64>,
    /// nv x nv each.
    pub velocity_dq: DMatrix<f64>,
    pub velocity_dv: DMatrix<f64>,
    /// 3k x nv each.
    pub impulses_dq: DMatrix<f64>,
    pub impulses_dv: DMatrix<f64>,
}

/// [a b], side by side.
fn stack_columns(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(a.nrows(), a.ncols() + b.ncols());
    out.columns_mut(0, a.ncols()).copy_from(a);
    out.columns_mut(a.ncols(), b.ncols()).copy_from(b);
    out
}

/// The KKT system of independent contacts, or the error of dependent ones.
fn independent(system: std::result::Result<Kkt, Dependent>) -> Result<Kkt> {
    system.map_err(|_| {
        Error::invalid("contacts", "the contacts are not independent (J M⁻¹ Jᵀ is singular): their forces, and so the derivatives, are not unique")
    })
}

/// The contact forces (3 per contact, world axes) as forces on their bodies, fixed in the bodies' frames (`rnea`'s
/// f_ext), from the poses `motion_derivatives` leaves.
fn body_forces(model: &Model, data: &Data, contacts: &[ContactPoint], forces: &DVector<f64>) -> Vec<Force> {
    let mut out = vec![Force::zeros(); model.nbodies()];
    for (k, contact) in contacts.iter().enumerate() {
        let f = data.centred_m_i[contact.body].rotation.tr_mul(&forces.fixed_rows::<3>(3 * k));
        out[contact.body] += spatial(f, contact.point.cross(&f));
    }
    out
}

/// ∂τ/∂q of `rnea_derivatives`, whose external forces turn with their bodies, for the same forces fixed in world axes
/// instead: less J_pᵀ [f]× J_ω per contact (a turn ω of the body turns a body-fixed force f by ω × f).
fn hold_forces_in_world_axes(dtau_dq: &mut DMatrix<f64>, rows: &Constraint, forces: &DVector<f64>) {
    for k in 0..forces.len() / 3 {
        let f = Vector3::new(forces[3 * k], forces[3 * k + 1], forces[3 * k + 2]);
        let column = |m: &DMatrix<f64>, c: usize| Vector3::new(m[(3 * k, c)], m[(3 * k + 1, c)], m[(3 * k + 2, c)]);
        for c in 0..dtau_dq.ncols() {
            let w = column(&rows.angular, c);
            // Only the contact's support turns it.
            if w == Vector3::zeros() {
                continue;
            }
            let change = f.cross(&w);
            for r in 0..dtau_dq.nrows() {
                dtau_dq[(r, c)] -= column(&rows.linear, r).dot(&change);
            }
        }
    }
}

/// Rows of the contact points' classical accelerations a + ω × v (world axes) differentiated with respect to q and q̇,
/// after `motion_derivatives` at the state (gravity in the base's acceleration adds a constant and changes nothing).
fn acceleration_rows(model: &Model, data: &Data, q: &[f64], contacts: &[ContactPoint]) -> (DMatrix<f64>, DMatrix<f64>) {
    let (rows, nv) = (3 * contacts.len(), model.nv());
    let (mut dq, mut dv) = (DMatrix::zeros(rows, nv), DMatrix::zeros(rows, nv));
    for (k, contact) in contacts.iter().enumerate() {
        let at = FramePoint::new(model, data, q, contact.body, &contact.point);
        let (velocity, omega) = (linear(&at.velocity), angular(&at.velocity));
        for_each_frame_derivative(model, data, &at, Frame::LocalWorldAligned, |c, d| {
            // ∂(a + ω × v) = ∂a + ∂ω × v + ω × ∂v, with ∂/∂q̇ of (v, ω) the Jacobian's columns.
            let along_q = linear(&d.acceleration_dq) + angular(&d.velocity_dq).cross(&velocity) + omega.cross(&linear(&d.velocity_dq));
            let along_v = linear(&d.acceleration_dv) + angular(&d.jacobian).cross(&velocity) + omega.cross(&linear(&d.jacobian));
            dq.view_mut((3 * k, c), (3, 1)).copy_from(&along_q);
            dv.view_mut((3 * k, c), (3, 1)).copy_from(&along_v);
        });
    }
    (dq, dv)
}

/// `contact_dynamics` (q̈ and the contact forces at configuration `q`, velocity `v`, joint forces `tau`, the
/// `contacts` held still) and its derivatives with respect to q, q̇ and τ. An error if M is singular or the contacts are
/// not independent.
pub fn contact_dynamics_derivatives(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    contacts: &[ContactPoint],
) -> Result<ContactDynamicsDerivatives> {
    check_contacts(model, contacts)?;
    let rows = constraint(model, data, q, v, contacts);
    let bias = DVector::from_column_slice(rnea(model, data, q, v, &vec![0.0; model.nv()], None).as_slice());
    let kkt = independent(kkt(model, data, q, &rows.linear)?)?;
    let (ddq, forces) = kkt.solve_vectors(&(DVector::from_column_slice(tau) - bias), &-&rows.drift);
    // The rows' partial derivatives: M q̈ + h − Jᵀλ − τ (inverse dynamics with the forces applied) and J q̈ + γ.
    let f_ext = body_forces(model, data, contacts, &forces);
    let (dtau_dq, dtau_dv) = rnea_derivatives(model, data, q, v, ddq.as_slice(), Some(&f_ext));
    let (mut dtau_dq, dtau_dv) = (dtau_dq.clone(), dtau_dv.clone());
    hold_forces_in_world_axes(&mut dtau_dq, &rows, &forces);
    let (da_dq, da_dv) = acceleration_rows(model, data, q, contacts);
    // One solve for q and q̇ side by side (fewer, larger products).
    let nv = model.nv();
    let (ddq_dx, forces_dx) = kkt.solve(&-stack_columns(&dtau_dq, &dtau_dv), &-stack_columns(&da_dq, &da_dv));
    let (ddq_dq, ddq_dv) = (ddq_dx.columns(0, nv).into_owned(), ddq_dx.columns(nv, nv).into_owned());
    let (forces_dq, forces_dv) = (forces_dx.columns(0, nv).into_owned(), forces_dx.columns(nv, nv).into_owned());
    let (ddq_dtau, forces_dtau) = (kkt.projected, -kkt.gain);
    Ok(ContactDynamicsDerivatives { ddq, forces, ddq_dq, ddq_dv, ddq_dtau, forces_dq, forces_dv, forces_dtau })
}

/// `impact` (the velocity after a perfectly inelastic impact at the contacts, and its impulses, at configuration `q`
/// and velocity `v` before it) and its derivatives with respect to q and that velocity.
pub fn impact_derivatives(model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint]) -> Result<ImpactDerivatives> {
    check_contacts(model, contacts)?;
    let rows = constraint(model, data, q, v, contacts);
    let kkt = independent(kkt(model, data, q, &rows.linear)?)?;
    let (nv, k3) = (model.nv(), 3 * contacts.len());
    let before = DVector::from_column_slice(v);
    // M (v⁺ − v) − Jᵀ Λ = 0, J v⁺ = 0.
    let (change, impulses) = kkt.solve_vectors(&DVector::zeros(nv), &-(&rows.linear * &before));
    let velocity = before + &change;
    // ∂(J v⁺)/∂q: the points' velocities at v⁺.
    motion_derivatives(model, data, q, velocity.as_slice(), None, Motion::zeros());
    let mut dvelocity_dq = DMatrix::zeros(k3, nv);
    for (k, contact) in contacts.iter().enumerate() {
        let at = FramePoint::new(model, data, q, contact.body, &contact.point);
        for_each_frame_derivative(model, data, &at, Frame::LocalWorldAligned, |c, d| {
            dvelocity_dq.view_mut((3 * k, c), (3, 1)).copy_from(&linear(&d.velocity_dq));
        });
    }
    // ∂(M (v⁺ − v) − Jᵀ Λ)/∂q: inverse dynamics at rest, accelerating by the change, without gravity.
    let zero = vec![0.0; nv];
    let f_ext = body_forces(model, data, contacts, &impulses);
    let (dq, _) = derivatives_with_base_acceleration(model, data, q, &zero, change.as_slice(), Some(&f_ext), Motion::zeros());
    let mut dresidual_dq = dq.clone();
    hold_forces_in_world_axes(&mut dresidual_dq, &rows, &impulses);
    let (velocity_dq, impulses_dq) = kkt.solve(&-dresidual_dq, &-dvelocity_dq);
    // Along v: M ∂v⁺ − Jᵀ ∂Λ = M, so ∂v⁺ = I + M⁻¹ Jᵀ ∂Λ with ∂Λ = −S⁻¹ J.
    let impulses_dv = -(&kkt.schur_inverse * &rows.linear);
    let velocity_dv = DMatrix::identity(nv, nv) + &kkt.minv_jt * &impulses_dv;
    Ok(ImpactDerivatives { velocity, impulses, velocity_dq, velocity_dv, impulses_dq, impulses_dv })
}
