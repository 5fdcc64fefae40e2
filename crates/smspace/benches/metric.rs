//! Benchmarks of the metric stage on seeded arm-like kernel sets `(M, 100, 4)`:
//!
//! * `matrix/METRIC/M`: the full matrix for a sweep of `M` (throughput in pairs), for
//!   the point metric `hausdorff` and the polyline metric `curve`;
//! * `versus_brute_force/*`: fast kernels against the brute-force reference on the same
//!   sets, both metrics;
//! * `knn/M`: the 15 nearest sets of every set;
//! * `surface/M`: the full matrix of the `surface` metric (points against tangent
//!   disks) on surface sets `(M, P, N)` from `SMSPACE_BENCH_SURFACE_SETS` (e.g. the
//!   `sets.npy` of `smspace run experiments/planar-arm-5.toml`), for the sizes of
//!   `SMSPACE_BENCH_SURFACE_SIZES` (default `200`); skipped without the file.
//!
//! Run: `cargo bench -p smspace --bench metric`. Environment:
//! `SMSPACE_BENCH_SIZES=500,1000,2500,5000` (matrix sweep, default `500,1000,2500`),
//! `SMSPACE_BENCH_KNN=20000` (kNN size, default 5000), and
//! `SMSPACE_BENCH_SETS=/path/sets.npy` to use real `(M, P, N)` kernel sets instead of
//! synthetic ones (the first `M` sets of the file for each size; sizes above its `M`
//! are skipped; their closures from `/path/sets.closed.npy`, else all closed loops),
//! `SMSPACE_BENCH_METRICS=hausdorff,curve` (default both). A size below 2 is skipped,
//! so `SMSPACE_BENCH_KNN=0` leaves the kNN search out. The SIMD level the kernels
//! ran with is printed first; `SMSPACE_SIMD=avx512`, `avx2` or `portable` caps it (the
//! fastest level of the CPU at most that one), for comparisons of the levels.
//!
//! Criterion runs every case at least ten times; for the large sizes set
//! `SMSPACE_BENCH_ONCE=1` to time each size once instead and print seconds and pairs per
//! second (the growth table of the issue), e.g.
//!
//! ```text
//! SMSPACE_BENCH_ONCE=1 SMSPACE_BENCH_SETS=/work/data/arm-sets-20000.npy \
//!   SMSPACE_BENCH_SIZES=500,1000,2500,5000 SMSPACE_BENCH_KNN=20000 \
//!   cargo bench -p smspace --bench metric
//! ```

#![allow(
    missing_docs,
    reason = "criterion's macros generate undocumented public functions"
)]

#[path = "../tests/common/arm_like.rs"]
mod arm_like;

use std::time::{Duration, Instant};

use criterion::{criterion_group, BenchmarkId, Criterion, Throughput};
use ndarray::{Array3, Axis, Slice};
use smspace::metric::{
    distance_matrix, distance_matrix_with, knn, reference, Closure, DistanceParams, KnnParams,
    MetricKind, Period, SetsView, Surface, SurfaceParams,
};
use smspace::progress::Silent;

const POINTS: usize = 100;

fn sizes(var: &str, default: &str) -> Vec<usize> {
    std::env::var(var)
        .unwrap_or_else(|_| default.to_owned())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .filter(|&m| m >= 2)
        .collect()
}

/// `m` kernel sets: the first `m` of `SMSPACE_BENCH_SETS` when given, else synthetic.
fn sets(m: usize) -> Option<Array3<f64>> {
    match std::env::var("SMSPACE_BENCH_SETS") {
        Ok(path) => {
            let all = smspace::io::read_cube(path.as_ref(), "(M, P, N)").expect("readable sets");
            (all.dim().0 >= m).then(|| all.slice_axis(Axis(0), Slice::from(..m)).to_owned())
        }
        Err(_) => Some(arm_like::arm_like_sets(m, POINTS, 2015)),
    }
}

/// The closures of the first `m` sets: `SETS.closed.npy` next to `SMSPACE_BENCH_SETS`
/// when it exists, else closed loops (the synthetic sets are loops).
fn closures(m: usize) -> Vec<Closure> {
    if let Ok(path) = std::env::var("SMSPACE_BENCH_SETS") {
        let record = std::path::Path::new(&path).with_extension("closed.npy");
        if record.exists() {
            let all = smspace::io::read_i64(&record).expect("readable closures");
            return all
                .iter()
                .take(m)
                .map(|&c| Closure::from_code(c).expect("codes 0 or 1"))
                .collect();
        }
    }
    vec![Closure::Closed; m]
}

fn metrics() -> Vec<MetricKind> {
    std::env::var("SMSPACE_BENCH_METRICS")
        .unwrap_or_else(|_| "hausdorff,curve".to_owned())
        .split(',')
        .map(|name| match name.trim() {
            "hausdorff" => MetricKind::Hausdorff,
            "mean-hausdorff" => MetricKind::MeanHausdorff,
            "curve" => MetricKind::Curve,
            other => panic!("unknown metric {other} in SMSPACE_BENCH_METRICS"),
        })
        .collect()
}

fn pairs(m: usize) -> u64 {
    (m * (m - 1) / 2) as u64
}

