//! Tests of the metric stage: exactness against the brute force, metric properties,
//! periodic wrap, row blocks, thread-count independence, nearest sets and bad input.

#[path = "common/arm_like.rs"]
mod arm_like;

use std::f64::consts::PI;

use approx::assert_abs_diff_eq;
use arm_like::{arm_like_sets, uniform_sets};
use ndarray::{array, Array2, Array3, Axis, Slice};
use rand::rngs::ChaCha8Rng;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use smspace::metric::{
    distance_matrix, distance_matrix_with, distance_rows, fill_rows, knn, reference,
    DistanceParams, Hausdorff, KnnParams, MeanHausdorff, MetricError, MetricKind, Period,
    PreparedSets, SetMetric,
};
use smspace::progress::Silent;

const KINDS: [MetricKind; 2] = [MetricKind::Hausdorff, MetricKind::MeanHausdorff];
const PERIODS: [Period; 2] = [Period::TwoPi, Period::None];

fn params(kind: MetricKind, period: Period) -> DistanceParams {
    DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .metric(kind)
        .period(period)
}

/// Rows `range` of `a` (ndarray's `s!` macro is unavailable under `forbid(unsafe_code)`).
fn rows<T>(a: &Array2<T>, range: std::ops::Range<usize>) -> ndarray::ArrayView2<'_, T> {
    a.slice_axis(Axis(0), Slice::from(range))
}

fn assert_matrix_eq(fast: &Array2<f64>, slow: &Array2<f64>, what: &str) {
    assert_eq!(fast.dim(), slow.dim(), "{what}");
    for ((i, j), &x) in fast.indexed_iter() {
        let y = slow[[i, j]];
        assert!(
            (x - y).abs() <= 1e-9,
            "{what}: D[{i}, {j}] = {x}, brute force {y}"
        );
    }
}

#[test]
fn equals_brute_force_on_uniform_sets_of_many_shapes() {
    let mut seed = 0;
    for &(m, p, n) in &[
        (2, 1, 1),
        (5, 3, 2),
        (9, 8, 3),
        (7, 9, 4),
        (6, 13, 5),
        (5, 17, 9),
        (4, 10, 17),
        (12, 40, 4),
    ] {
        seed += 1;
        let sets = uniform_sets(m, p, n, seed);
        for kind in KINDS {
            for period in PERIODS {
                let fast = distance_matrix(sets.view(), &params(kind, period), &Silent).unwrap();
                let slow = reference::distance_matrix(sets.view(), kind, period);
                assert_matrix_eq(
                    &fast,
                    &slow,
                    &format!("{kind:?} {period:?} ({m}, {p}, {n})"),
                );
            }
        }
    }
}

#[test]
fn equals_brute_force_on_arm_like_sets() {
    // 128 points: 16 blocks of 8, the largest count ordered by the rank sort; 200
    // points: 25 blocks, ordered by the comparison sort.
    for (m, p, seed) in [(24, 100, 7), (16, 37, 8), (10, 128, 12), (8, 200, 13)] {
        let sets = arm_like_sets(m, p, seed);
        for kind in KINDS {
            for period in PERIODS {
                let fast = distance_matrix(sets.view(), &params(kind, period), &Silent).unwrap();
                let slow = reference::distance_matrix(sets.view(), kind, period);
                assert_matrix_eq(&fast, &slow, &format!("arm-like {kind:?} {period:?}"));
            }
        }
    }
}

#[test]
fn equals_brute_force_on_close_and_shifted_sets() {
    // Near-duplicate sets (tiny Hausdorff distances, where early breaks are rare) and
    // sets shifted across the ±π seam.
    let base = arm_like_sets(6, 50, 11);
    let mut sets = Array3::zeros((12, 50, 4));
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    for i in 0..6 {
        sets.index_axis_mut(Axis(0), i)
            .assign(&base.index_axis(Axis(0), i));
        let mut shifted = base.index_axis(Axis(0), i).to_owned();
        shifted.mapv_inplace(|x| x + 1e-3 * (i as f64 + 1.0));
        shifted.as_slice_mut().unwrap().shuffle(&mut rng);
        sets.index_axis_mut(Axis(0), 6 + i).assign(&shifted);
    }
    for kind in KINDS {
        let fast = distance_matrix(sets.view(), &params(kind, Period::TwoPi), &Silent).unwrap();
        let slow = reference::distance_matrix(sets.view(), kind, Period::TwoPi);
        assert_matrix_eq(&fast, &slow, &format!("close {kind:?}"));
    }
}

#[test]
fn equals_brute_force_when_the_centre_table_overflows_f32() {
    // The centre table that orders the work is kept in f32. Without a period,
    // coordinates of 1e30 overflow its squared distances (and 1e40 the f32 range); the
    // distances, computed in f64, must not change.
    for scale in [1e30, 1e40] {
        let sets = uniform_sets(6, 20, 3, 21).mapv(|x| x * scale);
        for kind in KINDS {
            let fast = distance_matrix(sets.view(), &params(kind, Period::None), &Silent).unwrap();
            let slow = reference::distance_matrix(sets.view(), kind, Period::None);
            for ((i, j), &x) in fast.indexed_iter() {
                let y = slow[[i, j]];
                assert!(
                    (x - y).abs() <= 1e-12 * y.abs(),
                    "{kind:?} scale {scale}: D[{i}, {j}] = {x}, brute force {y}"
                );
            }
        }
    }
}

