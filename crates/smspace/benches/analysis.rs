//! Benchmarks of the analysis stage: Rips persistence up to `H1` on seeded samples of a
//! circle times a segment (the arm's manifold is a circle times a plane) over a size
//! sweep, the dimension estimates and the agreement figures; and, when
//! `SMSPACE_BENCH_DISTANCES` names an `(M, M)` `.npy` distance matrix (e.g. of the
//! paper's arm), its homology on 800 max–min landmarks (the default) and on 1500.
//!
//! `cargo bench -p smspace --bench analysis`
#![allow(
    missing_docs,
    reason = "criterion_group! generates undocumented functions"
)]

use std::path::Path;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::{Array2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::analysis::{agreement, dimension, maxmin_landmarks, rips_persistence};
use smspace::progress::Silent;

/// `n` points of a circle of radius 1 times a segment of length 1, and their
/// Euclidean distances.
fn cylinder(n: usize, seed: u64) -> (Array2<f64>, Array2<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let poses = Array2::from_shape_fn((n, 3), |(_, c)| match c {
        0 => rng.random_range(0.0..1.0),
        1 => 0.0,
        _ => rng.random_range(-3.1..3.1),
    });
    let point = |i: usize| {
        let a: f64 = poses[[i, 2]];
        [a.cos(), a.sin(), poses[[i, 0]]]
    };
    let d = Array2::from_shape_fn((n, n), |(i, j)| {
        let (p, q) = (point(i), point(j));
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    });
    (d, poses)
}

fn bench_homology(c: &mut Criterion) {
    let mut group = c.benchmark_group("rips_h1_cylinder");
    group.sample_size(10);
    for n in [200, 400, 800] {
        let (d, _) = cylinder(n, 1);
        group.bench_with_input(BenchmarkId::from_parameter(n), &d, |b, d| {
            b.iter(|| rips_persistence(d.view(), 1, None, &Silent).unwrap())
        });
    }
    group.finish();
}

fn bench_dimension_and_agreement(c: &mut Criterion) {
    let mut group = c.benchmark_group("dimension_agreement");
    group.sample_size(10);
    let (d, poses) = cylinder(1500, 2);
    group.bench_function("twonn_mle_1500", |b| {
        b.iter(|| {
            (
                dimension::twonn(d.view(), 0.1).unwrap(),
                dimension::mle(d.view(), 20).unwrap(),
            )
        })
    });
    group.bench_function("agreement_1500", |b| {
        b.iter(|| agreement::agreement(d.view(), poses.view(), 10).unwrap())
    });
    group.finish();
}

fn bench_given_matrix(c: &mut Criterion) {
    let Ok(path) = std::env::var("SMSPACE_BENCH_DISTANCES") else {
        return;
    };
    let d = smspace::io::read_matrix(Path::new(&path), None, "(M, M)").unwrap();
    let mut group = c.benchmark_group("rips_h1_given");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(60));
    for n in [800, 1500] {
        let (rows, _) = maxmin_landmarks(d.view(), n);
        let sub = d.select(Axis(0), &rows).select(Axis(1), &rows);
        group.bench_with_input(BenchmarkId::from_parameter(n), &sub, |b, sub| {
            b.iter(|| rips_persistence(sub.view(), 1, None, &Silent).unwrap())
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    bench_homology,
    bench_dimension_and_agreement,
    bench_given_matrix
);
criterion_main!(benches);
