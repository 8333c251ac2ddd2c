//! The simulation against the dynamics core (free motion against ABA + RK4), statics (contact forces
//! against weight), determinism, actuation and input checks.

use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};

use super::*;
use crate::algorithms::{free_rollout, Method};
use crate::geometry::{Convex, Shape, ShapeKind};
use crate::model::{JointLimits, STANDARD_GRAVITY};
use crate::sim::options::Backend;
use crate::Joint;
use crate::{Data, MassProperties};

fn rod(mass: f64, length: f64) -> MassProperties {
    // A 4 cm square bar along the body's x axis, starting at the joint.
    MassProperties::solid_box(mass, Vector3::new(length, 0.04, 0.04), Vector3::new(length / 2.0, 0.0, 0.0), &Matrix3::identity()).unwrap()
}

/// A 10-link branching tree hanging from a fixed base: a chain of 5 with three side branches, joint axes
/// not aligned with the links, one prismatic joint.
pub(crate) fn ten_link_tree() -> Model {
    let mut model =
        Model::new(false, MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap(), "base");
    let turn = |x: f64, y: f64, z: f64| Rotation3::from_euler_angles(x, y, z).into_inner();
    let along = |length: f64, r: Matrix3<f64>| Transform::new(r, Vector3::new(length, 0.0, 0.0));
    let axes = [Vector3::y(), Vector3::new(0.0, 1.0, 0.3), Vector3::z(), Vector3::new(0.2, 1.0, 0.0), Vector3::y()];
    let mut parent = 0;
    let mut chain = Vec::new();
    for (k, axis) in axes.iter().enumerate() {
        // The first link hangs down (body x onto world −z); the rest continue it with small bends.
        let placement = if k == 0 {
            Transform::new(turn(0.0, std::f64::consts::FRAC_PI_2, 0.0), Vector3::zeros())
        } else {
            along(0.25, turn(0.1 * k as f64, 0.0, 0.2))
        };
        parent = model
            .add_body(parent, Joint::Revolute(*axis), placement, rod(0.6 - 0.05 * k as f64, 0.25), &format!("chain{k}"), JointLimits::NONE)
            .unwrap();
        chain.push(parent);
    }
    let b =
        model.add_body(chain[1], Joint::Revolute(Vector3::x()), along(0.25, turn(0.0, 0.0, 1.2)), rod(0.3, 0.2), "side0", JointLimits::NONE).unwrap();
    model
        .add_body(b, Joint::Revolute(Vector3::new(0.0, 0.4, 1.0)), along(0.2, turn(0.3, 0.0, 0.0)), rod(0.2, 0.15), "side1", JointLimits::NONE)
        .unwrap();
    let c = model
        .add_body(chain[2], Joint::Prismatic(Vector3::x()), along(0.25, turn(0.0, 0.5, -1.0)), rod(0.25, 0.2), "slider", JointLimits::NONE)
        .unwrap();
    model.add_body(c, Joint::Revolute(Vector3::y()), along(0.2, Matrix3::identity()), rod(0.2, 0.2), "side2", JointLimits::NONE).unwrap();
    model.add_body(chain[4], Joint::Revolute(Vector3::z()), along(0.25, turn(0.0, 0.0, -0.4)), rod(0.15, 0.15), "tip", JointLimits::NONE).unwrap();
    assert_eq!(model.nv(), 10);
    model
}

fn start(model: &Model) -> (Vec<f64>, Vec<f64>) {
    let q: Vec<f64> = (0..model.nq()).map(|k| 0.3 * ((k as f64) * 1.7).sin()).collect();
    (q, vec![0.0; model.nv()])
}

/// legkit's reference: ABA + RK4 at `dt`, `steps` steps; returns the final (q, v).
fn reference(model: &Model, q: &[f64], v: &[f64], dt: f64, steps: usize) -> (Vec<f64>, Vec<f64>) {
    let (nq, nv) = (model.nq(), model.nv());
    let mut qs = vec![0.0; (steps + 1) * nq];
    let mut vs = vec![0.0; (steps + 1) * nv];
    free_rollout(model, &mut Data::new(model), q, v, &vec![0.0; nv], dt, steps, Method::Rk4, &mut qs, &mut vs).unwrap();
    (qs[steps * nq..].to_vec(), vs[steps * nv..].to_vec())
}

fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// Errors of runs whose substep halves from one to the next fall by about half each time: first order.
fn assert_first_order(errors: &[f64]) {
    for pair in errors.windows(2) {
        let ratio = pair[0] / pair[1];
        assert!((1.6..2.5).contains(&ratio), "halving the substep should halve the error, ratio {ratio}");
    }
}

fn released(model: &Model, substeps: usize, backend: Backend) -> Simulation {
    let (q, v) = start(model);
    let mut options = opts(backend, 1e-3);
    options.substeps = substeps;
    let mut sim = Simulation::new(model, options).unwrap();
    sim.set_state(Some(&q), Some(&v)).unwrap();
    sim
}

fn state_round_trips(backend: Backend) {
    let model = ten_link_tree();
    let (q, _) = start(&model);
    let v: Vec<f64> = (0..model.nv()).map(|k| 0.1 * k as f64 - 0.4).collect();
    let mut sim = Simulation::new(&model, opts(backend, 1e-3)).unwrap();
    sim.set_state(Some(&q), Some(&v)).unwrap();
    assert_eq!(sim.q(), q.as_slice());
    assert_eq!(sim.v(), v.as_slice());
    // Body poses agree with legkit's forward kinematics.
    let mut data = Data::new(&model);
    crate::algorithms::forward_kinematics_unchecked(&model, &mut data, &q);
    for (pose, expected) in sim.body_poses().iter().zip(&data.o_m_i) {
        assert!((pose.rotation - expected.rotation).amax() < 1e-12);
        assert!((pose.translation - expected.translation).amax() < 1e-12);
    }
}

