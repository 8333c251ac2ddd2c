//! Dynamics with point contacts held fixed (Hardt & von Stryk, eq. 1–3 and 7): the constrained forward
//! dynamics, the reduced ODE on independent coordinates, and perfectly inelastic impacts.
//!
//! A contact is a point on a body whose world position may not move: J_c q̈ + γ = 0 with J_c the 3k x nv
//! stack of the points' linear Jacobians (world axes) and γ = J̇_c q̇ their velocity-product acceleration.
//! Contact forces are 3-vectors in world axes acting on the robot at the points. These functions
//! allocate their k-dependent matrices on each call.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::kinematics::body_motions;
use super::{crba, jacobian, rnea, Frame};
use crate::model::{Data, Model};
use crate::spatial::{angular, linear, Motion};
use crate::{Error, Result};

/// A point on a body, in the body's frame, held still by `contact_dynamics`, `reduced_dynamics` and `impact` (their
/// input). Not to be confused with `sim::Contact`, a contact the simulation reports with its forces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPoint {
    pub body: usize,
    pub point: Vector3<f64>,
}

/// Accelerations and the contact forces that keep the contact points still.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactDynamics {
    pub ddq: DVector<f64>,
    /// 3k forces, contact after contact, world axes.
    pub forces: DVector<f64>,
}

/// The dynamics reduced to independent velocity coordinates: `mass · v̇_I = force`, with
/// `v = N v_I` and `q̈ = N v̇_I + offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedDynamics {
    pub independent: Vec<usize>,
    pub dependent: Vec<usize>,
    /// nv x n_I map from independent to all velocities.
    pub basis: DMatrix<f64>,
    /// The acceleration that keeps the contacts still when v̇_I = 0.
    pub offset: DVector<f64>,
    pub mass: DMatrix<f64>,
    pub force: DVector<f64>,
    pub ddq_independent: DVector<f64>,
    pub ddq: DVector<f64>,
}

pub fn check_contacts(model: &Model, contacts: &[ContactPoint]) -> Result<()> {
    if contacts.is_empty() {
        return Err(Error::invalid("contacts", "needs at least one contact"));
    }
    for c in contacts {
        if c.body >= model.nbodies() {
            return Err(Error::invalid("contacts", format!("body {} does not exist", c.body)));
        }
        crate::validate::finite_vector("contacts", c.point)?;
    }
    Ok(())
}

/// J_c (3k x nv) and γ (3k) at (q, v).
fn constraint(model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint]) -> (DMatrix<f64>, DVector<f64>) {
    let nv = model.nv();
    let mut jc = DMatrix::zeros(3 * contacts.len(), nv);
    for (c, contact) in contacts.iter().enumerate() {
        let j = jacobian(model, data, q, contact.body, &contact.point, Frame::LocalWorldAligned);
        jc.view_mut((3 * c, 0), (3, nv)).copy_from(&j.rows(0, 3));
    }
    let mut gamma = DVector::zeros(3 * contacts.len());
    point_accelerations(model, data, q, v, None, contacts, gamma.as_mut_slice());
    (jc, gamma)
}

/// Writes the world-axes (classical) acceleration of each point to `out` (3k): J_c q̈ + J̇_c q̇ at (q, v, q̈),
/// or with q̈ None the velocity-product term γ = J̇_c q̇ alone.
pub fn point_accelerations(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>, points: &[ContactPoint], out: &mut [f64]) {
    // The bodies' spatial accelerations (no gravity), then the points': a_point = R (a + α × r + ω × (v + ω × r)).
    body_motions(model, data, q, v, a, Motion::zeros());
    for (point, chunk) in points.iter().zip(out.chunks_exact_mut(3)) {
        let (vb, ab, r) = (&data.v[point.body], &data.a[point.body], point.point);
        let w = angular(vb);
        let local = linear(ab) + angular(ab).cross(&r) + w.cross(&(linear(vb) + w.cross(&r)));
        chunk.copy_from_slice((world_rotation(model, data, point.body) * local).as_slice());
    }
}

/// A body's orientation in the world from the parent-frame poses `body_motions` leaves in `data.li_m_i`
/// (its chain only, rather than forward kinematics over the whole tree).
fn world_rotation(model: &Model, data: &Data, body: usize) -> Matrix3<f64> {
    let mut rotation = data.li_m_i[body].rotation;
    let mut j = body;
    while j > 0 {
        j = model.parent(j);
        rotation = data.li_m_i[j].rotation * rotation;
    }
    rotation
}

/// Solves the symmetric positive semi-definite system `a x = b` in the least-squares, minimum-norm sense:
/// redundant contacts (a rank-deficient J) get the smallest forces that do the job.
fn solve_spd(a: DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let eigen = a.symmetric_eigen();
    let tolerance = 1e-12 * eigen.eigenvalues.amax();
    let inverse = eigen.eigenvalues.map(|l| if l > tolerance { 1.0 / l } else { 0.0 });
    &eigen.eigenvectors * inverse.component_mul(&(eigen.eigenvectors.transpose() * b))
}

/// M, a Cholesky factor of M, and the bias h = C q̇ + g.
type MassAndBias = (DMatrix<f64>, nalgebra::Cholesky<f64, nalgebra::Dyn>, DVector<f64>);