#[test]
fn huge_coordinates_wrap_to_finite_distances() {
    // Coordinates near 1e300 are angles like any other: wrapped exactly, every
    // periodic distance stays within π√N, and equals that of the wrapped sets.
    let sets = arm_like_sets(6, 9, 3);
    let mut huge = sets.clone();
    for (i, x) in huge.iter_mut().enumerate() {
        *x += [1e300, -3e299, 7.5e250, 1e20][i % 4];
    }
    let wrapped = huge.mapv(|x| {
        let w = x.rem_euclid(2.0 * PI);
        if w >= PI {
            w - 2.0 * PI
        } else {
            w
        }
    });
    for kind in KINDS {
        let d = distance_matrix(huge.view(), &params(kind, Period::TwoPi), &Silent).unwrap();
        assert!(d
            .iter()
            .all(|v| v.is_finite() && *v <= PI * 3f64.sqrt() + 1e-12));
        let expected =
            distance_matrix(wrapped.view(), &params(kind, Period::TwoPi), &Silent).unwrap();
        assert_matrix_eq(&d, &expected, "huge coordinates");
    }
}

#[test]
fn symmetric_with_zero_diagonal() {
    let sets = arm_like_sets(20, 30, 3);
    for kind in KINDS {
        let d = distance_matrix(sets.view(), &params(kind, Period::TwoPi), &Silent).unwrap();
        for i in 0..20 {
            assert_eq!(d[[i, i]], 0.0);
            for j in 0..20 {
                assert_eq!(d[[i, j]], d[[j, i]]);
                if i != j {
                    assert!(d[[i, j]] > 0.0);
                }
            }
        }
    }
}

#[test]
fn zero_between_a_set_and_its_permutation() {
    let sets = arm_like_sets(3, 64, 5);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    for i in 0..3 {
        let a = sets.index_axis(Axis(0), i);
        let mut order: Vec<usize> = (0..64).collect();
        order.shuffle(&mut rng);
        let b = a.select(Axis(0), &order);
        for metric in [
            Box::new(Hausdorff::default()) as Box<dyn SetMetric>,
            Box::new(MeanHausdorff::default()),
        ] {
            assert_eq!(metric.distance(a, b.view()).unwrap(), 0.0);
        }
    }
}

#[test]
fn triangle_inequality_on_random_sets() {
    for (m, p, n, seed) in [(10, 5, 2, 21), (10, 20, 4, 22), (8, 60, 3, 23)] {
        let sets = uniform_sets(m, p, n, seed);
        for period in PERIODS {
            let d = distance_matrix(sets.view(), &params(MetricKind::Hausdorff, period), &Silent)
                .unwrap();
            let tolerance = 1e-12 * (1.0 + d.iter().fold(0.0_f64, |a, &b| a.max(b)));
            for i in 0..m {
                for j in 0..m {
                    for k in 0..m {
                        assert!(d[[i, k]] <= d[[i, j]] + d[[j, k]] + tolerance);
                    }
                }
            }
        }
    }
}

#[test]
fn periodic_wrap_puts_the_seam_points_together() {
    let eps = 1e-3;
    let a = array![[-PI + eps, 0.5]];
    let b = array![[PI - eps, 0.5]];
    let periodic = Hausdorff {
        period: Period::TwoPi.into(),
    };
    let euclidean = Hausdorff {
        period: Period::None.into(),
    };
    assert_abs_diff_eq!(
        periodic.distance(a.view(), b.view()).unwrap(),
        2.0 * eps,
        epsilon = 1e-12
    );
    assert_abs_diff_eq!(
        euclidean.distance(a.view(), b.view()).unwrap(),
        2.0 * PI - 2.0 * eps,
        epsilon = 1e-12
    );
    // Coordinates outside [-π, π) are taken modulo 2π.
    let c = array![[PI - eps + 4.0 * PI, 0.5 - 2.0 * PI]];
    assert_abs_diff_eq!(
        periodic.distance(a.view(), c.view()).unwrap(),
        2.0 * eps,
        epsilon = 1e-9
    );
    // The largest distance between two points is sqrt(N)·π.
    let far = array![[0.0, 0.0], [0.1, 0.1]];
    let opposite = array![[PI, -PI], [-PI, PI]];
    assert_abs_diff_eq!(
        periodic.distance(far.view(), opposite.view()).unwrap(),
        (2.0_f64).sqrt() * PI,
        epsilon = 1e-12
    );
}