fn free_tree_follows_aba_rk4(backend: Backend) {
    // Both integrators are first order: the error after 1 s must halve with the substep length. At 8
    // substeps per 1 ms step Rapier (Coriolis terms linearly implicit) stays within 1e-3 rad, the tree
    // engine's semi-implicit Euler (Coriolis explicit, as MuJoCo's Euler) within 2.5e-3 rad.
    let model = ten_link_tree();
    let (q, v) = start(&model);
    let (q_ref, _) = reference(&model, &q, &v, 1e-3, 1000);
    let errors: Vec<f64> = [1, 2, 4, 8]
        .iter()
        .map(|&substeps| {
            let mut sim = released(&model, substeps, backend);
            sim.step(None, 1000).unwrap();
            let error = max_difference(sim.q(), &q_ref);
            println!("free 10-link tree, 1 s at 1 kHz, {substeps} substeps: max |q - q_rk4| = {error:.3e}");
            error
        })
        .collect();
    assert_first_order(&errors);
    let bound = match backend {
        Backend::Rapier => 1e-3,
        Backend::Tree => 2.5e-3,
    };
    assert!(errors[3] < bound, "joint coordinates differ from ABA + RK4 by {}", errors[3]);
}

fn floating_base_follows_aba_rk4(backend: Backend) {
    // A tumbling floating box with an off-centre COM and a two-link arm, thrown upward and spinning.
    let base = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::new(0.03, -0.02, 0.01), &Matrix3::identity()).unwrap();
    let mut model = Model::new(true, base, "base");
    let a = model
        .add_body(0, Joint::Revolute(Vector3::z()), Transform::from_translation(Vector3::new(0.15, 0.0, 0.05)), rod(0.4, 0.2), "a", JointLimits::NONE)
        .unwrap();
    model
        .add_body(a, Joint::Revolute(Vector3::y()), Transform::from_translation(Vector3::new(0.2, 0.0, 0.0)), rod(0.3, 0.2), "b", JointLimits::NONE)
        .unwrap();
    let rotation = nalgebra::UnitQuaternion::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)), 0.7);
    let q = vec![0.1, -0.2, 1.0, rotation.i, rotation.j, rotation.k, rotation.w, 0.4, -0.3];
    let v = vec![0.2, 0.1, 3.0, 1.0, -2.0, 0.5, 1.5, -1.0];
    let (q_ref, v_ref) = reference(&model, &q, &v, 1e-3, 500);
    let mut options = opts(backend, 1e-3);
    options.substeps = 8;
    let mut sim = Simulation::new(&model, options).unwrap();
    sim.set_state(Some(&q), Some(&v)).unwrap();
    assert!(max_difference(sim.q(), &q) < 1e-14 && max_difference(sim.v(), &v) < 1e-12);
    sim.step(None, 500).unwrap();
    let (eq, ev) = (max_difference(sim.q(), &q_ref), max_difference(sim.v(), &v_ref));
    println!("floating base, 0.5 s at 1 kHz, 8 substeps: max |q - q_rk4| = {eq:.3e}, max |v - v_rk4| = {ev:.3e}");
    assert!(eq < 1e-3, "configuration differs from ABA + RK4 by {eq}");
}

fn joint_torques_match_aba_accelerations(backend: Backend) {
    // One step from rest: Δv / dt is the acceleration Rapier used; with no Coriolis terms at rest it must
    // equal ABA's q̈ for the same torques to first order in dt.
    let model = ten_link_tree();
    let (q, v) = start(&model);
    let tau: Vec<f64> = (0..model.nv()).map(|k| 0.5 * ((k as f64) * 0.9).cos()).collect();
    let mut sim = released(&model, 1, backend);
    sim.step(Some(&tau), 1).unwrap();
    let mut data = Data::new(&model);
    let ddq = crate::algorithms::aba_unchecked(&model, &mut data, &q, &v, &tau, None).clone();
    let numeric: Vec<f64> = sim.v().iter().map(|x| x / 1e-3).collect();
    let error = max_difference(&numeric, ddq.as_slice()) / ddq.amax();
    assert!(error < 1e-2, "relative acceleration error {error}");
}

fn floating_box(mass: f64, size: Vector3<f64>) -> Model {
    Model::new(true, MassProperties::solid_box(mass, size, Vector3::zeros(), &Matrix3::identity()).unwrap(), "box")
}

fn total_normal_force(contacts: &[Contact]) -> Vector3<f64> {
    contacts.iter().map(|c| c.normal * c.normal_force + c.tangential_force).sum()
}

fn box_resting_on_the_plane_carries_its_weight(backend: Backend) {
    let model = floating_box(3.0, Vector3::new(0.4, 0.3, 0.2));
    let mut options = opts(backend, 1e-3);
    options.ground = Some(Ground::plane(0.8).unwrap());
    let mut sim = Simulation::new(&model, options).unwrap();
    sim.set_state(Some(&[0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 1.0]), None).unwrap();
    sim.step(None, 1000).unwrap();
    let contacts = sim.contacts();
    assert!(contacts.len() >= 4, "a box face on a plane has 4 contact points, got {}", contacts.len());
    let force = total_normal_force(&contacts);
    let weight = 3.0 * STANDARD_GRAVITY;
    println!("box on plane: contact force {force:?}, weight {weight}");
    assert!((force.z - weight).abs() < 0.01 * weight, "vertical contact force {} vs weight {weight}", force.z);
    assert!(force.xy().norm() < 0.01 * weight);
    assert!(contacts.iter().all(|c| c.body == 0 && c.other.is_none() && (c.normal - Vector3::z()).norm() < 1e-9 && c.point.z.abs() < 2e-3));
}

