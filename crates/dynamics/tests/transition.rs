//! The tree engine's transition Jacobians against central differences of the step itself: each displaced step
//! replayed from a scene built and run to the state under test (contact history and warm starts included),
//! on scenes whose contacts stick, slide, press a joint limit, meet the ground through parry, or whose
//! servos saturate.

use legkit_dynamics::algorithms::{difference, integrate};
use legkit_dynamics::geometry::{Convex, Shape, ShapeKind};
use legkit_dynamics::sim::{FrictionLaw, Ground, Options, Servo, Simulation};
use legkit_dynamics::{Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{DMatrix, Matrix3, Rotation3, Vector3};

#[path = "fixtures/quadruped.rs"]
mod fixture;

/// The displacement of each input for the central differences (rad, m, m/s, N m).
const STEP: f64 = 1e-7;

/// [A | B] of the step from `build()`'s state, and the same by central differences of `Simulation::step` in each of
/// the 5 nv inputs (q on its tangent space, v, τ_ff, target_q, target_v), with feed-forward `tau`.
fn jacobians_and_differences(build: &dyn Fn() -> Simulation, tau: &[f64], displacement: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut sim = build();
    let model = sim.model().clone();
    let nv = model.nv();
    let (mut a, mut b) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    sim.transition_jacobians(Some(tau), &mut a, &mut b).unwrap();
    let (q, v, servo) = (sim.q().to_vec(), sim.v().to_vec(), sim.servo().clone());
    let step = |input: usize, delta: f64| {
        let mut displaced = build();
        let mut d = vec![0.0; 5 * nv];
        d[input] = delta;
        let mut q1 = vec![0.0; model.nq()];
        integrate(&model, &q, &d[..nv], 1.0, &mut q1).unwrap();
        let v1: Vec<f64> = (0..nv).map(|k| v[k] + d[nv + k]).collect();
        let tau1: Vec<f64> = (0..nv).map(|k| tau[k] + d[2 * nv + k]).collect();
        let mut servo1 = servo.clone();
        for k in 0..nv {
            servo1.target_q[k] += d[3 * nv + k];
            servo1.target_v[k] += d[4 * nv + k];
        }
        displaced.set_state(Some(&q1), Some(&v1)).unwrap();
        displaced.set_servo(servo1).unwrap();
        displaced.step(Some(&tau1), 1).unwrap();
        (displaced.q().to_vec(), displaced.v().to_vec())
    };
    let (q_next, _) = step(0, 0.0);
    let mut numeric = DMatrix::zeros(2 * nv, 5 * nv);
    let (mut plus, mut minus) = (vec![0.0; nv], vec![0.0; nv]);
    for input in 0..5 * nv {
        let ((q_plus, v_plus), (q_minus, v_minus)) = (step(input, displacement), step(input, -displacement));
        // Both on the tangent space at the undisplaced step's q⁺, where A and B map.
        difference(&model, &q_next, &q_plus, &mut plus).unwrap();
        difference(&model, &q_next, &q_minus, &mut minus).unwrap();
        for k in 0..nv {
            numeric[(k, input)] = (plus[k] - minus[k]) / (2.0 * displacement);
            numeric[(nv + k, input)] = (v_plus[k] - v_minus[k]) / (2.0 * displacement);
        }
    }
    let mut analytic = DMatrix::zeros(2 * nv, 5 * nv);
    analytic.columns_mut(0, 2 * nv).copy_from(&a);
    analytic.columns_mut(2 * nv, 3 * nv).copy_from(&b);
    (analytic, numeric)
}

fn assert_matches_differences(label: &str, build: &dyn Fn() -> Simulation, tau: &[f64], tolerance: f64) {
    assert_matches_differences_in(label, build, tau, tolerance, 1);
}

/// `assert_matches_differences` for a step of `substeps`, displaced by STEP / substeps². A resting contact settles
/// within ε g h² of where its normal row's law bends (gap 0: speculative while apart, Baumgarte overlapping), h the
/// substep: 4e-8 m with 4 substeps of 0.25 ms, 7e-9 m with 10, where displacements of STEP would straddle the bend.
fn assert_matches_differences_in(label: &str, build: &dyn Fn() -> Simulation, tau: &[f64], tolerance: f64, substeps: usize) {
    assert_matches_differences_at(label, build, tau, tolerance, STEP / (substeps * substeps) as f64);
}

/// `assert_matches_differences` displaced by `displacement`.
fn assert_matches_differences_at(label: &str, build: &dyn Fn() -> Simulation, tau: &[f64], tolerance: f64, displacement: f64) {
    let (analytic, numeric) = jacobians_and_differences(build, tau, displacement);
    let scale = analytic.amax().max(1.0);
    let error = (&analytic - &numeric).amax();
    let (row, column) = (&analytic - &numeric).iamax_full();
    println!(
        "{label}: |[A B]| {scale:.3e}, largest difference {error:.3e} at ({row}, {column}): {} vs {}",
        analytic[(row, column)],
        numeric[(row, column)]
    );
    assert!(error <= tolerance * scale, "{label}: [A B] off central differences by {error:.3e} at ({row}, {column}) (scale {scale:.3e})");
}

fn plane() -> Option<Ground> {
    Some(Ground::plane(0.8).unwrap())
}

/// The fixture's quadruped standing on its servos (its ball feet sticking), run `settle` steps, then given base
/// velocity `base_v` (a sideways push makes the feet slide).
fn quadruped(settle: usize, base_v: [f64; 6], servo_limit: f64) -> Simulation {
    quadruped_under(settle, base_v, servo_limit, FrictionLaw::Cone)
}

fn quadruped_under(settle: usize, base_v: [f64; 6], servo_limit: f64, friction_law: FrictionLaw) -> Simulation {
    quadruped_in_substeps(settle, base_v, servo_limit, friction_law, 1)
}

fn quadruped_in_substeps(settle: usize, base_v: [f64; 6], servo_limit: f64, friction_law: FrictionLaw, substeps: usize) -> Simulation {
    let (model, shapes) = fixture::quadruped(0.2, JointLimits::NONE);
    let nv = model.nv();
    let options = Options { ground: plane(), shapes, friction_law, substeps, ..Options::new(1e-3) };
    let mut sim = Simulation::new(&model, options).unwrap();
    let mut q = model.neutral().as_slice().to_vec();
    q[2] = 0.03 + 0.3 + 0.02 + 0.005;
    sim.set_state(Some(&q), None).unwrap();
    let (mut kp, mut kd) = (vec![40.0; nv], vec![1.0; nv]);
    kp[..6].fill(0.0);
    kd[..6].fill(0.0);
    let target: Vec<f64> = (0..nv).map(|k| if k < 6 { 0.0 } else { 0.1 * (k as f64).sin() }).collect();
    sim.set_servo(Servo::new(&model, kp, kd, vec![servo_limit; nv], target, vec![0.0; nv]).unwrap()).unwrap();
    sim.step(None, settle).unwrap();
    let mut v = sim.v().to_vec();
    v[..6].iter_mut().zip(base_v).for_each(|(x, d)| *x += d);
    sim.set_state(None, Some(&v)).unwrap();
    sim
}

fn joint_torques(nv: usize) -> Vec<f64> {
    (0..nv).map(|k| if k < 6 { 0.0 } else { 0.2 * (k as f64 * 0.7).cos() }).collect()
}

#[test]
fn quadruped_standing_sliding_and_saturated() {
    let tau = joint_torques(14);
    assert_matches_differences("quadruped standing", &|| quadruped(300, [0.0; 6], 20.0), &tau, 1e-6);
    assert_matches_differences("quadruped sliding", &|| quadruped(300, [0.4, 0.3, 0.0, 0.0, 0.0, 0.5], 20.0), &tau, 1e-6);
    // Servos limited to 0.5 N m saturate under the standing load.
    assert_matches_differences("quadruped saturated", &|| quadruped(100, [0.0, 0.0, 0.0, 0.2, 0.0, 0.0], 0.5), &tau, 1e-6);
}

/// Under Coulomb's law a sliding foot's friction bound follows its normal impulse: the step's Hessian has the
/// law's unsymmetric coupling (`solver`), which the Jacobians must carry.
#[test]
fn quadruped_standing_and_sliding_under_coulombs_law() {
    let tau = joint_torques(14);
    let coulomb = FrictionLaw::Coulomb;
    assert_matches_differences("quadruped standing (Coulomb)", &|| quadruped_under(300, [0.0; 6], 20.0, coulomb), &tau, 1e-6);
    assert_matches_differences("quadruped sliding (Coulomb)", &|| quadruped_under(300, [0.4, 0.3, 0.0, 0.0, 0.0, 0.5], 20.0, coulomb), &tau, 1e-6);
}

/// A step of 2, 4 and 10 substeps under both friction laws, feet sticking and sliding: the substeps' Jacobians
/// chained, each substep's warm starts followed from the one before (the friction rows ask for R_t λ_t,warm: held
/// constant, the Jacobians would be off by about 1e-2).
#[test]
fn quadruped_with_substeps() {
    let tau = joint_torques(14);
    for (substeps, law) in
        [(2, FrictionLaw::Cone), (4, FrictionLaw::Cone), (10, FrictionLaw::Cone), (4, FrictionLaw::Coulomb), (10, FrictionLaw::Coulomb)]
    {
        for (label, push) in [("standing", [0.0; 6]), ("sliding", [0.4, 0.3, 0.0, 0.0, 0.0, 0.5])] {
            let build = || quadruped_in_substeps(150, push, 20.0, law, substeps);
            assert_matches_differences_in(&format!("quadruped {label}, {substeps} substeps ({})", law.name()), &build, &tau, 1e-6, substeps);
        }
    }
}

/// A tilted box on one corner, or flat on four, on the plane (closed form) or as a convex hull (parry), set
/// sliding into the ground (the step the Jacobians are of is its first: no warm start).
fn sliding_box(hull: bool, tilt: f64, friction_law: FrictionLaw) -> Simulation {
    let size = Vector3::new(0.3, 0.2, 0.1);
    let mut model = Model::new(true, MassProperties::solid_box(2.0, size, Vector3::zeros(), &Matrix3::identity()).unwrap(), "box");
    if hull {
        let corners: Vec<Vector3<f64>> =
            (0..8).map(|k| Vector3::new((k & 1) as f64 - 0.5, (k >> 1 & 1) as f64 - 0.5, (k >> 2 & 1) as f64 - 0.5).component_mul(&size)).collect();
        let shape = Shape::new(ShapeKind::Convex(Convex::hull(&corners).unwrap()), Some(Transform::identity())).unwrap();
        model.set_collision_shapes(vec![(0, shape)]).unwrap();
    }
    let mut sim = Simulation::new(&model, Options { ground: plane(), friction_law, ..Options::new(1e-3) }).unwrap();
    let rotation = Rotation3::from_euler_angles(tilt, 0.6 * tilt, 0.0);
    let quaternion = nalgebra::UnitQuaternion::from_rotation_matrix(&rotation);
    let lowest = (0..8)
        .map(|k| (rotation * Vector3::new((k & 1) as f64 - 0.5, (k >> 1 & 1) as f64 - 0.5, (k >> 2 & 1) as f64 - 0.5).component_mul(&size)).z)
        .fold(f64::INFINITY, f64::min);
    let q = [0.0, 0.0, -lowest - 1e-5, quaternion.i, quaternion.j, quaternion.k, quaternion.w];
    sim.set_state(Some(&q), Some(&[0.8, 0.3, 0.0, 0.0, 0.0, 0.2])).unwrap();
    sim
}

#[test]
fn boxes_sliding_on_the_plane_and_on_parry_hulls() {
    let tau = [0.0, 0.0, 0.0, 0.05, -0.02, 0.01];
    for (hull, law) in [false, true].into_iter().flat_map(|hull| [(hull, FrictionLaw::Cone), (hull, FrictionLaw::Coulomb)]) {
        for tilt in [0.0, 0.25] {
            let label = format!("box (hull: {hull}, tilt {tilt}, {})", law.name());
            let mut stepped = sliding_box(hull, tilt, law);
            stepped.step(Some(&tau), 1).unwrap();
            let loaded = stepped.contacts().iter().filter(|c| c.normal_force > 0.0 && c.tangential_force.norm() > 0.0).count();
            assert!(loaded >= if tilt == 0.0 { 4 } else { 1 }, "{label}: {loaded} loaded sliding contacts");
            assert_matches_differences(&label, &|| sliding_box(hull, tilt, law), &tau, 1e-6);
        }
    }
}

/// A pendulum leaning on its joint's lower limit under a servo pushing into it.
#[test]
fn pendulum_pressing_its_limit() {
    let build = || {
        let mut model = Model::new(false, MassProperties::zero(), "base");
        let rod = MassProperties::solid_box(1.0, Vector3::new(0.5, 0.02, 0.02), Vector3::new(0.25, 0.0, 0.0), &Matrix3::identity()).unwrap();
        let limits = JointLimits::new(-0.3, 0.3, 100.0, 10.0).unwrap();
        model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), rod, "rod", limits).unwrap();
        let mut sim = Simulation::new(&model, Options::new(1e-3)).unwrap();
        sim.set_servo(Servo::new(&model, vec![5.0], vec![0.2], vec![f64::INFINITY], vec![-2.0], vec![0.0]).unwrap()).unwrap();
        sim.step(None, 400).unwrap();
        sim
    };
    assert!((build().q()[0] + 0.3).abs() < 1e-3, "the pendulum rests on its limit");
    assert_matches_differences("pendulum on its limit", &build, &[0.1], 1e-6);
}

