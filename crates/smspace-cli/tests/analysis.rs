//! Runs `smspace analyze` and `smspace invariance` in a temporary folder, bad input
//! included.

mod common;

use std::f64::consts::TAU;

use ndarray::{Array2, Array3};
use ndarray_npy::write_npy;

use common::{fails, ok};

/// `n` points on a circle (angles `alpha`, poses `(0, 0, alpha)`) and their chord
/// distances.
fn circle(n: usize) -> (Array2<f64>, Array2<f64>) {
    // Uniform angles from a fixed xorshift stream.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let alpha: Vec<f64> = (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * TAU - 3.1
        })
        .collect();
    let d = Array2::from_shape_fn((n, n), |(i, j)| {
        2.0 * (0.5 * (alpha[i] - alpha[j])).sin().abs()
    });
    let poses = Array2::from_shape_fn((n, 3), |(i, c)| if c == 2 { alpha[i] } else { 0.0 });
    (d, poses)
}

#[test]
fn analyze_a_circle_writes_the_contract_keys() {
    let dir = tempfile::tempdir().unwrap();
    let (d, poses) = circle(120);
    write_npy(dir.path().join("D.npy"), &d).unwrap();
    write_npy(dir.path().join("poses.npy"), &poses).unwrap();
    let out = ok(
        dir.path(),
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--poses",
            "poses.npy",
            "--out",
            "report.json",
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("betti [1, 1]"), "{stderr}");
    let text = std::fs::read_to_string(dir.path().join("report.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(report["betti"], serde_json::json!([1, 1]));
    for key in [
        "/persistence/1",
        "/intrinsic_dimension/twonn",
        "/intrinsic_dimension/mle",
        "/agreement/spearman",
        "/agreement/trustworthiness",
        "/agreement/continuity",
    ] {
        assert!(report.pointer(key).is_some(), "missing {key}");
    }
    assert!(report["agreement"]["spearman"].as_f64().unwrap() > 0.999);
    let twonn = report["intrinsic_dimension"]["twonn"].as_f64().unwrap();
    assert!((twonn - 1.0).abs() < 0.3, "{twonn}");
    // The loop as a number: the circular coordinate of every point beside the report,
    // which gives the angle back.
    let rho = report["circle"]["agreement"]["alpha"]["circular_correlation"]
        .as_f64()
        .unwrap();
    assert!(rho > 0.99, "{rho}");
    assert!(stderr.contains("circular correlation"), "{stderr}");
    let values: ndarray::Array1<f64> =
        ndarray_npy::read_npy(dir.path().join("circle.npy")).unwrap();
    assert_eq!(values.len(), 120);
    assert!(values.iter().all(|v| (0.0..TAU).contains(v)));

    // Positions read off a representation: the poses' own (x, y) plus a constant
    // column are an affine image of them (the circle's poses are all at the origin,
    // so positions come from a second file).
    let positions = Array2::from_shape_fn((120, 3), |(i, c)| match c {
        0 => (i % 12) as f64,
        1 => (i / 12) as f64,
        _ => poses[[i, 2]],
    });
    write_npy(dir.path().join("grid-poses.npy"), &positions).unwrap();
    let representation = Array2::from_shape_fn((120, 2), |(i, c)| {
        if c == 0 {
            2.0 * positions[[i, 0]] + 1.0
        } else {
            positions[[i, 1]] - positions[[i, 0]]
        }
    });
    write_npy(dir.path().join("H.npy"), &representation).unwrap();
    let out = ok(
        dir.path(),
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--poses",
            "grid-poses.npy",
            "--representation",
            "H.npy",
        ],
    );
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let affine = &printed["affine"];
    assert!(affine["metric_error"].as_f64().unwrap() < 1e-9, "{affine}");
    assert!(
        (affine["r_squared"].as_f64().unwrap() - 1.0).abs() < 1e-9,
        "{affine}"
    );
    // The positions alone, (x, y) of a sensor whose orientation is fixed: the same fit,
    // and the agreement names the two coordinates only.
    let xy = Array2::from_shape_fn((120, 2), |(i, c)| positions[[i, c]]);
    write_npy(dir.path().join("xy.npy"), &xy).unwrap();
    let out = ok(
        dir.path(),
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--poses",
            "xy.npy",
            "--representation",
            "H.npy",
        ],
    );
    let alone: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(alone["affine"], printed["affine"]);
    let coordinates = alone["agreement"]["coordinates"].as_object().unwrap();
    assert_eq!(coordinates.keys().collect::<Vec<_>>(), ["x", "y"]);
    let four = Array2::<f64>::zeros((120, 4));
    write_npy(dir.path().join("four.npy"), &four).unwrap();
    let err = fails(
        dir.path(),
        &["analyze", "--distances", "D.npy", "--poses", "four.npy"],
    );
    assert!(
        err.contains("four.npy has 4 columns") && err.contains("(M, 2) (x, y)"),
        "{err}"
    );

    // Without --out the report goes to standard output, identical; without poses the
    // agreement is null.
    let out = ok(
        dir.path(),
        &["analyze", "--distances", "D.npy", "--poses", "poses.npy"],
    );
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(printed, report);
    let out = ok(dir.path(), &["analyze", "--distances", "D.npy"]);
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(printed["agreement"].is_null());
}

