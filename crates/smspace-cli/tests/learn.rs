//! `smspace simulate` and `smspace learn`: a simulated log learned from, the files of
//! `smspace trace`, and bad logs refused with the file and the fix.

mod common;

use std::path::PathBuf;

use ndarray::{Array1, Array2, Array3};
use ndarray_npy::{read_npy, write_npy};

use common::{fails, ok};

/// The first `count` rows of `a`.
fn first_rows(a: &Array2<f64>, count: usize) -> Array2<f64> {
    a.select(ndarray::Axis(0), &(0..count).collect::<Vec<_>>())
}

fn temp() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().to_owned();
    (dir, path)
}

/// Simulates 5000 samples of the redundant toy into `dir/log` (`extra` arguments
/// added) and writes the first 4 of its motor rows to `dir/starts.npy`; returns them.
fn toy_log_and_starts(dir: &std::path::Path, extra: &[&str]) -> Array2<f64> {
    let mut args = vec![
        "simulate",
        "--agent",
        "toy-redundant",
        "--n",
        "5000",
        "--env-seed",
        "3",
        "--out-dir",
        "log",
    ];
    args.extend_from_slice(extra);
    ok(dir, &args);
    let motors: Array2<f64> = read_npy(dir.join("log/motors.npy")).unwrap();
    let starts = first_rows(&motors, 4);
    write_npy(dir.join("starts.npy"), &starts).unwrap();
    starts
}

/// `smspace learn` from the toy log of [`toy_log_and_starts`] through its starts, 20
/// points per set, into `sets.npy`, with `extra` arguments added.
fn learn_toy(extra: &[&str]) -> Vec<String> {
    let mut args = vec![
        "learn",
        "--motors",
        "log/motors.npy",
        "--sensors",
        "log/sensors.npy",
        "--starts",
        "starts.npy",
        "--period",
        "none",
        "--points",
        "20",
        "--out",
        "sets.npy",
    ];
    args.extend_from_slice(extra);
    args.into_iter().map(str::to_owned).collect()
}

/// `ok` with owned arguments.
fn ok_owned(dir: &std::path::Path, args: &[String]) -> std::process::Output {
    ok(dir, &args.iter().map(String::as_str).collect::<Vec<_>>())
}

/// The JSON file `dir/name`.
fn json(dir: &std::path::Path, name: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap()
}

#[test]
fn simulate_then_learn_writes_the_files_of_trace() {
    let (_guard, dir) = temp();
    let starts = toy_log_and_starts(&dir, &["--relative-noise", "0.001"]);
    let motors: Array2<f64> = read_npy(dir.join("log/motors.npy")).unwrap();
    let sensors: Array2<f64> = read_npy(dir.join("log/sensors.npy")).unwrap();
    let poses: Array2<f64> = read_npy(dir.join("log/poses.npy")).unwrap();
    assert_eq!(
        (motors.dim(), sensors.dim(), poses.dim()),
        ((5000, 2), (5000, 2), (5000, 3))
    );
    assert!(dir.join("log/log.json").is_file() && dir.join("log/environment.json").is_file());
    ok_owned(&dir, &learn_toy(&[]));
    let sets: Array3<f64> = read_npy(dir.join("sets.npy")).unwrap();
    let kept: Array1<i64> = read_npy(dir.join("sets.kept.npy")).unwrap();
    assert_eq!(sets.dim().1, 20);
    assert_eq!(sets.dim().0, kept.len());
    // The learned sets keep m1 + m2 of their start (the toy's kernel).
    for (set, &row) in sets.outer_iter().zip(kept.iter()) {
        let x = starts[[row as usize, 0]] + starts[[row as usize, 1]];
        for p in set.outer_iter() {
            assert!((p[0] + p[1] - x).abs() < 0.05, "{} vs {x}", p[0] + p[1]);
        }
    }
    assert_eq!(json(&dir, "sets.trace.json")["agent"], "learned");
    let law = json(&dir, "sets.law.json");
    assert_eq!(law["rank"], 1);
    assert!(law["logs"][0]["held_out_relative_rms"].as_f64().unwrap() < 0.05);
    // Against the true sets through the same starts.
    ok(
        &dir,
        &[
            "trace",
            "--agent",
            "toy-redundant",
            "--motors",
            "starts.npy",
            "--points",
            "20",
            "--out",
            "truth.npy",
        ],
    );
    let out = ok_owned(&dir, &learn_toy(&["--truth-sets", "truth.npy"]));
    let errors = json(&dir, "sets.errors.json");
    let median = errors["median"].as_f64().unwrap();
    assert!(errors["compared"].as_u64().unwrap() >= 1, "{errors}");
    assert!(
        median < 0.05 && errors["p90"].as_f64().unwrap() >= median,
        "{errors}"
    );
    assert!(common::stderr(&out).contains("set error against the truth"));
}