#[test]
fn set_metric_accepts_different_point_counts() {
    let sets = arm_like_sets(2, 40, 9);
    let a = sets.index_axis(Axis(0), 0);
    let b = sets
        .index_axis(Axis(0), 1)
        .slice_axis_move(Axis(0), Slice::from(..25));
    for kind in KINDS {
        let metric = kind.with_period(Period::TwoPi, smspace::metric::Closure::Open);
        let expected = match kind {
            MetricKind::Hausdorff => reference::hausdorff(a, b, Period::TwoPi),
            MetricKind::MeanHausdorff => reference::mean_hausdorff(a, b, Period::TwoPi),
            _ => unreachable!("KINDS holds the point metrics"),
        };
        assert_abs_diff_eq!(metric.distance(a, b).unwrap(), expected, epsilon = 1e-12);
    }
    let err = Hausdorff::default()
        .distance(
            a,
            sets.index_axis(Axis(0), 1)
                .slice_axis_move(Axis(1), Slice::from(..2)),
        )
        .unwrap_err();
    assert!(
        matches!(err, MetricError::DimensionMismatch { a: 4, b: 2 }),
        "{err}"
    );
}

#[test]
fn tiles_of_rows_and_columns_give_the_brute_force_matrix() {
    // More sets than one tile of 32 rows × 32 columns, and row blocks that start and end
    // inside tiles.
    let sets = arm_like_sets(100, 12, 61);
    for kind in KINDS {
        let p = params(kind, Period::TwoPi);
        let full = distance_matrix(sets.view(), &p, &Silent).unwrap();
        let slow = reference::distance_matrix(sets.view(), kind, Period::TwoPi);
        assert_matrix_eq(&full, &slow, &format!("tiled {kind:?}"));
        for range in [30..70, 0..33, 64..100, 31..32] {
            let block = distance_rows(sets.view(), &p, range.clone(), &Silent).unwrap();
            assert_eq!(block, rows(&full, range.clone()), "{kind:?} {range:?}");
        }
    }
}

#[test]
fn row_blocks_stack_to_the_full_matrix() {
    let sets = arm_like_sets(23, 24, 31);
    for kind in KINDS {
        let p = params(kind, Period::TwoPi);
        let full = distance_matrix(sets.view(), &p, &Silent).unwrap();
        for cuts in [
            vec![0, 23],
            vec![0, 1, 23],
            vec![0, 7, 8, 16, 23],
            vec![0, 22, 23],
        ] {
            for w in cuts.windows(2) {
                let block = distance_rows(sets.view(), &p, w[0]..w[1], &Silent).unwrap();
                assert_eq!(block, rows(&full, w[0]..w[1]), "{kind:?} {w:?}");
            }
        }
        // The low-level form, into a caller's buffer.
        let prepared = PreparedSets::new(sets.view(), Period::TwoPi).unwrap();
        let mut buffer = Array2::from_elem((5, 23), f64::NAN);
        fill_rows(&prepared, kind, 10..15, buffer.view_mut(), &Silent).unwrap();
        assert_eq!(buffer, rows(&full, 10..15));
    }
}

#[test]
fn identical_for_any_thread_count() {
    let sets = arm_like_sets(40, 50, 41);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let d = distance_matrix(
                    sets.view(),
                    &DistanceParams::new().metric(MetricKind::Hausdorff),
                    &Silent,
                )
                .unwrap();
                let k = knn(
                    sets.view(),
                    &DistanceParams::new().metric(MetricKind::Hausdorff),
                    &KnnParams::new().k(5),
                    0..40,
                    &Silent,
                )
                .unwrap();
                (d, k)
            })
    };
    let one = run(1);
    for threads in [2, 3] {
        assert_eq!(run(threads), one);
    }
}

/// The first `k` entries of each row of `d` by (distance, index), diagonal excluded.
fn top_k(d: &Array2<f64>, k: usize) -> (Array2<usize>, Array2<f64>) {
    let m = d.nrows();
    let mut indices = Array2::zeros((m, k));
    let mut distances = Array2::zeros((m, k));
    for i in 0..m {
        let mut row: Vec<(f64, usize)> =
            (0..m).filter(|&j| j != i).map(|j| (d[[i, j]], j)).collect();
        row.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        for (e, &(v, j)) in row.iter().take(k).enumerate() {
            indices[[i, e]] = j;
            distances[[i, e]] = v;
        }
    }
    (indices, distances)
}

#[test]
fn knn_equals_the_top_k_of_the_full_matrix() {
    let mut sets = arm_like_sets(120, 40, 51);
    // Exact duplicates make ties that must break by index.
    for (dst, src) in [(100, 3), (101, 3), (102, 50)] {
        let copy = sets.index_axis(Axis(0), src).to_owned();
        sets.index_axis_mut(Axis(0), dst).assign(&copy);
    }
    for kind in KINDS {
        let p = params(kind, Period::TwoPi);
        let full = distance_matrix(sets.view(), &p, &Silent).unwrap();
        for (k, pivots) in [(1, 4), (6, 16), (15, 0), (15, 120)] {
            let (indices, distances) = top_k(&full, k);
            let found = knn(
                sets.view(),
                &p,
                &KnnParams::new().k(k).pivots(pivots),
                0..120,
                &Silent,
            )
            .unwrap();
            assert_eq!(found.indices, indices, "{kind:?} k={k} pivots={pivots}");
            assert_eq!(found.distances, distances, "{kind:?} k={k} pivots={pivots}");
            let block = knn(
                sets.view(),
                &p,
                &KnnParams::new().k(k).pivots(pivots),
                30..47,
                &Silent,
            )
            .unwrap();
            assert_eq!(block.indices, rows(&indices, 30..47));
            assert_eq!(block.distances, rows(&distances, 30..47));
        }
    }
}

