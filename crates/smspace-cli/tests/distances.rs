//! Drives `smspace distances` in a temporary folder: matrix, row blocks, nearest sets
//! and bad input.

mod common;

use ndarray::{Array2, Array3, Axis, Slice};
use ndarray_npy::{read_npy, write_npy};
use smspace::metric::{distance_matrix, DistanceParams, MetricKind, Period};
use smspace::progress::Silent;

use common::{fails, smspace, stderr};

/// Deterministic closed curves on the torus, `(m, p, 4)`, wrapped into [-π, π).
fn curves(m: usize, p: usize) -> Array3<f64> {
    use std::f64::consts::{PI, TAU};
    Array3::from_shape_fn((m, p, 4), |(i, k, n)| {
        let t = TAU * k as f64 / p as f64 + 0.37 * i as f64;
        let x = 0.9 * (1.3 * i as f64 + n as f64).sin()
            + 0.6 * (t + n as f64).cos()
            + if n == 0 { t } else { 0.0 };
        (x + PI).rem_euclid(TAU) - PI
    })
}

#[test]
fn writes_the_matrix_equal_to_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let sets = curves(30, 20);
    write_npy(dir.path().join("sets.npy"), &sets).unwrap();
    for (metric, period, kind, per) in [
        ("hausdorff", "2pi", MetricKind::Hausdorff, Period::TwoPi),
        (
            "mean-hausdorff",
            "none",
            MetricKind::MeanHausdorff,
            Period::None,
        ),
    ] {
        let out = smspace(
            dir.path(),
            &[
                "distances",
                "--sets",
                "sets.npy",
                "--out",
                "D.npy",
                "--metric",
                metric,
                "--period",
                period,
            ],
        );
        assert!(out.status.success(), "{}", stderr(&out));
        let d: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
        let params = DistanceParams::new().metric(kind).period(per);
        assert_eq!(d, distance_matrix(sets.view(), &params, &Silent).unwrap());
    }
}

/// `smspace distances` without `--metric` or `--period` computes the library's default
/// `[metric]` table (`DistanceParams::default()`: `curve` under `2pi`, what
/// `smspace.distances` and a run without `metric` compute): the same matrix, byte for
/// byte, and not the point metric's.
#[test]
fn the_default_metric_is_the_library_s() {
    use smspace::metric::{Closure, SetsView, DEFAULT_METRIC};
    let dir = tempfile::tempdir().unwrap();
    let sets = curves(14, 12);
    write_npy(dir.path().join("sets.npy"), &sets).unwrap();
    let codes: ndarray::Array1<i64> = (0..14).map(|i| i64::from(i % 3 != 0)).collect();
    write_npy(dir.path().join("sets.closed.npy"), &codes).unwrap();
    common::ok(
        dir.path(),
        &["distances", "--sets", "sets.npy", "--out", "D.npy"],
    );
    let d: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
    let closure: Vec<Closure> = codes
        .iter()
        .map(|&c| Closure::from_code(c).unwrap())
        .collect();
    let view = || SetsView::new(sets.view()).with_closure(&closure);
    let library = distance_matrix(view(), &DistanceParams::default(), &Silent).unwrap();
    assert_eq!(d, library);
    assert_eq!(DistanceParams::default().metric.as_str(), "curve");
    assert_eq!(DEFAULT_METRIC, MetricKind::Curve);
    let points = DistanceParams::new().metric(MetricKind::Hausdorff);
    assert_ne!(d, distance_matrix(view(), &points, &Silent).unwrap());
}

