//! The analytic derivatives against central differences of the kernels they differentiate, on random trees
//! (every joint kind, fixed and floating bases, armature, external forces), q stepped on its tangent space
//! (q ⊕ ε e_j, as `integrate`). The differential tests against Pinocchio are in the Python suite.

use legkit_dynamics::algorithms::{
    aba, aba_derivatives, contact_dynamics, contact_dynamics_derivatives, frame_acceleration, frame_acceleration_derivatives, frame_velocity,
    frame_velocity_derivatives, impact, impact_derivatives, integrate, jacobian, jacobian_time_variation, rnea, rnea_derivatives, ContactDim,
    ContactPoint, Frame,
};
use legkit_dynamics::spatial::Force;
use legkit_dynamics::{Data, Model};
use nalgebra::{DMatrix, DVector, Matrix6xX, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "fixtures/trees.rs"]
mod trees;
use trees::{random_case, random_state, random_tree};

#[path = "fixtures/slopes.rs"]
mod slopes;
use slopes::{assert_close, assert_close_conditioned, central_differences, stepped, stepped_q, STEP};

fn random_forces(rng: &mut StdRng, model: &Model) -> Vec<Force> {
    (0..model.nbodies()).map(|_| Force::from_fn(|_, _| rng.random_range(-5.0..5.0))).collect()
}

#[test]
fn rnea_derivatives_are_the_slopes_of_rnea() {
    let mut rng = StdRng::seed_from_u64(3);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let nv = model.nv();
        let a: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
        let forces = random_forces(&mut rng, &model);
        let f_ext = (case % 3 == 0).then_some(forces.as_slice());
        let (q, v) = (q.as_slice(), v.as_slice());
        let (dq, dv) = rnea_derivatives(&model, &mut data, q, v, &a, f_ext).unwrap();
        let (dq, dv) = (dq.clone(), dv.clone());
        let mut scratch = Data::new(&model);
        let want_dq = central_differences(nv, |j, h| rnea(&model, &mut scratch, &stepped_q(&model, q, j, h), v, &a, f_ext).unwrap().clone());
        let want_dv = central_differences(nv, |j, h| rnea(&model, &mut scratch, q, &stepped(v, j, h), &a, f_ext).unwrap().clone());
        assert_close(&dq, &want_dq, &format!("case {case}: dtau/dq"));
        assert_close(&dv, &want_dv, &format!("case {case}: dtau/dv"));
    }
}

/// `aba_derivatives` against central differences of `aba` for one case.
fn check_aba_derivatives(rng: &mut StdRng, case: usize, model: &Model, data: &mut Data, q: &[f64], v: &[f64]) {
    let nv = model.nv();
    let tau: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
    let forces = random_forces(rng, model);
    let f_ext = (case % 3 == 1).then_some(forces.as_slice());
    let (dq, dv, dtau) = aba_derivatives(model, data, q, v, &tau, f_ext).unwrap();
    let (dq, dv, dtau) = (dq.clone(), dv.clone(), dtau.clone());
    let mut scratch = Data::new(model);
    let ddq = aba(model, &mut scratch, q, v, &tau, f_ext).unwrap().clone();
    assert_eq!(data.ddq, ddq, "case {case}: aba_derivatives leaves q̈ in data.ddq");
    let want_dq = central_differences(nv, |j, h| aba(model, &mut scratch, &stepped_q(model, q, j, h), v, &tau, f_ext).unwrap().clone());
    let want_dv = central_differences(nv, |j, h| aba(model, &mut scratch, q, &stepped(v, j, h), &tau, f_ext).unwrap().clone());
    let want_dtau = central_differences(nv, |j, h| aba(model, &mut scratch, q, v, &stepped(&tau, j, h), f_ext).unwrap().clone());
    assert_close(&dq, &want_dq, &format!("case {case}: dddq/dq"));
    assert_close(&dv, &want_dv, &format!("case {case}: dddq/dv"));
    assert_close(&dtau, &want_dtau, &format!("case {case}: dddq/dtau"));
}

