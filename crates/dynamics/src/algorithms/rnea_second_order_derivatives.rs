//! Second-order derivatives of inverse dynamics (Singh, Russell & Wensing, "Analytical second-order partial
//! derivatives of rigid-body inverse dynamics", IROS 2022; Pinocchio's `ComputeRNEASecondOrderDerivatives`):
//! ∂²τ/∂q², ∂²τ/∂q̇², ∂²τ/∂q∂q̇ and ∂²τ/∂q̈∂q = ∂M/∂q, nv x nv x nv each, q on its tangent space.
//!
//! The forward pass is the first derivatives' (`rnea_derivatives::forward_pass`): per velocity coordinate its
//! joint's S, ψ̇ = v_λ × S, ψ̈ = a_λ × S + v_λ × ψ̇ and ψ̇ + φ̇ = ∂a/∂q̇ (φ̇ = v × S); per body its inertia I, rate
//! matrix B (`RigidInertia::rate_matrix`) and net force f. The backward pass sums I, B and f over subtrees and, for
//! each coordinate p of body i, each coordinate j on i's support and each k on j's, writes the tensor entries that
//! involve (p, j, k) (the paper's Algorithm 2, in Pinocchio's order). Everything is in the centred frame.

use nalgebra::{Matrix6, Vector6};

use super::checks::{check_state, finite_result};
use super::rnea_derivatives::{column, forward_pass};
use crate::model::Dense;
use crate::model::{Data, Model, SecondOrder};
use crate::spatial::{cross_force, Force, Motion};
use crate::Result;

/// m ↦ m ×* f as a matrix (Pinocchio's `ForceCrossMatrix`; the paper's f×̄).
fn bar(f: &Force) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    let (l, a) = (f.fixed_rows::<3>(0).cross_matrix(), f.fixed_rows::<3>(3).cross_matrix());
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&-l);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&-l);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&-a);
    m
}

/// m ↦ s × m as a matrix.
fn motion_cross(s: &Motion) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    let (l, a) = (s.fixed_rows::<3>(0).cross_matrix(), s.fixed_rows::<3>(3).cross_matrix());
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&l);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&a);
    m
}

/// The rate of an inertia carried with velocity s: s ×* I − I s× (Pinocchio's `Inertia::variation`).
fn variation(inertia: &Matrix6<f64>, s: &Motion) -> Matrix6<f64> {
    let cross = motion_cross(s);
    -cross.transpose() * inertia - inertia * cross
}

/// The velocity coordinates of body `i`'s joint.
fn coordinates(model: &Model, i: usize) -> std::ops::Range<usize> {
    let k = model.idx_v(i);
    k..k + model.joint(i).nv()
}

