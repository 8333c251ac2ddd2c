//! The centroidal derivatives and the COM Jacobian against central differences of the kernels they differentiate
//! (`centroidal_momentum`, `centroidal_momentum_rate`, `center_of_mass`), on random trees (every joint kind, fixed
//! and floating bases), q stepped on its tangent space (q ⊕ ε e_j, as `integrate`). The differential tests against
//! Pinocchio are in the Python suite.

use legkit_dynamics::algorithms::{
    center_of_mass, center_of_mass_jacobian, centroidal_derivatives, centroidal_map, centroidal_momentum, centroidal_momentum_rate,
};
use legkit_dynamics::Data;
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "fixtures/trees.rs"]
mod trees;
use trees::random_case;
#[path = "fixtures/slopes.rs"]
mod slopes;
use slopes::{assert_close, central_differences, stepped, stepped_q};

#[test]
fn centroidal_derivatives_are_the_slopes_of_the_momentum_and_its_rate() {
    let mut rng = StdRng::seed_from_u64(11);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let nv = model.nv();
        let a: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
        let (q, v) = (q.as_slice(), v.as_slice());
        let (dh_dq, dhdot_dq, dhdot_dv, dhdot_da) = centroidal_derivatives(&model, &mut data, q, v, &a).unwrap();
        let got = [dh_dq, dhdot_dq, dhdot_dv, dhdot_da].map(|m| DMatrix::from_column_slice(6, nv, m.as_slice()));
        let mut scratch = Data::new(&model);
        let mut momentum = |q: &[f64], v: &[f64]| DVector::from_column_slice(centroidal_momentum(&model, &mut scratch, q, v).unwrap().as_slice());
        let want_dh_dq = central_differences(nv, |j, h| momentum(&stepped_q(&model, q, j, h), v));
        let want_dh_dv = central_differences(nv, |j, h| momentum(q, &stepped(v, j, h)));
        let mut rate =
            |q: &[f64], v: &[f64], a: &[f64]| DVector::from_column_slice(centroidal_momentum_rate(&model, &mut scratch, q, v, a).unwrap().as_slice());
        let want_dhdot_dq = central_differences(nv, |j, h| rate(&stepped_q(&model, q, j, h), v, &a));
        let want_dhdot_dv = central_differences(nv, |j, h| rate(q, &stepped(v, j, h), &a));
        let want_dhdot_da = central_differences(nv, |j, h| rate(q, v, &stepped(&a, j, h)));
        assert_close(&got[0], &want_dh_dq, &format!("case {case}: dh/dq"));
        assert_close(&got[1], &want_dhdot_dq, &format!("case {case}: dhdot/dq"));
        assert_close(&got[2], &want_dhdot_dv, &format!("case {case}: dhdot/dv"));
        assert_close(&got[3], &want_dhdot_da, &format!("case {case}: dhdot/da"));
        // h is linear in v: dh/dv is A_G exactly as `centroidal_map` gives it.
        assert_close(&got[3], &want_dh_dv, &format!("case {case}: dh/dv"));
        let map = centroidal_map(&model, &mut scratch, q).unwrap();
        assert_close(&got[3], &DMatrix::from_column_slice(6, nv, map.as_slice()), &format!("case {case}: A_G"));
    }
}

#[test]
fn center_of_mass_jacobian_is_the_slope_of_the_center_of_mass() {
    let mut rng = StdRng::seed_from_u64(13);
    for case in 0..40 {
        let (model, mut data, q, _) = random_case(&mut rng, case);
        let nv = model.nv();
        let q = q.as_slice();
        let got = center_of_mass_jacobian(&model, &mut data, q).unwrap();
        let got = DMatrix::from_column_slice(3, nv, got.as_slice());
        let mut scratch = Data::new(&model);
        let want = central_differences(nv, |j, h| {
            DVector::from_column_slice(center_of_mass(&model, &mut scratch, &stepped_q(&model, q, j, h)).unwrap().as_slice())
        });
        assert_close(&got, &want, &format!("case {case}: dc/dq"));
    }
}
