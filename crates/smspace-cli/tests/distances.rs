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

#[test]
fn row_blocks_and_threads_give_the_same_numbers() {
    let dir = tempfile::tempdir().unwrap();
    write_npy(dir.path().join("sets.npy"), &curves(25, 16)).unwrap();
    let out = smspace(
        dir.path(),
        &["distances", "--sets", "sets.npy", "--out", "D.npy"],
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
            "--knn",
            "5",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!dir.path().join("graph/D.npy").exists());
    let indices: Array2<i64> = read_npy(dir.path().join("graph/knn_indices.npy")).unwrap();
    let distances: Array2<f64> = read_npy(dir.path().join("graph/knn_distances.npy")).unwrap();
    assert_eq!(indices.dim(), (40, 5));
    let full = distance_matrix(sets.view(), &DistanceParams::new(), &Silent).unwrap();
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
    let run = |args: &[&str]| fails(dir.path(), args);
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
