//! ABA, RNEA, CRBA and M⁻¹ on the 63-DoF SuperBot-like modular tree, ABA on revolute chains of 64 and 1024 links, CRBA
//! and M⁻¹ on the 64-link chain
//! (targets: ABA on the 63-DoF tree <= 5 µs; ABA linear in the number of bodies), and the RNEA, ABA and centroidal
//! derivatives on the tree and on chains of 64 and 512 links (`benches/derivatives_vs_pinocchio.py` compares them with
//! Pinocchio's).
//!
//! The models are those of `benches/models.py` (the Python comparison with Pinocchio), built here again:
//! * tree: a fixed root module and 4 branches of 5 modules, each module 0.1 m long along its +x with three
//!   revolute joints in series, pitch (y) at its entry face, roll (x) 0.025 m further, pitch (y) 0.05 m
//!   further; end blocks 0.05 kg (0.025 x 0.05 x 0.05 m), middle block 0.1 kg (0.05 x 0.03 x 0.03 m). Two
//!   branches leave the root's last end block through its ±y side faces, two its first end block; along a
//!   branch a module plugs into the previous one's exit face, turned 90° about that face's normal (x) at
//!   every other connection.
//! * chain n: n box links of 0.5 kg, 0.1 m along z, joint axes cycling y, x, z.
//! * quadruped: a free-flyer 8 kg torso (0.5 x 0.25 x 0.1 m) and 4 legs of hip abduction (x), hip flexion (y) and
//!   knee (y), with the contact dynamics' and impacts' derivatives at a point on each shank (`contacts` group).
//!
//! States are random (joint angles in [-π, π], v and τ standard normal), fixed by a seed.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use legkit_dynamics::algorithms::{
    aba, aba_derivatives, centroidal_derivatives, contact_dynamics, contact_dynamics_derivatives, crba, impact_derivatives, minv, rnea,
    rnea_derivatives, rnea_second_order_derivatives, ContactDim, ContactPoint,
};
use legkit_dynamics::{Data, Joint, JointLimits, MassProperties, Model, Transform};
use nalgebra::{Matrix3, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A solid box of `mass`, edge lengths `size`, centred at `center` in its body frame.
fn solid_box(mass: f64, size: [f64; 3], center: [f64; 3]) -> MassProperties {
    MassProperties::solid_box(mass, Vector3::from(size), Vector3::from(center), &Matrix3::identity()).expect("valid box")
}

/// A quarter-turn rotation (`turns` × 90°) about coordinate axis `axis` (0 = x, 1 = y, 2 = z), exact.
fn quarter_turn(axis: usize, turns: i32) -> Matrix3<f64> {
    let (c, s) = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][turns.rem_euclid(4) as usize];
    let (i, j, k) = (axis, (axis + 1) % 3, (axis + 2) % 3);
    let mut r = Matrix3::zeros();
    r[(i, i)] = 1.0;
    r[(j, j)] = c;
    r[(j, k)] = -s;
    r[(k, j)] = s;
    r[(k, k)] = c;
    r
}

fn revolute(model: &mut Model, parent: usize, axis: Vector3<f64>, placement: Transform, body: MassProperties, name: String) -> usize {
    model.add_body(parent, Joint::Revolute(axis), placement, body, &name, JointLimits::NONE).expect("valid body")
}

/// One SuperBot-like module entering at `placement` in body `parent`: returns its (first, last) end blocks.
fn module(model: &mut Model, parent: usize, placement: Transform, name: &str) -> (usize, usize) {
    let end_block = solid_box(0.05, [0.025, 0.05, 0.05], [0.0125, 0.0, 0.0]);
    let middle_block = solid_box(0.10, [0.05, 0.03, 0.03], [0.025, 0.0, 0.0]);
    let first = revolute(model, parent, Vector3::y(), placement, end_block, format!("{name}_j0"));
    let middle = revolute(model, first, Vector3::x(), Transform::from_translation(Vector3::new(0.025, 0.0, 0.0)), middle_block, format!("{name}_j1"));
    let last = revolute(model, middle, Vector3::y(), Transform::from_translation(Vector3::new(0.05, 0.0, 0.0)), end_block, format!("{name}_j2"));
    (first, last)
}