#[test]
fn bad_input_is_reported() {
    let p = DistanceParams::new().metric(MetricKind::Hausdorff);
    let err = |sets: Array3<f64>| distance_matrix(sets.view(), &p, &Silent).unwrap_err();
    assert!(matches!(
        err(Array3::zeros((0, 5, 4))),
        MetricError::TooFewSets { sets: 0 }
    ));
    assert!(matches!(
        err(Array3::zeros((1, 5, 4))),
        MetricError::TooFewSets { sets: 1 }
    ));
    let e = err(Array3::zeros((3, 0, 4)));
    assert_eq!(
        e.to_string(),
        "kernel sets have shape (3, 0, 4), expected (M, P, N) with P >= 1 points and N >= 1 coordinates"
    );
    assert!(matches!(
        err(Array3::zeros((3, 5, 0))),
        MetricError::EmptySets { .. }
    ));
    let mut nan = Array3::zeros((3, 5, 4));
    nan[[2, 1, 3]] = f64::NAN;
    assert_eq!(
        err(nan).to_string(),
        "kernel set 2 point 1 coordinate 3 is NaN; every coordinate must be finite"
    );
    let mut inf = Array3::zeros((3, 5, 4));
    inf[[0, 4, 0]] = f64::NEG_INFINITY;
    assert!(matches!(
        err(inf),
        MetricError::NonFinite {
            set: 0,
            point: 4,
            coord: 0,
            ..
        }
    ));

    let sets = arm_like_sets(4, 10, 1);
    for rows in [2..2, 3..5, 5..6] {
        let e = distance_rows(sets.view(), &p, rows.clone(), &Silent).unwrap_err();
        assert!(matches!(e, MetricError::BadRows { .. }), "{rows:?}: {e}");
    }
    let e = distance_rows(sets.view(), &p, 3..5, &Silent).unwrap_err();
    assert_eq!(
        e.to_string(),
        "row block 3:5 is not a non-empty range within 0:4"
    );

    let prepared = PreparedSets::new(sets.view(), Period::TwoPi).unwrap();
    let mut wrong = Array2::zeros((2, 3));
    let e = fill_rows(
        &prepared,
        MetricKind::Hausdorff,
        0..2,
        wrong.view_mut(),
        &Silent,
    )
    .unwrap_err();
    assert!(matches!(
        e,
        MetricError::BadBuffer {
            found: (2, 3),
            expected: (2, 4)
        }
    ));
    let mut transposed = Array2::zeros((4, 2));
    let e = fill_rows(
        &prepared,
        MetricKind::Hausdorff,
        0..2,
        transposed.view_mut().reversed_axes(),
        &Silent,
    )
    .unwrap_err();
    assert!(matches!(e, MetricError::BadBuffer { .. }));

    for k in [4, 10] {
        let e = knn(sets.view(), &p, &KnnParams::new().k(k), 0..4, &Silent).unwrap_err();
        assert!(matches!(e, MetricError::BadK { .. }), "k = {k}: {e}");
    }
    // k = 0 and absurd pivot counts are parameter errors, whatever the data.
    let e = knn(sets.view(), &p, &KnnParams::new().k(0), 0..4, &Silent).unwrap_err();
    assert!(
        e.to_string().contains("k = 0") && !e.to_string().contains("M - 1"),
        "{e}"
    );
    let e = knn(
        sets.view(),
        &p,
        &KnnParams::new().k(2).pivots(1_000_000_000_000),
        0..4,
        &Silent,
    )
    .unwrap_err();
    assert!(e.to_string().contains("pivots = 1000000000000"), "{e}");
    // Out of memory in kNN mode does not suggest kNN.
    let e = knn(
        sets.view(),
        &DistanceParams::new()
            .metric(MetricKind::Hausdorff)
            .memory_limit_bytes(Some(10)),
        &KnnParams::new().k(2),
        0..4,
        &Silent,
    )
    .unwrap_err();
    assert!(matches!(e, MetricError::KnnOutOfMemory { .. }), "{e}");
    assert!(!e.to_string().contains("--knn"), "{e}");
    let e = knn(sets.view(), &p, &KnnParams::new().k(4), 0..4, &Silent).unwrap_err();
    assert_eq!(
        e.to_string(),
        "k = 4 nearest sets requested, but it must be between 1 and M - 1 = 3"
    );
}