/// Asking for the Jacobians changes nothing: what follows is bit-identical to a twin that never asked.
#[test]
fn asking_changes_nothing() {
    let tau = joint_torques(14);
    let (mut asked, mut twin) = (quadruped(200, [0.3, 0.0, 0.0, 0.0, 0.0, 0.0], 20.0), quadruped(200, [0.3, 0.0, 0.0, 0.0, 0.0, 0.0], 20.0));
    let (mut a, mut b) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    asked.transition_jacobians(Some(&tau), &mut a, &mut b).unwrap();
    assert_eq!(asked.contacts(), twin.contacts());
    for sim in [&mut asked, &mut twin] {
        sim.step(Some(&tau), 50).unwrap();
    }
    assert_eq!((asked.q(), asked.v(), asked.contacts(), asked.time()), (twin.q(), twin.v(), twin.contacts(), twin.time()));
}

#[test]
fn refused_on_rapier() {
    let model = Model::new(true, MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap(), "box");
    let (mut a, mut b) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    #[cfg(feature = "rapier")]
    {
        let rapier = Options { backend: legkit_dynamics::sim::Backend::Rapier, ..Options::new(1e-3) };
        let error = Simulation::new(&model, rapier).unwrap().transition_jacobians(None, &mut a, &mut b).unwrap_err();
        assert_eq!(error.argument(), "backend");
    }
    let error = Simulation::new(&model, Options::new(1e-3)).unwrap().transition_jacobians(Some(&[0.0; 5]), &mut a, &mut b).unwrap_err();
    assert_eq!(error.argument(), "tau");
}