/// A box lying on a plane tilted by 0.2 rad and lifted 0.5 m, friction holding it (tan 0.2 < 0.8): the plane's
/// normal carries its weight and friction the rest, and the box rests half its height above the plane.
fn box_resting_on_a_placed_plane_carries_its_weight(backend: Backend) {
    let model = floating_box(3.0, Vector3::new(0.4, 0.3, 0.2));
    let plane = Transform::new(Rotation3::from_euler_angles(0.2, 0.0, 0.3).into_inner(), Vector3::new(0.3, -0.2, 0.5));
    let normal = plane.rotation.column(2).into_owned();
    let mut options = opts(backend, 1e-3);
    options.ground = Some(Ground::placed_plane(0.8, plane).unwrap());
    let mut sim = Simulation::new(&model, options).unwrap();
    let start = plane.compose(&Transform::from_translation(Vector3::new(0.0, 0.0, 0.1)));
    let quaternion = UnitQuaternion::from_matrix(&start.rotation);
    let q = [start.translation.x, start.translation.y, start.translation.z, quaternion.i, quaternion.j, quaternion.k, quaternion.w];
    sim.set_state(Some(&q), None).unwrap();
    sim.step(None, 1000).unwrap();
    let contacts = sim.contacts();
    assert!(contacts.len() >= 4, "a box face on a plane has 4 contact points, got {}", contacts.len());
    let force = total_normal_force(&contacts);
    let weight = 3.0 * STANDARD_GRAVITY;
    assert!((force - Vector3::new(0.0, 0.0, weight)).norm() < 0.01 * weight, "contact force {force:?} vs weight {weight}");
    assert!(contacts.iter().all(|c| (c.normal - normal).norm() < 1e-9 && (c.point - plane.translation).dot(&normal).abs() < 2e-3));
    let height = (Vector3::new(sim.q()[0], sim.q()[1], sim.q()[2]) - plane.translation).dot(&normal);
    assert!((height - 0.1).abs() < 2e-3, "the box's centre is {height} m above the plane");
}

#[path = "../../tests/fixtures/quadruped.rs"]
mod fixture;

/// The fixture's quadruped (0.2 kg shins, knees unlimited) on the plane, standing on its servos.
fn quadruped_on_plane(substeps: usize, backend: Backend) -> Simulation {
    let (model, shapes) = fixture::quadruped(0.2, JointLimits::NONE);
    let mut options = opts(backend, 1e-3);
    options.ground = Some(Ground::plane(0.8).unwrap());
    options.shapes = shapes;
    options.substeps = substeps;
    let nv = model.nv();
    let mut sim = Simulation::new(&model, options).unwrap();
    let mut q = model.neutral().as_slice().to_vec();
    q[2] = 0.03 + 0.3 + 0.02 + 0.005;
    sim.set_state(Some(&q), None).unwrap();
    let mut kp = vec![40.0; nv];
    let mut kd = vec![1.0; nv];
    kp[..6].fill(0.0);
    kd[..6].fill(0.0);
    sim.set_servo(Servo::new(&model, kp, kd, vec![20.0; nv], vec![0.0; nv], vec![0.0; nv]).unwrap()).unwrap();
    sim
}

fn quadruped_standing_on_servos_carries_its_weight(backend: Backend) {
    let mut sim = quadruped_on_plane(1, backend);
    sim.step(None, 2000).unwrap();
    let contacts = sim.contacts();
    let force = total_normal_force(&contacts);
    let weight = sim.model().total_mass() * STANDARD_GRAVITY;
    println!("quadruped on plane: contact force {force:?}, weight {weight}, {} contacts", contacts.len());
    assert_eq!(contacts.len(), 4);
    assert!((force.z - weight).abs() < 0.01 * weight, "vertical contact force {} vs weight {weight}", force.z);
    assert!(sim.v().iter().all(|x| x.abs() < 1e-3), "not at rest: {:?}", sim.v());
}

fn identical_inputs_give_identical_trajectories(backend: Backend) {
    let run = || {
        let mut sim = quadruped_on_plane(2, backend);
        let nv = sim.model().nv();
        let tau: Vec<f64> = (0..nv).map(|k| if k < 6 { 0.0 } else { 0.3 * (k as f64).sin() }).collect();
        sim.step(Some(&tau), 300).unwrap();
        (sim.q().to_vec(), sim.v().to_vec(), sim.contacts())
    };
    let (a, b) = (run(), run());
    assert_eq!(a, b);
}

fn servo_torques_respect_limits_and_hold_targets(backend: Backend) {
    let model = ten_link_tree();
    let nv = model.nv();
    let mut sim = released(&model, 1, backend);
    let target: Vec<f64> = vec![0.0; nv];
    let servo = Servo::new(&model, vec![50.0; nv], vec![2.0; nv], vec![1.5; nv], target, vec![0.0; nv]).unwrap();
    sim.set_servo(servo).unwrap();
    let mut peak: f64 = 0.0;
    for _ in 0..2000 {
        sim.step(Some(&vec![3.0; nv]), 1).unwrap();
        peak = peak.max(sim.applied_tau().iter().fold(0.0, |m, t| m.max(t.abs())));
    }
    assert!(peak <= 1.5, "peak torque {peak} exceeds the 1.5 limit");
    assert!(peak == 1.5, "the feed-forward of 3 must saturate");
}

