//! Self-consistency of the dynamics algorithms on random trees (every joint kind, with and without
//! armature): RNEA inverts ABA, CRBA agrees with RNEA column by column, Minv inverts CRBA, A_G v is the
//! centroidal momentum. (Differential tests against Pinocchio are in the Python suite.)

use legkit_dynamics::algorithms::{aba, centroidal_map, centroidal_momentum, crba, forward_kinematics, minv, rnea};
use legkit_dynamics::{Data, Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{DMatrix, DVector, Rotation3, Unit, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn unit(rng: &mut StdRng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        if v.norm() > 0.1 {
            return v.normalize();
        }
    }
}

fn random_body(rng: &mut StdRng) -> MassProperties {
    let size = Vector3::new(rng.random_range(0.05..0.5), rng.random_range(0.05..0.5), rng.random_range(0.05..0.5));
    let center = Vector3::new(rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2));
    let rotation = Rotation3::from_axis_angle(&Unit::new_normalize(unit(rng)), rng.random_range(-3.0..3.0)).into_inner();
    MassProperties::solid_box(rng.random_range(0.1..3.0), size, center, &rotation).unwrap()
}

fn random_tree(rng: &mut StdRng, n: usize, floating: bool) -> Model {
    let mut model = Model::new(floating, random_body(rng), "base");
    for i in 1..=n {
        let parent = rng.random_range(0..i);
        let joint = match rng.random_range(0..10) {
            0 => Joint::Fixed,
            1 | 2 => Joint::Prismatic(unit(rng)),
            3 => Joint::Helical { axis: unit(rng), pitch: rng.random_range(-0.2..0.2) },
            _ => Joint::Revolute(unit(rng)),
        };
        let rotation = Rotation3::from_axis_angle(&Unit::new_normalize(unit(rng)), rng.random_range(-3.0..3.0)).into_inner();
        let placement = Transform::new(rotation, unit(rng) * rng.random_range(0.0..0.5));
        model.add_body(parent, joint, placement, random_body(rng), &format!("body{i}"), JointLimits::NONE).unwrap();
    }
    if rng.random_bool(0.5) {
        let base = if floating { 6 } else { 0 };
        let armature: Vec<f64> = (0..model.nv()).map(|k| if k < base { 0.0 } else { rng.random_range(0.0..0.5) }).collect();
        model.set_armature(&armature).unwrap();
    }
    model
}

fn random_state(rng: &mut StdRng, model: &Model) -> (DVector<f64>, DVector<f64>) {
    let mut q = DVector::from_fn(model.nq(), |_, _| rng.random_range(-2.0..2.0));
    if model.floating_base() {
        let quat = nalgebra::UnitQuaternion::from_axis_angle(&Unit::new_normalize(unit(rng)), rng.random_range(-3.0..3.0));
        q.rows_mut(3, 4).copy_from_slice(&[quat.i, quat.j, quat.k, quat.w]);
    }
    let v = DVector::from_fn(model.nv(), |_, _| rng.random_range(-2.0..2.0));
    (q, v)
}

/// Case `case` of a randomised sweep: a tree of 1..=25 bodies, floating on even cases, its workspace and a state.
fn random_case(rng: &mut StdRng, case: usize) -> (Model, Data, DVector<f64>, DVector<f64>) {
    let model = random_tree(rng, 1 + case % 25, case.is_multiple_of(2));
    let data = Data::new(&model);
    let (q, v) = random_state(rng, &model);
    (model, data, q, v)
}

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

        let mass_matrix = crba(&model, &mut data, q.as_slice()).clone();
        let bias = rnea(&model, &mut data, q.as_slice(), v.as_slice(), &vec![0.0; nv], None).clone();
        let ddq = aba(&model, &mut data, q.as_slice(), v.as_slice(), tau.as_slice(), None).clone();
        let expected = mass_matrix.clone().lu().solve(&(&tau - &bias)).unwrap();
        assert!((&ddq - &expected).amax() < 1e-9 * expected.amax().max(1.0), "case {case}: ABA vs CRBA");

        let tau_back = rnea(&model, &mut data, q.as_slice(), v.as_slice(), ddq.as_slice(), None).clone();
        assert!((&tau_back - &tau).amax() < 1e-9 * tau.amax().max(1.0), "case {case}: RNEA(ABA(tau)) != tau");

        // Column j of M is RNEA(q, 0, e_j) minus the gravity term.
        let gravity = rnea(&model, &mut data, q.as_slice(), &vec![0.0; nv], &vec![0.0; nv], None).clone();
        for j in 0..nv {
            let mut e = vec![0.0; nv];
            e[j] = 1.0;
            let column = rnea(&model, &mut data, q.as_slice(), &vec![0.0; nv], &e, None) - &gravity;
            assert!((column - mass_matrix.column(j)).amax() < 1e-10 * mass_matrix.amax(), "case {case}: CRBA column {j}");
        }

        let inverse = minv(&model, &mut data, q.as_slice()).clone();
        let identity = DMatrix::identity(nv, nv);
        assert!(relative_error(&(&inverse * &mass_matrix), &identity) < 1e-9, "case {case}: Minv M != I");
    }
}

#[test]
fn centroidal_map_times_v_is_the_centroidal_momentum() {
    let mut rng = StdRng::seed_from_u64(11);
    for case in 0..40 {
        let (model, mut data, q, v) = random_case(&mut rng, case);
        let map = centroidal_map(&model, &mut data, q.as_slice()).clone();
        let momentum = centroidal_momentum(&model, &mut data, q.as_slice(), v.as_slice());
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
    forward_kinematics(&model, &mut data, &[std::f64::consts::FRAC_PI_2, 0.25]);
    // Rotating +90° about y takes the local -z axis to -x; the prismatic joint slides along it by 0.25 after the
    // 1 m offset, so the lower body sits 0.75 m along -x from the shoulder at height 1.
    let tip = data.o_m_i[2].translation;
    assert!((tip - Vector3::new(-0.75, 0.0, 1.0)).amax() < 1e-15, "{tip}");
}
