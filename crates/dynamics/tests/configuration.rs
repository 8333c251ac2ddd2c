//! `difference` and the Jacobians of `integrate` and `difference` on random trees (every joint kind, fixed and
//! floating bases): the round trip q0 ⊕ (q1 ⊖ q0) = q1, and the Jacobians against central differences, inputs
//! perturbed on their tangent spaces with `integrate` and configurations measured with `difference`; then the free
//! flyer at rotation angles near 0, at the series' switch, near π and at 2π. The comparison with Pinocchio is in
//! the Python suite (tests/test_configuration_jacobians.py).

use legkit_dynamics::algorithms::{difference, difference_jacobians, integrate, integrate_jacobians};
use legkit_dynamics::Model;
use nalgebra::{DMatrix, DVector, Unit, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "fixtures/trees.rs"]
mod trees;
use trees::{random_body, random_case, random_state, random_tree, unit};

const STEP: f64 = 1e-6;

fn integrated(model: &Model, q: &[f64], v: &[f64], dt: f64) -> Vec<f64> {
    let mut out = vec![0.0; model.nq()];
    integrate(model, q, v, dt, &mut out).unwrap();
    out
}

fn differenced(model: &Model, q0: &[f64], q1: &[f64]) -> DVector<f64> {
    let mut out = DVector::zeros(model.nv());
    difference(model, q0, q1, out.as_mut_slice()).unwrap();
    out
}

/// q ⊕ h e_j.
fn stepped_q(model: &Model, q: &[f64], j: usize, h: f64) -> Vec<f64> {
    integrated(model, q, DVector::<f64>::from_fn(model.nv(), |k, _| if k == j { 1.0 } else { 0.0 }).as_slice(), h)
}

fn stepped(x: &[f64], j: usize, h: f64) -> Vec<f64> {
    let mut out = x.to_vec();
    out[j] += h;
    out
}

/// Column j is (f(j, h) − f(j, −h)) / 2h, f measured in a tangent space.
fn central_differences(nv: usize, mut f: impl FnMut(usize, f64) -> DVector<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(nv, nv);
    for j in 0..nv {
        out.set_column(j, &((f(j, STEP) - f(j, -STEP)) / (2.0 * STEP)));
    }
    out
}

fn jacobians_of_integrate(model: &Model, v: &[f64], dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let (mut dq, mut dv) = (DMatrix::from_element(model.nv(), model.nv(), f64::NAN), DMatrix::from_element(model.nv(), model.nv(), f64::NAN));
    integrate_jacobians(model, v, dt, &mut dq, &mut dv).unwrap();
    (dq, dv)
}

fn jacobians_of_difference(model: &Model, q0: &[f64], q1: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
    let (mut d0, mut d1) = (DMatrix::from_element(model.nv(), model.nv(), f64::NAN), DMatrix::from_element(model.nv(), model.nv(), f64::NAN));
    difference_jacobians(model, q0, q1, &mut d0, &mut d1).unwrap();
    (d0, d1)
}

fn assert_close(got: &DMatrix<f64>, want: &DMatrix<f64>, tolerance: f64, what: &str) {
    let error = (got - want).amax();
    assert!(error <= tolerance * want.amax().max(1.0), "{what}: error {error:.3e}\ngot {got:.9}\nwant {want:.9}");
}

