//! `smspace embed` end to end, in a temporary directory, bad input included.

mod common;

use std::path::Path;

use ndarray::Array2;
use ndarray_npy::{read_npy, write_npy};

use common::{fails_with, ok};

/// Chord distances of `n` evenly spaced points on the unit circle, with a wobble so
/// that neighbours are not tied.
fn circle(n: usize) -> Array2<f64> {
    let angle = |i: usize| std::f64::consts::TAU * (i as f64 + 0.3 * (i as f64).sin()) / n as f64;
    Array2::from_shape_fn((n, n), |(i, j)| {
        let (a, b) = (angle(i), angle(j));
        ((a.cos() - b.cos()).powi(2) + (a.sin() - b.sin()).powi(2)).sqrt()
    })
}

/// The report as JSON, after checking that it reads as the library's `EmbedFile` (the
/// format `smspace run` writes too).
fn report(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap();
    let file: smspace::embed::EmbedFile = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("{} is not an EmbedFile: {e}", path.display()));
    assert!(file.seconds.is_some());
    serde_json::from_str(&text).unwrap()
}

#[test]
fn every_method_writes_coordinates_report_and_dydx() {
    let dir = tempfile::tempdir().unwrap();
    write_npy(dir.path().join("D.npy"), &circle(120)).unwrap();
    for method in ["cca", "isomap", "mds"] {
        let out = format!("{method}.npy");
        ok(
            dir.path(),
            &[
                "embed",
                "--distances",
                "D.npy",
                "--method",
                method,
                "--dim",
                "2",
                "--seed",
                "3",
                "--out",
                &out,
            ],
        );
        let y: Array2<f64> = read_npy(dir.path().join(&out)).unwrap();
        assert_eq!(y.dim(), (120, 2));
        let r = report(&dir.path().join(format!("{method}.embed.json")));
        assert_eq!(r["method"], method);
        assert_eq!(r["points"], 120);
        let t = r["quality"]["trustworthiness"].as_f64().unwrap();
        let c = r["quality"]["continuity"].as_f64().unwrap();
        assert!(t >= 0.99 && c >= 0.99, "{method}: T = {t}, C = {c}");
        assert!(!r["eigenvalues"].as_array().unwrap().is_empty());
        assert_eq!(r["params"]["method"], method);
        let pairs: Array2<f64> = read_npy(dir.path().join(format!("{method}.dydx.npy"))).unwrap();
        assert_eq!(pairs.dim(), (120 * 119 / 2, 2));
        assert_eq!(r["dydx"]["pairs"], 120 * 119 / 2);
        if method == "cca" {
            assert_eq!(r["stress_trace"].as_array().unwrap().len(), 50);
        }
    }
}

#[test]
fn extend_places_new_points_and_threads_do_not_change_the_result() {
    let dir = tempfile::tempdir().unwrap();
    let all = circle(100);
    // Old: even indices; new: odd ones.
    let old: Vec<usize> = (0..100).step_by(2).collect();
    let new: Vec<usize> = (1..100).step_by(2).collect();
    let d = Array2::from_shape_fn((50, 50), |(a, b)| all[[old[a], old[b]]]);
    let x = Array2::from_shape_fn((50, 50), |(a, b)| all[[new[a], old[b]]]);
    write_npy(dir.path().join("D.npy"), &d).unwrap();
    write_npy(dir.path().join("new.npy"), &x).unwrap();
    let args = |threads: &'static str, out: &'static str| {
        vec![
            "--threads",
            threads,
            "embed",
            "--distances",
            "D.npy",
            "--dim",
            "2",
            "--epochs",
            "20",
            "--extend",
            "new.npy",
            "--out",
            out,
        ]
    };
    ok(dir.path(), &args("1", "one.npy"));
    ok(dir.path(), &args("2", "two.npy"));
    let one = std::fs::read(dir.path().join("one.npy")).unwrap();
    let two = std::fs::read(dir.path().join("two.npy")).unwrap();
    assert_eq!(one, two, "the thread count changed the embedding");
    let y: Array2<f64> = read_npy(dir.path().join("one.npy")).unwrap();
    let placed: Array2<f64> = read_npy(dir.path().join("one.extended.npy")).unwrap();
    assert_eq!(placed.dim(), (50, 2));
    // New point a sits between old points a and a+1 on the circle.
    for a in 0..50 {
        let nearest = (0..50)
            .min_by(|&i, &j| {
                let di = (&y.row(i) - &placed.row(a)).mapv(|v| v * v).sum();
                let dj = (&y.row(j) - &placed.row(a)).mapv(|v| v * v).sum();
                di.total_cmp(&dj)
            })
            .unwrap();
        assert!(
            nearest == a || nearest == (a + 1) % 50,
            "new {a} next to old {nearest}"
        );
    }
    let r = report(&dir.path().join("one.embed.json"));
    assert_eq!(r["extended"]["points"], 50);
}

