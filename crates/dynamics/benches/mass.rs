//! Mass-property algebra: composition and rigid transform (targets: add <= 10 ns).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use legkit_dynamics::MassProperties;
use nalgebra::{Matrix3, Rotation3, Vector3};

fn mass(c: &mut Criterion) {
    let a = MassProperties::cuboid(1.5, Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.1, -0.2, 0.3), &Matrix3::identity())
        .unwrap();
    let b = MassProperties::cuboid(0.5, Vector3::new(0.3, 0.1, 0.2), Vector3::new(-0.4, 0.2, 0.1), &Matrix3::identity())
        .unwrap();
    let rotation = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
    let translation = Vector3::new(0.5, 0.1, -0.3);
    c.bench_function("mass_properties/add", |bench| bench.iter(|| black_box(a) + black_box(b)));
    c.bench_function("mass_properties/sub", |bench| bench.iter(|| black_box(a + b) - black_box(b)));
    c.bench_function("mass_properties/transform", |bench| {
        bench.iter(|| black_box(a).transformed_unchecked(black_box(&rotation), black_box(&translation)))
    });
}

criterion_group!(benches, mass);
criterion_main!(benches);
