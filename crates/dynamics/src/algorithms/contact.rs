//! Dynamics with point contacts held fixed (Hardt & von Stryk, eq. 1–3 and 7): the constrained forward
//! dynamics, the reduced ODE on independent coordinates, and perfectly inelastic impacts.
//!
//! A contact is a point on a body whose world position may not move: J_c q̈ + γ = 0 with J_c the 3k x nv
//! stack of the points' linear Jacobians (world axes) and γ = J̇_c q̇ their velocity-product acceleration.
//! Contact forces are 3-vectors in world axes acting on the robot at the points. These functions
//! allocate their k-dependent matrices on each call.

use nalgebra::{DMatrix, DVector, Vector3};

use super::kinematics_derivatives::FramePoint;
use super::rnea_derivatives::motion_derivatives;
use super::{crba, minv, rnea};
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

/// The contact points' rows: J (3k x nv, their velocities in world axes), J_ω (3k x nv, their bodies' angular
/// velocities) and γ (3k, their classical accelerations at q̈ = 0).
pub(crate) struct Constraint {
    pub linear: DMatrix<f64>,
    pub angular: DMatrix<f64>,
    pub drift: DVector<f64>,
}

pub(crate) fn constraint(model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint]) -> Constraint {
    motion_derivatives(model, data, q, v, None, Motion::zeros());
    let (rows, nv) = (3 * contacts.len(), model.nv());
    let mut out = Constraint { linear: DMatrix::zeros(rows, nv), angular: DMatrix::zeros(rows, nv), drift: DVector::zeros(rows) };
    for (k, contact) in contacts.iter().enumerate() {
        let at = FramePoint::new(model, data, q, contact.body, &contact.point);
        at.support(model, |c, _| {
            let s = at.jacobian_column(&data.derivatives.subspace, c);
            out.linear.view_mut((3 * k, c), (3, 1)).copy_from(&linear(&s));
            out.angular.view_mut((3 * k, c), (3, 1)).copy_from(&angular(&s));
        });
        out.drift.rows_mut(3 * k, 3).copy_from(&at.classical_acceleration());
    }
    out
}

/// Writes the world-axes (classical) acceleration of each point to `out` (3k): J_c q̈ + J̇_c q̇ at (q, v, q̈),
/// or with q̈ None the velocity-product term γ = J̇_c q̇ alone.
pub fn point_accelerations(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>, points: &[ContactPoint], out: &mut [f64]) {
    motion_derivatives(model, data, q, v, a, Motion::zeros());
    for (point, chunk) in points.iter().zip(out.chunks_exact_mut(3)) {
        chunk.copy_from_slice(FramePoint::new(model, data, q, point.body, &point.point).classical_acceleration().as_slice());
    }
}

/// The KKT system [M −Jᵀ; J 0] solved through the Schur complement S = J M⁻¹ Jᵀ, with its inverse in dense blocks:
/// x = (M⁻¹ − M⁻¹ Jᵀ G) a + Gᵀ b and y = S⁻¹ b − G a, where G = S⁻¹ J M⁻¹ (nv and 3k are small where contacts are used,
/// and the solves then run as matrix products).
pub(crate) struct Kkt {
    /// M⁻¹ Jᵀ (nv x 3k).
    pub minv_jt: DMatrix<f64>,
    pub schur_inverse: DMatrix<f64>,
    /// G (3k x nv): minus y's derivative with respect to a; and Gᵀ = M⁻¹ Jᵀ S⁻¹, x's with respect to b.
    pub gain: DMatrix<f64>,
    gain_t: DMatrix<f64>,
    /// M⁻¹ − M⁻¹ Jᵀ G (nv x nv): x's derivative with respect to a.
    pub projected: DMatrix<f64>,
}

impl Kkt {
    /// From M⁻¹ at q and the contact rows J; the pieces back if the contacts are not independent.
    fn new(minv: DMatrix<f64>, j: &DMatrix<f64>) -> std::result::Result<Self, Dependent> {
        let minv_jt = &minv * j.transpose();
        let schur = j * &minv_jt;
        let Some(schur_inverse) = spd_inverse(&schur) else { return Err(Dependent { minv, minv_jt, schur }) };
        let gain_t = &minv_jt * &schur_inverse;
        let gain = gain_t.transpose();
        let projected = minv - &minv_jt * &gain;
        Ok(Kkt { minv_jt, schur_inverse, gain, gain_t, projected })
    }

    /// Solves M x − Jᵀ y = a, J x = b for each column of a and b.
    pub fn solve(&self, a: &DMatrix<f64>, b: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
        let mut x = &self.projected * a;
        x.gemm(1.0, &self.gain_t, b, 1.0);
        let mut y = &self.schur_inverse * b;
        y.gemm(-1.0, &self.gain, a, 1.0);
        (x, y)
    }

