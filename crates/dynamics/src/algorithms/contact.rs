//! Dynamics with contacts held fixed (Hardt & von Stryk, eq. 1–3 and 7): the constrained forward dynamics, the reduced
//! ODE on independent coordinates, and perfectly inelastic impacts.
//!
//! A contact holds a point on a body still (`ContactDim::Point`: J_c q̈ + γ = 0 with J_c the 3k x nv stack of the
//! points' linear Jacobians, world axes, and γ = J̇_c q̇ their velocity-product acceleration), or the body's whole frame
//! at the point (`ContactDim::Frame`: 6 rows per contact, the point's velocity and the body's angular velocity, world
//! axes, whose spatial acceleration is held at zero; Pinocchio's CONTACT_6D in LOCAL_WORLD_ALIGNED). Contact forces act on the robot at the points, in world axes:
//! 3-vectors, or wrenches [force; torque about the point]. The k-dependent matrices live in `ContactWorkspace`, sized
//! (fallibly) on first use.

use nalgebra::{DMatrix, DVector, Vector3};

use super::checks::{check_output, check_state, finite_result};
use super::kinematics_derivatives::FramePoint;
use super::rnea_derivatives::motion_derivatives;
use super::{crba_unchecked, minv_unchecked, rnea_unchecked};
use crate::model::check_vector;
use crate::model::Dense;
use crate::model::{ContactWorkspace, Data, Model};
use crate::spatial::Motion;
use crate::{Error, Result};

/// A point on a body, in the body's frame, held still by `contact_dynamics`, `reduced_dynamics` and `impact` (their
/// input). Not to be confused with `sim::Contact`, a contact the simulation reports with its forces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPoint {
    /// The body the point is fixed to.
    pub body: usize,
    /// The point in the body's frame (m).
    pub point: Vector3<f64>,
}

/// What a contact holds still: the point (a point foot; Pinocchio's CONTACT_3D) or the body's frame at it, turning
/// included (a flat foot; CONTACT_6D). One kind for all the contacts of a call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ContactDim {
    /// 3 rows per contact; forces.
    #[default]
    Point,
    /// 6 rows per contact, [linear; angular]; wrenches [force; torque about the point].
    Frame,
}

impl ContactDim {
    /// Constraint rows per contact.
    pub fn rows(self) -> usize {
        match self {
            ContactDim::Point => 3,
            ContactDim::Frame => 6,
        }
    }
}

/// Accelerations and the contact forces that keep the contacts still.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactDynamics {
    /// Generalized accelerations q̈ (nv).
    pub ddq: DVector<f64>,
    /// 3 (or 6) per contact, contact after contact, world axes.
    pub forces: DVector<f64>,
}

/// The dynamics reduced to independent velocity coordinates: `mass · v̇_I = force`, with
/// `v = N v_I` and `q̈ = N v̇_I + offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedDynamics {
    /// The independent velocity coordinates v_I, increasing.
    pub independent: Vec<usize>,
    /// The others, increasing: fixed by the contacts given v_I.
    pub dependent: Vec<usize>,
    /// nv x n_I map from independent to all velocities.
    pub basis: DMatrix<f64>,
    /// The acceleration that keeps the contacts still when v̇_I = 0.
    pub offset: DVector<f64>,
    /// The reduced mass matrix Nᵀ M N (n_I x n_I) [Hardt 2002, eq. 7].
    pub mass: DMatrix<f64>,
    /// The reduced generalized force Nᵀ (τ − h − M offset), h the bias forces C q̇ + g (n_I).
    pub force: DVector<f64>,
    /// v̇_I, the solution of `mass · v̇_I = force`.
    pub ddq_independent: DVector<f64>,
    /// All accelerations: N v̇_I + offset (nv).
    pub ddq: DVector<f64>,
}

/// Checks contacts for the contact kernels: at least one, each on an existing body at a finite point; an error
/// on `contacts` otherwise.
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