#[test]
fn learn_with_the_invariants_traces_the_lines_and_reports_the_eigenvalues() {
    let (_guard, dir) = temp();
    let starts = toy_log_and_starts(&dir, &[]);
    let learn = |extra: &[&str]| learn_toy(&[&["--method", "invariants"], extra].concat());
    let out = ok_owned(&dir, &learn(&["--verbose"]));
    let text = common::stderr(&out);
    assert!(text.contains("invariants of 8 basis functions"), "{text}");
    // The estimate before it starts, every stage's time, the quality figures.
    assert!(
        text.contains(
            "learning from 5000 samples (1 logs, 2 motors) and tracing 4 sets need about"
        ),
        "{text}"
    );
    for stage in ["log", "noise", "pairs", "basis sums", "held out", "trace"] {
        assert!(
            text.lines().any(|l| l.starts_with(&format!("{stage}: "))),
            "no time for {stage}: {text}"
        );
    }
    assert!(
        text.contains("fitted samples per dimension (of 1)"),
        "{text}"
    );
    assert!(text.contains("% of the curves closed"), "{text}");
    let law = json(&dir, "sets.law.json");
    assert!(
        law["quality"]["closure_rate"].as_f64().unwrap() > 0.5,
        "{law}"
    );
    assert!(
        law["memory"]["log_bytes"].as_u64().unwrap() == 5000 * 4 * 8,
        "{law}"
    );
    let sets: Array3<f64> = read_npy(dir.join("sets.npy")).unwrap();
    let kept: Array1<i64> = read_npy(dir.join("sets.kept.npy")).unwrap();
    assert!(kept.len() >= 3, "{kept}");
    for (set, &row) in sets.outer_iter().zip(kept.iter()) {
        let x = starts[[row as usize, 0]] + starts[[row as usize, 1]];
        for p in set.outer_iter() {
            assert!((p[0] + p[1] - x).abs() < 0.05, "{} vs {x}", p[0] + p[1]);
        }
    }
    let law = json(&dir, "sets.law.json");
    assert_eq!(
        (law["method"].as_str(), law["rank"].as_u64()),
        (Some("invariants"), Some(1))
    );
    assert_eq!(law["invariants"]["features"], 8);
    // Impossible counts are refused with the key.
    let args = learn(&["--invariants", "40"]);
    let e = fails(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("invariants") && e.contains("1..=32"), "{e}");
    let args = learn_toy(&["--method", "neural"]);
    let e = fails(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("local-quadratic or invariants"), "{e}");
}

