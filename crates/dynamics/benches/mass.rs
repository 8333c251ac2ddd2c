//! Mass-property algebra: composition and rigid transform (target: add <= 10 ns).
//!
//! Each measurement runs over 1,000 bodies so that the harness' per-iteration cost (moving 104-byte
//! values through `black_box`) does not swamp a ~10 ns operation; read the per-element time.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use legkit_dynamics::MassProperties;
use nalgebra::{Rotation3, Vector3};

const N: usize = 1000;

fn bodies(seed: f64) -> Vec<MassProperties> {
    (0..N)
        .map(|i| {
            let x = seed + i as f64 * 0.37;
            let rotation = Rotation3::from_euler_angles(x.sin(), x.cos(), 0.5 * x).into_inner();
            let size = Vector3::new(0.1 + 0.05 * x.sin().abs(), 0.2, 0.3);
            let center = Vector3::new(x.cos(), (2.0 * x).sin(), 0.3 * x.sin());
            MassProperties::solid_box(1.0 + x.sin().abs(), size, center, &rotation).unwrap()
        })
        .collect()
}

fn mass(c: &mut Criterion) {
    let (a, b) = (bodies(0.0), bodies(1.0));
    let mut out = vec![MassProperties::zero(); N];
    let rotation = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
    let translation = Vector3::new(0.5, 0.1, -0.3);
    let mut group = c.benchmark_group("mass_properties");
    group.throughput(Throughput::Elements(N as u64));
    group.bench_function("add (independent pairs)", |bench| {
        bench.iter(|| {
            for ((o, x), y) in out.iter_mut().zip(black_box(&a)).zip(black_box(&b)) {
                *o = *x + *y;
            }
            black_box(&out);
        })
    });
    group.bench_function("add (running sum)", |bench| bench.iter(|| black_box(black_box(&a).iter().copied().sum::<MassProperties>())));
    group.bench_function("transform", |bench| {
        bench.iter(|| {
            for (o, x) in out.iter_mut().zip(black_box(&a)) {
                *o = x.transformed_unchecked(&rotation, &translation);
            }
            black_box(&out);
        })
    });
    group.bench_function("sub (validated)", |bench| {
        bench.iter(|| {
            for ((o, x), y) in out.iter_mut().zip(black_box(&a)).zip(black_box(&b)) {
                *o = (*x + *y - *y).unwrap();
            }
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group!(benches, mass);
criterion_main!(benches);
