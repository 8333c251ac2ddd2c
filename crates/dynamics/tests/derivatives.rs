//! The analytic derivatives against central differences of the kernels they differentiate, on random trees
//! (every joint kind, fixed and floating bases, armature, external forces), q stepped on its tangent space
//! (q ⊕ ε e_j, as `integrate`). The differential tests against Pinocchio are in the Python suite.

use legkit_dynamics::algorithms::{aba, aba_derivatives, rnea, rnea_derivatives};
use legkit_dynamics::spatial::Force;
use legkit_dynamics::{Data, Model};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "fixtures/trees.rs"]
mod trees;
use trees::random_case;
#[path = "fixtures/slopes.rs"]
mod slopes;
use slopes::{assert_close, central_differences, stepped, stepped_q};

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
        let (dq, dv) = rnea_derivatives(&model, &mut data, q, v, &a, f_ext);
        let (dq, dv) = (dq.clone(), dv.clone());
        let mut scratch = Data::new(&model);
        let want_dq = central_differences(nv, nv, |j, h| rnea(&model, &mut scratch, &stepped_q(&model, q, j, h), v, &a, f_ext).clone());
        let want_dv = central_differences(nv, nv, |j, h| rnea(&model, &mut scratch, q, &stepped(v, j, h), &a, f_ext).clone());
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
        let want_dq = central_differences(nv, nv, |j, h| aba(&model, &mut scratch, &stepped_q(&model, q, j, h), v, &tau, f_ext).clone());
        let want_dv = central_differences(nv, nv, |j, h| aba(&model, &mut scratch, q, &stepped(v, j, h), &tau, f_ext).clone());
        let want_dtau = central_differences(nv, nv, |j, h| aba(&model, &mut scratch, q, v, &stepped(&tau, j, h), f_ext).clone());
        assert_close(&dq, &want_dq, &format!("case {case}: dddq/dq"));
        assert_close(&dv, &want_dv, &format!("case {case}: dddq/dv"));
        assert_close(&dtau, &want_dtau, &format!("case {case}: dddq/dtau"));
    }
}
