//! Benchmarks of the embeddings at the paper's size (M = 2500) and beyond.
//!
//! Run: `cargo bench -p smspace --bench embed` (add `-- cca` etc. to filter).
//!
//! Inputs are seeded points on a circle × plane, `(cos a, sin a, x, y)`, the topology
//! of the paper's manifold (T × R²), with Euclidean distances. When the environment
//! variable `SMSPACE_ARM_D` names an `(M, M)` `.npy` distance matrix (e.g. the arm's
//! `arm-D-2500.npy`), CCA and Isomap are also timed on it.

#![allow(
    missing_docs,
    reason = "criterion_group! generates an undocumented function"
)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::embed::{CcaParams, Embedding, IsomapParams, KnnGraph, LandmarkChoice, MdsParams};
use smspace::metric::DistanceMatrix;
use smspace::progress::Silent;

/// `n` seeded points `(cos a, sin a, x, y)` with `a ∈ [0, 2π)`, `x, y ∈ [0, 2)`.
fn circle_times_plane(n: usize, seed: u64) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut p = Array2::zeros((n, 4));
    for i in 0..n {
        let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        p[[i, 0]] = a.cos();
        p[[i, 1]] = a.sin();
        p[[i, 2]] = rng.random_range(0.0..2.0);
        p[[i, 3]] = rng.random_range(0.0..2.0);
    }
    p
}

fn euclidean(p: &Array2<f64>) -> Array2<f64> {
    let n = p.nrows();
    Array2::from_shape_fn((n, n), |(i, j)| {
        let d = &p.row(i) - &p.row(j);
        d.dot(&d).sqrt()
    })
}

/// The `k` nearest neighbours of every point, by brute force (the metric stage's kNN
/// mode would supply this graph).
fn knn_arrays(p: &Array2<f64>, k: usize) -> KnnGraph {
    use rayon::prelude::*;
    let n = p.nrows();
    let rows: Vec<Vec<(usize, f64)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut d: Vec<(usize, f64)> = (0..n)
                .filter(|&j| j != i)
                .map(|j| {
                    let v = &p.row(i) - &p.row(j);
                    (j, v.dot(&v).sqrt())
                })
                .collect();
            d.select_nth_unstable_by(k - 1, |a, b| a.1.total_cmp(&b.1));
            d.truncate(k);
            d.sort_by(|a, b| a.1.total_cmp(&b.1));
            d
        })
        .collect();
    let indices = Array2::from_shape_fn((n, k), |(i, c)| rows[i][c].0 as i64);
    let dists = Array2::from_shape_fn((n, k), |(i, c)| rows[i][c].1);
    KnnGraph::from_arrays(indices.view(), dists.view()).expect("valid graph")
}

fn arm_distances() -> Option<DistanceMatrix> {
    let path = std::env::var_os("SMSPACE_ARM_D")?;
    DistanceMatrix::load(std::path::Path::new(&path)).ok()
}

fn cca(c: &mut Criterion) {
    let mut group = c.benchmark_group("cca_3d_50_epochs");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(15));
    let method = CcaParams::default().dim(3).epochs(50).check().unwrap();
    for n in [500, 1000, 2500] {
        let d = DistanceMatrix::new(euclidean(&circle_times_plane(n, 1))).unwrap();
        group.bench_with_input(BenchmarkId::new("circle_x_plane", n), &d, |b, d| {
            b.iter(|| black_box(method.fit(d, &Silent).unwrap()))
        });
    }
    if let Some(d) = arm_distances() {
        group.bench_function(BenchmarkId::new("arm", d.nrows()), |b| {
            b.iter(|| black_box(method.fit(&d, &Silent).unwrap()))
        });
    }
    group.finish();
}

fn isomap(c: &mut Criterion) {
    let mut group = c.benchmark_group("isomap_k10");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(15));
    let method = IsomapParams::default().dim(3).k(10).check().unwrap();
    for n in [1000, 2500] {
        let d = DistanceMatrix::new(euclidean(&circle_times_plane(n, 2))).unwrap();
        group.bench_with_input(BenchmarkId::new("exact", n), &d, |b, d| {
            b.iter(|| black_box(method.fit(d, &Silent).unwrap()))
        });
    }
    if let Some(d) = arm_distances() {
        group.bench_function(BenchmarkId::new("arm_exact", d.nrows()), |b| {
            b.iter(|| black_box(method.fit(&d, &Silent).unwrap()))
        });
    }
    let n = 20_000;
    let graph = knn_arrays(&circle_times_plane(n, 3), 10);
    for choice in [LandmarkChoice::MaxMin, LandmarkChoice::Random] {
        let method = IsomapParams::default()
            .dim(3)
            .k(10)
            .landmarks(Some(500))
            .landmark_choice(choice)
            .check()
            .unwrap();
        group.bench_function(
            BenchmarkId::new(format!("landmarks_500_{choice:?}_from_knn"), n),
            |b| b.iter(|| black_box(method.fit_knn(&graph, &Silent).unwrap())),
        );
    }
    group.finish();
}

fn mds(c: &mut Criterion) {
    let mut group = c.benchmark_group("mds_3d");
    group.sample_size(10);
    let d = DistanceMatrix::new(euclidean(&circle_times_plane(2500, 4))).unwrap();
    for solver in [
        smspace::embed::EigenSolver::Partial,
        smspace::embed::EigenSolver::Dense,
    ] {
        let method = MdsParams::default().solver(solver).check().unwrap();
        group.bench_function(BenchmarkId::new(format!("{solver:?}"), 2500), |b| {
            b.iter(|| black_box(method.fit(&d, &Silent).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, cca, isomap, mds);
criterion_main!(benches);
