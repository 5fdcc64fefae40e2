//! Tests of the `curve` metric (the Hausdorff distance between polylines): cases with
//! known answers, the dense-sampling reference, metric properties, seams, open vs
//! closed, row blocks, thread counts, nearest sets and bad input.

#[path = "common/arm_like.rs"]
mod arm_like;

use std::f64::consts::PI;

use arm_like::{arm_like_sets, uniform_sets};
use ndarray::{array, Array2, Array3, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::metric::{
    distance_matrix, distance_rows, fill_rows, fill_tile, knn, reference, Closure, Curve,
    DistanceParams, KnnParams, MetricError, MetricKind, MetricRegistry, Period, Periods,
    PreparedSets, SetMetric, SetsView, Tile, CURVE_TOLERANCE,
};
use smspace::progress::Silent;

fn curve(period: Period) -> DistanceParams {
    DistanceParams::new()
        .metric(MetricKind::Curve)
        .period(period)
}

/// The curve distance between two sets given with their closures, through the matrix
/// path (the fast kernel) and through [`SetMetric`].
fn pair(a: &Array2<f64>, ca: Closure, b: &Array2<f64>, cb: Closure, period: Period) -> f64 {
    let p = a.nrows().max(b.nrows());
    assert_eq!(a.nrows(), b.nrows(), "use sets of one size here ({p})");
    let mut sets = Array3::zeros((2, a.nrows(), a.ncols()));
    sets.index_axis_mut(Axis(0), 0).assign(a);
    sets.index_axis_mut(Axis(0), 1).assign(b);
    let closure = [ca, cb];
    let d = distance_matrix(
        SetsView::new(sets.view()).with_closure(&closure),
        &curve(period),
        &Silent,
    )
    .unwrap();
    assert_eq!(d[[0, 1]], d[[1, 0]]);
    d[[0, 1]]
}

fn wrapped(x: f64) -> f64 {
    (x + PI).rem_euclid(2.0 * PI) - PI
}

#[test]
fn parallel_segments_are_their_gap_apart() {
    // Open segments on y = 0 and y = 1 (no period): every point is 1 from the other.
    let a = array![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
    let b = array![[0.0, 1.0], [1.0, 1.0], [2.0, 1.0]];
    assert!((pair(&a, Closure::Open, &b, Closure::Open, Period::None) - 1.0).abs() < 1e-12);
    // Shifted along x by 1: the ends see the other segment's end at distance sqrt(2).
    let b = array![[1.0, 1.0], [2.0, 1.0], [3.0, 1.0]];
    let d = pair(&a, Closure::Open, &b, Closure::Open, Period::None);
    assert!((d - 2f64.sqrt()).abs() < 1e-12, "{d}");
    // The point metric on two samples per unit length: the same answer only at the ends.
    let a = array![[0.0, 0.0], [2.0, 0.0]];
    let b = array![[0.5, 0.3], [1.5, 0.3]];
    // From A's ends (0,0) and (2,0) to B's segment: sqrt(0.25 + 0.09).
    let d = pair(&a, Closure::Open, &b, Closure::Open, Period::None);
    assert!((d - (0.25f64 + 0.09).sqrt()).abs() < 1e-12, "{d}");
}

#[test]
fn a_point_set_lies_on_its_own_polyline() {
    // A unit square: B closed, A the same points open. A ⊂ B, so h(A, B) = 0, while
    // B's closing edge (0,1) → (0,0) is farthest from A at its middle: 0.5.
    let square = array![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let d = pair(
        &square,
        Closure::Open,
        &square,
        Closure::Closed,
        Period::None,
    );
    assert!((d - 0.5).abs() < 1e-12, "{d}");
    let d = pair(
        &square,
        Closure::Closed,
        &square,
        Closure::Closed,
        Period::None,
    );
    assert_eq!(d, 0.0);
    // The point metric gives 0 for both: it cannot see the closing edge.
    let mut sets = Array3::zeros((2, 4, 2));
    sets.index_axis_mut(Axis(0), 0).assign(&square);
    sets.index_axis_mut(Axis(0), 1).assign(&square);
    let d = distance_matrix(
        sets.view(),
        &DistanceParams::new()
            .metric(MetricKind::Hausdorff)
            .period(Period::None),
        &Silent,
    )
    .unwrap();
    assert_eq!(d[[0, 1]], 0.0);
}

#[test]
fn a_loop_against_itself_sampled_half_a_step_later() {
    // Two inscribed regular P-gons of a circle of radius r, rotated by half a step: the
    // curve distance is r (1 − cos(π/P)) (a vertex of one against the facing edge of
    // the other), the point distance 2 r sin(π / 2P).
    let (r, p) = (0.7, 24);
    let polygon = |phase: f64| {
        Array2::from_shape_fn((p, 2), |(k, n)| {
            let angle = 2.0 * PI * (k as f64 + phase) / p as f64;
            if n == 0 {
                r * angle.cos()
            } else {
                r * angle.sin()
            }
        })
    };
    let (a, b) = (polygon(0.0), polygon(0.5));
    for period in [Period::None, Period::TwoPi] {
        let d = pair(&a, Closure::Closed, &b, Closure::Closed, period);
        let expected = r * (1.0 - (PI / p as f64).cos());
        assert!(
            (d - expected).abs() < 1e-10,
            "{period:?}: {d} vs {expected}"
        );
        let points = Hausdorff(period).distance(a.view(), b.view()).unwrap();
        assert!((points - 2.0 * r * (PI / (2.0 * p as f64)).sin()).abs() < 1e-12);
    }
}

/// The point metric for comparisons.
#[allow(non_snake_case)]
fn Hausdorff(period: Period) -> smspace::metric::Hausdorff {
    smspace::metric::Hausdorff {
        period: period.into(),
    }
}

#[test]
fn a_loop_across_the_seam_against_its_translate() {
    // A square loop of side 0.5 centred on (π − 0.1, 0.4, 1, −2) in 4-D crosses the seam
    // x = ±π; its translate by 0.1 along x is centred on ±π. The curve distance of a
    // square and its translate along an edge direction is the translation.
    let square = |cx: f64| {
        let corners = [(-0.25, -0.25), (0.25, -0.25), (0.25, 0.25), (-0.25, 0.25)];
        let mut x = Array2::zeros((8, 4));
        for k in 0..8 {
            // Corners and edge midpoints, in order.
            let (a, b) = corners[k / 2];
            let (c, d) = corners[(k / 2 + 1) % 4];
            let t = if k % 2 == 0 { 0.0 } else { 0.5 };
            x[[k, 0]] = wrapped(cx + a + t * (c - a));
            x[[k, 1]] = 0.4 + b + t * (d - b);
            x[[k, 2]] = 1.0;
            x[[k, 3]] = -2.0;
        }
        x
    };
    let a = square(PI - 0.1);
    let b = square(PI);
    assert!(a.iter().all(|v| (-PI..PI).contains(v)));
    let d = pair(&a, Closure::Closed, &b, Closure::Closed, Period::TwoPi);
    assert!((d - 0.1).abs() < 1e-10, "{d}");
    // Without the period the loops are cut at the seam into different shapes, farther
    // apart than their translation.
    let flat = pair(&a, Closure::Closed, &b, Closure::Closed, Period::None);
    assert!(flat > d + 0.01, "{flat}");
}

#[test]
fn a_segment_crossing_the_seam_is_measured_through_it() {
    // A: the open segment from x = π − 0.1 to x = −π + 0.1 (through the seam, length
    // 0.2). A point set at (π, 0.3) (two equal points) is 0.3 from its middle; a point
    // at (0, 0.3) is π − 0.1 away in x from the nearest end.
    let a = array![[PI - 0.1, 0.0], [-PI + 0.1, 0.0]];
    let b = array![[-PI, 0.3], [-PI, 0.3]];
    let d = pair(&a, Closure::Open, &b, Closure::Open, Period::TwoPi);
    // From A to B: the ends of A are sqrt(0.01 + 0.09) from B; from B to A: 0.3.
    assert!((d - (0.1f64).sqrt()).abs() < 1e-12, "{d}");
    let b = array![[0.0, 0.3], [0.0, 0.3]];
    let d = pair(&a, Closure::Open, &b, Closure::Open, Period::TwoPi);
    // Farthest point of A from (0, 0.3): its middle (π, 0), at sqrt(π² + 0.09).
    assert!((d - (PI * PI + 0.09).sqrt()).abs() < 1e-12, "{d}");
}

/// Random polylines: `m` sets of `p` points near a random walk (so that the segments
/// are of every length, some crossing the seam).
fn random_polylines(m: usize, p: usize, n: usize, step: f64, seed: u64) -> Array3<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sets = Array3::zeros((m, p, n));
    for i in 0..m {
        let mut x: Vec<f64> = (0..n).map(|_| rng.random_range(-PI..PI)).collect();
        for j in 0..p {
            for k in 0..n {
                x[k] += rng.random_range(-step..step);
                sets[[i, j, k]] = wrapped(x[k]);
            }
        }
    }
    sets
}

#[test]
fn within_the_dense_sampling_bounds_on_random_polylines() {
    for (seed, &(m, p, n, step, period)) in [
        (6, 7, 2, 0.9, Period::TwoPi),
        (5, 9, 3, 0.5, Period::TwoPi),
        (5, 12, 4, 0.3, Period::TwoPi),
        (5, 10, 3, 0.4, Period::None),
        (3, 17, 5, 0.3, Period::TwoPi),
        // Far apart with long segments in 7-D (like the 3-D arm's sets): most vertices
        // have segments that cross the seam relative to them within reach.
        (2, 10, 7, 0.6, Period::TwoPi),
    ]
    .iter()
    .enumerate()
    {
        let sets = random_polylines(m, p, n, step, 100 + seed as u64);
        for closure in [Closure::Closed, Closure::Open] {
            let closures = vec![closure; m];
            let d = distance_matrix(
                SetsView::new(sets.view()).with_closure(&closures),
                &curve(period),
                &Silent,
            )
            .unwrap();
            for i in 0..m {
                for j in i + 1..m {
                    let closed = closure == Closure::Closed;
                    let a = sets.index_axis(Axis(0), i);
                    let b = sets.index_axis(Axis(0), j);
                    let pieces = if n > 4 { 40 } else { 150 };
                    let (lo, hi) = reference::curve_bounds(a, closed, b, closed, period, pieces);
                    let x = d[[i, j]];
                    assert!(
                        x >= lo - 1e-9 && x <= hi + 1e-9,
                        "seed {seed} {closure:?} {period:?} ({i}, {j}): {lo} <= {x} <= {hi}"
                    );
                }
            }
        }
    }
}

#[test]
fn within_the_dense_sampling_bounds_on_arm_like_sets() {
    let sets = arm_like_sets(5, 24, 3);
    let closures = vec![Closure::Closed; 5];
    let d = distance_matrix(
        SetsView::new(sets.view()).with_closure(&closures),
        &curve(Period::TwoPi),
        &Silent,
    )
    .unwrap();
    for i in 0..5 {
        for j in i + 1..5 {
            let a = sets.index_axis(Axis(0), i);
            let b = sets.index_axis(Axis(0), j);
            let (lo, hi) = reference::curve_bounds(a, true, b, true, Period::TwoPi, 16);
            assert!(
                d[[i, j]] >= lo - 1e-9 && d[[i, j]] <= hi + 1e-9,
                "({i}, {j}): {lo} <= {} <= {hi}",
                d[[i, j]]
            );
        }
    }
}

#[test]
fn symmetric_zero_diagonal_and_triangle_inequality() {
    let sets = random_polylines(14, 9, 3, 0.6, 9);
    let closures: Vec<Closure> = (0..14)
        .map(|i| {
            if i % 3 == 0 {
                Closure::Open
            } else {
                Closure::Closed
            }
        })
        .collect();
    let d = distance_matrix(
        SetsView::new(sets.view()).with_closure(&closures),
        &curve(Period::TwoPi),
        &Silent,
    )
    .unwrap();
    for i in 0..14 {
        assert_eq!(d[[i, i]], 0.0);
        for j in 0..14 {
            assert_eq!(d[[i, j]], d[[j, i]]);
            for k in 0..14 {
                assert!(
                    d[[i, k]] <= d[[i, j]] + d[[j, k]] + 3.0 * CURVE_TOLERANCE,
                    "({i}, {j}, {k})"
                );
            }
        }
    }
}

#[test]
fn rows_threads_and_nearest_sets_agree_with_the_matrix() {
    let mut sets = arm_like_sets(70, 30, 21);
    for (dst, src) in [(60, 3), (61, 3)] {
        let copy = sets.index_axis(Axis(0), src).to_owned();
        sets.index_axis_mut(Axis(0), dst).assign(&copy);
    }
    let closures = vec![Closure::Closed; 70];
    let view = SetsView::new(sets.view()).with_closure(&closures);
    let params = curve(Period::TwoPi);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| distance_matrix(view, &params, &Silent).unwrap())
    };
    let full = run(1);
    assert_eq!(run(2), full);
    assert_eq!(run(3), full);
    let block = distance_rows(view, &params, 20..45, &Silent).unwrap();
    for i in 20..45 {
        for j in 0..70 {
            assert_eq!(block[[i - 20, j]], full[[i, j]]);
        }
    }
    for (k, pivots) in [(1, 4), (7, 16), (10, 0)] {
        let found = knn(
            view,
            &params,
            &KnnParams::new().k(k).pivots(pivots),
            0..70,
            &Silent,
        )
        .unwrap();
        for i in 0..70 {
            let mut row: Vec<(f64, usize)> = (0..70)
                .filter(|&j| j != i)
                .map(|j| (full[[i, j]], j))
                .collect();
            row.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            for e in 0..k {
                assert_eq!(
                    found.indices[[i, e]],
                    row[e].1,
                    "k={k} pivots={pivots} row {i}"
                );
                assert_eq!(found.distances[[i, e]], row[e].0);
            }
        }
    }
}