fn bad_input_is_rejected_and_changes_nothing(backend: Backend) {
    let model = ten_link_tree();
    let mut sim = released(&model, 1, backend);
    sim.step(None, 10).unwrap();
    let (q, v, t) = (sim.q().to_vec(), sim.v().to_vec(), sim.time());
    let mut nan = vec![0.0; model.nv()];
    nan[3] = f64::NAN;
    assert_eq!(sim.step(Some(&nan), 5).unwrap_err().argument(), "tau");
    assert_eq!(sim.step(Some(&[0.0; 3]), 5).unwrap_err().argument(), "tau");
    assert_eq!(sim.set_state(Some(&[0.0; 3]), None).unwrap_err().argument(), "q");
    assert_eq!(sim.set_state(None, Some(&nan)).unwrap_err().argument(), "v");
    assert_eq!(sim.reset(&q, &[1.0]).unwrap_err().argument(), "v");
    assert!(Servo::new(&model, vec![-1.0; model.nv()], vec![0.0; model.nv()], vec![1.0; model.nv()], vec![0.0; model.nv()], vec![0.0; model.nv()])
        .is_err());
    assert_eq!((sim.q(), sim.v(), sim.time()), (q.as_slice(), v.as_slice(), t));
    assert_eq!(Simulation::new(&model, opts(backend, 0.0)).err().unwrap().argument(), "dt");
    assert_eq!(Ground::heightfield(nalgebra::DMatrix::zeros(1, 5), 0.1, 0.8).unwrap_err().argument(), "heights");
}

fn reset_reproduces_a_fresh_simulation(backend: Backend) {
    let mut fresh = quadruped_on_plane(1, backend);
    let (q, v) = (fresh.q().to_vec(), fresh.v().to_vec());
    fresh.step(None, 200).unwrap();
    let mut reused = quadruped_on_plane(1, backend);
    reused.step(None, 137).unwrap();
    reused.reset(&q, &v).unwrap();
    reused.step(None, 200).unwrap();
    assert_eq!((fresh.q(), fresh.v(), fresh.time()), (reused.q(), reused.v(), reused.time()));
}

/// An inverted pendulum: a 1 kg, 0.5 m rod standing up from a fixed base on a revolute joint about y
/// (q > 0 leans the tip toward +x, so gravity drives |q| up), with `limits`.
fn inverted_pendulum(limits: JointLimits) -> Model {
    let mut model = Model::new(false, MassProperties::zero(), "base");
    // Body x (the rod) onto world +z: the tip is at L (sin q, 0, cos q).
    let up = Transform::new(Rotation3::from_euler_angles(0.0, -std::f64::consts::FRAC_PI_2, 0.0).into_inner(), Vector3::zeros());
    model.add_body(0, Joint::Revolute(Vector3::y()), up, rod(1.0, 0.5), "rod", limits).unwrap();
    model
}

/// Runs `sim` for `steps` steps with no actuation; returns the largest and smallest joint coordinate seen.
fn excursion(sim: &mut Simulation, steps: usize) -> (f64, f64) {
    let (mut high, mut low) = (f64::NEG_INFINITY, f64::INFINITY);
    for _ in 0..steps {
        sim.step(None, 1).unwrap();
        high = high.max(sim.q()[0]);
        low = low.min(sim.q()[0]);
    }
    (high, low)
}

fn revolute_limit_stops_a_falling_pendulum(backend: Backend) {
    // Released at rest from ±0.4 rad, the pendulum falls onto the ±0.5 rad limit. Rapier's limit is a
    // velocity constraint that engages only once the coordinate is past the bound (checked at the start
    // of each substep, of length h = dt / substeps), so the joint can travel one substep past it before
    // being driven back. Semi-implicit Euler moves it by h v_{n+1} = h (v_n + h α_n) in that substep, so
    // the overshoot is at most ω h + α h², with ω the speed at the limit (energy conservation from
    // 0.4 rad; Rapier's integrator only loses energy) and α ≤ m g (L/2) / I the largest gravitational
    // acceleration.
    let (m, length, g, dt): (f64, f64, f64, f64) = (1.0, 0.5, STANDARD_GRAVITY, 1e-3);
    let inertia = m * (length * length + 0.04 * 0.04) / 12.0 + m * (length / 2.0).powi(2);
    let omega = (2.0 * m * g * (length / 2.0) * (0.4f64.cos() - 0.5f64.cos()) / inertia).sqrt();
    let alpha = m * g * (length / 2.0) / inertia;
    for substeps in [1, 4] {
        let h = dt / substeps as f64;
        let tolerance = omega * h + alpha * h * h;
        for sign in [1.0, -1.0] {
            let model = inverted_pendulum(JointLimits::position(-0.5, 0.5).unwrap());
            let mut options = opts(backend, dt);
            options.substeps = substeps;
            let mut sim = Simulation::new(&model, options).unwrap();
            sim.set_state(Some(&[0.4 * sign]), None).unwrap();
            let (high, low) = excursion(&mut sim, 1000);
            let overshoot = if sign > 0.0 { high - 0.5 } else { -0.5 - low };
            println!("pendulum onto ±0.5 rad limit ({substeps} substeps, side {sign}): overshoot {overshoot:.3e} rad, bound {tolerance:.3e}");
            assert!(overshoot <= tolerance, "overshoot {overshoot} exceeds the one-substep bound {tolerance}");
            // It did reach the limit (unlimited, it would pass 0.5 within 0.3 s) and rests against it.
            assert!(overshoot > -1e-6, "the pendulum never reached the limit: overshoot {overshoot}");
            assert!(
                (sim.q()[0] - 0.5 * sign).abs() < 1e-4 && sim.v()[0].abs() < 1e-2,
                "not resting at the limit: q {}, v {}",
                sim.q()[0],
                sim.v()[0]
            );
        }
    }
    // Without limits the same release falls through 0.5 rad: the limit is what stopped it.
    let mut free = Simulation::new(&inverted_pendulum(JointLimits::NONE), opts(backend, dt)).unwrap();
    free.set_state(Some(&[0.4]), None).unwrap();
    assert!(excursion(&mut free, 1000).0 > 1.0);
}