/// Fills `data.derivatives.second_order` with the second derivatives of `rnea(q, v, a)` (no external forces) and
/// returns them.
///
/// # Examples
///
/// On a double pendulum (two 1 kg links 0.4 m long, hinged about y; built in the hidden lines), against central
/// differences: ∂M/∂q (`dadq`, entry (i, j, k) = ∂M_ij/∂q_k at (i nv + j) nv + k) of `crba`'s M, and ∂²τ/∂q̇² (`dvdv`)
/// of `rnea_derivatives`' ∂τ/∂q̇.
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
/// let (q, v, a, nv, h) = ([0.3, -0.5], [1.0, 2.0], [-3.0, 0.5], 2, 1e-6);
/// let second = algorithms::rnea_second_order_derivatives(&model, &mut data, &q, &v, &a)?.clone();
/// for k in 0..nv {
///     let plus = algorithms::crba(&model, &mut data, &nudge(q, k, h))?.clone();
///     let by_q = (plus - algorithms::crba(&model, &mut data, &nudge(q, k, -h))?) / (2.0 * h);
///     let plus = algorithms::rnea_derivatives(&model, &mut data, &q, &nudge(v, k, h), &a, None)?.1.clone();
///     let by_v = (plus - algorithms::rnea_derivatives(&model, &mut data, &q, &nudge(v, k, -h), &a, None)?.1) / (2.0 * h);
///     for (i, j) in (0..nv).flat_map(|i| (0..nv).map(move |j| (i, j))) {
///         assert!((second.dadq[(i * nv + j) * nv + k] - by_q[(i, j)]).abs() < 1e-8);
///         assert!((second.dvdv[(i * nv + j) * nv + k] - by_v[(i, j)]).abs() < 1e-8);
///     }
/// }
/// # Ok::<(), legkit_dynamics::Error>(())
/// ```
pub fn rnea_second_order_derivatives<'d>(model: &Model, data: &'d mut Data, q: &[f64], v: &[f64], a: &[f64]) -> Result<&'d SecondOrder> {
    check_state(model, data, q, &[("v", v), ("a", a)])?;
    data.reserve_dense(model, &[Dense::SecondOrder])?;
    let (n, nv) = (model.nbodies(), model.nv());
    forward_pass(model, data, q, v, a, model.gravity_bias());
    let d = &mut data.derivatives;
    // Which entries the passes write depends on the tree alone, so the others stay zero from the first call on.
    for tensor in [&mut d.second_order.dqdq, &mut d.second_order.dvdv, &mut d.second_order.dqdv, &mut d.second_order.dadq] {
        if tensor.len() != nv * nv * nv {
            *tensor = vec![0.0; nv * nv * nv];
        }
    }
    let at = |i: usize, j: usize, k: usize| (i * nv + j) * nv + k;
    for i in (0..n).rev() {
        let inertia = d.composite[i].matrix();
        let rate = d.rate[i].matrix();
        let force = d.force[i];
        for ip in coordinates(model, i) {
            let (s_i, psid_i, psidd_i, dadv_i) = (column(&d.subspace, ip), column(&d.dv_dq, ip), column(&d.da_dq, ip), column(&d.da_dv, ip));
            let r0 = bar(&(inertia * s_i));
            let r1 = variation(&inertia, &s_i);
            let bic_phi = r1 + r0;
            let bic_psid = variation(&inertia, &psid_i) + bar(&(inertia * psid_i));
            let r2 = 2.0 * r0 - bic_phi;
            let s_cross = motion_cross(&s_i);
            let r3 = bic_psid - s_cross.transpose() * rate - rate * s_cross;
            let r4 = bar(&(rate.transpose() * s_i));
            let r5 = bar(&(rate * psid_i + cross_force(&s_i, &force) + inertia * psidd_i));
            let r6 = r0 - s_cross.transpose() * inertia;
            let r7 = bar(&(rate * s_i + inertia * dadv_i));
            let mut j = i;
            loop {
                for jq in coordinates(model, j) {
                    let (s_j, psid_j, psidd_j, dadv_j) = (column(&d.subspace, jq), column(&d.dv_dq, jq), column(&d.da_dq, jq), column(&d.da_dv, jq));
                    let u1: Vector6<f64> = r3.tr_mul(&s_j);
                    let u2: Vector6<f64> = r1.tr_mul(&s_j);
                    let u3 = r3 * psid_j + r1 * psidd_j + r5 * s_j;
                    let u4 = r6 * s_j;
                    let u5 = r2 * psid_j;
                    let u6 = bic_phi * psid_j + r7 * s_j;
                    let u7 = r3 * s_j + r1 * dadv_j;
                    let u8 = r4 * s_j;
                    let u9 = r0 * s_j;
                    let u10 = bic_phi * s_j;
                    let u11: Vector6<f64> = bic_phi.tr_mul(&s_j);
                    let u12: Vector6<f64> = bic_phi.tr_mul(&psid_j);
                    let u13 = r1 * s_j;
                    let t = &mut d.second_order;
                    let mut k = j;
                    loop {
                        for kr in coordinates(model, k) {
                            let (s_k, psid_k, psidd_k, dadv_k) =
                                (column(&d.subspace, kr), column(&d.dv_dq, kr), column(&d.da_dq, kr), column(&d.da_dv, kr));
                            let p1 = u11.dot(&psid_k);
                            let p2 = u9.dot(&psidd_k) + (u8 - u12).dot(&psid_k);
                            t.dqdq[at(ip, jq, kr)] = p2;
                            t.dqdv[at(ip, kr, jq)] = -p1;
                            if j != i {
                                let p3 = -u11.dot(&s_k);
                                let p4 = s_k.dot(&u13);
                                let dqdq = u1.dot(&psid_k) + u2.dot(&psidd_k);
                                t.dqdq[at(jq, kr, ip)] = dqdq;
                                t.dqdq[at(jq, ip, kr)] = dqdq;
                                t.dqdv[at(jq, kr, ip)] = p1;
                                t.dqdv[at(jq, ip, kr)] = u1.dot(&s_k) + u2.dot(&dadv_k);
                                t.dvdv[at(jq, kr, ip)] = -p3;
                                t.dvdv[at(jq, ip, kr)] = -p3;
                                t.dadq[at(kr, jq, ip)] = p4;
                                t.dadq[at(jq, kr, ip)] = p4;
                            }
                            if k != j {
                                let p3 = -u11.dot(&s_k);
                                let p5 = s_k.dot(&u9);
                                let dqdq = s_k.dot(&u3);
                                t.dqdq[at(ip, kr, jq)] = p2;
                                t.dqdq[at(kr, ip, jq)] = dqdq;
                                t.dvdv[at(ip, jq, kr)] = p3;
                                t.dvdv[at(ip, kr, jq)] = p3;
                                t.dqdv[at(ip, jq, kr)] = s_k.dot(&(u5 + u8)) + u9.dot(&dadv_k);
                                t.dqdv[at(kr, jq, ip)] = s_k.dot(&u6);
                                t.dadq[at(kr, ip, jq)] = p5;
                                t.dadq[at(ip, kr, jq)] = p5;
                                if j != i {
                                    let p6 = s_k.dot(&u10);
                                    t.dqdq[at(kr, jq, ip)] = dqdq;
                                    t.dvdv[at(kr, ip, jq)] = p6;
                                    t.dvdv[at(kr, jq, ip)] = p6;
                                    t.dqdv[at(kr, ip, jq)] = s_k.dot(&u7);
                                } else {
                                    t.dvdv[at(kr, jq, ip)] = s_k.dot(&u4);
                                }
                            } else {
                                t.dvdv[at(ip, jq, kr)] = -u2.dot(&s_k);
                            }
                        }
                        if k == 0 {
                            break;
                        }
                        k = model.parent(k);
                    }
                }
                if j == 0 {
                    break;
                }
                j = model.parent(j);
            }
        }
        if i > 0 {
            let p = model.parent(i);
            let (composite, rate, force) = (d.composite[i], d.rate[i], d.force[i]);
            d.composite[p] += composite;
            d.rate[p] += rate;
            d.force[p] += force;
        }
    }
    let second = &data.derivatives.second_order;
    for tensor in [&second.dqdq, &second.dvdv, &second.dqdv, &second.dadq] {
        finite_result(tensor)?;
    }
    Ok(second)
}