#[test]
fn landmark_isomap_runs_from_a_knn_graph() {
    let dir = tempfile::tempdir().unwrap();
    let d = circle(200);
    let k = 8;
    let mut idx = Array2::<i64>::zeros((200, k));
    let mut dist = Array2::<f64>::zeros((200, k));
    for i in 0..200 {
        let mut order: Vec<usize> = (0..200).filter(|&j| j != i).collect();
        order.sort_by(|&a, &b| d[[i, a]].total_cmp(&d[[i, b]]));
        for c in 0..k {
            idx[[i, c]] = order[c] as i64;
            dist[[i, c]] = d[[i, order[c]]];
        }
    }
    write_npy(dir.path().join("knn_indices.npy"), &idx).unwrap();
    write_npy(dir.path().join("knn_distances.npy"), &dist).unwrap();
    ok(
        dir.path(),
        &[
            "embed",
            "--knn-indices",
            "knn_indices.npy",
            "--knn-distances",
            "knn_distances.npy",
            "--method",
            "isomap",
            "--k",
            "6",
            "--landmarks",
            "40",
            "--dim",
            "2",
            "--out",
            "Y.npy",
        ],
    );
    let y: Array2<f64> = read_npy(dir.path().join("Y.npy")).unwrap();
    assert_eq!(y.dim(), (200, 2));
    let r = report(&dir.path().join("Y.embed.json"));
    assert_eq!(r["landmarks"].as_array().unwrap().len(), 40);
    assert!(r["quality"].is_null());
    fails_with(
        dir.path(),
        &[
            "embed",
            "--knn-indices",
            "knn_indices.npy",
            "--knn-distances",
            "knn_distances.npy",
            "--method",
            "isomap",
            "--k",
            "9",
            "--out",
            "Y.npy",
        ],
        "use k ≤ 8",
    );
}

#[test]
fn bad_input_gets_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path();
    write_npy(p.join("rect.npy"), &Array2::<f64>::zeros((3, 4))).unwrap();
    fails_with(
        p,
        &["embed", "--distances", "rect.npy", "--out", "Y.npy"],
        "rect.npy has shape (3, 4); a distance matrix is square",
    );
    let mut asym = circle(20);
    asym[[1, 2]] += 0.1;
    write_npy(p.join("asym.npy"), &asym).unwrap();
    fails_with(
        p,
        &["embed", "--distances", "asym.npy", "--out", "Y.npy"],
        "asym.npy is not symmetric",
    );
    let mut nan = circle(20);
    nan[[3, 3]] = f64::NAN;
    write_npy(p.join("nan.npy"), &nan).unwrap();
    fails_with(
        p,
        &["embed", "--distances", "nan.npy", "--out", "Y.npy"],
        "non-finite",
    );
    let mut neg = circle(20);
    neg[[1, 2]] = -1.0;
    neg[[2, 1]] = -1.0;
    write_npy(p.join("neg.npy"), &neg).unwrap();
    fails_with(
        p,
        &["embed", "--distances", "neg.npy", "--out", "Y.npy"],
        "neg.npy holds a negative distance",
    );
    write_npy(p.join("D.npy"), &circle(20)).unwrap();
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "mds",
            "--dim",
            "20",
            "--out",
            "Y.npy",
        ],
        "cannot embed 20 points in 20 dimensions",
    );
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "isomap",
            "--k",
            "20",
            "--out",
            "Y.npy",
        ],
        "use k < 20",
    );
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "mds",
            "--k",
            "5",
            "--out",
            "Y.npy",
        ],
        "--method isomap only",
    );
    fails_with(
        p,
        &["embed", "--distances", "missing.npy", "--out", "Y.npy"],
        "missing.npy",
    );
    write_npy(p.join("new.npy"), &Array2::<f64>::zeros((2, 7))).unwrap();
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "mds",
            "--dim",
            "2",
            "--extend",
            "new.npy",
            "--out",
            "Y.npy",
        ],
        "expected (N, 20)",
    );
    // Two far-apart clusters: the graph is disconnected.
    let two = Array2::from_shape_fn((20, 20), |(i, j)| {
        if i == j {
            0.0
        } else if (i < 10) == (j < 10) {
            1.0 + 0.01 * (i + j) as f64
        } else {
            100.0
        }
    });
    write_npy(p.join("two.npy"), &two).unwrap();
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "two.npy",
            "--method",
            "isomap",
            "--k",
            "3",
            "--out",
            "Y.npy",
        ],
        "2 connected components",
    );
}