    /// `solve` for one right-hand side.
    pub fn solve_vectors(&self, a: &DVector<f64>, b: &DVector<f64>) -> (DVector<f64>, DVector<f64>) {
        (&self.projected * a + &self.gain_t * b, &self.schur_inverse * b - &self.gain * a)
    }
}

/// The inverse of a symmetric positive definite matrix by its Cholesky factor L (S⁻¹ = L⁻ᵀ L⁻¹), in plain loops (the
/// matrices are 3k x 3k); None if a pivot keeps no more than 1e-10 of its diagonal entry (a rank deficiency in
/// rounding) or the matrix is not positive definite.
fn spd_inverse(s: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = s.nrows();
    let mut l = DMatrix::zeros(n, n);
    for j in 0..n {
        let pivot = s[(j, j)] - (0..j).map(|k| l[(j, k)] * l[(j, k)]).sum::<f64>();
        if !(pivot > 1e-10 * s[(j, j)]) {
            return None;
        }
        l[(j, j)] = pivot.sqrt();
        for i in j + 1..n {
            l[(i, j)] = (s[(i, j)] - (0..j).map(|k| l[(i, k)] * l[(j, k)]).sum::<f64>()) / l[(j, j)];
        }
    }
    // L⁻¹, lower triangular, column by column.
    let mut inverse_l = DMatrix::zeros(n, n);
    for j in 0..n {
        inverse_l[(j, j)] = 1.0 / l[(j, j)];
        for i in j + 1..n {
            inverse_l[(i, j)] = -(j..i).map(|k| l[(i, k)] * inverse_l[(k, j)]).sum::<f64>() / l[(i, i)];
        }
    }
    Some(inverse_l.tr_mul(&inverse_l))
}

/// M⁻¹, M⁻¹ Jᵀ and J M⁻¹ Jᵀ of contacts that are not independent.
pub(crate) struct Dependent {
    minv: DMatrix<f64>,
    minv_jt: DMatrix<f64>,
    schur: DMatrix<f64>,
}

/// The KKT system of the `contacts` at q (`Kkt` if they are independent); an error if M is singular.
pub(crate) fn kkt(model: &Model, data: &mut Data, q: &[f64], j: &DMatrix<f64>) -> Result<std::result::Result<Kkt, Dependent>> {
    let minv = minv(model, data, q);
    if !minv.diagonal().iter().all(|x| x.is_finite() && *x > 0.0) {
        return Err(Error::numerical("model", "the mass matrix is singular at this configuration (a moving joint carrying no inertia?)"));
    }
    Ok(Kkt::new(minv.clone(), j))
}

/// Solves M x − Jᵀ y = a, J x = b for vectors a and b: by `Kkt`, or for dependent contacts in the least-squares,
/// minimum-norm sense (the smallest forces that do the job).
fn solve_vectors(system: &std::result::Result<Kkt, Dependent>, j: &DMatrix<f64>, a: DVector<f64>, b: DVector<f64>) -> (DVector<f64>, DVector<f64>) {
    match system {
        Ok(kkt) => kkt.solve_vectors(&a, &b),
        Err(Dependent { minv, minv_jt, schur }) => {
            let free = minv * a;
            let y = solve_spd(schur.clone(), &(b - j * &free));
            (free + minv_jt * &y, y)
        }
    }
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
    let rows = constraint(model, data, q, v, contacts);
    let bias = DVector::from_column_slice(rnea(model, data, q, v, &vec![0.0; model.nv()], None).as_slice());
    let system = kkt(model, data, q, &rows.linear)?;
    let (ddq, forces) = solve_vectors(&system, &rows.linear, DVector::from_column_slice(tau) - bias, -&rows.drift);
    Ok(ContactDynamics { ddq, forces })
}

/// Post-impact velocities of a perfectly inelastic impact at the contacts: M (v⁺ − v⁻) = Jᵀ Λ, J v⁺ = 0.
/// Returns (v⁺, the 3k impulses Λ).
pub fn impact(model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint]) -> Result<(DVector<f64>, DVector<f64>)> {
    check_contacts(model, contacts)?;
    let rows = constraint(model, data, q, v, contacts);
    let system = kkt(model, data, q, &rows.linear)?;
    let v_minus = DVector::from_column_slice(v);
    let (change, impulses) = solve_vectors(&system, &rows.linear, DVector::zeros(model.nv()), -(&rows.linear * &v_minus));
    Ok((v_minus + change, impulses))
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
    let Constraint { linear: jc, drift: gamma, .. } = constraint(model, data, q, v, contacts);
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