/// The 63-DoF tree: 21 modules x 3 revolute joints on a fixed base, bodies in depth-first order.
fn superbot_tree() -> Model {
    let mut model = Model::new(false, MassProperties::zero(), "base");
    let (first, last) = module(&mut model, 0, Transform::identity(), "root");
    let faces = [
        (last, quarter_turn(2, 1), Vector3::new(0.0125, 0.025, 0.0)),
        (last, quarter_turn(2, -1), Vector3::new(0.0125, -0.025, 0.0)),
        (first, quarter_turn(2, 1), Vector3::new(0.0125, 0.025, 0.0)),
        (first, quarter_turn(2, -1), Vector3::new(0.0125, -0.025, 0.0)),
    ];
    for (b, (host, r_face, t_face)) in faces.into_iter().enumerate() {
        let (mut parent, mut r, mut t) = (host, r_face, t_face);
        for m in 0..5 {
            let twist = quarter_turn(0, m % 2);
            parent = module(&mut model, parent, Transform::new(r * twist, t), &format!("b{b}m{m}")).1;
            (r, t) = (Matrix3::identity(), Vector3::new(0.025, 0.0, 0.0));
        }
    }
    assert_eq!(model.nv(), 63);
    model
}

/// A revolute chain of `n` 0.1 m box links along z, axes cycling y, x, z.
fn chain(n: usize) -> Model {
    let mut model = Model::new(false, MassProperties::zero(), "base");
    let axes = [Vector3::y(), Vector3::x(), Vector3::z()];
    let link = solid_box(0.5, [0.03, 0.03, 0.1], [0.0, 0.0, 0.05]);
    for i in 0..n {
        let offset = if i > 0 { 0.1 } else { 0.0 };
        revolute(&mut model, i, axes[i % 3], Transform::from_translation(Vector3::new(0.0, 0.0, offset)), link, format!("link{i}"));
    }
    model
}

/// The 18-DoF floating quadruped, and a contact point on each shank (0.22 m below its knee).
fn quadruped() -> (Model, Vec<ContactPoint>) {
    let mut model = Model::new(true, solid_box(8.0, [0.5, 0.25, 0.1], [0.0; 3]), "torso");
    let mut feet = Vec::new();
    for (name, sx, sy) in [("fl", 1.0, 1.0), ("fr", 1.0, -1.0), ("hl", -1.0, 1.0), ("hr", -1.0, -1.0)] {
        let at = |x: f64, y: f64, z: f64| Transform::from_translation(Vector3::new(x, y, z));
        let hip = revolute(
            &mut model,
            0,
            Vector3::x(),
            at(0.22 * sx, 0.09 * sy, 0.0),
            solid_box(0.6, [0.08, 0.06, 0.06], [0.0; 3]),
            format!("{name}_hip_abad"),
        );
        let thigh = revolute(
            &mut model,
            hip,
            Vector3::y(),
            at(0.0, 0.07 * sy, 0.0),
            solid_box(1.0, [0.04, 0.04, 0.22], [0.0, 0.0, -0.11]),
            format!("{name}_hip_flex"),
        );
        let shank = revolute(
            &mut model,
            thigh,
            Vector3::y(),
            at(0.0, 0.0, -0.22),
            solid_box(0.25, [0.025, 0.025, 0.22], [0.0, 0.0, -0.11]),
            format!("{name}_knee"),
        );
        feet.push(ContactPoint { body: shank, point: Vector3::new(0.0, 0.0, -0.22) });
    }
    (model, feet)
}

/// A random state (q, v, τ) for a fixed-base model of revolute joints.
fn random_state(model: &Model, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let q = (0..model.nq()).map(|_| rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)).collect();
    // Standard normal by Box–Muller, to match the Python side's distribution (not its numbers).
    let mut normal = || {
        let (u1, u2): (f64, f64) = (rng.random_range(f64::EPSILON..1.0), rng.random());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let v = (0..model.nv()).map(|_| normal()).collect();
    let tau = (0..model.nv()).map(|_| normal()).collect();
    (q, v, tau)
}