/// `--method` is resolved through the library's embedding registry and `--param` sets
/// any key of the method's `[embedding]` table: `--param epochs=7` is `--epochs 7`, and
/// the library's default table gives the same coordinates as no flag at all.
#[test]
fn method_by_name_and_any_parameter_with_param() {
    use smspace::embed::EmbedParams;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path();
    write_npy(p.join("D.npy"), &circle(40)).unwrap();
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec!["embed", "--distances", "D.npy", "--out", out];
        args.extend_from_slice(extra);
        ok(p, &args);
        read_npy::<_, Array2<f64>>(p.join(out)).unwrap()
    };
    let flag = run(
        "flag.npy",
        &["--method", "cca", "--epochs", "7", "--dim", "2"],
    );
    let param = run(
        "param.npy",
        &["--method", "cca", "--param", "epochs=7", "--param", "dim=2"],
    );
    assert_eq!(flag, param);
    let r = report(&p.join("param.embed.json"));
    assert_eq!(r["params"]["epochs"], 7);
    assert_eq!(r["params"]["method"], "cca");
    // A parameter no flag has: MDS's solver.
    let dense = run(
        "dense.npy",
        &[
            "--method",
            "mds",
            "--param",
            "solver=\"dense\"",
            "--dim",
            "2",
        ],
    );
    assert_eq!(dense.dim(), (40, 2));
    // No flag: the library's default method and table (on a helix, which spans 3-D).
    let helix = Array2::from_shape_fn((40, 40), |(i, j)| {
        let point = |k: usize| {
            let t = 0.4 * k as f64;
            [t.cos(), t.sin(), 0.1 * t]
        };
        let (a, b) = (point(i), point(j));
        (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
    });
    write_npy(p.join("H.npy"), &helix).unwrap();
    ok(
        p,
        &["embed", "--distances", "H.npy", "--out", "default.npy"],
    );
    let default: Array2<f64> = read_npy(p.join("default.npy")).unwrap();
    let d = smspace::metric::DistanceMatrix::new(helix).unwrap();
    let library = EmbedParams::default()
        .build()
        .unwrap()
        .fit(&d, &smspace::progress::Silent)
        .unwrap()
        .coordinates;
    assert_eq!(default, library);
    // Unknown names and keys are errors that name them.
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "umap",
            "--out",
            "X.npy",
        ],
        "unknown embedding method 'umap'; the registered methods are cca, isomap, mds",
    );
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "mds",
            "--param",
            "epoch=3",
            "--out",
            "X.npy",
        ],
        "epoch",
    );
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--epochs",
            "3",
            "--param",
            "epochs=4",
            "--out",
            "X.npy",
        ],
        "--epochs and --param epochs",
    );
    fails_with(
        p,
        &[
            "embed",
            "--distances",
            "D.npy",
            "--method",
            "isomap",
            "--epochs",
            "3",
            "--out",
            "X.npy",
        ],
        "--epochs applies to --method cca only",
    );
    assert!(!p.join("X.npy").exists());
}