#[test]
fn aba_derivatives_are_the_slopes_of_aba() {
    let mut rng = StdRng::seed_from_u64(5);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        check_aba_derivatives(&mut rng, case, &model, &mut data, q.as_slice(), v.as_slice());
    }
}

/// Beyond 32 degrees of freedom the products by M⁻¹ are solves with the articulated-body factors.
#[test]
fn aba_derivatives_on_large_trees_are_the_slopes_of_aba() {
    let mut rng = StdRng::seed_from_u64(6);
    for case in 0..4 {
        let model = random_tree(&mut rng, 45, case % 2 == 0);
        assert!(model.nv() > 32, "case {case}: nv {}", model.nv());
        let (q, v) = random_state(&mut rng, &model);
        check_aba_derivatives(&mut rng, case, &model, &mut Data::new(&model), q.as_slice(), v.as_slice());
    }
}

const FRAMES: [Frame; 3] = [Frame::Local, Frame::World, Frame::LocalWorldAligned];

fn dense(m: &Matrix6xX<f64>) -> DMatrix<f64> {
    DMatrix::from_column_slice(6, m.ncols(), m.as_slice())
}

/// A random body of `model` and a point on it.
fn random_frame(rng: &mut StdRng, model: &Model) -> (usize, Vector3<f64>) {
    (rng.random_range(0..model.nbodies()), Vector3::from_fn(|_, _| rng.random_range(-0.5..0.5)))
}

#[test]
fn frame_velocity_and_acceleration_derivatives_are_their_slopes() {
    let mut rng = StdRng::seed_from_u64(7);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let nv = model.nv();
        let a: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
        let (body, point) = random_frame(&mut rng, &model);
        let (q, v, point) = (q.as_slice(), v.as_slice(), &point);
        let mut scratch = Data::new(&model);
        for frame in FRAMES {
            let what = |name: &str| format!("case {case}, body {body}, {frame:?}: {name}");
            let (v_dq, v_dv) = frame_velocity_derivatives(&model, &mut data, q, v, body, point, frame).unwrap();
            let (v_dq, v_dv) = (dense(v_dq), dense(v_dv));
            let mut velocity =
                |q: &[f64], v: &[f64]| DVector::from_column_slice(frame_velocity(&model, &mut scratch, q, v, body, point, frame).unwrap().as_slice());
            assert_close(&v_dq, &central_differences(nv, |j, h| velocity(&stepped_q(&model, q, j, h), v)), &what("dv/dq"));
            assert_close(&v_dv, &central_differences(nv, |j, h| velocity(q, &stepped(v, j, h))), &what("dv/dv"));
            let j = dense(jacobian(&model, &mut scratch, q, body, point, frame).unwrap());
            assert_close(&v_dv, &j, &what("dv/dv = J"));

            let (a_v_dq, a_dq, a_dv, a_da) = frame_acceleration_derivatives(&model, &mut data, q, v, &a, body, point, frame).unwrap();
            let (a_v_dq, a_dq, a_dv, a_da) = (dense(a_v_dq), dense(a_dq), dense(a_dv), dense(a_da));
            assert_close(&a_v_dq, &v_dq, &what("dv/dq beside the acceleration's"));
            let mut acceleration = |q: &[f64], v: &[f64], a: &[f64]| {
                DVector::from_column_slice(frame_acceleration(&model, &mut scratch, q, v, a, body, point, frame).unwrap().as_slice())
            };
            assert_close(&a_dq, &central_differences(nv, |j, h| acceleration(&stepped_q(&model, q, j, h), v, &a)), &what("da/dq"));
            assert_close(&a_dv, &central_differences(nv, |j, h| acceleration(q, &stepped(v, j, h), &a)), &what("da/dv"));
            assert_close(&a_da, &central_differences(nv, |j, h| acceleration(q, v, &stepped(&a, j, h))), &what("da/da"));
        }
    }
}