/// A box on four joints (x, y, z sliders and a turn about z) sliding on a heavy platform held by a stiff servo on
/// a vertical slider: a contact between two bodies (self-collision through parry, box corners on the platform's
/// face), which couples the two bodies' chains in the step's Hessian.
#[test]
fn box_sliding_on_a_platform() {
    for law in [FrictionLaw::Cone, FrictionLaw::Coulomb] {
        box_sliding_on_a_platform_under(law);
    }
}

fn box_sliding_on_a_platform_under(friction_law: FrictionLaw) {
    let build = || {
        let mut model = Model::new(false, MassProperties::zero(), "world");
        let solid = |mass: f64, size: Vector3<f64>| MassProperties::solid_box(mass, size, Vector3::zeros(), &Matrix3::identity()).unwrap();
        model
            .add_body(
                0,
                Joint::Prismatic(Vector3::z()),
                Transform::identity(),
                solid(100.0, Vector3::new(0.6, 0.6, 0.1)),
                "platform",
                JointLimits::NONE,
            )
            .unwrap();
        let lift = Transform::from_translation(Vector3::new(0.0, 0.0, 0.1));
        let x = model.add_body(0, Joint::Prismatic(Vector3::x()), lift, solid(0.1, Vector3::new(0.01, 0.01, 0.01)), "x", JointLimits::NONE).unwrap();
        let y = model
            .add_body(x, Joint::Prismatic(Vector3::y()), Transform::identity(), solid(0.1, Vector3::new(0.01, 0.01, 0.01)), "y", JointLimits::NONE)
            .unwrap();
        let z = model
            .add_body(y, Joint::Prismatic(Vector3::z()), Transform::identity(), solid(0.1, Vector3::new(0.01, 0.01, 0.01)), "z", JointLimits::NONE)
            .unwrap();
        model
            .add_body(z, Joint::Revolute(Vector3::z()), Transform::identity(), solid(1.0, Vector3::new(0.2, 0.15, 0.1)), "box", JointLimits::NONE)
            .unwrap();
        let options = Options {
            self_collision: true,
            shapes: vec![(x, None), (y, None), (z, None)],
            solver_iterations: 500,
            friction_law,
            ..Options::new(1e-3)
        };
        let mut sim = Simulation::new(&model, options).unwrap();
        // The box's bottom (0.1 - 0.05 + z) rests on the platform's top (q_platform + 0.05).
        sim.set_state(Some(&[0.0, 0.02, -0.01, -0.05 + 2e-6, 0.3]), Some(&[0.0, 0.4, 0.2, 0.0, 0.5])).unwrap();
        sim.set_servo(
            Servo::new(&model, vec![1e5, 0.0, 0.0, 0.0, 0.0], vec![1e3, 0.0, 0.0, 0.0, 0.0], vec![f64::INFINITY; 5], vec![0.0; 5], vec![0.0; 5])
                .unwrap(),
        )
        .unwrap();
        sim.step(None, 5).unwrap();
        sim
    };
    let mut stepped = build();
    stepped.step(None, 1).unwrap();
    let loaded = stepped.contacts().iter().filter(|c| c.other.is_some() && c.normal_force > 0.0 && c.tangential_force.norm() > 0.0).count();
    assert_eq!(loaded, 4, "{:?}", stepped.contacts());
    // The solver's iterations on a contact between two bodies converge linearly (its Newton matrix leaves out
    // the bodies' coupling; 89 iterations here under the cone, about 200 under Coulomb's law), so the step, and its central differences, are exact only to
    // about 1e-4 of the Jacobians' scale: the tolerance. Leaving the coupling out of the Jacobians' Hessian
    // puts them 0.6 off.
    assert_matches_differences(&format!("box on a platform ({})", friction_law.name()), &build, &[0.0, 0.1, 0.0, 0.0, 0.02], 1e-3);
}