/// `c = beta c + alpha a b` for column-major a (m x p, `a.len() / m` = p) and b (p x n) read at b[k rs + j cs], c m x
/// n: in plain loops, as the matrices here are a few dozen wide (a blocked product spent more time packing and
/// allocating than multiplying). Four columns of a at a time, so that c's column is read and written once per four;
/// b's zeros (the contact rows outside their bodies' supports) skipped four at a time.
pub(crate) fn gemm(c: &mut [f64], m: usize, alpha: f64, a: &[f64], b: &[f64], (rs, cs): (usize, usize), beta: f64) {
    let m = m.max(1);
    let p = a.len() / m;
    for (j, cj) in c.chunks_exact_mut(m).enumerate() {
        if beta == 0.0 {
            cj.fill(0.0);
        } else if beta != 1.0 {
            cj.iter_mut().for_each(|x| *x *= beta);
        }
        let x = |k: usize| alpha * b[k * rs + j * cs];
        let mut k = 0;
        while k + 4 <= p {
            let (x0, x1, x2, x3) = (x(k), x(k + 1), x(k + 2), x(k + 3));
            if x0 != 0.0 || x1 != 0.0 || x2 != 0.0 || x3 != 0.0 {
                let (a0, a1, a2, a3) =
                    (&a[k * m..(k + 1) * m], &a[(k + 1) * m..(k + 2) * m], &a[(k + 2) * m..(k + 3) * m], &a[(k + 3) * m..(k + 4) * m]);
                for (c, (((a0, a1), a2), a3)) in cj.iter_mut().zip(a0.iter().zip(a1).zip(a2).zip(a3)) {
                    *c += x0 * a0 + x1 * a1 + x2 * a2 + x3 * a3;
                }
            }
            k += 4;
        }
        for k in k..p {
            let xk = x(k);
            if xk != 0.0 {
                cj.iter_mut().zip(&a[k * m..(k + 1) * m]).for_each(|(c, a)| *c += xk * a);
            }
        }
    }
}

/// The strides of a column-major matrix with `rows` rows, read as it is, and read transposed.
pub(crate) fn plain(rows: usize) -> (usize, usize) {
    (1, rows)
}
pub(crate) fn transposed(rows: usize) -> (usize, usize) {
    (rows, 1)
}