#[test]
fn refuses_a_matrix_larger_than_the_memory_limit() {
    let sets = arm_like_sets(50, 10, 2);
    let p = DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .memory_limit_bytes(Some(10_000));
    let e = distance_matrix(sets.view(), &p, &Silent).unwrap_err();
    assert!(matches!(
        e,
        MetricError::OutOfMemory {
            sets: 50,
            available: 10_000,
            ..
        }
    ));
    let message = e.to_string();
    assert!(message.contains("--knn"), "{message}");
    assert!(
        message.starts_with("the distance matrix of 50 sets needs "),
        "{message}"
    );
    // The matrix of the same sets fits under a generous limit.
    let p = DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .memory_limit_bytes(Some(1 << 30));
    assert!(distance_matrix(sets.view(), &p, &Silent).is_ok());
}

#[test]
fn progress_counts_every_pair() {
    use std::sync::atomic::{AtomicU64, Ordering};
    #[derive(Default)]
    struct Count {
        total: AtomicU64,
        done: AtomicU64,
    }
    impl smspace::progress::Progress for Count {
        fn start(&self, _stage: &str, total: u64) {
            self.total.store(total, Ordering::SeqCst);
        }
        fn advance(&self, done: u64) {
            self.done.fetch_add(done, Ordering::SeqCst);
        }
    }
    let sets = arm_like_sets(9, 10, 4);
    let count = Count::default();
    distance_rows(
        sets.view(),
        &DistanceParams::new().metric(MetricKind::Hausdorff),
        2..6,
        &count,
    )
    .unwrap();
    let total = count.total.load(Ordering::SeqCst);
    assert_eq!(total, count.done.load(Ordering::SeqCst));
    // Rows 2..6 of 9 sets: 4·8 pairs, of which the 6 inside the block are shared.
    assert_eq!(total, 4 * 8 - 6);
}

/// A metric defined outside the crate: the distance between the sets' centroids
/// (Euclidean, no wrap), failing on sets whose first coordinate is exactly 42.
struct Centroids;

impl SetMetric for Centroids {
    fn name(&self) -> &'static str {
        "centroids"
    }
    fn distance(
        &self,
        a: ndarray::ArrayView2<'_, f64>,
        b: ndarray::ArrayView2<'_, f64>,
    ) -> Result<f64, MetricError> {
        if a[[0, 0]] == 42.0 || b[[0, 0]] == 42.0 {
            return Err(MetricError::EmptySets { shape: (0, 0, 0) });
        }
        let (ca, cb) = (a.mean_axis(Axis(0)).unwrap(), b.mean_axis(Axis(0)).unwrap());
        Ok((&ca - &cb).mapv(|x| x * x).sum().sqrt())
    }
}

#[test]
fn a_user_defined_metric_goes_through_the_tiled_threaded_path() {
    let sets = uniform_sets(70, 9, 3, 5);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                distance_matrix_with(
                    sets.view(),
                    &Centroids,
                    &DistanceParams::new().metric(MetricKind::Hausdorff),
                    &Silent,
                )
                .unwrap()
            })
    };
    let d = run(2);
    assert_eq!(d, run(1), "thread count changed the matrix");
    for i in 0..70 {
        for j in 0..70 {
            let one = Centroids
                .distance(sets.index_axis(Axis(0), i), sets.index_axis(Axis(0), j))
                .unwrap();
            let expected = if i == j { 0.0 } else { one };
            assert_eq!(d[[i, j]], expected, "D[{i}, {j}]");
        }
    }
    // The built-in Hausdorff through the generic path agrees with its SIMD kernels.
    let generic = distance_matrix_with(
        sets.view(),
        &Hausdorff {
            period: Period::TwoPi.into(),
        },
        &DistanceParams::new().metric(MetricKind::Hausdorff),
        &Silent,
    )
    .unwrap();
    let simd = distance_matrix(
        sets.view(),
        &DistanceParams::new().metric(MetricKind::Hausdorff),
        &Silent,
    )
    .unwrap();
    assert_matrix_eq(&generic, &simd, "generic vs SIMD Hausdorff");
    // A failing pair is reported, the first in row-major order, whatever the threads.
    let mut bad = sets.clone();
    bad[[40, 0, 0]] = 42.0;
    bad[[12, 0, 0]] = 42.0;
    let err = distance_matrix_with(
        bad.view(),
        &Centroids,
        &DistanceParams::new().metric(MetricKind::Hausdorff),
        &Silent,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("centroids metric failed on sets 0 and 12"),
        "{err}"
    );
    // The memory check and the input checks are the built-in metrics'.
    let small = DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .memory_limit_bytes(Some(1000));
    assert!(matches!(
        distance_matrix_with(sets.view(), &Centroids, &small, &Silent),
        Err(MetricError::OutOfMemory { .. })
    ));
    let mut nan = sets.clone();
    nan[[3, 1, 2]] = f64::NAN;
    assert!(matches!(
        distance_matrix_with(
            nan.view(),
            &Centroids,
            &DistanceParams::new().metric(MetricKind::Hausdorff),
            &Silent
        ),
        Err(MetricError::NonFinite {
            set: 3,
            point: 1,
            coord: 2,
            ..
        })
    ));
}