#[test]
fn the_jacobian_time_variation_is_the_jacobians_slope_along_the_velocity() {
    let mut rng = StdRng::seed_from_u64(11);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let (body, point) = random_frame(&mut rng, &model);
        let (q, v) = (q.as_slice(), v.as_slice());
        let mut scratch = Data::new(&model);
        for frame in FRAMES {
            let rate = dense(jacobian_time_variation(&model, &mut data, q, v, body, &point, frame).unwrap());
            let mut along = |h: f64| {
                let mut moved = vec![0.0; model.nq()];
                integrate(&model, q, v, h, &mut moved).unwrap();
                dense(jacobian(&model, &mut scratch, &moved, body, &point, frame).unwrap())
            };
            let want = (along(-2.0 * STEP) - along(-STEP) * 8.0 + along(STEP) * 8.0 - along(2.0 * STEP)) / (12.0 * STEP);
            assert_close(&rate, &want, &format!("case {case}, body {body}, {frame:?}: dJ/dt"));
        }
    }
}

/// Up to three contacts on distinct random bodies of `model` (at most nv rows).
fn random_contacts(rng: &mut StdRng, model: &Model, dim: ContactDim) -> Vec<ContactPoint> {
    let count = rng.random_range(1..=3).min(model.nv() / dim.rows()).min(model.nbodies());
    let mut bodies: Vec<usize> = (0..model.nbodies()).collect();
    (0..count)
        .map(|_| {
            let body = bodies.swap_remove(rng.random_range(0..bodies.len()));
            ContactPoint { body, point: Vector3::from_fn(|_, _| rng.random_range(-0.5..0.5)) }
        })
        .collect()
}

/// The condition number of J M⁻¹ Jᵀ, the contacts' KKT system's Schur complement.
fn contact_condition(model: &Model, q: &[f64], contacts: &[ContactPoint], dim: ContactDim) -> f64 {
    let mut data = Data::new(model);
    let rows: Vec<DMatrix<f64>> = contacts
        .iter()
        .map(|c| dense(jacobian(model, &mut data, q, c.body, &c.point, Frame::LocalWorldAligned).unwrap()).rows(0, dim.rows()).into_owned())
        .collect();
    let j = DMatrix::from_rows(&rows.iter().flat_map(|r| r.row_iter().map(|x| x.into_owned()).collect::<Vec<_>>()).collect::<Vec<_>>());
    let mass = legkit_dynamics::algorithms::crba(model, &mut data, q).unwrap().clone();
    let schur = &j * mass.cholesky().unwrap().solve(&j.transpose());
    let eigenvalues = schur.symmetric_eigen().eigenvalues;
    eigenvalues.max() / eigenvalues.min()
}

fn stacked(a: &DVector<f64>, b: &DVector<f64>) -> DVector<f64> {
    DVector::from_iterator(a.len() + b.len(), a.iter().chain(b.iter()).copied())
}

/// Runs `check(rng, case, model, data, q, v, contacts)` on 80 random trees with up to three random contacts each, of
/// each `ContactDim` (`Frame` needs six coordinates per contact: on fewer trees); it returns false for dependent
/// contacts, which the derivatives refuse, and most are independent.
fn for_contact_cases(
    seed: u64, dim: ContactDim, mut check: impl FnMut(&mut StdRng, usize, &Model, &mut Data, &[f64], &[f64], &[ContactPoint]) -> bool,
) {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut checked = 0;
    for case in 0..80 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let contacts = random_contacts(&mut rng, &model, dim);
        if !contacts.is_empty() && check(&mut rng, case, &model, &mut data, q.as_slice(), v.as_slice(), &contacts) {
            checked += 1;
        }
    }
    let wanted = if dim == ContactDim::Point { 35 } else { 15 };
    assert!(checked >= wanted, "only {checked} cases had independent contacts ({dim:?})");
}