#[test]
fn one_period_per_motor_wraps_only_the_hinges() {
    let dir = tempfile::tempdir().unwrap();
    // The last coordinate is a slider spread over [0, 6]: differences reach past π.
    let mut sets = curves(12, 10);
    for (i, mut set) in sets.outer_iter_mut().enumerate() {
        for mut point in set.outer_iter_mut() {
            point[3] = 0.5 * i as f64 + 0.1 * point[3];
        }
    }
    write_npy(dir.path().join("sets.npy"), &sets).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "hausdorff",
            "--period",
            "2pi,2pi,2pi,none",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let d: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
    let periods = smspace::metric::Periodicity::parse("2pi,2pi,2pi,none").unwrap();
    let reference =
        smspace::metric::reference::distance_matrix(sets.view(), MetricKind::Hausdorff, &periods);
    let worst = (&d - &reference)
        .mapv(f64::abs)
        .fold(0.0_f64, |a, &b| a.max(b));
    assert!(worst < 1e-12, "{worst}");
    let wrapped = DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .period(Period::TwoPi);
    assert_ne!(d, distance_matrix(sets.view(), &wrapped, &Silent).unwrap());
    // A list of the wrong length, a bad entry, and "motors" without an agent.
    for (period, expected) in [
        ("2pi,none", "2 periods given for points with 4 coordinates"),
        ("2pi,abc,2pi,2pi", "entry 1 is \"abc\""),
        ("motors", "needs an agent"),
    ] {
        let text = fails(
            dir.path(),
            &[
                "distances",
                "--sets",
                "sets.npy",
                "--out",
                "E.npy",
                "--metric",
                "hausdorff",
                "--period",
                period,
            ],
        );
        assert!(text.contains(expected), "{period}: {text}");
        assert!(!dir.path().join("E.npy").exists());
    }
}

#[test]
fn row_blocks_and_threads_give_the_same_numbers() {
    let dir = tempfile::tempdir().unwrap();
    write_npy(dir.path().join("sets.npy"), &curves(25, 16)).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "hausdorff",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let full: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "--threads",
            "1",
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "B.npy",
            "--metric",
            "hausdorff",
            "--rows",
            "7:19",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let block: Array2<f64> = read_npy(dir.path().join("B.npy")).unwrap();
    assert_eq!(block, full.slice_axis(Axis(0), Slice::from(7..19)));
}

#[test]
fn knn_writes_indices_and_distances_next_to_out() {
    let dir = tempfile::tempdir().unwrap();
    let sets = curves(40, 16);
    write_npy(dir.path().join("sets.npy"), &sets).unwrap();
    std::fs::create_dir(dir.path().join("graph")).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "graph/D.npy",
            "--metric",
            "hausdorff",
            "--knn",
            "5",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!dir.path().join("graph/D.npy").exists());
    let indices: Array2<i64> = read_npy(dir.path().join("graph/knn_indices.npy")).unwrap();
    let distances: Array2<f64> = read_npy(dir.path().join("graph/knn_distances.npy")).unwrap();
    assert_eq!(indices.dim(), (40, 5));
    let hausdorff = DistanceParams::new().metric(MetricKind::Hausdorff);
    let full = distance_matrix(sets.view(), &hausdorff, &Silent).unwrap();
    for i in 0..40 {
        let mut row: Vec<(f64, usize)> = (0..40)
            .filter(|&j| j != i)
            .map(|j| (full[[i, j]], j))
            .collect();
        row.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        for e in 0..5 {
            assert_eq!(indices[[i, e]], row[e].1 as i64);
            assert_eq!(distances[[i, e]], row[e].0);
        }
    }
}

#[test]
fn bad_input_gets_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    // Under the point metric: bare sets, without a closure record.
    let run = |args: &[&str]| {
        let mut args = args.to_vec();
        args.extend(["--metric", "hausdorff"]);
        fails(dir.path(), &args)
    };
    write_npy(dir.path().join("flat.npy"), &Array2::<f64>::zeros((10, 3))).unwrap();
    let e = run(&["distances", "--sets", "flat.npy", "--out", "D.npy"]);
    assert!(
        e.contains("flat.npy has shape (10, 3), expected (M, P, N)"),
        "{e}"
    );

    let mut nan = curves(3, 4);
    nan[[1, 2, 0]] = f64::NAN;
    write_npy(dir.path().join("nan.npy"), &nan).unwrap();
    let e = run(&["distances", "--sets", "nan.npy", "--out", "D.npy"]);
    assert!(e.contains("non-finite"), "{e}");

    write_npy(dir.path().join("one.npy"), &curves(1, 4)).unwrap();
    let e = run(&["distances", "--sets", "one.npy", "--out", "D.npy"]);
    assert!(e.contains("need at least 2 kernel sets"), "{e}");

    write_npy(
        dir.path().join("empty.npy"),
        &Array3::<f64>::zeros((3, 0, 4)),
    )
    .unwrap();
    let e = run(&["distances", "--sets", "empty.npy", "--out", "D.npy"]);
    assert!(e.contains("P >= 1 points"), "{e}");

    write_npy(dir.path().join("sets.npy"), &curves(6, 4)).unwrap();
    let e = run(&[
        "distances",
        "--sets",
        "sets.npy",
        "--out",
        "D.npy",
        "--rows",
        "4:2",
    ]);
    assert!(
        e.contains("row block 4:2 is not a non-empty range within 0:6"),
        "{e}"
    );
    let e = run(&[
        "distances",
        "--sets",
        "sets.npy",
        "--out",
        "D.npy",
        "--rows",
        "x",
    ]);
    assert!(e.contains("expected I0:I1"), "{e}");
    let e = run(&[
        "distances",
        "--sets",
        "sets.npy",
        "--out",
        "D.npy",
        "--knn",
        "6",
    ]);
    assert!(e.contains("between 1 and M - 1 = 5"), "{e}");
    let e = run(&[
        "distances",
        "--sets",
        "sets.npy",
        "--out",
        "D.npy",
        "--max-memory",
        "100",
    ]);
    assert!(e.contains("--knn K"), "{e}");
    assert!(!dir.path().join("D.npy").exists());
    let e = run(&["distances", "--sets", "missing.npy", "--out", "D.npy"]);
    assert!(e.contains("cannot read missing.npy"), "{e}");
}