/// Every plan of tiles, computed from the sets of each tile's rows and columns only,
/// merges into the matrix bit for bit, for the three built-in metrics and a
/// user-defined one, with 1 and 2 threads.
#[test]
fn any_tiling_merges_into_the_matrix_bit_for_bit() {
    use smspace::metric::{distance_tile, Closure, SetsView, TileMerge, TilePlan};
    let sets = arm_like_sets(45, 20, 71);
    let closure: Vec<Closure> = (0..45)
        .map(|i| {
            if i % 3 == 0 {
                Closure::Open
            } else {
                Closure::Closed
            }
        })
        .collect();
    let view = |r: std::ops::Range<usize>| {
        SetsView::new(sets.slice_axis(Axis(0), Slice::from(r.clone()))).with_closure(&closure[r])
    };
    let mut metrics: Vec<(Box<dyn SetMetric>, DistanceParams)> = Vec::new();
    for kind in [
        MetricKind::Hausdorff,
        MetricKind::MeanHausdorff,
        MetricKind::Curve,
    ] {
        let p = params(kind, Period::TwoPi);
        metrics.push((p.check().unwrap().set_metric(), p));
    }
    metrics.push((
        Box::new(Centroids),
        DistanceParams::new().metric(MetricKind::Hausdorff),
    ));
    for (metric, p) in &metrics {
        let whole = match metric.kernel() {
            Some(_) => distance_matrix(view(0..45), p, &Silent).unwrap(),
            None => distance_matrix_with(view(0..45), metric.as_ref(), p, &Silent).unwrap(),
        };
        for (size, threads) in [(1, 2), (4, 1), (7, 2), (32, 2), (44, 1), (45, 2), (100, 1)] {
            let plan = TilePlan::new(45, size).unwrap();
            let merged = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut merge = TileMerge::new(45, None).unwrap();
                    for tile in plan.tiles() {
                        let values = distance_tile(
                            view(tile.rows.clone()),
                            view(tile.cols.clone()),
                            &tile,
                            metric.as_ref(),
                            &Silent,
                        )
                        .unwrap();
                        merge.add(&tile, values.view()).unwrap();
                    }
                    merge.finish().unwrap()
                });
            assert_eq!(merged, whole, "{} in tiles of {size}", metric.name());
        }
        // Any tile, in or off the plan (overlapping rows and columns included), is the
        // block of the matrix.
        for (r, c) in [
            (3..20, 10..45),
            (0..45, 0..45),
            (40..45, 0..2),
            (5..6, 5..6),
        ] {
            let tile = smspace::metric::Tile::new(r.clone(), c.clone());
            let values = distance_tile(
                view(r.clone()),
                view(c.clone()),
                &tile,
                metric.as_ref(),
                &Silent,
            )
            .unwrap();
            let block = whole
                .slice_axis(Axis(0), Slice::from(r.clone()))
                .slice_axis(Axis(1), Slice::from(c.clone()))
                .to_owned();
            assert_eq!(values, block, "{} tile {r:?} x {c:?}", metric.name());
        }
    }
}

/// A metric that counts its calls (the distance between the sets' first points).
#[derive(Default)]
struct Counting {
    calls: std::sync::atomic::AtomicUsize,
    metric: bool,
}

impl SetMetric for Counting {
    fn name(&self) -> &'static str {
        "counting"
    }
    fn distance(
        &self,
        a: ndarray::ArrayView2<'_, f64>,
        b: ndarray::ArrayView2<'_, f64>,
    ) -> Result<f64, MetricError> {
        self.calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok((a[[0, 0]] - b[[0, 0]]).abs() + (a[[0, 1]] - b[[0, 1]]).abs())
    }
    fn is_metric(&self) -> bool {
        self.metric
    }
}

#[test]
fn a_tile_plan_computes_every_pair_exactly_once() {
    use smspace::metric::{distance_tile, TilePlan};
    let sets = uniform_sets(37, 4, 2, 3);
    for size in [1, 5, 36, 37] {
        let metric = Counting::default();
        let plan = TilePlan::new(37, size).unwrap();
        let mut pairs = 0;
        for tile in plan.tiles() {
            let r = sets.slice_axis(Axis(0), Slice::from(tile.rows.clone()));
            let c = sets.slice_axis(Axis(0), Slice::from(tile.cols.clone()));
            distance_tile(r, c, &tile, &metric, &Silent).unwrap();
            pairs += tile.pairs();
        }
        let calls = metric.calls.load(std::sync::atomic::Ordering::Relaxed);
        assert_eq!(calls, 37 * 36 / 2, "tiles of {size}");
        assert_eq!(pairs, 37 * 36 / 2);
    }
}