#[test]
fn set_metric_pads_sets_of_different_sizes() {
    let square = array![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let fine = array![[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    for closure in [Closure::Closed, Closure::Open] {
        let metric = Curve {
            period: Period::None.into(),
            closure,
        };
        assert_eq!(metric.distance(square.view(), fine.view()).unwrap(), 0.0);
        assert!(metric.is_metric());
    }
}

#[test]
fn bad_input_is_reported() {
    let sets = uniform_sets(4, 5, 3, 1);
    // No closures.
    let err = distance_matrix(sets.view(), &curve(Period::TwoPi), &Silent).unwrap_err();
    assert!(matches!(err, MetricError::MissingClosure));
    assert!(err.to_string().contains("--curve closed"), "{err}");
    let err = knn(
        sets.view(),
        &curve(Period::TwoPi),
        &KnnParams::new().k(2),
        0..4,
        &Silent,
    )
    .unwrap_err();
    assert!(matches!(err, MetricError::MissingClosure));
    // Wrong number of closures.
    let three = [Closure::Closed; 3];
    let err = distance_matrix(
        SetsView::new(sets.view()).with_closure(&three),
        &curve(Period::TwoPi),
        &Silent,
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .contains("3 closed/open records were given for 4 sets"),
        "{err}"
    );
    // One point per set.
    let single = uniform_sets(4, 1, 3, 1);
    let four = [Closure::Open; 4];
    let err = distance_matrix(
        SetsView::new(single.view()).with_closure(&four),
        &curve(Period::TwoPi),
        &Silent,
    )
    .unwrap_err();
    assert!(
        matches!(err, MetricError::TooFewPoints { points: 1 }),
        "{err}"
    );
    // NaN.
    let mut bad = sets.clone();
    bad[[2, 1, 0]] = f64::NAN;
    let err = distance_matrix(
        SetsView::new(bad.view()).with_closure(&four),
        &curve(Period::TwoPi),
        &Silent,
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            MetricError::NonFinite {
                set: 2,
                point: 1,
                coord: 0,
                ..
            }
        ),
        "{err}"
    );
    // The point metrics ignore closures.
    let d = distance_matrix(
        SetsView::new(sets.view()).with_closure(&four),
        &DistanceParams::new().metric(MetricKind::Hausdorff),
        &Silent,
    )
    .unwrap();
    assert_eq!(
        d,
        distance_matrix(
            sets.view(),
            &DistanceParams::new().metric(MetricKind::Hausdorff),
            &Silent
        )
        .unwrap()
    );
}

#[test]
fn the_inradius_of_a_polygon_from_a_spoke_through_its_centre() {
    // B: the regular 64-gon of radius 1. A: a 56-gon of radius 1 and a spoke from (1, 0)
    // through the centre, closed back to (1, 0). The point of A farthest from B's
    // polyline is the centre, in the middle of a segment, at the inradius cos(π/64);
    // every edge of B is that far from it, so the exact envelope has too many segments
    // and the branch and bound settles it.
    let p = 64;
    let b = Array2::from_shape_fn((p, 2), |(k, n)| {
        let angle = 2.0 * PI * k as f64 / p as f64;
        if n == 0 {
            angle.cos()
        } else {
            angle.sin()
        }
    });
    let mut a = Array2::zeros((p, 2));
    for k in 0..56 {
        let angle = 2.0 * PI * k as f64 / 56.0;
        a[[k, 0]] = angle.cos();
        a[[k, 1]] = angle.sin();
    }
    for (k, x) in [0.85, 0.7, 0.55, 0.4, 0.25, 0.1, -0.03, 0.5]
        .into_iter()
        .enumerate()
    {
        a[[56 + k, 0]] = x;
    }
    let inradius = (PI / p as f64).cos();
    let d = pair(&a, Closure::Closed, &b, Closure::Closed, Period::None);
    assert!(d <= inradius + 1e-12, "{d} > {inradius}");
    assert!(inradius - d < 1e-10, "{d} vs {inradius}");
}

// Periods per coordinate: the point metric and the curve metric with each coordinate
// wrapped with its own period, or not wrapped.

/// Two periodic coordinates (`2π` and 1.7, the second one smaller than the segments'
/// reach so that many segments cross its seam) and an unwrapped one.
fn mixed_periods() -> Periods {
    Periods::new(vec![Some(2.0 * PI), None, Some(1.7)]).unwrap()
}

/// `m` random walks of `p` points under `periods`: a periodic coordinate wrapped into
/// `[−T/2, T/2)`, an unwrapped one left where the walk goes.
fn random_walks(m: usize, p: usize, step: f64, periods: &Periods, seed: u64) -> Array3<f64> {
    let n = periods.dims();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sets = Array3::zeros((m, p, n));
    for i in 0..m {
        let mut x: Vec<f64> = (0..n).map(|_| rng.random_range(-3.0..3.0)).collect();
        for j in 0..p {
            for k in 0..n {
                x[k] += rng.random_range(-step..step);
                sets[[i, j, k]] = match periods.get(k) {
                    Some(t) => (x[k] + 0.5 * t).rem_euclid(t) - 0.5 * t,
                    None => x[k],
                };
            }
        }
    }
    sets
}

/// The matrix of `metric` through the prepared layout (the public path for
/// per-coordinate periods).
fn prepared_matrix(view: SetsView<'_>, periods: &Periods, metric: MetricKind) -> Array2<f64> {
    let m = view.points().dim().0;
    let prepared = PreparedSets::new(view, periods).unwrap();
    let mut out = Array2::zeros((m, m));
    fill_rows(&prepared, metric, 0..m, out.view_mut(), &Silent).unwrap();
    out
}

#[test]
fn mixed_periods_point_metrics_equal_the_brute_force() {
    let periods = mixed_periods();
    let sets = random_walks(9, 21, 0.5, &periods, 31);
    for metric in [MetricKind::Hausdorff, MetricKind::MeanHausdorff] {
        let fast = prepared_matrix(SetsView::new(sets.view()), &periods, metric);
        let brute = reference::distance_matrix(sets.view(), metric, &periods);
        let diff = (&fast - &brute).iter().fold(0.0f64, |x, y| x.max(y.abs()));
        assert!(diff < 1e-12, "{metric:?}: max |diff| {diff}");
        // Each coordinate counts with its own period: with every coordinate wrapped
        // by 2π the distances differ.
        let uniform = Periods::uniform(Period::TwoPi, 3);
        let other = prepared_matrix(SetsView::new(sets.view()), &uniform, metric);
        assert!(
            (&other - &fast).iter().any(|x| x.abs() > 1e-3),
            "{metric:?}"
        );
    }
}

#[test]
fn mixed_periods_curve_within_the_dense_sampling_bounds() {
    let periods = mixed_periods();
    let (m, p) = (6, 11);
    let sets = random_walks(m, p, 0.45, &periods, 32);
    for closure in [Closure::Closed, Closure::Open] {
        let closures = vec![closure; m];
        let view = SetsView::new(sets.view()).with_closure(&closures);
        let d = prepared_matrix(view, &periods, MetricKind::Curve);
        let closed = closure == Closure::Closed;
        for i in 0..m {
            for j in i + 1..m {
                let a = sets.index_axis(Axis(0), i);
                let b = sets.index_axis(Axis(0), j);
                let (lo, hi) = reference::curve_bounds(a, closed, b, closed, &periods, 150);
                let x = d[[i, j]];
                assert!(
                    x >= lo - 1e-9 && x <= hi + 1e-9,
                    "{closure:?} ({i}, {j}): {lo} <= {x} <= {hi}"
                );
            }
        }
    }
}

#[test]
fn a_segment_crosses_the_seam_of_a_small_period() {
    // Coordinate 0 has period 1; coordinate 1 is not wrapped. A runs from 0.45 to 0.55
    // ≡ −0.45 across the seam (its segment is 0.1 long, through ±0.5), B sits at
    // x = 0.5 ≡ −0.5, 0.3 above.
    let periods = Periods::new(vec![Some(1.0), None]).unwrap();
    let a = array![[0.45, 0.0], [-0.45, 0.0]];
    let b = array![[-0.5, 0.3], [-0.5, 0.3 + 1e-3]];
    let mut sets = Array3::zeros((2, 2, 2));
    sets.index_axis_mut(Axis(0), 0).assign(&a);
    sets.index_axis_mut(Axis(0), 1).assign(&b);
    let closures = [Closure::Open, Closure::Open];
    let view = SetsView::new(sets.view()).with_closure(&closures);
    let d = prepared_matrix(view, &periods, MetricKind::Curve);
    // Farthest: A's ends, 0.05 across and 0.3 below B's lower end (B → A reaches only
    // 0.301).
    let expected = f64::hypot(0.05, 0.3);
    assert!(
        (d[[0, 1]] - expected).abs() < 1e-12,
        "{} vs {expected}",
        d[[0, 1]]
    );
}

#[test]
fn a_period_scales_with_the_coordinates() {
    // Every coordinate with period T: scaling the sets by 2π/T scales every distance by
    // 2π/T and gives the 2π case, seams included.
    let t = 1.3;
    let periods = Periods::new(vec![Some(t); 4]).unwrap();
    let sets = random_walks(7, 13, 0.35, &periods, 33);
    let scale = 2.0 * PI / t;
    let scaled = sets.mapv(|x| x * scale);
    let closures = vec![Closure::Closed; 7];
    let small = prepared_matrix(
        SetsView::new(sets.view()).with_closure(&closures),
        &periods,
        MetricKind::Curve,
    );
    let large = prepared_matrix(
        SetsView::new(scaled.view()).with_closure(&closures),
        &Periods::uniform(Period::TwoPi, 4),
        MetricKind::Curve,
    );
    for (x, y) in small.iter().zip(large.iter()) {
        assert!(
            (x * scale - y).abs() <= 1e-9 * (1.0 + y),
            "{} vs {y}",
            x * scale
        );
    }
    assert!(small.iter().any(|&x| x > 0.1));
}

#[test]
fn uniform_periods_equal_their_shorthand_bit_for_bit() {
    let sets = arm_like_sets(12, 24, 5);
    let closures = vec![Closure::Closed; 12];
    let view = SetsView::new(sets.view()).with_closure(&closures);
    for period in [Period::TwoPi, Period::None] {
        let uniform = Periods::uniform(period, 4);
        assert_eq!(uniform.as_uniform(), Some(period));
        for metric in [MetricKind::Curve, MetricKind::Hausdorff] {
            let shorthand = distance_matrix(
                view,
                &DistanceParams::new().metric(metric).period(period),
                &Silent,
            )
            .unwrap();
            assert_eq!(prepared_matrix(view, &uniform, metric), shorthand);
        }
    }
}

/// Two 2-D sets of five points, `a` then `b`, as an `(2, 5, 2)` array.
fn two_sets(a: [[f64; 2]; 5], b: [[f64; 2]; 5]) -> Array3<f64> {
    Array3::from_shape_fn(
        (2, 5, 2),
        |(s, p, n)| if s == 0 { a[p][n] } else { b[p][n] },
    )
}

/// Both sets open polylines, under the `curve` metric without periods.
fn open_unwrapped_curves() -> ([Closure; 2], DistanceParams) {
    let params = DistanceParams::new()
        .metric(MetricKind::Curve)
        .period(Period::None);
    ([Closure::Open; 2], params)
}

#[test]
fn no_segment_joins_two_pieces_of_a_set() {
    // A: two unit segments, y = 0 and y = 2 (its last point repeated). B: the same
    // two segments and the point (0.5, 1) as a third piece. Every point of A is on B;
    // the point (0.5, 1) is at distance 1 from A's segments. Read as one polyline, A's
    // segment from (1, 0) to (0, 2) would pass through (0.5, 1).
    let a = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [1.0, 2.0], [1.0, 2.0]];
    let b = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [1.0, 2.0], [0.5, 1.0]];
    let sets = two_sets(a, b);
    let pieces = array![[0_i64, 0, 1, 1, 1], [0, 0, 1, 1, 2]];
    let (closures, params) = open_unwrapped_curves();
    let view = SetsView::new(sets.view()).with_closure(&closures);
    let with =
        distance_matrix(view.reborrow().with_pieces(pieces.view()), &params, &Silent).unwrap();
    assert!((with[[0, 1]] - 1.0).abs() < 1e-9, "{}", with[[0, 1]]);
    let joined = distance_matrix(view, &params, &Silent).unwrap();
    assert!((joined[[0, 1]] - 1.0).abs() > 0.1, "{}", joined[[0, 1]]);
}

