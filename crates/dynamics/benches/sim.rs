//! One 1 ms step of the simulation, legkit's tree engine and the Rapier reference, on the SuperBot-like trees
//! of `benches/simulation_vs_mujoco.py` (the engine's targets, measured against MuJoCo by that script: the
//! 21-module, 63-DoF tree with ground contact and position servos at ≤ 0.6x MuJoCo's step; a 101-module
//! tree at ≥ 1x real time).
//!
//! Trees: modules of four 0.0125 kg bodies (0.06 x 0.06 x 0.0425 m boxes stacked along the module's +z):
//! end block, pitch (y), link, roll (z), link, pitch (y), end block. A vertical root module fixed to the
//! ground; four branches of (n − 1)/4 modules leave its top block horizontally (turned 0°, 90°, 180°,
//! 270° about z) and sag onto the ground plane. Servos: kp 0.5 N m/rad, kd 0.002 N m s/rad, limit 0.5 N m,
//! holding the neutral configuration. `simulation_step` times one step after 100 settling steps, when the
//! trees have come to rest (the contact solver converges at its warm start); `simulation_sway` times the
//! 1,000 steps after those 100, while the trees still sag and sway (the regime the Python benchmark times).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BatchSize, BenchmarkId, Criterion};
use legkit_dynamics::sim::{Backend, Ground, Options, Servo, Simulation};
use legkit_dynamics::{Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{Matrix3, Vector3};

const MODULE_LENGTH: f64 = 0.17;
const PART_MASS: f64 = 0.05 / 4.0;

fn module_tree(n_modules: usize) -> Model {
    let part = MassProperties::solid_box(
        PART_MASS,
        Vector3::new(0.06, 0.06, MODULE_LENGTH / 4.0),
        Vector3::new(0.0, 0.0, MODULE_LENGTH / 8.0),
        &Matrix3::identity(),
    )
    .expect("valid box");
    let mut model = Model::new(false, MassProperties::zero(), "base");
    let step = Transform::from_translation(Vector3::new(0.0, 0.0, MODULE_LENGTH / 4.0));
    let add_module = |model: &mut Model, parent: usize, placement: Transform| -> usize {
        let mut body = model.add_body(parent, Joint::Fixed, placement, part, &format!("block{}", model.nbodies()), JointLimits::NONE).expect("valid");
        for axis in [Vector3::y(), Vector3::z(), Vector3::y()] {
            body = model.add_body(body, Joint::Revolute(axis), step, part, &format!("part{}", model.nbodies()), JointLimits::NONE).expect("valid");
        }
        body
    };
    let top = add_module(&mut model, 0, Transform::from_translation(Vector3::new(0.0, 0.0, 0.05)));
    for branch in 0..4 {
        let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), branch as f64 * std::f64::consts::FRAC_PI_2)
            * nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
        let mut parent = top;
        let mut placement = Transform::new(turn.into_inner(), step.translation);
        for _ in 0..(n_modules - 1) / 4 {
            parent = add_module(&mut model, parent, placement);
            placement = step;
        }
    }
    model
}

fn settled(model: &Model, backend: Backend) -> Simulation {
    let mut options = Options::new(1e-3);
    options.backend = backend;
    options.ground = Some(Ground::plane(0.8).expect("valid friction"));
    let mut sim = Simulation::new(model, options).expect("valid model");
    let nv = model.nv();
    let servo = Servo::new(model, vec![0.5; nv], vec![0.002; nv], vec![0.5; nv], vec![0.0; nv], vec![0.0; nv]).expect("valid servo");
    sim.set_servo(servo).expect("sized for the model");
    sim.step(None, 100).expect("stable");
    sim
}

fn step(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulation_step");
    group.sample_size(10);
    for (backend, sizes) in [(Backend::Tree, &[21, 51, 101][..]), (Backend::Rapier, &[21][..])] {
        for &n in sizes {
            let model = module_tree(n);
            let mut sim = settled(&model, backend);
            let id = BenchmarkId::new(format!("{}_superbot_tree_modules", backend.name()), n);
            group.bench_with_input(id, &n, |b, _| b.iter(|| black_box(&mut sim).step(None, 1).expect("stable")));
        }
    }
    group.finish();
}

fn sway(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulation_sway");
    group.sample_size(10);
    for n in [21, 101] {
        let model = module_tree(n);
        let id = BenchmarkId::new("tree_superbot_tree_modules_1000_steps", n);
        group.bench_with_input(id, &n, |b, _| {
            b.iter_batched_ref(|| settled(&model, Backend::Tree), |sim| sim.step(None, 1000).expect("stable"), BatchSize::PerIteration)
        });
    }
    group.finish();
}

criterion_group!(benches, step, sway);
criterion_main!(benches);
