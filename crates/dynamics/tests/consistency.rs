//! Self-consistency of the dynamics algorithms on random trees (every joint kind, with and without
//! armature): RNEA inverts ABA, CRBA agrees with RNEA column by column, Minv inverts CRBA, A_G v is the
//! centroidal momentum. (Differential tests against Pinocchio are in the Python suite.)

use legkit_dynamics::algorithms::{aba, centroidal_map, centroidal_momentum, crba, forward_kinematics, minv, rnea};
use legkit_dynamics::{Data, Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{DMatrix, DVector, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "fixtures/trees.rs"]
mod trees;
use trees::random_case;

fn relative_error(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax().max(1.0)
}

#[test]
fn rnea_crba_aba_and_minv_agree() {
    let mut rng = StdRng::seed_from_u64(7);
    for case in 0..60 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let tau = DVector::from_fn(model.nv(), |_, _| rng.random_range(-5.0..5.0));
        let nv = model.nv();

        let mass_matrix = crba(&model, &mut data, q.as_slice()).unwrap().clone();
        let bias = rnea(&model, &mut data, q.as_slice(), v.as_slice(), &vec![0.0; nv], None).unwrap().clone();
        let ddq = aba(&model, &mut data, q.as_slice(), v.as_slice(), tau.as_slice(), None).unwrap().clone();
        let expected = mass_matrix.clone().lu().solve(&(&tau - &bias)).unwrap();
        assert!((&ddq - &expected).amax() < 1e-9 * expected.amax().max(1.0), "case {case}: ABA vs CRBA");

        let tau_back = rnea(&model, &mut data, q.as_slice(), v.as_slice(), ddq.as_slice(), None).unwrap().clone();
        assert!((&tau_back - &tau).amax() < 1e-9 * tau.amax().max(1.0), "case {case}: RNEA(ABA(tau)) != tau");

        // Column j of M is RNEA(q, 0, e_j) minus the gravity term.
        let gravity = rnea(&model, &mut data, q.as_slice(), &vec![0.0; nv], &vec![0.0; nv], None).unwrap().clone();
        for j in 0..nv {
            let mut e = vec![0.0; nv];
            e[j] = 1.0;
            let column = rnea(&model, &mut data, q.as_slice(), &vec![0.0; nv], &e, None).unwrap() - &gravity;
            assert!((column - mass_matrix.column(j)).amax() < 1e-10 * mass_matrix.amax(), "case {case}: CRBA column {j}");
        }

        let inverse = minv(&model, &mut data, q.as_slice()).unwrap().clone();
        let identity = DMatrix::identity(nv, nv);
        assert!(relative_error(&(&inverse * &mass_matrix), &identity) < 1e-9, "case {case}: Minv M != I");
    }
}

#[test]
fn centroidal_map_times_v_is_the_centroidal_momentum() {
    let mut rng = StdRng::seed_from_u64(11);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let map = centroidal_map(&model, &mut data, q.as_slice()).unwrap().clone();
        let momentum = centroidal_momentum(&model, &mut data, q.as_slice(), v.as_slice()).unwrap();
        let product = &map * &v;
        assert!((product - momentum).amax() < 1e-10 * momentum.amax().max(1.0), "case {case}: A_G v != h");
    }
}

#[test]
fn kinematics_composes_placements_and_joint_motions() {
    let mut model = Model::new(false, MassProperties::zero(), "base");
    let upper = MassProperties::point(1.0, Vector3::new(0.0, 0.0, -0.5)).unwrap();
    let shoulder = model
        .add_body(0, Joint::Revolute(Vector3::y()), Transform::from_translation(Vector3::new(0.0, 0.0, 1.0)), upper, "upper", JointLimits::NONE)
        .unwrap();
    model
        .add_body(
            shoulder,
            Joint::Prismatic(Vector3::z()),
            Transform::from_translation(Vector3::new(0.0, 0.0, -1.0)),
            upper,
            "lower",
            JointLimits::NONE,
        )
        .unwrap();
    let mut data = Data::new(&model);
    forward_kinematics(&model, &mut data, &[std::f64::consts::FRAC_PI_2, 0.25]).unwrap();
    // Rotating +90° about y takes the local -z axis to -x; the prismatic joint slides along it by 0.25 after the
    // 1 m offset, so the lower body sits 0.75 m along -x from the shoulder at height 1.
    let tip = data.o_m_i[2].translation;
    assert!((tip - Vector3::new(-0.75, 0.0, 1.0)).amax() < 1e-15, "{tip}");
}