fn tree(c: &mut Criterion) {
    let model = superbot_tree();
    let mut data = Data::new(&model);
    let (q, v, tau) = random_state(&model, 1);
    let mut group = c.benchmark_group("tree63");
    group.bench_function("aba", |b| b.iter(|| aba(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), None).unwrap()[0]));
    group.bench_function("rnea", |b| b.iter(|| rnea(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), None).unwrap()[0]));
    group.bench_function("crba", |b| b.iter(|| crba(&model, &mut data, black_box(&q)).unwrap()[(0, 0)]));
    group.bench_function("minv", |b| b.iter(|| minv(&model, &mut data, black_box(&q)).unwrap()[(0, 0)]));
    group.finish();
}

fn chains(c: &mut Criterion) {
    let mut group = c.benchmark_group("chain_aba");
    for n in [64, 1024] {
        let model = chain(n);
        let mut data = Data::new(&model);
        let (q, v, tau) = random_state(&model, n as u64);
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| aba(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), None).unwrap()[0])
        });
    }
    group.finish();
}

/// CRBA and M⁻¹ on the 64-link chain, the row of `benches/dynamics_vs_pinocchio.py` where M⁻¹ is furthest from CRBA.
fn chain64(c: &mut Criterion) {
    let model = chain(64);
    let mut data = Data::new(&model);
    let (q, _, _) = random_state(&model, 64);
    let mut group = c.benchmark_group("chain64");
    group.bench_function("crba", |b| b.iter(|| crba(&model, &mut data, black_box(&q)).unwrap()[(0, 0)]));
    group.bench_function("minv", |b| b.iter(|| minv(&model, &mut data, black_box(&q)).unwrap()[(0, 0)]));
    group.finish();
}

fn derivatives(c: &mut Criterion) {
    let mut group = c.benchmark_group("derivatives");
    for (name, model) in [("quadruped", quadruped().0), ("tree63", superbot_tree()), ("chain64", chain(64)), ("chain512", chain(512))] {
        let mut data = Data::new(&model);
        let (mut q, v, tau) = random_state(&model, model.nv() as u64);
        if model.floating_base() {
            q[3..7].copy_from_slice(&[0.0, 0.0, 0.0, 1.0]);
        }
        group.bench_function(BenchmarkId::new("rnea", name), |b| {
            b.iter(|| rnea_derivatives(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), None).unwrap().0[(0, 0)])
        });
        group.bench_function(BenchmarkId::new("aba", name), |b| {
            b.iter(|| aba_derivatives(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), None).unwrap().0[(0, 0)])
        });
        if model.nv() <= 64 {
            group.bench_function(BenchmarkId::new("rnea_second_order", name), |b| {
                b.iter(|| rnea_second_order_derivatives(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau)).unwrap().dqdq[0])
            });
        }
        group.bench_function(BenchmarkId::new("centroidal", name), |b| {
            b.iter(|| centroidal_derivatives(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau)).unwrap().0[(0, 0)])
        });
    }
    group.finish();
}

fn contacts(c: &mut Criterion) {
    let (model, feet) = quadruped();
    let mut data = Data::new(&model);
    let (mut q, v, tau) = random_state(&model, 4);
    q[3..7].copy_from_slice(&[0.0, 0.0, 0.0, 1.0]); // the base upright
    let mut group = c.benchmark_group("contacts");
    group.bench_function("contact_dynamics/quadruped", |b| {
        b.iter(|| {
            contact_dynamics(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), &feet, ContactDim::Point).expect("independent").ddq[0]
        })
    });
    group.bench_function("contact_dynamics_derivatives/quadruped", |b| {
        b.iter(|| {
            contact_dynamics_derivatives(&model, &mut data, black_box(&q), black_box(&v), black_box(&tau), &feet, ContactDim::Point)
                .expect("independent")
                .ddq_dq[(0, 0)]
        })
    });
    group.bench_function("impact_derivatives/quadruped", |b| {
        b.iter(|| {
            impact_derivatives(&model, &mut data, black_box(&q), black_box(&v), &feet, ContactDim::Point).expect("independent").velocity_dq[(0, 0)]
        })
    });
    group.finish();
}

criterion_group!(benches, tree, chains, chain64, derivatives, contacts);
criterion_main!(benches);
