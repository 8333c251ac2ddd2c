//! Mean cost of one `circle_line` query over a million random configurations.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use legkit_dynamics::{circle_line, Circle, Line};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const QUERIES: usize = 1_000_000;

fn random_vector(rng: &mut StdRng) -> Vector3<f64> {
    Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0))
}

fn queries() -> Vec<(Circle, Line)> {
    let mut rng = StdRng::seed_from_u64(42);
    (0..QUERIES)
        .map(|_| {
            let circle = Circle::new(
                random_vector(&mut rng) * 10.0,
                random_vector(&mut rng),
                rng.random_range(0.1..5.0),
            );
            let line = Line::new(random_vector(&mut rng) * 10.0, random_vector(&mut rng));
            // A zero vector has probability zero; unwrap documents that it cannot occur here.
            (circle.unwrap(), line.unwrap())
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let queries = queries();
    let mut group = c.benchmark_group("circle_line");
    group.sample_size(10).throughput(Throughput::Elements(QUERIES as u64));
    group.bench_function("random_1m", |b| {
        b.iter(|| {
            for (circle, line) in &queries {
                black_box(circle_line(black_box(circle), black_box(line)));
            }
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