/// Checks all four Jacobians at (q0, v, dt) and at (q0, q1 = q0 ⊕ v dt) against central differences, and the
/// chain rules that tie them: ∂⊖/∂q1 ∂⊕/∂v = dt and ∂⊖/∂q0 = −∂⊖/∂q1 ∂⊕/∂q, while the angle stays below π.
fn check_jacobians(model: &Model, q0: &[f64], v: &[f64], dt: f64, what: &str) {
    let nv = model.nv();
    let q1 = integrated(model, q0, v, dt);
    let (dq, dv) = jacobians_of_integrate(model, v, dt);
    let slope_of_integrate = |from: &[f64], to: &[f64]| differenced(model, &q1, &integrated(model, from, to, dt));
    assert_close(&dq, &central_differences(nv, |j, h| slope_of_integrate(&stepped_q(model, q0, j, h), v)), 1e-8, &format!("{what}: ∂⊕/∂q"));
    assert_close(&dv, &central_differences(nv, |j, h| slope_of_integrate(q0, &stepped(v, j, h))), 1e-8, &format!("{what}: ∂⊕/∂v"));
    let (d0, d1) = jacobians_of_difference(model, q0, &q1);
    let want_d0 = central_differences(nv, |j, h| differenced(model, &stepped_q(model, q0, j, h), &q1));
    let want_d1 = central_differences(nv, |j, h| differenced(model, q0, &stepped_q(model, &q1, j, h)));
    assert_close(&d0, &want_d0, 1e-8, &format!("{what}: ∂⊖/∂q0"));
    assert_close(&d1, &want_d1, 1e-8, &format!("{what}: ∂⊖/∂q1"));
    assert_close(&(&d1 * &dv), &(DMatrix::identity(nv, nv) * dt), 1e-12, &format!("{what}: ∂⊖/∂q1 ∂⊕/∂v"));
    assert_close(&d0, &-(&d1 * &dq), 1e-12, &format!("{what}: ∂⊖/∂q0"));
}

/// The same configuration: equal coordinates, the quaternions up to their sign.
fn assert_same_configuration(model: &Model, got: &[f64], want: &[f64], what: &str) {
    let mut aligned = got.to_vec();
    for i in 0..model.nbodies() {
        let Some(quaternion) = model.joint(i).quaternion_coordinates() else { continue };
        let k = model.idx_q(i) + quaternion.start..model.idx_q(i) + quaternion.end;
        if k.clone().map(|k| got[k] * want[k]).sum::<f64>() < 0.0 {
            aligned[k].iter_mut().for_each(|x| *x = -*x);
        }
    }
    let error = aligned.iter().zip(want).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(error < 1e-12, "{what}: error {error:.3e}\ngot {got:?}\nwant {want:?}");
}

#[test]
fn integrate_inverts_difference_and_difference_inverts_integrate() {
    let mut rng = StdRng::seed_from_u64(11);
    for case in 0..60 {
        let (model, _, q0, v) = random_case(&mut rng, case);
        let (q1, _) = random_state(&mut rng, &model);
        let (q0, q1) = (q0.as_slice(), q1.as_slice());
        let v01 = differenced(&model, q0, q1);
        assert_same_configuration(&model, &integrated(&model, q0, v01.as_slice(), 1.0), q1, &format!("case {case}: q0 ⊕ (q1 ⊖ q0)"));
        // Within the logarithm's range (angle < π) ⊖ undoes ⊕ exactly.
        let v = v * 0.5;
        let back = differenced(&model, q0, &integrated(&model, q0, v.as_slice(), 1.0));
        assert!((back - &v).amax() < 1e-12, "case {case}: (q0 ⊕ v) ⊖ q0");
    }
}

#[test]
fn jacobians_are_the_slopes_on_random_trees() {
    let mut rng = StdRng::seed_from_u64(12);
    for case in 0..40 {
        let (model, _, q0, v) = random_case(&mut rng, case);
        // v dt of angle below π, where ⊖ is the inverse of ⊕ (the chain rules).
        let dt = rng.random_range(0.05..0.8);
        check_jacobians(&model, q0.as_slice(), v.as_slice(), dt, &format!("case {case}"));
    }
}

/// A free-flying base alone, q0 a random pose, and v of angle `angle` about a random axis (dt = 1).
fn base_at_angle(rng: &mut StdRng, angle: f64) -> (Model, Vec<f64>, Vec<f64>) {
    let model = random_tree(rng, 0, true);
    let (q0, _) = random_state(rng, &model);
    let axis = unit(rng);
    let linear = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
    let v: Vec<f64> = linear.iter().chain((axis * angle).iter()).copied().collect();
    (model, q0.as_slice().to_vec(), v)
}