/// M and the bias h = C q̇ + g at (q, v), and a Cholesky factor of M.
fn mass_and_bias(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> Result<MassAndBias> {
    let mass = crba(model, data, q).clone();
    let bias = rnea(model, data, q, v, &vec![0.0; model.nv()], None).clone();
    let chol = mass
        .clone()
        .cholesky()
        .ok_or_else(|| Error::numerical("model", "the mass matrix is singular at this configuration (a moving joint carrying no inertia?)"))?;
    Ok((mass, chol, bias))
}

/// Constrained forward dynamics: [M −Jᵀ; J 0] [q̈; λ] = [τ − h; −γ], by the Schur complement
/// (J M⁻¹ Jᵀ) λ = −γ − J M⁻¹ (τ − h).
pub fn contact_dynamics(model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], contacts: &[ContactPoint]) -> Result<ContactDynamics> {
    check_contacts(model, contacts)?;
    let (_, chol, bias) = mass_and_bias(model, data, q, v)?;
    let (jc, gamma) = constraint(model, data, q, v, contacts);
    let free = chol.solve(&(DVector::from_column_slice(tau) - bias));
    let minv_jt = chol.solve(&jc.transpose());
    let forces = solve_spd(&jc * &minv_jt, &(-&gamma - &jc * &free));
    let ddq = free + minv_jt * &forces;
    Ok(ContactDynamics { ddq, forces })
}

/// Post-impact velocities of a perfectly inelastic impact at the contacts: M (v⁺ − v⁻) = Jᵀ Λ, J v⁺ = 0.
/// Returns (v⁺, the 3k impulses Λ).
pub fn impact(model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint]) -> Result<(DVector<f64>, DVector<f64>)> {
    check_contacts(model, contacts)?;
    let (_, chol, _) = mass_and_bias(model, data, q, v)?;
    let (jc, _) = constraint(model, data, q, v, contacts);
    let v_minus = DVector::from_column_slice(v);
    let minv_jt = chol.solve(&jc.transpose());
    let impulses = solve_spd(&jc * &minv_jt, &(-(&jc * &v_minus)));
    Ok((v_minus + minv_jt * &impulses, impulses))
}

/// Picks `rank` columns of `j` that are linearly independent (greedy pivoting on the residual norms).
fn pivot_columns(j: &DMatrix<f64>) -> Vec<usize> {
    let mut residual = j.clone();
    let scale = j.amax().max(f64::MIN_POSITIVE);
    let mut chosen = Vec::new();
    while chosen.len() < j.nrows() {
        let (best, norm) = (0..j.ncols())
            .filter(|c| !chosen.contains(c))
            .map(|c| (c, residual.column(c).norm()))
            .fold((usize::MAX, 0.0), |acc, x| if x.1 > acc.1 { x } else { acc });
        if best == usize::MAX || norm <= 1e-10 * scale {
            break;
        }
        let direction = residual.column(best) / norm;
        for c in 0..j.ncols() {
            let projection = direction.dot(&residual.column(c));
            let mut col = residual.column_mut(c);
            col -= &direction * projection;
        }
        chosen.push(best);
    }
    chosen.sort_unstable();
    chosen
}

/// The reduced ODE on independent coordinates (Hardt & von Stryk eq. 7): the velocity coordinates split
/// into dependent ones D (J_D invertible; chosen by pivoting unless `independent` is given) and independent
/// ones I, with v_D = −J_D⁻¹ J_I v_I. Then Nᵀ M N v̇_I = Nᵀ (τ − h − M d), where d holds −J_D⁻¹ γ on D.
pub fn reduced_dynamics(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    contacts: &[ContactPoint],
    independent: Option<&[usize]>,
) -> Result<ReducedDynamics> {
    check_contacts(model, contacts)?;
    let nv = model.nv();
    let (mass, _, bias) = mass_and_bias(model, data, q, v)?;
    let (jc, gamma) = constraint(model, data, q, v, contacts);
    let dependent: Vec<usize> = match independent {
        Some(ind) => {
            if let Some(&bad) = ind.iter().find(|&&i| i >= nv) {
                return Err(Error::invalid("independent", format!("index {bad} is out of range for nv = {nv}")));
            }
            (0..nv).filter(|i| !ind.contains(i)).collect()
        }
        None => pivot_columns(&jc),
    };
    let independent: Vec<usize> = (0..nv).filter(|i| !dependent.contains(i)).collect();
    if dependent.len() != jc.nrows() {
        return Err(Error::invalid(
            "contacts",
            format!("{} constraints are not independent (rank {}): the reduced ODE needs independent contacts", jc.nrows(), dependent.len()),
        ));
    }
    let j_dependent = jc.select_columns(&dependent);
    let j_independent = jc.select_columns(&independent);
    let lu = j_dependent.lu();
    let coupling = lu
        .solve(&j_independent)
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .ok_or_else(|| Error::invalid("independent", "the constraint Jacobian is singular on the dependent coordinates"))?;
    let drift = lu.solve(&gamma).expect("same factorisation");
    let mut basis = DMatrix::zeros(nv, independent.len());
    let mut offset = DVector::zeros(nv);
    for (c, &i) in independent.iter().enumerate() {
        basis[(i, c)] = 1.0;
    }
    for (r, &d) in dependent.iter().enumerate() {
        basis.row_mut(d).copy_from(&(-coupling.row(r)));
        offset[d] = -drift[r];
    }
    let reduced_mass = basis.transpose() * &mass * &basis;
    let force = basis.transpose() * (DVector::from_column_slice(tau) - bias - &mass * &offset);
    let ddq_independent =
        reduced_mass.clone().cholesky().ok_or_else(|| Error::invalid("contacts", "the reduced mass matrix is singular"))?.solve(&force);
    let ddq = &basis * &ddq_independent + &offset;
    Ok(ReducedDynamics { independent, dependent, basis, offset, mass: reduced_mass, force, ddq_independent, ddq })
}