#[test]
fn analyze_rejects_bad_input_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path();
    let (d, poses) = circle(40);
    write_npy(p.join("D.npy"), &d).unwrap();
    write_npy(p.join("rect.npy"), &Array2::<f64>::zeros((4, 5))).unwrap();
    write_npy(p.join("cube.npy"), &Array3::<f64>::zeros((2, 2, 2))).unwrap();
    let mut asym = d.clone();
    asym[[2, 5]] += 1.0;
    write_npy(p.join("asym.npy"), &asym).unwrap();
    let mut nan = d.clone();
    nan[[1, 1]] = f64::NAN;
    write_npy(p.join("nan.npy"), &nan).unwrap();
    write_npy(
        p.join("poses.npy"),
        &poses.select(ndarray::Axis(0), &(0..30).collect::<Vec<_>>()),
    )
    .unwrap();

    let err = fails(p, &["analyze", "--distances", "missing.npy"]);
    assert!(err.contains("missing.npy"), "{err}");
    let err = fails(p, &["analyze", "--distances", "rect.npy"]);
    assert!(err.contains("rect.npy") && err.contains("(4, 5)"), "{err}");
    let err = fails(p, &["analyze", "--distances", "cube.npy"]);
    assert!(err.contains("cube.npy") && err.contains("(M, M)"), "{err}");
    let err = fails(p, &["analyze", "--distances", "asym.npy"]);
    assert!(
        err.contains("asym.npy") && err.contains("symmetric") && err.contains("[2, 5]"),
        "{err}"
    );
    let err = fails(p, &["analyze", "--distances", "nan.npy"]);
    assert!(err.contains("nan.npy") && err.contains("NaN"), "{err}");
    let err = fails(
        p,
        &["analyze", "--distances", "D.npy", "--poses", "poses.npy"],
    );
    assert!(
        err.contains("poses.npy") && err.contains("30 rows"),
        "{err}"
    );
    let err = fails(p, &["analyze", "--distances", "D.npy", "--max-dim", "3"]);
    assert!(err.contains("max_homology_dim"), "{err}");
    let err = fails(p, &["analyze", "--distances", "D.npy", "--threshold", "-1"]);
    assert!(err.contains("threshold"), "{err}");
    write_npy(p.join("poses40.npy"), &poses).unwrap();
    let err = fails(
        p,
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--poses",
            "poses40.npy",
            "--neighbors",
            "30",
        ],
    );
    assert!(err.contains("neighbors"), "{err}");
    // A representation is fitted to the poses' positions; it needs the poses and the
    // same rows.
    let err = fails(
        p,
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--representation",
            "poses40.npy",
        ],
    );
    assert!(err.contains("--poses"), "{err}");
    let err = fails(
        p,
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--poses",
            "poses40.npy",
            "--representation",
            "rect.npy",
        ],
    );
    assert!(err.contains("rect.npy") && err.contains("4 rows"), "{err}");
    // --param reaches the keys without a flag and refuses the others by name.
    let err = fails(
        p,
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--param",
            "circle_scale=1.5",
        ],
    );
    assert!(err.contains("circle_scale") && err.contains("1.5"), "{err}");
    let err = fails(
        p,
        &["analyze", "--distances", "D.npy", "--param", "max_points=5"],
    );
    assert!(err.contains("--max-points"), "{err}");
    let err = fails(
        p,
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--param",
            "circle_marks=5",
        ],
    );
    assert!(
        err.contains("circle_marks") && err.contains("circle_landmarks"),
        "{err}"
    );
    let out = ok(
        p,
        &[
            "analyze",
            "--distances",
            "D.npy",
            "--param",
            "circle_landmarks=0",
        ],
    );
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(printed.get("circle").is_none(), "{printed}");
}

