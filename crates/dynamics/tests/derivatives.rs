//! The analytic derivatives against central differences of the kernels they differentiate, on random trees
//! (every joint kind, fixed and floating bases, armature, external forces), q stepped on its tangent space
//! (q ⊕ ε e_j, as `integrate`). The differential tests against Pinocchio are in the Python suite.

use legkit_dynamics::algorithms::{aba, aba_derivatives, integrate, rnea, rnea_derivatives};
use legkit_dynamics::spatial::Force;
use legkit_dynamics::{Data, Model};
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "fixtures/trees.rs"]
mod trees;
use trees::random_case;

const STEP: f64 = 1e-6;

/// Column j is (f(x + h e_j) − f(x − h e_j)) / 2h, where `f(j, h)` evaluates at the step.
fn central_differences(nv: usize, mut f: impl FnMut(usize, f64) -> DVector<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(nv, nv);
    for j in 0..nv {
        out.set_column(j, &((f(j, STEP) - f(j, -STEP)) / (2.0 * STEP)));
    }
    out
}

fn stepped(x: &[f64], j: usize, h: f64) -> Vec<f64> {
    let mut out = x.to_vec();
    out[j] += h;
    out
}

/// q ⊕ h e_j.
fn stepped_q(model: &Model, q: &[f64], j: usize, h: f64) -> Vec<f64> {
    let mut out = vec![0.0; model.nq()];
    integrate(model, q, &stepped(&vec![0.0; model.nv()], j, 1.0), h, &mut out);
    out
}

fn random_forces(rng: &mut StdRng, model: &Model) -> Vec<Force> {
    (0..model.nbodies()).map(|_| Force::from_fn(|_, _| rng.random_range(-5.0..5.0))).collect()
}

fn assert_close(got: &DMatrix<f64>, want: &DMatrix<f64>, what: &str) {
    let scale = want.amax().max(1.0);
    let error = (got - want).amax();
    assert!(error < 1e-6 * scale, "{what}: error {error:.3e} (scale {scale:.3e})\ngot {got:.6}\nwant {want:.6}");
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
        let (dq, dv) = rnea_derivatives(&model, &mut data, q, v, &a, f_ext);
        let (dq, dv) = (dq.clone(), dv.clone());
        let mut scratch = Data::new(&model);
        let want_dq = central_differences(nv, |j, h| rnea(&model, &mut scratch, &stepped_q(&model, q, j, h), v, &a, f_ext).clone());
        let want_dv = central_differences(nv, |j, h| rnea(&model, &mut scratch, q, &stepped(v, j, h), &a, f_ext).clone());
        assert_close(&dq, &want_dq, &format!("case {case}: dtau/dq"));
        assert_close(&dv, &want_dv, &format!("case {case}: dtau/dv"));
    }
}

#[test]
fn aba_derivatives_are_the_slopes_of_aba() {
    let mut rng = StdRng::seed_from_u64(5);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let nv = model.nv();
        let tau: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
        let forces = random_forces(&mut rng, &model);
        let f_ext = (case % 3 == 1).then_some(forces.as_slice());
        let (q, v) = (q.as_slice(), v.as_slice());
        let (dq, dv, dtau) = aba_derivatives(&model, &mut data, q, v, &tau, f_ext);
        let (dq, dv, dtau) = (dq.clone(), dv.clone(), dtau.clone());
        let mut scratch = Data::new(&model);
        let ddq = aba(&model, &mut scratch, q, v, &tau, f_ext).clone();
        assert_eq!(data.ddq, ddq, "case {case}: aba_derivatives leaves q̈ in data.ddq");
        let want_dq = central_differences(nv, |j, h| aba(&model, &mut scratch, &stepped_q(&model, q, j, h), v, &tau, f_ext).clone());
        let want_dv = central_differences(nv, |j, h| aba(&model, &mut scratch, q, &stepped(v, j, h), &tau, f_ext).clone());
        let want_dtau = central_differences(nv, |j, h| aba(&model, &mut scratch, q, v, &stepped(&tau, j, h), f_ext).clone());
        assert_close(&dq, &want_dq, &format!("case {case}: dddq/dq"));
        assert_close(&dv, &want_dv, &format!("case {case}: dddq/dv"));
        assert_close(&dtau, &want_dtau, &format!("case {case}: dddq/dtau"));
    }
}