/// The contacts' constraint rows J into `w.jacobian` and γ (their accelerations at q̈ = 0, `contact_acceleration`) into
/// `w.drift`, after sizing `w`.
pub(crate) fn constraint(
    model: &Model, data: &mut Data, w: &mut ContactWorkspace, q: &[f64], v: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<()> {
    let (d, r) = (dim.rows(), dim.rows() * contacts.len());
    w.reserve(model, r)?;
    motion_derivatives(model, data, q, v, None, Motion::zeros());
    w.jacobian.fill(0.0);
    for (k, contact) in contacts.iter().enumerate() {
        let at = FramePoint::new(model, data, q, contact.body, &contact.point);
        let jacobian = &mut w.jacobian;
        at.support(model, |c, _| {
            let s = at.jacobian_column(&data.derivatives.subspace, c);
            jacobian[c * r + d * k..c * r + d * k + d].copy_from_slice(&s.as_slice()[..d]);
        });
        contact_acceleration(&at, dim, &mut w.drift[d * k..d * k + d]);
    }
    Ok(())
}

/// Writes each contact's acceleration to `out` (3 or 6 per contact, world axes, `contact_acceleration`): J_c q̈ + J̇_c q̇
/// at (q, v, q̈), or with q̈ None the velocity-product term γ = J̇_c q̇ alone.
#[allow(clippy::too_many_arguments)]
pub fn point_accelerations(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: Option<&[f64]>, points: &[ContactPoint], dim: ContactDim, out: &mut [f64],
) -> Result<()> {
    check_state(model, data, q, &[("v", v)])?;
    if let Some(a) = a {
        check_vector("a", a, model.nv())?;
    }
    check_contacts(model, points)?;
    check_output("out", out, points.len() * dim.rows())?;
    data.reserve_dense(model, &[Dense::Workspace])?;
    motion_derivatives(model, data, q, v, a, Motion::zeros());
    for (point, chunk) in points.iter().zip(out.chunks_exact_mut(dim.rows())) {
        contact_acceleration(&FramePoint::new(model, data, q, point.body, &point.point), dim, chunk);
    }
    finite_result(out)
}

/// What a contact holds at zero: the point's classical acceleration (3), or the frame's spatial acceleration [linear;
/// angular] (6; world axes, about the point), the derivative of its velocity in its own frame, as Pinocchio's
/// CONTACT_6D. The two agree where the contact is still (ω × v = 0).
fn contact_acceleration(at: &FramePoint, dim: ContactDim, out: &mut [f64]) {
    match dim {
        ContactDim::Point => out.copy_from_slice(at.classical_acceleration().as_slice()),
        ContactDim::Frame => out.copy_from_slice(at.acceleration.as_slice()),
    }
}

/// The inverse of the symmetric positive definite `s` (n x n, column-major) into `inverse` by its Cholesky factor L
/// (S⁻¹ = L⁻ᵀ L⁻¹), in plain loops with `l` (n x n) as scratch; Err(j) at the first pivot j that keeps no more than
/// 1e-10 of its diagonal entry (a rank deficiency in rounding: row j depends on the rows before it) or is not positive.
fn spd_inverse(s: &[f64], n: usize, l: &mut [f64], inverse: &mut [f64]) -> std::result::Result<(), usize> {
    // L in the lower triangle: l[i + n j] = L_ij (i ≥ j).
    for j in 0..n {
        let pivot = s[j + n * j] - (0..j).map(|k| l[j + n * k] * l[j + n * k]).sum::<f64>();
        if !(pivot > 1e-10 * s[j + n * j]) {
            return Err(j);
        }
        l[j + n * j] = pivot.sqrt();
        for i in j + 1..n {
            l[i + n * j] = (s[i + n * j] - (0..j).map(|k| l[i + n * k] * l[j + n * k]).sum::<f64>()) / l[j + n * j];
        }
    }
    // L⁻¹ column by column into the upper triangle and the diagonal: l[j + n i] = (L⁻¹)_ij (i ≥ j), the lower
    // triangle's L still read (L_ii is replaced only once column i is reached).
    for j in 0..n {
        l[j + n * j] = 1.0 / l[j + n * j];
        for i in j + 1..n {
            l[j + n * i] = -(j..i).map(|k| l[i + n * k] * l[j + n * k]).sum::<f64>() / l[i + n * i];
        }
    }
    // S⁻¹_ij = Σ_k (L⁻¹)_ki (L⁻¹)_kj over k ≥ max(i, j).
    for j in 0..n {
        for i in 0..=j {
            let x = (j..n).map(|k| l[i + n * k] * l[j + n * k]).sum::<f64>();
            inverse[i + n * j] = x;
            inverse[j + n * i] = x;
        }
    }
    Ok(())
}

/// A singular M: the model's fault (a numerical failure with valid arguments), not the contacts'.
fn singular_mass_matrix() -> Error {
    Error::numerical("model", "the mass matrix is singular at this configuration (a moving joint carrying no inertia?)")
}

/// M⁻¹ at q, checked: an error if M is singular.
fn checked_minv<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> Result<&'d DMatrix<f64>> {
    let minv = minv_unchecked(model, data, q);
    // The diagonal read in place (`diagonal()` would copy it out).
    if !minv.as_slice().iter().step_by(minv.nrows() + 1).all(|x| x.is_finite() && *x > 0.0) {
        return Err(singular_mass_matrix());
    }
    Ok(minv)
}