fn prismatic_limit_stops_a_falling_slider(backend: Backend) {
    // A 2 kg block sliding along world z from 0 falls onto its lower limit at −0.2 m: speed at the limit
    // √(2 g 0.2), and the same one-step overshoot bound v dt + g dt².
    let (g, dt) = (STANDARD_GRAVITY, 1e-3);
    let mut model = Model::new(false, MassProperties::zero(), "base");
    let block = MassProperties::solid_box(2.0, Vector3::new(0.1, 0.1, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap();
    model.add_body(0, Joint::Prismatic(Vector3::z()), Transform::identity(), block, "block", JointLimits::position(-0.2, 0.3).unwrap()).unwrap();
    let mut sim = Simulation::new(&model, opts(backend, dt)).unwrap();
    let (_, low) = excursion(&mut sim, 1000);
    let tolerance = (2.0 * g * 0.2f64).sqrt() * dt + g * dt * dt;
    let overshoot = -0.2 - low;
    println!("slider onto -0.2 m limit: overshoot {overshoot:.3e} m, bound {tolerance:.3e}");
    assert!(overshoot <= tolerance && overshoot > -1e-6, "overshoot {overshoot}, bound {tolerance}");
    assert!((sim.q()[0] + 0.2).abs() < 1e-4 && sim.v()[0].abs() < 1e-2);
}

fn limits_out_of_reach_change_nothing(backend: Backend) {
    // Inside the range, the limit constraints carry zero impulse: the free tree's motion is unchanged.
    let free = ten_link_tree();
    let mut limited = Model::new(false, *free.body(0), free.name(0));
    for i in 1..free.nbodies() {
        let limits = JointLimits::new(-10.0, 10.0, 1e3, 1e3).unwrap();
        limited.add_body(free.parent(i), *free.joint(i), *free.placement(i), *free.body(i), free.name(i), limits).unwrap();
    }
    let (mut a, mut b) = (released(&free, 1, backend), released(&limited, 1, backend));
    a.step(None, 300).unwrap();
    b.step(None, 300).unwrap();
    assert!(max_difference(a.q(), b.q()) < 1e-12 && max_difference(a.v(), b.v()) < 1e-12);
}

fn effort_limit_clips_actuation(backend: Backend) {
    // Joint effort bound 1.5 N m; servo limit 3 (looser) then 1 (tighter); feed-forward ±10.
    let limited = inverted_pendulum(JointLimits::new(f64::NEG_INFINITY, f64::INFINITY, 1.5, f64::INFINITY).unwrap());
    let mut sim = Simulation::new(&limited, opts(backend, 1e-3)).unwrap();
    sim.step(Some(&[10.0]), 1).unwrap();
    assert_eq!(sim.applied_tau(), &[1.5]);
    sim.step(Some(&[-10.0]), 1).unwrap();
    assert_eq!(sim.applied_tau(), &[-1.5]);
    sim.set_servo(Servo::new(&limited, vec![5.0], vec![0.0], vec![3.0], vec![0.0], vec![0.0]).unwrap()).unwrap();
    sim.step(Some(&[10.0]), 1).unwrap();
    assert_eq!(sim.applied_tau(), &[1.5]);
    sim.set_servo(Servo::new(&limited, vec![5.0], vec![0.0], vec![1.0], vec![0.0], vec![0.0]).unwrap()).unwrap();
    sim.step(Some(&[10.0]), 1).unwrap();
    assert_eq!(sim.applied_tau(), &[1.0]);
    // The clipped torque is what drives the joint: the same motion as commanding 1.5 without a bound.
    let mut bounded = Simulation::new(&limited, opts(backend, 1e-3)).unwrap();
    let mut unbounded = Simulation::new(&inverted_pendulum(JointLimits::NONE), opts(backend, 1e-3)).unwrap();
    bounded.step(Some(&[10.0]), 200).unwrap();
    unbounded.step(Some(&[1.5]), 200).unwrap();
    assert_eq!((bounded.q(), bounded.v()), (unbounded.q(), unbounded.v()));
}

/// A body described with three spheres below it (the model's own collision shapes, as from URDF) rests
/// on them, not on its default box.
fn model_collision_shapes_replace_default_boxes(backend: Backend) {
    let mut model = floating_box(2.0, Vector3::new(0.3, 0.3, 0.05));
    let foot = |x: f64, y: f64| Shape::new(ShapeKind::Sphere(0.02), Some(Transform::from_translation(Vector3::new(x, y, -0.1)))).unwrap();
    model.set_collision_shapes(vec![(0, foot(0.1, 0.0)), (0, foot(-0.1, 0.1)), (0, foot(-0.1, -0.1))]).unwrap();
    let mut options = opts(backend, 1e-3);
    options.ground = Some(Ground::plane(0.8).unwrap());
    let mut sim = Simulation::new(&model, options).unwrap();
    sim.set_state(Some(&[0.0, 0.0, 0.13, 0.0, 0.0, 0.0, 1.0]), None).unwrap();
    sim.step(None, 500).unwrap();
    let contacts = sim.contacts();
    assert_eq!(contacts.len(), 3, "{contacts:?}");
    let height = sim.q()[2];
    assert!((height - 0.12).abs() <= 2e-3, "rests at {height} m, not on its spheres (0.12 m)");
    let bad = model.set_collision_shapes(vec![(5, foot(0.0, 0.0))]).unwrap_err();
    assert_eq!(bad.argument(), "shapes");
}

/// A box described by its mesh's convex hull (a collision mesh's vertices, an interior point among them)
/// rests on the ground like the box it is: at its half height, its weight carried.
fn convex_mesh_rests_like_its_box(backend: Backend) {
    let size = Vector3::new(0.3, 0.2, 0.05);
    let mut model = floating_box(2.0, size);
    let mut vertices: Vec<Vector3<f64>> =
        (0..8).map(|k| Vector3::new((k & 1) as f64 - 0.5, (k >> 1 & 1) as f64 - 0.5, (k >> 2 & 1) as f64 - 0.5).component_mul(&size)).collect();
    vertices.push(Vector3::new(0.01, 0.02, 0.0));
    let hull = Convex::hull(&vertices).unwrap();
    assert_eq!(hull.vertices().len(), 8);
    model.set_collision_shapes(vec![(0, Shape::new(ShapeKind::Convex(hull), Some(Transform::identity())).unwrap())]).unwrap();
    let mut options = opts(backend, 1e-3);
    options.ground = Some(Ground::plane(0.8).unwrap());
    let mut sim = Simulation::new(&model, options).unwrap();
    sim.set_state(Some(&[0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 1.0]), None).unwrap();
    sim.step(None, 1000).unwrap();
    let height = sim.q()[2];
    assert!((height - 0.025).abs() <= 1e-3, "rests at {height} m, not on its hull's bottom face (0.025 m)");
    let weight = 2.0 * STANDARD_GRAVITY;
    let force = total_normal_force(&sim.contacts());
    assert!((force.z - weight).abs() <= 1e-3 * weight && force.xy().norm() <= 1e-3 * weight, "contact force {force:?} vs weight {weight}");
    assert!(Convex::hull(&vertices[..4]).is_err(), "four corners of one face span no volume");
}

/// Bodies on fixed joints move as one body with their carrier: a floating box carrying a rotated slab on a
/// fixed joint, and an arm on a hinge carrying a fixed tip, fall and land as the same robot described
/// with the slab and the tip merged into their carriers (mass properties summed, shapes moved along);
/// contacts name the body whose shape touches.
fn fixed_bodies_move_with_their_carrier(backend: Backend) {
    let turn = Rotation3::from_euler_angles(0.3, -0.2, 0.5).into_inner();
    let slab_at = Transform::new(turn, Vector3::new(0.05, -0.1, -0.08));
    let tip_at = Transform::new(Rotation3::from_euler_angles(0.0, 0.4, 0.0).into_inner(), Vector3::new(0.3, 0.0, 0.0));
    let torso = MassProperties::solid_box(3.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity()).unwrap();
    let slab = MassProperties::solid_box(1.0, Vector3::new(0.2, 0.2, 0.04), Vector3::zeros(), &Matrix3::identity()).unwrap();
    let arm = rod(0.5, 0.3);
    let tip = MassProperties::solid_box(0.2, Vector3::new(0.06, 0.06, 0.06), Vector3::zeros(), &Matrix3::identity()).unwrap();
    let arm_at = Transform::from_translation(Vector3::new(0.15, 0.0, 0.0));
    let boxed = |size: Vector3<f64>, at: Transform| Shape::new(ShapeKind::Box(size), Some(at)).unwrap();
    let mut split = Model::new(true, torso, "torso");
    let slab_body = split.add_body(0, Joint::Fixed, slab_at, slab, "slab", JointLimits::NONE).unwrap();
    let arm_body =
        split.add_body(slab_body, Joint::Revolute(Vector3::y()), slab_at.inverse().compose(&arm_at), arm, "arm", JointLimits::NONE).unwrap();
    let tip_body = split.add_body(arm_body, Joint::Fixed, tip_at, tip, "tip", JointLimits::NONE).unwrap();
    split
        .set_collision_shapes(vec![
            (0, boxed(Vector3::new(0.3, 0.2, 0.1), Transform::identity())),
            (slab_body, boxed(Vector3::new(0.2, 0.2, 0.04), Transform::identity())),
            (arm_body, boxed(Vector3::new(0.3, 0.04, 0.04), Transform::from_translation(Vector3::new(0.15, 0.0, 0.0)))),
            (tip_body, boxed(Vector3::new(0.06, 0.06, 0.06), Transform::identity())),
        ])
        .unwrap();
    let merged_torso = torso + slab.transformed(&slab_at.rotation, &slab_at.translation).unwrap();
    let merged_arm = arm + tip.transformed(&tip_at.rotation, &tip_at.translation).unwrap();
    let mut merged = Model::new(true, merged_torso, "torso");
    merged.add_body(0, Joint::Revolute(Vector3::y()), arm_at, merged_arm, "arm", JointLimits::NONE).unwrap();
    merged
        .set_collision_shapes(vec![
            (0, boxed(Vector3::new(0.3, 0.2, 0.1), Transform::identity())),
            (0, boxed(Vector3::new(0.2, 0.2, 0.04), slab_at)),
            (1, boxed(Vector3::new(0.3, 0.04, 0.04), Transform::from_translation(Vector3::new(0.15, 0.0, 0.0)))),
            (1, boxed(Vector3::new(0.06, 0.06, 0.06), tip_at)),
        ])
        .unwrap();
    let run = |model: &Model| {
        let mut options = opts(backend, 1e-3);
        options.ground = Some(Ground::plane(0.8).unwrap());
        let mut sim = Simulation::new(model, options).unwrap();
        sim.set_state(Some(&[0.0, 0.0, 0.4, 0.1, 0.05, 0.0, (1.0f64 - 0.0125).sqrt(), 0.3]), Some(&[0.2, 0.0, 0.0, 0.0, 1.0, 0.5, 2.0])).unwrap();
        sim.step(Some(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3]), 400).unwrap();
        let touching: Vec<String> = sim.contacts().iter().map(|c| model.name(c.body).to_owned()).collect();
        (sim.q().to_vec(), touching)
    };
    let ((q_split, touch_split), (q_merged, _)) = (run(&split), run(&merged));
    assert!(q_split[2] < 0.2, "it has landed: base at {}", q_split[2]);
    assert!(max_difference(&q_split, &q_merged) < 1e-6, "{q_split:?} vs {q_merged:?}");
    assert!(!touch_split.is_empty() && touch_split.iter().all(|name| ["torso", "slab", "arm", "tip"].contains(&name.as_str())));
}

/// A turntable (a box on a vertical revolute axis) lying on the ground: its joint moves the contacts
/// only along the ground, so their normal rows are immovable (zero Delassus diagonal). They carry
/// nothing, and the table turns as without the ground (it used to turn the step's state into NaN).
#[test]
fn immovable_contacts_carry_nothing() {
    let mut model = Model::new(false, MassProperties::zero(), "ground");
    let plate = MassProperties::solid_box(0.5, Vector3::new(0.2, 0.1, 0.1), Vector3::new(0.3, 0.0, 0.0499), &Matrix3::identity()).unwrap();
    model.add_body(0, Joint::Revolute(Vector3::z()), Transform::identity(), plate, "table", JointLimits::NONE).unwrap();
    let mut on_ground = Options::new(1e-3);
    on_ground.ground = Some(Ground::plane(0.8).unwrap());
    let mut sim = Simulation::new(&model, on_ground).unwrap();
    let mut free = Simulation::new(&model, Options::new(1e-3)).unwrap();
    sim.step(Some(&[0.2]), 100).unwrap();
    free.step(Some(&[0.2]), 100).unwrap();
    assert!(!sim.contacts().is_empty());
    assert!(sim.contacts().iter().all(|c| c.normal_force == 0.0 && c.tangential_force == Vector3::zeros()));
    assert_eq!((sim.q(), sim.v()), (free.q(), free.v()));
}

/// A step that fails leaves the simulation as a twin that never took it, bit for bit, however many steps came
/// before it (the Rapier backend undoes from a checkpoint taken every few steps, replaying those since), also
/// after a change of state from outside, and after a failure just undone.
fn a_failed_step_leaves_a_never_failed_twin(backend: Backend) {
    let tau = |k: usize, nv: usize| -> Vec<f64> { (0..nv).map(|j| if j < 6 { 0.0 } else { 0.3 * ((k + j) as f64).sin() }).collect() };
    let state = |sim: &Simulation| (sim.q().to_vec(), sim.v().to_vec(), sim.time(), sim.applied_tau().to_vec(), sim.contacts());
    for before in [0, 1, 2, 31, 32, 33, 63, 64, 65, 100] {
        let (mut sim, mut twin) = (quadruped_on_plane(1, backend), quadruped_on_plane(1, backend));
        let nv = sim.model().nv();
        // The fixture's servos clip every coordinate to 20; free the base's wrench, through which a huge push
        // makes the step diverge.
        let (mut kp, mut kd, mut limit) = (vec![40.0; nv], vec![1.0; nv], vec![20.0; nv]);
        kp[..6].fill(0.0);
        kd[..6].fill(0.0);
        limit[..6].fill(f64::INFINITY);
        for s in [&mut sim, &mut twin] {
            let servo = Servo::new(s.model(), kp.clone(), kd.clone(), limit.clone(), vec![0.0; nv], vec![0.0; nv]).unwrap();
            s.set_servo(servo).unwrap();
        }
        for k in 0..before {
            if k == 50 {
                // A push from outside between steps.
                let mut v = sim.v().to_vec();
                v[0] += 0.1;
                sim.set_state(None, Some(&v)).unwrap();
                twin.set_state(None, Some(&v)).unwrap();
            }
            sim.step(Some(&tau(k, nv)), 1).unwrap();
            twin.step(Some(&tau(k, nv)), 1).unwrap();
        }
        for _ in 0..2 {
            let error = sim.step(Some(&vec![1e11; nv]), 1).unwrap_err();
            assert!(error.to_string().contains("diverged"), "{error}");
            assert_eq!(state(&sim), state(&twin), "after {before} steps");
        }
        for k in before..before + 40 {
            sim.step(Some(&tau(k, nv)), 1).unwrap();
            twin.step(Some(&tau(k, nv)), 1).unwrap();
        }
        assert_eq!(state(&sim), state(&twin), "40 steps after a failure after {before} steps");
    }
}

/// Jacobians asked of the Rapier backend are refused and change nothing: after `transition_jacobians` or a
/// rollout asking for them, the simulation steps on as a twin never asked (the refused step counted, so that
/// the undo replays the steps before it from the checkpoint, and only those).
#[cfg(feature = "rapier")]
#[test]
fn refused_jacobians_leave_a_rapier_simulation_as_its_twin() {
    let state = |sim: &Simulation| (sim.q().to_vec(), sim.v().to_vec(), sim.time(), sim.applied_tau().to_vec(), sim.contacts());
    let (mut sim, mut twin) = (quadruped_on_plane(1, Backend::Rapier), quadruped_on_plane(1, Backend::Rapier));
    let nv = sim.model().nv();
    for s in [&mut sim, &mut twin] {
        s.step(None, 5).unwrap();
    }
    let (mut a, mut b) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    assert_eq!(sim.transition_jacobians(None, &mut a, &mut b).unwrap_err().argument(), "backend");
    assert_eq!(sim.rollout(&vec![0.0; nv], true, &mut Rollout::default()).unwrap_err().argument(), "backend");
    assert_eq!(state(&sim), state(&twin));
    for s in [&mut sim, &mut twin] {
        s.step(None, 40).unwrap();
    }
    assert_eq!(state(&sim), state(&twin), "40 steps after the refusals");
}

#[cfg(not(feature = "rapier"))]
#[test]
fn the_rapier_backend_is_refused_without_its_feature() {
    let error = Simulation::new(&ten_link_tree(), opts(Backend::Rapier, 1e-3)).err().expect("no Rapier backend to build");
    assert_eq!(error.argument(), "backend");
    assert!(error.to_string().contains("`rapier` feature"), "{error}");
}

/// A fixed-base chain of a revolute and two ball joints with a side link on a ball, tumbling freely from a
/// spinning start (unit quaternions in q).
fn ball_chain() -> (Model, Vec<f64>, Vec<f64>) {
    let mut model = Model::new(false, rod(1.0, 0.1), "base");
    let down = Transform::new(Rotation3::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0).into_inner(), Vector3::zeros());
    let along = |length: f64| Transform::from_translation(Vector3::new(length, 0.0, 0.0));
    let a = model.add_body(0, Joint::Revolute(Vector3::y()), down, rod(0.6, 0.25), "a", JointLimits::NONE).unwrap();
    let b = model.add_body(a, Joint::Spherical, along(0.25), rod(0.5, 0.25), "b", JointLimits::NONE).unwrap();
    model.add_body(b, Joint::Spherical, along(0.25), rod(0.4, 0.2), "c", JointLimits::NONE).unwrap();
    model.add_body(a, Joint::Spherical, along(0.1), rod(0.2, 0.15), "side", JointLimits::NONE).unwrap();
    let turn = |x: f64, y: f64, z: f64| {
        let r = nalgebra::UnitQuaternion::from_euler_angles(x, y, z);
        [r.i, r.j, r.k, r.w]
    };
    let q = [vec![0.4], turn(0.3, -0.5, 0.2).to_vec(), turn(-0.2, 0.6, 0.4).to_vec(), turn(0.5, 0.1, -0.3).to_vec()].concat();
    let v = vec![0.5, 1.0, -2.0, 0.7, -0.5, 1.5, 3.0, 2.0, 0.0, -1.0];
    (model, q, v)
}