#[test]
fn contact_dynamics_derivatives_are_its_slopes() {
    for dim in [ContactDim::Point, ContactDim::Frame] {
        contact_dynamics_derivatives_are_slopes(dim);
    }
}

fn contact_dynamics_derivatives_are_slopes(dim: ContactDim) {
    for_contact_cases(13, dim, |rng, case, model, data, q, v, contacts| {
        let nv = model.nv();
        let tau: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
        let Ok(got) = contact_dynamics_derivatives(model, data, q, v, &tau, contacts, dim) else { return false };
        let mut scratch = Data::new(model);
        let solved = contact_dynamics(model, &mut scratch, q, v, &tau, contacts, dim).unwrap();
        let condition = contact_condition(model, q, contacts, dim);
        let what = |name: &str| format!("case {case}, {} contacts {dim:?} (condition {condition:.1e}): {name}", contacts.len());
        assert_close(&DMatrix::from_column_slice(nv, 1, got.ddq.as_slice()), &DMatrix::from_column_slice(nv, 1, solved.ddq.as_slice()), &what("ddq"));
        let mut both = |q: &[f64], v: &[f64], tau: &[f64]| {
            let s = contact_dynamics(model, &mut scratch, q, v, tau, contacts, dim).unwrap();
            stacked(&s.ddq, &s.forces)
        };
        let want_dq = central_differences(nv, |j, h| both(&stepped_q(model, q, j, h), v, &tau));
        let want_dv = central_differences(nv, |j, h| both(q, &stepped(v, j, h), &tau));
        let want_dtau = central_differences(nv, |j, h| both(q, v, &stepped(&tau, j, h)));
        for (got_ddq, got_forces, want, name) in [
            (&got.ddq_dq, &got.forces_dq, want_dq, "q"),
            (&got.ddq_dv, &got.forces_dv, want_dv, "v"),
            (&got.ddq_dtau, &got.forces_dtau, want_dtau, "tau"),
        ] {
            assert_close_conditioned(got_ddq, &want.rows(0, nv).into_owned(), condition, &what(&format!("ddq/d{name}")));
            assert_close_conditioned(got_forces, &want.rows(nv, want.nrows() - nv).into_owned(), condition, &what(&format!("forces/d{name}")));
        }
        true
    });
}

#[test]
fn impact_derivatives_are_its_slopes() {
    for dim in [ContactDim::Point, ContactDim::Frame] {
        impact_derivatives_are_slopes(dim);
    }
}

fn impact_derivatives_are_slopes(dim: ContactDim) {
    for_contact_cases(17, dim, |_, case, model, data, q, v, contacts| {
        let nv = model.nv();
        let Ok(got) = impact_derivatives(model, data, q, v, contacts, dim) else { return false };
        let mut scratch = Data::new(model);
        let mut both = |q: &[f64], v: &[f64]| {
            let (after, impulses) = impact(model, &mut scratch, q, v, contacts, dim).unwrap();
            stacked(&after, &impulses)
        };
        let at = both(q, v);
        let what = |name: &str| format!("case {case}, {} contacts {dim:?}: {name}", contacts.len());
        assert_close(
            &DMatrix::from_column_slice(nv, 1, got.velocity.as_slice()),
            &DMatrix::from_column_slice(nv, 1, &at.as_slice()[..nv]),
            &what("v+"),
        );
        let want_dq = central_differences(nv, |j, h| both(&stepped_q(model, q, j, h), v));
        let want_dv = central_differences(nv, |j, h| both(q, &stepped(v, j, h)));
        for (got_v, got_impulses, want, name) in
            [(&got.velocity_dq, &got.impulses_dq, want_dq, "q"), (&got.velocity_dv, &got.impulses_dv, want_dv, "v")]
        {
            assert_close(got_v, &want.rows(0, nv).into_owned(), &what(&format!("v+/d{name}")));
            assert_close(got_impulses, &want.rows(nv, want.nrows() - nv).into_owned(), &what(&format!("impulses/d{name}")));
        }
        true
    });
}