/// The KKT system [M −Jᵀ; J 0] of the rows in `w` at q, through the Schur complement S = J M⁻¹ Jᵀ (the contacts'
/// Gram matrix in the metric M⁻¹, the Delassus matrix): M⁻¹ Jᵀ and S⁻¹ into `w` (after `constraint`). Ok(Some(j)) if
/// the contacts are not independent, j the first constraint row that depends on the rows before it (S singular);
/// then `w.schur_inverse` holds S itself. An error if M is singular.
pub(crate) fn factor(model: &Model, data: &mut Data, w: &mut ContactWorkspace, q: &[f64]) -> Result<Option<usize>> {
    let (r, nv) = w.shape;
    let minv = checked_minv(model, data, q)?.as_slice();
    gemm(&mut w.minv_jt, nv, 1.0, minv, &w.jacobian, transposed(r), 0.0);
    gemm(&mut w.schur, r, 1.0, &w.jacobian, &w.minv_jt, plain(nv), 0.0);
    let dependent = spd_inverse(&w.schur, r, &mut w.cholesky, &mut w.schur_inverse).err();
    if dependent.is_some() {
        w.schur_inverse.copy_from_slice(&w.schur);
    }
    Ok(dependent)
}

/// After `factor` of independent contacts, G and the projected M⁻¹ − M⁻¹ Jᵀ G into `w` (the KKT inverse's blocks):
/// x = (M⁻¹ − M⁻¹ Jᵀ G) a + Gᵀ b and y = S⁻¹ b − G a solve M x − Jᵀ y = a, J x = b.
fn inverse_blocks(data: &Data, w: &mut ContactWorkspace) {
    let (r, nv) = w.shape;
    gemm(&mut w.gain_t, nv, 1.0, &w.minv_jt, &w.schur_inverse, plain(r), 0.0);
    for c in 0..nv {
        for i in 0..r {
            w.gain[i + r * c] = w.gain_t[c + nv * i];
        }
    }
    w.projected.copy_from_slice(data.minv.as_slice());
    gemm(&mut w.projected, nv, -1.0, &w.minv_jt, &w.gain, plain(r), 1.0);
}