#[test]
fn curve_metric_reads_the_closed_record_or_the_flag() {
    use smspace::metric::{Closure, SetsView};
    let dir = tempfile::tempdir().unwrap();
    let sets = curves(12, 10);
    write_npy(dir.path().join("sets.npy"), &sets).unwrap();
    // A bare .npy: the metric must be told how the points are joined.
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
        ],
    );
    assert!(!out.status.success());
    let message = stderr(&out);
    assert!(
        message.contains("sets.closed.npy") && message.contains("--curve closed"),
        "{message}"
    );
    // --curve closed: every set a loop.
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
            "--curve",
            "closed",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let d: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
    let closed = vec![Closure::Closed; 12];
    let params = DistanceParams::new().metric(MetricKind::Curve);
    let expected = distance_matrix(
        SetsView::new(sets.view()).with_closure(&closed),
        &params,
        &Silent,
    )
    .unwrap();
    assert_eq!(d, expected);
    // The record next to the sets (as `smspace trace` writes it): mixed closures.
    let record: ndarray::Array1<i64> = (0..12).map(|i| i64::from(i % 2 == 0)).collect();
    write_npy(dir.path().join("sets.closed.npy"), &record).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let d: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
    let mixed: Vec<Closure> = (0..12)
        .map(|i| {
            if i % 2 == 0 {
                Closure::Closed
            } else {
                Closure::Open
            }
        })
        .collect();
    let expected = distance_matrix(
        SetsView::new(sets.view()).with_closure(&mixed),
        &params,
        &Silent,
    )
    .unwrap();
    assert_eq!(d, expected);
    assert_ne!(
        d,
        distance_matrix(
            SetsView::new(sets.view()).with_closure(&closed),
            &params,
            &Silent
        )
        .unwrap()
    );
    // kNN with the record equals the top of the matrix rows.
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
            "--knn",
            "3",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let knn: Array2<f64> = read_npy(dir.path().join("knn_distances.npy")).unwrap();
    for i in 0..12 {
        let mut row: Vec<f64> = (0..12)
            .filter(|&j| j != i)
            .map(|j| expected[[i, j]])
            .collect();
        row.sort_by(f64::total_cmp);
        assert_eq!(knn.row(i).to_vec(), row[..3].to_vec());
    }
    // A record of the wrong length, or with a code other than 0/1.
    write_npy(
        dir.path().join("sets.closed.npy"),
        &ndarray::Array1::<i64>::ones(5),
    )
    .unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
        ],
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("sets.closed.npy has shape (5,), expected (12,)"),
        "{}",
        stderr(&out)
    );
    write_npy(dir.path().join("sets.closed.npy"), &(&record * 2)).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
        ],
    );
    assert!(!out.status.success());
    assert!(stderr(&out).contains("entry 0 is 2"), "{}", stderr(&out));
    // --curve with a point metric is a mistake, said so.
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "hausdorff",
            "--curve",
            "open",
        ],
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("--curve only applies to a metric that reads polylines"),
        "{}",
        stderr(&out)
    );
    // One point per set cannot make a polyline.
    write_npy(dir.path().join("one.npy"), &curves(4, 1)).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "one.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
            "--curve",
            "open",
        ],
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("at least 2 points per set"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn trace_records_which_sets_are_closed() {
    let dir = tempfile::tempdir().unwrap();
    let motors = ndarray::array![
        [0.3, 0.5, -0.4, 0.2],
        [0.1, 0.9, -0.8, 0.5],
        [-0.2, 0.7, -0.2, 0.1]
    ];
    write_npy(dir.path().join("motors.npy"), &motors).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "trace",
            "--agent",
            "planar-arm",
            "--motors",
            "motors.npy",
            "--points",
            "30",
            "--step-control",
            "adaptive",
            "--workspace",
            "none",
            "--out",
            "sets.npy",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let closed: ndarray::Array1<i64> = read_npy(dir.path().join("sets.closed.npy")).unwrap();
    let sets: Array3<f64> = read_npy(dir.path().join("sets.npy")).unwrap();
    assert_eq!(closed.len(), sets.dim().0);
    assert!(
        closed.iter().all(|&c| c == 1),
        "the arm's sets are loops: {closed}"
    );
    let out = smspace(
        dir.path(),
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--out",
            "D.npy",
            "--metric",
            "curve",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    // The redundant toy's sets are open segments.
    let toy = ndarray::array![[0.2, 0.1], [-0.5, 0.3]];
    write_npy(dir.path().join("toy.npy"), &toy).unwrap();
    let out = smspace(
        dir.path(),
        &[
            "trace",
            "--agent",
            "toy-redundant",
            "--motors",
            "toy.npy",
            "--points",
            "10",
            "--out",
            "toy-sets.npy",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let closed: ndarray::Array1<i64> = read_npy(dir.path().join("toy-sets.closed.npy")).unwrap();
    assert!(closed.iter().all(|&c| c == 0), "{closed}");
}

/// The tiles of a plan, each written by its own process, merge into the matrix byte for
/// byte; row blocks merge too; a missing or foreign tile is refused.
#[test]
fn tiles_merge_into_the_matrix() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_npy(d.join("sets.npy"), &curves(23, 12)).unwrap();
    // The default metric (curve), every set a loop as recorded beside the sets.
    write_npy(d.join("sets.closed.npy"), &ndarray::Array1::<i64>::ones(23)).unwrap();
    common::ok(d, &["distances", "--sets", "sets.npy", "--out", "D.npy"]);
    // Blocks 0:10, 10:20, 20:23: the tiles (a, b) with a <= b.
    let blocks = ["0:10", "10:20", "20:23"];
    let mut tiles = Vec::new();
    for a in 0..3 {
        for b in a..3 {
            let name = format!("T{a}{b}.npy");
            let tile = format!("{},{}", blocks[a], blocks[b]);
            common::ok(
                d,
                &[
                    "distances",
                    "--sets",
                    "sets.npy",
                    "--tile",
                    &tile,
                    "--out",
                    &name,
                ],
            );
            assert!(d.join(format!("T{a}{b}.tile.json")).is_file());
            tiles.push(name);
        }
    }
    let t01: Array2<f64> = read_npy(d.join("T01.npy")).unwrap();
    assert_eq!(t01.dim(), (10, 10));
    let mut args = vec!["distances", "--out", "M.npy", "--merge"];
    args.extend(tiles.iter().map(String::as_str));
    common::ok(d, &args);
    assert_eq!(
        std::fs::read(d.join("M.npy")).unwrap(),
        std::fs::read(d.join("D.npy")).unwrap()
    );
    // Row blocks are tiles of every column: they merge too.
    for (rows, name) in [("0:12", "R0.npy"), ("12:23", "R1.npy")] {
        common::ok(
            d,
            &[
                "distances",
                "--sets",
                "sets.npy",
                "--rows",
                rows,
                "--out",
                name,
            ],
        );
    }
    common::ok(
        d,
        &["distances", "--out", "R.npy", "--merge", "R0.npy", "R1.npy"],
    );
    assert_eq!(
        std::fs::read(d.join("R.npy")).unwrap(),
        std::fs::read(d.join("D.npy")).unwrap()
    );
    // A tile left out, a tile of another metric, a tile without its record.
    let e = fails(
        d,
        &[
            "distances",
            "--out",
            "X.npy",
            "--merge",
            "T00.npy",
            "T11.npy",
        ],
    );
    assert!(e.contains("no tile holds the pair (0, 10)"), "{e}");
    common::ok(
        d,
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--tile",
            "0:10,10:20",
            "--metric",
            "mean-hausdorff",
            "--out",
            "H.npy",
        ],
    );
    let e = fails(
        d,
        &["distances", "--out", "X.npy", "--merge", "T00.npy", "H.npy"],
    );
    assert!(
        e.contains("mean-hausdorff") && e.contains("merge the tiles of one matrix"),
        "{e}"
    );
    std::fs::copy(d.join("T00.npy"), d.join("bare.npy")).unwrap();
    let e = fails(d, &["distances", "--out", "X.npy", "--merge", "bare.npy"]);
    assert!(e.contains("bare.tile.json"), "{e}");
    assert!(!d.join("X.npy").exists());
    let e = fails(
        d,
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--tile",
            "0:10,20:30",
            "--out",
            "X.npy",
        ],
    );
    assert!(
        e.contains("20:30 is not a non-empty range within 0:23"),
        "{e}"
    );
    let e = fails(
        d,
        &[
            "distances",
            "--sets",
            "sets.npy",
            "--tile",
            "0:10",
            "--out",
            "X.npy",
        ],
    );
    assert!(e.contains("expected I0:I1,J0:J1"), "{e}");
}

/// `m` sampled planes `z = h_i` of R³, each a 6 × 6 grid of spacing 0.3 shifted in the
/// plane by at most a fifth of a step: their `surface` distances are `|h_i − h_j|`.
fn planes(m: usize) -> (Array3<f64>, Vec<f64>) {
    let heights: Vec<f64> = (0..m).map(|i| (0.37 * i as f64).sin()).collect();
    let sets = Array3::from_shape_fn((m, 36, 3), |(s, p, c)| {
        let shift = 0.06 * (1.7 * s as f64).cos();
        match c {
            0 => 0.3 * (p / 6) as f64 + shift,
            1 => 0.3 * (p % 6) as f64 - shift,
            _ => heights[s],
        }
    });
    (sets, heights)
}

#[test]
fn surface_metric_measures_sampled_planes_by_their_gap() {
    let dir = tempfile::tempdir().unwrap();
    let (sets, heights) = planes(8);
    write_npy(dir.path().join("planes.npy"), &sets).unwrap();
    let args = [
        "distances",
        "--sets",
        "planes.npy",
        "--metric",
        "surface",
        "--period",
        "none",
    ];
    let run = |extra: &[&str]| {
        let mut all = args.to_vec();
        all.extend_from_slice(extra);
        let out = smspace(dir.path(), &all);
        assert!(out.status.success(), "{}", stderr(&out));
    };
    run(&["--out", "D.npy"]);
    let d: Array2<f64> = read_npy(dir.path().join("D.npy")).unwrap();
    for i in 0..8 {
        for j in 0..8 {
            assert!(
                (d[[i, j]] - (heights[i] - heights[j]).abs()).abs() < 1e-12,
                "({i}, {j}): {}",
                d[[i, j]]
            );
        }
    }
    // Row blocks and the nearest sets agree with the matrix.
    run(&["--out", "R.npy", "--rows", "2:5", "--param", "dimension=2"]);
    let rows: Array2<f64> = read_npy(dir.path().join("R.npy")).unwrap();
    assert_eq!(rows, d.slice_axis(Axis(0), Slice::from(2..5)));
    run(&["--out", "D.npy", "--knn", "2"]);
    let near: Array2<f64> = read_npy(dir.path().join("knn_distances.npy")).unwrap();
    for i in 0..8 {
        let mut row: Vec<f64> = (0..8).filter(|&j| j != i).map(|j| d[[i, j]]).collect();
        row.sort_by(f64::total_cmp);
        assert_eq!(near.row(i).to_vec(), row[..2].to_vec(), "row {i}");
    }
    // Bad input names the flag or the parameter.
    let e = fails(
        dir.path(),
        &[
            "distances",
            "--sets",
            "planes.npy",
            "--out",
            "X.npy",
            "--metric",
            "hausdorff",
            "--param",
            "dimension=2",
        ],
    );
    assert!(
        e.contains("hausdorff") && e.contains("dimension") && e.contains("--param"),
        "{e}"
    );
    let e = fails(
        dir.path(),
        &[
            "distances",
            "--sets",
            "planes.npy",
            "--out",
            "X.npy",
            "--metric",
            "surface",
            "--param",
            "dimension=3",
        ],
    );
    assert!(e.contains("dimension") && e.contains("N = 3"), "{e}");
}