/// The SuperBot-like tree of `benches/simulation_vs_mujoco.py` (21 modules, 63 joints): a vertical root module
/// (blocks 0.06 x 0.06 x 0.0425 m, pitch, roll and pitch joints) fixed to the ground, four horizontal branches that
/// sag onto the plane against weak servos, taken 0.3 s in while they sway. A displacement of one branch's joint moves
/// that branch's contacts alone; the others' impulses follow it through their Delassus diagonals (the factor moves with
/// every joint), which the Jacobians take by the chain rule (under the cone law, where that matters most).
fn sagging_tree(substeps: usize) -> Simulation {
    let length = 0.17;
    let part = MassProperties::solid_box(0.0125, Vector3::new(0.06, 0.06, length / 4.0), Vector3::new(0.0, 0.0, length / 8.0), &Matrix3::identity())
        .unwrap();
    let mut model = Model::new(false, MassProperties::zero(), "base");
    let step = Transform::from_translation(Vector3::new(0.0, 0.0, length / 4.0));
    let add_module = |model: &mut Model, parent: usize, placement: Transform| {
        let mut body = model.add_body(parent, Joint::Fixed, placement, part, &format!("block{}", model.nbodies()), JointLimits::NONE).unwrap();
        for axis in [Vector3::y(), Vector3::z(), Vector3::y()] {
            body = model.add_body(body, Joint::Revolute(axis), step, part, &format!("part{}", model.nbodies()), JointLimits::NONE).unwrap();
        }
        body
    };
    let top = add_module(&mut model, 0, Transform::from_translation(Vector3::new(0.0, 0.0, 0.05)));
    for branch in 0..4 {
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), branch as f64 * std::f64::consts::FRAC_PI_2)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
        let mut parent = add_module(&mut model, top, Transform::new(turn.into_inner(), step.translation));
        for _ in 1..5 {
            parent = add_module(&mut model, parent, step);
        }
    }
    let nv = model.nv();
    let options = Options { ground: Some(Ground::plane(0.8).unwrap()), friction_law: FrictionLaw::Cone, substeps, ..Options::new(1e-3) };
    let mut sim = Simulation::new(&model, options).unwrap();
    sim.set_servo(Servo::new(&model, vec![0.5; nv], vec![0.002; nv], vec![0.5; nv], vec![0.0; nv], vec![0.0; nv]).unwrap()).unwrap();
    sim.step(None, 300).unwrap();
    sim
}

#[test]
fn tree_sagging_onto_the_plane() {
    let mut sim = sagging_tree(1);
    sim.step(None, 1).unwrap();
    let bodies: std::collections::BTreeSet<usize> = sim.contacts().iter().filter(|c| c.normal_force > 0.0).map(|c| c.body).collect();
    assert!(bodies.len() >= 8, "contacts on {bodies:?}");
    // Held at their configuration's diagonals, the other branches' contacts leave 8e-7 of the Jacobians off (measured).
    assert_matches_differences("tree sagging onto the plane", &|| sagging_tree(1), &[0.0; 63], 1e-7);
}

/// The tree's step in 4 substeps, its blocks resting on their corners: the contacts' impulses curve sharply in q, and
/// the Jacobians' own central differences in q, at too large a step, leave 5e-6 of them off (measured at 1e-6).
/// Displaced by 2.5e-8, within the 4e-8 of the contacts' bends: at STEP / 16 the step's converged solve leaves 1e-6
/// of noise in the differences.
#[test]
fn tree_sagging_onto_the_plane_in_substeps() {
    assert_matches_differences_at("tree sagging onto the plane, 4 substeps", &|| sagging_tree(4), &[0.0; 63], 1e-6, 2.5e-8);
}