fn matrix(c: &mut Criterion) {
    let mut group = c.benchmark_group("matrix");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500));
    for m in sizes("SMSPACE_BENCH_SIZES", "500,1000,2500") {
        let Some(sets) = sets(m) else { continue };
        let closure = closures(m);
        group.throughput(Throughput::Elements(pairs(m)));
        for kind in metrics() {
            let params = DistanceParams::new().metric(kind);
            let view = SetsView::new(sets.view()).with_closure(&closure);
            group.bench_with_input(BenchmarkId::new(kind.name(), m), &view, |b, view| {
                b.iter(|| distance_matrix(*view, &params, &Silent).unwrap())
            });
        }
    }
    group.finish();
}

fn versus_brute_force(c: &mut Criterion) {
    let m = 40;
    let Some(sets) = sets(m) else { return };
    let mut group = c.benchmark_group("versus_brute_force");
    group
        .sample_size(10)
        .throughput(Throughput::Elements(pairs(m)));
    for kind in [MetricKind::Hausdorff, MetricKind::MeanHausdorff] {
        let params = DistanceParams::new().metric(kind);
        group.bench_function(format!("fast/{}", kind.name()), |b| {
            b.iter(|| distance_matrix(sets.view(), &params, &Silent).unwrap())
        });
        group.bench_function(format!("brute/{}", kind.name()), |b| {
            b.iter(|| reference::distance_matrix(sets.view(), kind, &params.period))
        });
    }
    group.finish();
}

fn nearest(c: &mut Criterion) {
    let mut group = c.benchmark_group("knn");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500));
    for m in sizes("SMSPACE_BENCH_KNN", "5000") {
        let Some(sets) = sets(m) else { continue };
        let closure = closures(m);
        group.throughput(Throughput::Elements(m as u64));
        for kind in metrics() {
            let params = DistanceParams::new().metric(kind);
            let view = SetsView::new(sets.view()).with_closure(&closure);
            group.bench_with_input(BenchmarkId::new(kind.name(), m), &view, |b, view| {
                b.iter(|| knn(*view, &params, &KnnParams::new().k(15), 0..m, &Silent).unwrap())
            });
        }
    }
    group.finish();
}

/// One timed run per size and metric, printed as a table.
fn once() {
    let threads = rayon::current_num_threads();
    println!("threads {threads}, SIMD {}", smspace::metric::simd_level());
    println!(
        "{:>14} {:>7} {:>12} {:>9} {:>14}",
        "metric", "M", "pairs", "seconds", "pairs/s"
    );
    for m in sizes("SMSPACE_BENCH_SIZES", "500,1000,2500") {
        let Some(sets) = sets(m) else { continue };
        let closure = closures(m);
        for kind in metrics() {
            let view = SetsView::new(sets.view()).with_closure(&closure);
            let start = Instant::now();
            distance_matrix(view, &DistanceParams::new().metric(kind), &Silent).unwrap();
            let seconds = start.elapsed().as_secs_f64();
            let pairs = pairs(m);
            println!(
                "{:>14} {m:>7} {pairs:>12} {seconds:>9.2} {:>14.0}",
                kind.name(),
                pairs as f64 / seconds
            );
        }
    }
    println!(
        "{:>14} {:>7} {:>4} {:>9}",
        "metric", "kNN M", "k", "seconds"
    );
    for m in sizes("SMSPACE_BENCH_KNN", "5000") {
        let Some(sets) = sets(m) else { continue };
        let closure = closures(m);
        for kind in metrics() {
            let view = SetsView::new(sets.view()).with_closure(&closure);
            let start = Instant::now();
            knn(
                view,
                &DistanceParams::new().metric(kind),
                &KnnParams::new().k(15),
                0..m,
                &Silent,
            )
            .unwrap();
            println!(
                "{:>14} {m:>7} {:>4} {:>9.2}",
                kind.name(),
                15,
                start.elapsed().as_secs_f64()
            );
        }
    }
}

/// The first `m` surface sets of `SMSPACE_BENCH_SURFACE_SETS`, if given and that large.
fn surface_sets(m: usize) -> Option<Array3<f64>> {
    let path = std::env::var("SMSPACE_BENCH_SURFACE_SETS").ok()?;
    let all: Array3<f64> = ndarray_npy::read_npy(&path).expect("a float64 (M, P, N) .npy");
    (all.dim().0 >= m).then(|| all.slice_axis(Axis(0), Slice::from(..m)).to_owned())
}

fn surface(c: &mut Criterion) {
    if std::env::var_os("SMSPACE_BENCH_SURFACE_SETS").is_none() {
        eprintln!(
            "surface: skipped (set SMSPACE_BENCH_SURFACE_SETS to a (M, P, N) .npy of surface sets)"
        );
        return;
    }
    let metric = Surface::new(SurfaceParams::default(), Period::TwoPi.into()).unwrap();
    let mut group = c.benchmark_group("surface");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500));
    for m in sizes("SMSPACE_BENCH_SURFACE_SIZES", "200") {
        let Some(sets) = surface_sets(m) else {
            continue;
        };
        group.throughput(Throughput::Elements(pairs(m)));
        group.bench_with_input(BenchmarkId::from_parameter(m), &sets, |b, sets| {
            b.iter(|| {
                distance_matrix_with(sets.view(), &metric, &DistanceParams::new(), &Silent).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, versus_brute_force, matrix, nearest, surface);

fn main() {
    if std::env::var_os("SMSPACE_BENCH_ONCE").is_some() {
        once();
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