#[test]
fn ball_joints_follow_aba_rk4() {
    // As `free_tree_follows_aba_rk4`: first order, the error halving with the substep.
    let (model, q, v) = ball_chain();
    let (q_ref, v_ref) = reference(&model, &q, &v, 1e-3, 500);
    let errors: Vec<f64> = [2, 4, 8, 16]
        .iter()
        .map(|&substeps| {
            let mut options = opts(Backend::Tree, 1e-3);
            options.substeps = substeps;
            let mut sim = Simulation::new(&model, options).unwrap();
            sim.set_state(Some(&q), Some(&v)).unwrap();
            sim.step(None, 500).unwrap();
            let error = max_difference(sim.q(), &q_ref).max(0.1 * max_difference(sim.v(), &v_ref));
            println!("ball chain, 0.5 s at 1 kHz, {substeps} substeps: max(|q - q_rk4|, |v - v_rk4| / 10) = {error:.3e}");
            error
        })
        .collect();
    assert_first_order(&errors);
    assert!(errors[3] < 2.5e-3, "coordinates differ from ABA + RK4 by {}", errors[3]);
}

#[test]
fn ball_joints_take_velocity_servos_and_refuse_position_servos() {
    let (model, q, v) = ball_chain();
    let nv = model.nv();
    let mut kp = vec![0.0; nv];
    kp[2] = 5.0;
    let error = Servo::new(&model, kp, vec![0.0; nv], vec![f64::INFINITY; nv], vec![0.0; nv], vec![0.0; nv]).unwrap_err();
    assert_eq!(error.argument(), "kp");
    assert!(error.to_string().contains("ball joint of body 'b'"), "{error}");
    // A strong velocity servo (implicit) on every axis stops the spinning joints within a few steps.
    let mut sim = Simulation::new(&model, opts(Backend::Tree, 1e-3)).unwrap();
    sim.set_state(Some(&q), Some(&v)).unwrap();
    sim.set_servo(Servo::new(&model, vec![0.0; nv], vec![100.0; nv], vec![f64::INFINITY; nv], vec![0.0; nv], vec![0.0; nv]).unwrap()).unwrap();
    sim.step(None, 20).unwrap();
    assert!(sim.v().iter().all(|x| x.abs() < 0.05), "{:?}", sim.v());
    // The transition Jacobians take the ball joints' tangent spaces (checked against differences in Python).
    let (mut a, mut b) = (nalgebra::DMatrix::zeros(0, 0), nalgebra::DMatrix::zeros(0, 0));
    sim.transition_jacobians(None, &mut a, &mut b).unwrap();
    assert_eq!((a.shape(), b.shape()), ((2 * nv, 2 * nv), (2 * nv, 3 * nv)));
    assert!(a.iter().chain(b.iter()).all(|x| x.is_finite()));
}