#[test]
fn free_flyer_jacobians_near_zero_angle_and_at_the_series_switch() {
    let mut rng = StdRng::seed_from_u64(13);
    for angle in [0.0, 1e-300, 1e-12, 1e-8, 1e-5, 1e-3, 0.05, 0.1 * (1.0 - 1e-9), 0.1 * (1.0 + 1e-9), 0.3] {
        let (model, q0, v) = base_at_angle(&mut rng, angle);
        check_jacobians(&model, &q0, &v, 1.0, &format!("angle {angle:e}"));
    }
    // At q1 = q0 the difference's Jacobians are −1 and 1.
    let (model, q0, _) = base_at_angle(&mut rng, 0.0);
    let (d0, d1) = jacobians_of_difference(&model, &q0, &q0);
    assert_close(&d0, &-DMatrix::identity(6, 6), 1e-15, "∂⊖/∂q0 at q1 = q0");
    assert_close(&d1, &DMatrix::identity(6, 6), 1e-15, "∂⊖/∂q1 at q1 = q0");
}

#[test]
fn free_flyer_jacobians_near_pi_and_beyond() {
    let mut rng = StdRng::seed_from_u64(14);
    // Central differences stay on one side of π up to 1e-3 from it.
    for angle in [2.0, 3.0, std::f64::consts::PI - 1e-3] {
        let (model, q0, v) = base_at_angle(&mut rng, angle);
        check_jacobians(&model, &q0, &v, 1.0, &format!("angle {angle}"));
    }
    // Closer to π, the chain rule: the log's Jacobian inverts exp's.
    for gap in [1e-6, 1e-9, 0.0] {
        let (model, q0, v) = base_at_angle(&mut rng, std::f64::consts::PI - gap);
        let q1 = integrated(&model, &q0, &v, 1.0);
        let ((dq, dv), (d0, d1)) = (jacobians_of_integrate(&model, &v, 1.0), jacobians_of_difference(&model, &q0, &q1));
        assert!(d0.iter().chain(d1.iter()).all(|x| x.is_finite()), "π − {gap:e}: {d0} {d1}");
        if gap > 0.0 {
            assert_close(&(&d1 * &dv), &DMatrix::identity(6, 6), 1e-9, &format!("π − {gap:e}: ∂⊖/∂q1 ∂⊕/∂v"));
            assert_close(&d0, &-(&d1 * &dq), 1e-9, &format!("π − {gap:e}: ∂⊖/∂q0"));
        }
        assert_same_configuration(&model, &integrated(&model, &q0, differenced(&model, &q0, &q1).as_slice(), 1.0), &q1, &format!("π − {gap:e}"));
    }
    // exp's Jacobian has no singularity at 2π (Pinocchio's Jexp6 divides by 1 − cos θ there).
    for angle in [2.0 * std::f64::consts::PI, 5.0] {
        let (model, q0, v) = base_at_angle(&mut rng, angle);
        let (dq, dv) = jacobians_of_integrate(&model, &v, 1.0);
        let q1 = integrated(&model, &q0, &v, 1.0);
        let slope = |to: &[f64]| differenced(&model, &q1, &integrated(&model, &q0, to, 1.0));
        assert_close(&dv, &central_differences(6, |j, h| slope(&stepped(&v, j, h))), 1e-8, &format!("angle {angle}: ∂⊕/∂v"));
        assert!(dq.iter().all(|x| x.is_finite()));
    }
}

#[test]
fn the_rotation_of_the_difference_is_the_relative_rotation() {
    // q1 ⊖ q0 for two bases turned about one axis by a and b: the angular part is (b − a) about that axis, in q0's frame.
    let model = Model::new(true, random_body(&mut StdRng::seed_from_u64(15)), "base");
    let axis = Unit::new_normalize(Vector3::new(0.2, -0.5, 0.8));
    let pose = |angle: f64| {
        let r = UnitQuaternion::from_axis_angle(&axis, angle);
        vec![0.0, 0.0, 0.0, r.i, r.j, r.k, r.w]
    };
    let v = differenced(&model, &pose(0.4), &pose(1.5));
    assert!((v.fixed_rows::<3>(3) - axis.into_inner() * 1.1).amax() < 1e-14 && v.fixed_rows::<3>(0).amax() == 0.0, "{v}");
}
