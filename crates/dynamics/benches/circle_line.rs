//! Mean cost of one `circle_line` query over a million random configurations: the solve alone
//! (`random_1m`), and the whole job a batch call does (`random_1m_from_raw`: validate raw inputs,
//! solve, write every result into freshly allocated output arrays), the baseline for the Python batch.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use legkit_dynamics::{circle_line, Circle, CircleLineColumns, Line};
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
            let circle = Circle::new(random_vector(&mut rng) * 10.0, random_vector(&mut rng), rng.random_range(0.1..5.0));
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
    let raw: Vec<[Vector3<f64>; 4]> = queries.iter().map(|(c, l)| [c.center, c.normal * 2.0, l.point, l.direction * 3.0]).collect();
    let radii: Vec<f64> = queries.iter().map(|(c, _)| c.radius).collect();
    group.bench_function("random_1m_from_raw", |b| {
        b.iter(|| {
            let (mut distance, mut count, mut equidistant) = (vec![0.0; QUERIES], vec![0i64; QUERIES], vec![false; QUERIES]);
            let (mut circle_points, mut line_points) = (vec![0.0; 6 * QUERIES], vec![0.0; 6 * QUERIES]);
            let mut columns = CircleLineColumns {
                distance: &mut distance,
                count: &mut count,
                circle_points: &mut circle_points,
                line_points: &mut line_points,
                equidistant: &mut equidistant,
            };
            for (i, ([center, normal, point, direction], radius)) in raw.iter().zip(&radii).enumerate() {
                let circle = Circle::new(*center, *normal, *radius).unwrap();
                columns.set(i, &circle_line(&circle, &Line::new(*point, *direction).unwrap()));
            }
            black_box((distance, count, equidistant, circle_points, line_points))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