#[test]
fn invariance_of_the_redundant_toy() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path();
    let motors = Array2::from_shape_fn((12, 2), |(i, c)| {
        let x = -2.0 + 0.35 * i as f64;
        if c == 0 {
            0.6 * x
        } else {
            0.4 * x
        }
    });
    write_npy(p.join("motors.npy"), &motors).unwrap();
    ok(
        p,
        &[
            "invariance",
            "--agent",
            "toy-redundant",
            "--motors",
            "motors.npy",
            "--env-seeds",
            "1,2,3",
            "--lights",
            "5,8,3",
            "--points",
            "20",
            "--out",
            "invariance.json",
        ],
    );
    let text = std::fs::read_to_string(p.join("invariance.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(report["environments"].as_array().unwrap().len(), 3);
    assert_eq!(report["environments"][1]["lights"], 8);
    assert_eq!(report["pairs"].as_array().unwrap().len(), 3);
    assert!(
        report["max_set_distance_relative"].as_f64().unwrap() < 1e-6,
        "{report}"
    );
    assert!(
        report["min_mantel"].as_f64().unwrap() > 0.999_999,
        "{report}"
    );
    assert!(
        report["min_sensor_difference_relative"].as_f64().unwrap() > 0.1,
        "{report}"
    );
    // The invariance stage's writer: beside the report, what was compared per
    // environment, as `smspace run` writes it.
    let d1: Array2<f64> = ndarray_npy::read_npy(p.join("invariance-D-1.npy")).unwrap();
    let d3: Array2<f64> = ndarray_npy::read_npy(p.join("invariance-D-3.npy")).unwrap();
    let common = report["common_sets"].as_u64().unwrap() as usize;
    assert_eq!(d1.dim(), (common, common));
    let largest = d1
        .iter()
        .zip(&d3)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(largest < 1e-6, "{largest}");
    let sensors: Array2<f64> = ndarray_npy::read_npy(p.join("invariance-sensors-2.npy")).unwrap();
    assert_eq!(sensors.nrows(), common);

    // --starts traces only the first rows (as `[analysis] invariance_starts`).
    ok(
        p,
        &[
            "invariance",
            "--agent",
            "toy-redundant",
            "--motors",
            "motors.npy",
            "--env-seeds",
            "1,2",
            "--starts",
            "5",
            "--points",
            "20",
            "--out",
            "five.json",
        ],
    );
    let five: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p.join("five.json")).unwrap()).unwrap();
    assert_eq!(five["starts"], 5, "{five}");
    let err = fails(
        p,
        &[
            "invariance",
            "--agent",
            "toy-redundant",
            "--motors",
            "motors.npy",
            "--env-seeds",
            "1,2",
            "--starts",
            "0",
            "--out",
            "zero.json",
        ],
    );
    assert!(err.contains("--starts 0"), "{err}");

    let args = |seeds: &'static str, lights: &'static str| {
        vec![
            "invariance",
            "--agent",
            "toy-redundant",
            "--motors",
            "motors.npy",
            "--env-seeds",
            seeds,
            "--lights",
            lights,
            "--out",
            "x.json",
        ]
    };
    let err = fails(p, &args("1", "5"));
    assert!(err.contains("at least two seeds"), "{err}");
    let err = fails(p, &args("1,2", "5,6,7"));
    assert!(err.contains("--lights"), "{err}");
    let err = fails(p, &args("1,2", "0"));
    assert!(err.contains("lights = 0"), "{err}");
    let err = fails(p, &args("1,x", "5"));
    assert!(err.contains("x"), "{err}");
    // The metric is built as smspace distances builds it: any registered name, its
    // parameters, and the period resolved against the agent as a run resolves it.
    let with = |extra: &[&'static str]| {
        let mut all = args("1,2", "5");
        all.extend_from_slice(extra);
        all
    };
    ok(p, &with(&["--metric", "hausdorff", "--period", "motors"]));
    std::fs::remove_file(p.join("x.json")).unwrap();
    let err = fails(p, &with(&["--metric", "hausdorf"]));
    assert!(err.contains("hausdorf") && err.contains("curve"), "{err}");
    let err = fails(p, &with(&["--period", "2pi,2pi,2pi"]));
    assert!(err.contains("period") && err.contains("motors"), "{err}");
    let err = fails(p, &with(&["--metric", "curve", "--param", "dimension=2"]));
    assert!(err.contains("dimension"), "{err}");
    let err = fails(
        p,
        &[
            "invariance",
            "--agent",
            "planar-arm",
            "--motors",
            "motors.npy",
            "--env-seeds",
            "1,2",
            "--out",
            "x.json",
        ],
    );
    assert!(
        err.contains("motors.npy") && err.contains("(M, 4)"),
        "{err}"
    );
    assert!(!p.join("x.json").exists());
}