#[test]
fn a_given_rank_is_used_reported_beside_the_estimate_and_checked() {
    let (_guard, dir) = temp();
    toy_log_and_starts(&dir, &[]);
    let out = ok_owned(&dir, &learn_toy(&["--rank", "1"]));
    let text = common::stderr(&out);
    assert!(
        text.contains("rank: 1 (given; kernels of dimension 1)"),
        "{text}"
    );
    let law = json(&dir, "sets.law.json");
    assert_eq!(law["rank"].as_u64(), Some(1), "{law}");
    assert_eq!(law["rank_source"].as_str(), Some("given"), "{law}");
    let choice = &law["rank_choice"];
    assert_eq!(
        (choice["given"].as_u64(), choice["estimate"].as_u64()),
        (Some(1), Some(1)),
        "{law}"
    );
    // Without it, the estimate and its reason.
    let out = ok_owned(&dir, &learn_toy(&[]));
    let text = common::stderr(&out);
    assert!(text.contains("rank: 1 (the data's spectrum"), "{text}");
    assert_eq!(
        json(&dir, "sets.law.json")["rank_choice"]["given"],
        serde_json::Value::Null
    );
    // Out of 1..=N−1 (2 motors): refused with the key and the kernel dimension.
    for bad in ["0", "2", "7"] {
        let args = learn_toy(&["--rank", bad]);
        let e = fails(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(e.contains("rank") && e.contains(bad), "{e}");
        assert!(e.contains("dimension"), "{e}");
    }
    let args = learn_toy(&["--rank", "2"]);
    let e = fails(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("1..=1 for 2 motors"), "{e}");
}

#[test]
fn bad_logs_name_the_file_and_the_fix() {
    let (_guard, dir) = temp();
    let motors = Array2::from_shape_fn((400, 2), |(i, j)| {
        ((i * 7 + j * 3) % 100) as f64 / 20.0 - 2.5
    });
    let sensors = Array2::from_shape_fn((400, 2), |(i, j)| (i as f64 * 0.1 + j as f64).sin());
    write_npy(dir.join("m.npy"), &motors).unwrap();
    write_npy(dir.join("s.npy"), &sensors).unwrap();
    write_npy(dir.join("starts.npy"), &first_rows(&motors, 2)).unwrap();
    let learn = |m: &str, s: &str, extra: &[&str]| {
        let mut args = vec![
            "learn",
            "--motors",
            m,
            "--sensors",
            s,
            "--starts",
            "starts.npy",
            "--out",
            "sets.npy",
        ];
        args.extend_from_slice(extra);
        // `learn` states its memory before it reads the logs, so the error is the last
        // line rather than the first.
        let out = common::smspace(&dir, &args);
        let text = common::stderr(&out);
        assert!(!out.status.success(), "smspace {args:?} should fail");
        assert!(
            !text.contains("panicked") && !text.contains("RUST_BACKTRACE"),
            "{text}"
        );
        assert!(
            text.lines().any(|line| line.starts_with("error: ")),
            "smspace {args:?}: {text}"
        );
        text
    };
    // Different row counts.
    write_npy(dir.join("short.npy"), &first_rows(&sensors, 399)).unwrap();
    let e = learn("m.npy", "short.npy", &[]);
    assert!(
        e.contains("m.npy has 400 rows but short.npy has 399"),
        "{e}"
    );
    // NaN.
    let mut nan = sensors.clone();
    nan[[5, 0]] = f64::NAN;
    write_npy(dir.join("nan.npy"), &nan).unwrap();
    let e = learn("m.npy", "nan.npy", &[]);
    assert!(e.contains("nan.npy") && e.contains("non-finite"), "{e}");
    // A constant sensor.
    let mut constant = sensors.clone();
    constant.column_mut(1).fill(2.0);
    write_npy(dir.join("constant.npy"), &constant).unwrap();
    let e = learn("m.npy", "constant.npy", &[]);
    assert!(
        e.contains("sensor column 1 of constant.npy is constant"),
        "{e}"
    );
    // Motors outside their declared range.
    let e = learn("m.npy", "s.npy", &["--period=-1:1"]);
    assert!(
        e.contains("m.npy, row") && e.contains("outside its declared range"),
        "{e}"
    );
    // Too few samples for the method.
    write_npy(dir.join("m30.npy"), &first_rows(&motors, 30)).unwrap();
    write_npy(dir.join("s30.npy"), &first_rows(&sensors, 30)).unwrap();
    let e = learn("m30.npy", "s30.npy", &["--period", "none"]);
    assert!(
        e.contains("m30.npy has too few samples (30)") && e.contains("record a longer log"),
        "{e}"
    );
    let e = learn(
        "m30.npy",
        "s30.npy",
        &["--period", "none", "--method", "local-quadratic"],
    );
    assert!(
        e.contains("m30.npy has too few samples (30)") && e.contains("local-linear"),
        "{e}"
    );
    // A bad declaration, mismatched pairs, a missing file.
    let e = learn("m.npy", "s.npy", &["--period", "circle"]);
    assert!(
        e.contains("--period circle") && e.contains("LOW:HIGH"),
        "{e}"
    );
    let e = fails(
        &dir,
        &[
            "learn",
            "--motors",
            "m.npy",
            "--motors",
            "m.npy",
            "--sensors",
            "s.npy",
            "--starts",
            "starts.npy",
            "--out",
            "x.npy",
        ],
    );
    assert!(e.contains("2 --motors files but 1 --sensors"), "{e}");
    let e = learn("missing.npy", "s.npy", &[]);
    assert!(e.contains("missing.npy"), "{e}");
    // Memory, up front.
    let e = learn("m.npy", "s.npy", &["--max-memory", "1000"]);
    assert!(e.contains("--max-memory"), "{e}");
    assert!(!dir.join("sets.npy").exists());
}

#[test]
fn every_law_and_kernel_key_is_reachable_as_a_param() {
    let (_guard, dir) = temp();
    toy_log_and_starts(&dir, &[]);
    let with = |extra: &[&str]| learn_toy(extra);
    ok_owned(
        &dir,
        &with(&["--param", "ridge=1e-6", "--param", "kernel.step=0.002"]),
    );
    for (params, expected) in [
        (vec!["--param", "rigde=1e-6"], "rigde"),
        (vec!["--param", "ridge=-1.0"], "ridge"),
        (vec!["--param", "neighbours=30"], "--neighbours"),
        (vec!["--param", "kernel.points=5"], "--points"),
        (vec!["--param", "kernel.no_such_key=1"], "no_such_key"),
    ] {
        let args = with(&params);
        let message = fails(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(message.contains(expected), "{params:?}: {message}");
    }
}