#[test]
fn merging_refuses_missing_and_conflicting_tiles() {
    use smspace::metric::{distance_tile, Tile, TileMerge, TilePlan};
    let sets = uniform_sets(9, 3, 2, 4);
    let metric = DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .check()
        .unwrap()
        .set_metric();
    let tile_of = |t: &Tile| {
        distance_tile(
            sets.slice_axis(Axis(0), Slice::from(t.rows.clone())),
            sets.slice_axis(Axis(0), Slice::from(t.cols.clone())),
            t,
            metric.as_ref(),
            &Silent,
        )
        .unwrap()
    };
    let tiles: Vec<Tile> = TilePlan::new(9, 4).unwrap().tiles().collect();
    let mut merge = TileMerge::new(9, None).unwrap();
    for t in &tiles[..tiles.len() - 1] {
        merge.add(t, tile_of(t).view()).unwrap();
    }
    // The last tile (8..9 × 8..9) holds only the diagonal: nothing is missing.
    assert!(merge.clone().finish().is_ok());
    let mut merge = TileMerge::new(9, None).unwrap();
    for t in &tiles[1..] {
        merge.add(t, tile_of(t).view()).unwrap();
    }
    let err = merge.finish().unwrap_err();
    assert!(
        matches!(err, MetricError::TileMissing { i: 0, j: 1 }),
        "{err}"
    );
    let mut merge = TileMerge::new(9, None).unwrap();
    let t = &tiles[1];
    merge.add(t, tile_of(t).view()).unwrap();
    let mut other = tile_of(t);
    other[[0, 0]] += 1.0;
    let err = merge.add(t, other.view()).unwrap_err().to_string();
    assert!(
        err.contains("two tiles disagree on the pair (0, 4)"),
        "{err}"
    );
    let err = merge
        .add(&Tile::new(0..3, 5..12), Array2::zeros((3, 7)).view())
        .unwrap_err();
    assert!(matches!(err, MetricError::BadRows { end: 12, .. }), "{err}");
}

#[test]
fn knn_of_a_user_metric_is_the_top_k_of_its_matrix() {
    use smspace::metric::knn_with;
    let mut sets = uniform_sets(60, 5, 3, 8);
    for (dst, src) in [(50, 3), (51, 3)] {
        let copy = sets.index_axis(Axis(0), src).to_owned();
        sets.index_axis_mut(Axis(0), dst).assign(&copy);
    }
    for metric in [false, true] {
        let counting = Counting {
            metric,
            ..Counting::default()
        };
        let full = distance_matrix_with(
            sets.view(),
            &counting,
            &DistanceParams::new().metric(MetricKind::Hausdorff),
            &Silent,
        )
        .unwrap();
        for (k, pivots) in [(1, 4), (7, 16), (7, 0)] {
            let (indices, distances) = top_k(&full, k);
            let calls = |c: &Counting| c.calls.load(std::sync::atomic::Ordering::Relaxed);
            let before = calls(&counting);
            let knn_params = KnnParams::new().k(k).pivots(pivots);
            let found = knn_with(
                sets.view(),
                &counting,
                &DistanceParams::new().metric(MetricKind::Hausdorff),
                &knn_params,
                0..60,
                &Silent,
            )
            .unwrap();
            assert_eq!(found.indices, indices, "metric {metric} k={k}");
            assert_eq!(found.distances, distances);
            let used = calls(&counting) - before;
            // Pruning only for a metric (and with pivots): otherwise every pair of
            // every row is measured.
            if metric && pivots > 0 {
                assert!(used < 60 * 59, "{used} calls");
            } else {
                assert_eq!(used, 60 * 59);
            }
            let block = knn_with(
                sets.view(),
                &counting,
                &DistanceParams::new().metric(MetricKind::Hausdorff),
                &knn_params,
                10..25,
                &Silent,
            )
            .unwrap();
            assert_eq!(block.indices, rows(&indices, 10..25));
        }
    }
    // The built-in Hausdorff through knn_with runs on its kernels: the same lists as knn.
    let p = DistanceParams::new().metric(MetricKind::Hausdorff);
    let h = Hausdorff {
        period: Period::TwoPi.into(),
    };
    let knn_params = KnnParams::new().k(4);
    assert_eq!(
        knn_with(sets.view(), &h, &p, &knn_params, 0..60, &Silent).unwrap(),
        knn(sets.view(), &p, &knn_params, 0..60, &Silent).unwrap()
    );
    // A failing pair is reported; so is the memory limit.
    let mut bad = sets.clone();
    bad[[20, 0, 0]] = 42.0;
    let err = knn_with(bad.view(), &Centroids, &p, &knn_params, 0..60, &Silent)
        .unwrap_err()
        .to_string();
    assert!(err.contains("centroids metric failed on sets"), "{err}");
    let small = DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .memory_limit_bytes(Some(100));
    assert!(matches!(
        knn_with(sets.view(), &Centroids, &small, &knn_params, 0..60, &Silent),
        Err(MetricError::KnnOutOfMemory { .. })
    ));
}

