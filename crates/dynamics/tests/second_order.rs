//! The RNEA's second derivatives against central differences of its first derivatives (`rnea_derivatives`, which
//! tests/derivatives.rs checks against `rnea`) and of the mass matrix (`crba`), on random trees of every joint kind
//! (the free flyer and helical joints included, with armature).

use legkit_dynamics::algorithms::{crba, rnea_derivatives, rnea_second_order_derivatives};
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

/// The tensor's (i, j, k) entries as an (nv², nv) matrix with row j nv + i and column k: the layout of
/// `central_differences` of a column-major nv x nv matrix.
fn unfolded(tensor: &[f64], nv: usize) -> DMatrix<f64> {
    DMatrix::from_fn(nv * nv, nv, |row, k| tensor[((row % nv) * nv + row / nv) * nv + k])
}

fn flat(m: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_column_slice(m.as_slice())
}

#[test]
fn second_derivatives_are_the_slopes_of_the_first() {
    let mut rng = StdRng::seed_from_u64(11);
    for case in 0..30 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let nv = model.nv();
        let a: Vec<f64> = (0..nv).map(|_| rng.random_range(-3.0..3.0)).collect();
        let (q, v) = (q.as_slice(), v.as_slice());
        let second = rnea_second_order_derivatives(&model, &mut data, q, v, &a).unwrap().clone();
        let mut scratch = Data::new(&model);
        let mut first = |q: &[f64], v: &[f64]| {
            let (dq, dv) = rnea_derivatives(&model, &mut scratch, q, v, &a, None).unwrap();
            (flat(dq), flat(dv))
        };
        let dq_by_q = central_differences(nv, |k, h| first(&stepped_q(&model, q, k, h), v).0);
        let dv_by_v = central_differences(nv, |k, h| first(q, &stepped(v, k, h)).1);
        let dq_by_v = central_differences(nv, |k, h| first(q, &stepped(v, k, h)).0);
        let mass_by_q = central_differences(nv, |k, h| flat(crba(&model, &mut scratch, &stepped_q(&model, q, k, h)).unwrap()));
        assert_close(&unfolded(&second.dqdq, nv), &dq_by_q, &format!("case {case}: d2tau/dqdq"));
        assert_close(&unfolded(&second.dqdv, nv), &dq_by_v, &format!("case {case}: d2tau/dqdv"));
        assert_close(&unfolded(&second.dvdv, nv), &dv_by_v, &format!("case {case}: d2tau/dvdv"));
        assert_close(&unfolded(&second.dadq, nv), &mass_by_q, &format!("case {case}: d2tau/dadq"));
    }
}