#[test]
fn the_last_point_of_an_open_set_counts_when_it_is_a_piece_of_its_own() {
    // B's last point (0.5, 5) is a piece of its own, 3 from A; the segment before it
    // is B's point (1, 2.1) alone (0.1 from A), and B's second piece is at most 0.3
    // from A. A point of B, (0.5, 5) must count: ρ = 3 (it was read as 0.3, the last
    // point on no segment).
    let a = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [1.0, 2.0], [1.0, 2.0]];
    let b = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.3], [1.0, 2.1], [0.5, 5.0]];
    let sets = two_sets(a, b);
    let pieces = array![[0_i64, 0, 1, 1, 1], [0, 0, 1, 1, 2]];
    let (closures, params) = open_unwrapped_curves();
    let view = SetsView::new(sets.view())
        .with_closure(&closures)
        .with_pieces(pieces.view());
    let d = distance_matrix(view, &params, &Silent).unwrap();
    assert!((d[[0, 1]] - 3.0).abs() < 1e-9, "{}", d[[0, 1]]);
    assert_eq!(d[[0, 1]], d[[1, 0]]);
}

#[test]
fn a_tile_keeps_the_pieces_of_its_rows_and_columns() {
    // The same two sets as above, one in the tile's rows and one in its columns: the
    // off-diagonal tile reads the pieces of both sides, as the whole matrix does.
    let a = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [1.0, 2.0], [1.0, 2.0]];
    let b = [[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [1.0, 2.0], [0.5, 1.0]];
    let sets = two_sets(a, b);
    let pieces = array![[0_i64, 0, 1, 1, 1], [0, 0, 1, 1, 2]];
    let (closures, params) = open_unwrapped_curves();
    let metric = MetricRegistry::builtin().build(&params).unwrap();
    let view = |range: std::ops::Range<usize>| {
        SetsView::new(sets.slice_axis(Axis(0), range.clone().into()))
            .with_closure(&closures[range.clone()])
            .with_pieces(pieces.slice_axis(Axis(0), range.into()))
    };
    let tile = Tile::new(0..1, 1..2);
    let mut out = Array2::zeros(tile.shape());
    fill_tile(
        view(0..1),
        view(1..2),
        &tile,
        metric.metric.as_ref(),
        out.view_mut(),
        &Silent,
    )
    .unwrap();
    let whole = distance_matrix(view(0..2), &params, &Silent).unwrap();
    assert_eq!(out[[0, 0]], whole[[0, 1]]);
    assert!((out[[0, 0]] - 1.0).abs() < 1e-9, "{}", out[[0, 0]]);
}