/// A sets array in Fortran order and one taken every other set of a larger array give
/// the matrix, the rows, the tiles and the nearest sets of the C-order array.
#[test]
fn inputs_in_any_layout_or_stride_give_the_same_numbers() {
    use ndarray::ShapeBuilder;
    use smspace::metric::{distance_tile, knn_with, Tile};
    let sets = arm_like_sets(21, 12, 81);
    let mut fortran = Array3::zeros(sets.raw_dim().f());
    fortran.assign(&sets);
    assert!(!fortran.is_standard_layout());
    let mut big = Array3::zeros((42, 12, 4));
    big.slice_axis_mut(Axis(0), Slice::new(0, None, 2))
        .assign(&sets);
    let strided = big.slice_axis(Axis(0), Slice::new(0, None, 2));
    let p = DistanceParams::new().metric(MetricKind::Hausdorff);
    let expected = distance_matrix(sets.view(), &p, &Silent).unwrap();
    let knn_params = KnnParams::new().k(3);
    let near = knn(sets.view(), &p, &knn_params, 0..21, &Silent).unwrap();
    let tile = Tile::new(2..9, 5..21);
    for view in [fortran.view(), strided] {
        assert_eq!(distance_matrix(view, &p, &Silent).unwrap(), expected);
        assert_eq!(
            distance_rows(view, &p, 4..11, &Silent).unwrap(),
            rows(&expected, 4..11)
        );
        assert_eq!(knn(view, &p, &knn_params, 0..21, &Silent).unwrap(), near);
        let generic = distance_matrix_with(view, &Centroids, &p, &Silent).unwrap();
        assert_eq!(
            generic,
            distance_matrix_with(sets.view(), &Centroids, &p, &Silent).unwrap()
        );
        assert_eq!(
            knn_with(view, &Centroids, &p, &knn_params, 0..21, &Silent).unwrap(),
            knn_with(sets.view(), &Centroids, &p, &knn_params, 0..21, &Silent).unwrap()
        );
        let metric = p.check().unwrap().set_metric();
        let values = distance_tile(
            view.slice_axis(Axis(0), Slice::from(2..9)),
            view.slice_axis(Axis(0), Slice::from(5..21)),
            &tile,
            metric.as_ref(),
            &Silent,
        )
        .unwrap();
        assert_eq!(
            values,
            expected
                .slice_axis(Axis(0), Slice::from(2..9))
                .slice_axis(Axis(1), Slice::from(5..21))
        );
    }
}

/// One matrix of every kernel (the point metrics and `curve` with both periods and
/// dimensions 2, 4, 8 and 16 after padding, `surface`), as bits.
fn every_kernel_matrix() -> Vec<Vec<u64>> {
    use smspace::metric::{Closure, SetsView, Surface, SurfaceParams};
    let bits = |d: smspace::metric::DistanceMatrix| {
        d.into_array()
            .iter()
            .map(|x| x.to_bits())
            .collect::<Vec<u64>>()
    };
    let mut out = Vec::new();
    let kinds = [KINDS[0], KINDS[1], MetricKind::Curve];
    for (sets, period) in [
        (arm_like_sets(14, 100, 21), Period::TwoPi),
        (arm_like_sets(12, 37, 22), Period::None),
        (uniform_sets(9, 20, 2, 23), Period::TwoPi),
        (uniform_sets(9, 19, 7, 24), Period::TwoPi),
        (uniform_sets(8, 18, 13, 25), Period::None),
    ] {
        let closure: Vec<Closure> = (0..sets.dim().0)
            .map(|i| [Closure::Closed, Closure::Open][i % 2])
            .collect();
        for kind in kinds {
            let view = SetsView::new(sets.view()).with_closure(&closure);
            out.push(bits(
                distance_matrix(view, &params(kind, period), &Silent).unwrap(),
            ));
        }
    }
    let sets = uniform_sets(10, 30, 3, 26);
    for period in PERIODS {
        let metric = Surface::new(SurfaceParams::default(), period.into()).unwrap();
        let d = distance_matrix_with(
            sets.view(),
            &metric,
            &DistanceParams::new().metric(MetricKind::Hausdorff),
            &Silent,
        );
        out.push(bits(d.unwrap()));
    }
    out
}

#[test]
fn every_simd_level_gives_the_same_bits() {
    use smspace::metric::{force_simd_level, simd_level, SimdLevel};
    // Only this test forces a level in this test binary; the others, running beside
    // it, get the same bits whichever level runs.
    assert!(force_simd_level(Some(SimdLevel::Portable)));
    assert!(simd_level().starts_with("portable"));
    let portable = every_kernel_matrix();
    let mut levels = 0;
    for level in [SimdLevel::Avx2, SimdLevel::Avx512] {
        if !force_simd_level(Some(level)) {
            continue;
        }
        levels += 1;
        let name = simd_level();
        assert!(!name.starts_with("portable"), "{level:?}: {name}");
        let fast = every_kernel_matrix();
        for (k, (x, y)) in fast.iter().zip(&portable).enumerate() {
            assert_eq!(x, y, "matrix {k}: {name} against portable");
        }
    }
    assert!(force_simd_level(None));
    // Where the CPU has AVX-512 it has AVX2 too, and the default is the fastest.
    if SimdLevel::Avx512.available() {
        assert_eq!(levels, 2);
        assert!(SimdLevel::Avx2.available());
        assert!(simd_level().starts_with("AVX-512"));
    }
}