/// After `factor`, solves M x − Jᵀ y = a, J x = b for vectors a (nv) and b (`w.drift`, r) into `w.solution` and
/// `w.forces`: by the KKT inverse's blocks (`inverse_blocks`, which the derivatives reuse; through them rather than
/// as M⁻¹ a + M⁻¹ Jᵀ S⁻¹ (b − J M⁻¹ a), which cancels digits where J M⁻¹ Jᵀ is ill-conditioned), or for dependent
/// contacts in the least-squares, minimum-norm sense (the smallest forces that do the job).
fn solve(data: &Data, w: &mut ContactWorkspace, independent: bool, a: &[f64]) {
    let (r, nv) = w.shape;
    if independent {
        inverse_blocks(data, w);
        gemm(&mut w.solution, nv, 1.0, &w.projected, a, plain(nv), 0.0);
        gemm(&mut w.solution, nv, 1.0, &w.gain_t, &w.drift, plain(r), 1.0);
        gemm(&mut w.forces, r, 1.0, &w.schur_inverse, &w.drift, plain(r), 0.0);
        gemm(&mut w.forces, r, -1.0, &w.gain, a, plain(nv), 1.0);
    } else {
        gemm(&mut w.solution, nv, 1.0, data.minv.as_slice(), a, plain(nv), 0.0);
        gemm(&mut w.drift, r, -1.0, &w.jacobian, &w.solution, plain(nv), 1.0);
        let schur = DMatrix::from_column_slice(r, r, &w.schur_inverse);
        w.forces.copy_from_slice(solve_spd(schur, &DVector::from_column_slice(&w.drift)).as_slice());
        gemm(&mut w.solution, nv, 1.0, &w.minv_jt, &w.forces, plain(r), 1.0);
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

/// Runs `kernel` with the contact workspace lent out of `data` (and put back, also on an error).
pub(crate) fn with_workspace<T>(data: &mut Data, kernel: impl FnOnce(&mut Data, &mut ContactWorkspace) -> Result<T>) -> Result<T> {
    let mut w = std::mem::take(&mut data.contact);
    let result = kernel(data, &mut w);
    data.contact = w;
    result
}

/// Constrained forward dynamics: [M −Jᵀ; J 0] [q̈; λ] = [τ − h; −γ], by the Schur complement
/// (J M⁻¹ Jᵀ) λ = −γ − J M⁻¹ (τ − h).
///
/// # Examples
///
/// A 2 kg box (0.3 x 0.2 x 0.1 m on a free-flyer base; built in the hidden lines) standing on its bottom face's centre,
/// held there as a flat foot (`ContactDim::Frame`), does not move, the contact carrying its weight, 2 × 9.81 N up, and no
/// torque. Falling at 1 m/s onto a point foot there (`impact`), it stops dead, the impulse taking up its momentum.
///
/// ```
/// # use legkit_dynamics::algorithms::{self, ContactDim, ContactPoint};
/// # use legkit_dynamics::{Data, MassProperties, Model};
/// # use nalgebra::{DVector, Matrix3, Vector3};
/// # let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
/// # let model = Model::new(true, body, "box");
/// # let mut data = Data::new(&model);
/// let q = [0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 1.0];
/// let foot = [ContactPoint { body: 0, point: Vector3::new(0.0, 0.0, -0.05) }];
/// let standing = algorithms::contact_dynamics(&model, &mut data, &q, &[0.0; 6], &[0.0; 6], &foot, ContactDim::Frame)?;
/// assert!(standing.ddq.amax() < 1e-12);
/// assert!((standing.forces - DVector::from_row_slice(&[0.0, 0.0, 2.0 * 9.81, 0.0, 0.0, 0.0])).amax() < 1e-12);
/// let falling = [0.0, 0.0, -1.0, 0.0, 0.0, 0.0];
/// let (after, impulse) = algorithms::impact(&model, &mut data, &q, &falling, &foot, ContactDim::Point)?;
/// assert!(after.amax() < 1e-12 && (impulse - DVector::from_row_slice(&[0.0, 0.0, 2.0])).amax() < 1e-12);
/// let error = algorithms::check_contacts(&model, &[ContactPoint { body: 1, point: Vector3::zeros() }]).unwrap_err();
/// assert_eq!(error.to_string(), "contacts: body 1 does not exist");
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn contact_dynamics(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<ContactDynamics> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_contacts(model, contacts)?;
    with_workspace(data, |data, w| {
        contact_solution(model, data, w, q, v, tau, contacts, dim)?;
        finite_result(&w.solution)?;
        finite_result(&w.forces)?;
        Ok(ContactDynamics { ddq: DVector::from_column_slice(&w.solution), forces: DVector::from_column_slice(&w.forces) })
    })
}

/// `contact_dynamics` into `w.solution` and `w.forces`; Ok(the first dependent constraint row, if any: `factor`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn contact_solution(
    model: &Model, data: &mut Data, w: &mut ContactWorkspace, q: &[f64], v: &[f64], tau: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<Option<usize>> {
    constraint(model, data, w, q, v, contacts, dim)?;
    w.drift.iter_mut().for_each(|x| *x = -*x);
    // τ − h, h = rnea(q, v, 0), in `rhs_top`'s first column.
    let nv = model.nv();
    let bias = rnea_unchecked(model, data, q, v, &w.zeros, None);
    for ((x, t), h) in w.rhs_top[..nv].iter_mut().zip(tau).zip(bias.iter()) {
        *x = t - h;
    }
    let dependent = factor(model, data, w, q)?;
    let a = std::mem::take(&mut w.rhs_top);
    solve(data, w, dependent.is_none(), &a[..nv]);
    w.rhs_top = a;
    Ok(dependent)
}

/// Post-impact velocities of a perfectly inelastic impact at the contacts: M (v⁺ − v⁻) = Jᵀ Λ, J v⁺ = 0.
/// Returns (v⁺, the impulses Λ, 3 or 6 per contact).
pub fn impact(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<(DVector<f64>, DVector<f64>)> {
    check_state(model, data, q, &[("v", v)])?;
    check_contacts(model, contacts)?;
    with_workspace(data, |data, w| {
        impact_solution(model, data, w, q, v, contacts, dim)?;
        finite_result(&w.solution)?;
        finite_result(&w.forces)?;
        Ok((DVector::from_column_slice(&w.solution), DVector::from_column_slice(&w.forces)))
    })
}

/// `impact` into `w.solution` (v⁺) and `w.forces`; Ok(the first dependent constraint row, if any: `factor`).
pub(crate) fn impact_solution(
    model: &Model, data: &mut Data, w: &mut ContactWorkspace, q: &[f64], v: &[f64], contacts: &[ContactPoint], dim: ContactDim,
) -> Result<Option<usize>> {
    constraint(model, data, w, q, v, contacts, dim)?;
    let nv = model.nv();
    // The change of velocity: a = 0, b = −J v⁻.
    gemm(&mut w.drift, w.shape.0, -1.0, &w.jacobian, v, plain(nv), 0.0);
    let dependent = factor(model, data, w, q)?;
    let zeros = std::mem::take(&mut w.zeros);
    solve(data, w, dependent.is_none(), &zeros);
    w.zeros = zeros;
    w.solution.iter_mut().zip(v).for_each(|(x, v)| *x += v);
    Ok(dependent)
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
///
/// # Examples
///
/// Pivoting on a corner (`ContactDim::Point`) at a velocity that leaves the corner still: at the q̈ of
/// `contact_dynamics` the corner does not accelerate (`point_accelerations`), and the dynamics reduced to independent
/// coordinates (`reduced_dynamics`, [Hardt 2002, eq. 7]) give the same q̈.
///
/// ```
/// # use legkit_dynamics::algorithms::{self, ContactDim, ContactPoint};
/// # use legkit_dynamics::{Data, MassProperties, Model};
/// # use nalgebra::{DVector, Matrix3, Vector3};
/// # let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
/// # let model = Model::new(true, body, "box");
/// # let mut data = Data::new(&model);
/// let q = [0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 1.0];
/// let corner = [ContactPoint { body: 0, point: Vector3::new(0.15, 0.1, -0.05) }];
/// let (spin, pivot) = (Vector3::new(0.0, 0.5, 0.0), corner[0].point);
/// let drift = -spin.cross(&pivot);
/// let v = [drift.x, drift.y, drift.z, spin.x, spin.y, spin.z];
/// let pivoting = algorithms::contact_dynamics(&model, &mut data, &q, &v, &[0.0; 6], &corner, ContactDim::Point)?;
/// let mut corner_acceleration = [1.0; 3];
/// let ddq = Some(pivoting.ddq.as_slice());
/// algorithms::point_accelerations(&model, &mut data, &q, &v, ddq, &corner, ContactDim::Point, &mut corner_acceleration)?;
/// assert!(corner_acceleration.iter().all(|a| a.abs() < 1e-12));
/// let reduced = algorithms::reduced_dynamics(&model, &mut data, &q, &v, &[0.0; 6], &corner, None)?;
/// assert!((reduced.ddq - &pivoting.ddq).amax() < 1e-10);
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn reduced_dynamics(
    model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64], contacts: &[ContactPoint], independent: Option<&[usize]>,
) -> Result<ReducedDynamics> {
    check_state(model, data, q, &[("v", v), ("tau", tau)])?;
    check_contacts(model, contacts)?;
    let nv = model.nv();
    let mass = crba_unchecked(model, data, q).clone();
    let bias = rnea_unchecked(model, data, q, v, &vec![0.0; nv], None).clone();
    if mass.clone().cholesky().is_none() {
        return Err(singular_mass_matrix());
    }
    let (jc, gamma) = with_workspace(data, |data, w| {
        constraint(model, data, w, q, v, contacts, ContactDim::Point)?;
        Ok((DMatrix::from_column_slice(w.shape.0, nv, &w.jacobian), DVector::from_column_slice(&w.drift)))
    })?;
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