fn opts(backend: Backend, dt: f64) -> Options {
    Options { backend, ..Options::new(dt) }
}

/// Each test runs on both backends: `name::tree` and `name::rapier`.
macro_rules! on_both_backends {
    ($($name:ident),* $(,)?) => {
        $(mod $name {
            #[test]
            fn tree() {
                super::$name(super::Backend::Tree)
            }
            #[cfg(feature = "rapier")]
            #[test]
            fn rapier() {
                super::$name(super::Backend::Rapier)
            }
        })*
    };
}

on_both_backends!(
    state_round_trips,
    free_tree_follows_aba_rk4,
    floating_base_follows_aba_rk4,
    joint_torques_match_aba_accelerations,
    box_resting_on_the_plane_carries_its_weight,
    box_resting_on_a_placed_plane_carries_its_weight,
    quadruped_standing_on_servos_carries_its_weight,
    identical_inputs_give_identical_trajectories,
    servo_torques_respect_limits_and_hold_targets,
    bad_input_is_rejected_and_changes_nothing,
    reset_reproduces_a_fresh_simulation,
    revolute_limit_stops_a_falling_pendulum,
    prismatic_limit_stops_a_falling_slider,
    limits_out_of_reach_change_nothing,
    effort_limit_clips_actuation,
    model_collision_shapes_replace_default_boxes,
    convex_mesh_rests_like_its_box,
    fixed_bodies_move_with_their_carrier,
    a_failed_step_leaves_a_never_failed_twin,
);
