//! Runs the `smspace` binary on small inputs in a temporary folder, bad inputs included.

mod common;

use std::path::PathBuf;

use ndarray::{Array1, Array2, Array3};
use ndarray_npy::{read_npy, write_npy};

use common::{fails, ok, stderr};

fn temp() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().to_owned();
    (dir, path)
}

#[test]
fn explore_then_trace_the_arm() {
    let (_guard, dir) = temp();
    ok(
        &dir,
        &[
            "explore",
            "--agent",
            "planar-arm",
            "--n",
            "30",
            "--seed",
            "1",
            "--out-dir",
            "run",
            "--probes",
            "--probe-positions",
            "2",
            "--probe-orientations",
            "3",
        ],
    );
    let motors: Array2<f64> = read_npy(dir.join("run/motors.npy")).unwrap();
    let poses: Array2<f64> = read_npy(dir.join("run/poses.npy")).unwrap();
    let probes: Array2<i64> = read_npy(dir.join("run/probes.npy")).unwrap();
    assert_eq!(motors.dim(), (30 + 12, 4));
    assert_eq!(poses.dim(), (42, 3));
    assert_eq!(probes.row(41).to_vec(), vec![2, 1, 1]);
    assert_eq!(probes.row(0).to_vec(), vec![-1, -1, -1]);

    let stderr = stderr(&ok(
        &dir,
        &[
            "--threads",
            "2",
            "trace",
            "--agent",
            "planar-arm",
            "--motors",
            "run/motors.npy",
            "--method",
            "kinematic",
            "--points",
            "20",
            "--step-control",
            "adaptive",
            "--out",
            "run/sets.npy",
        ],
    ));
    assert!(stderr.contains("traced 42 of 42 sets"), "{stderr}");
    let sets: Array3<f64> = read_npy(dir.join("run/sets.npy")).unwrap();
    assert_eq!(sets.dim(), (42, 20, 4));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("run/sets.trace.json")).unwrap()).unwrap();
    assert_eq!(report["summary"]["traced"], 42);
    assert_eq!(report["sets"][0]["status"], "closed");
    // One writer for the trace outputs: the kept rows are written even when every set
    // was traced, as the pipeline does.
    let kept: Array1<i64> = read_npy(dir.join("run/sets.kept.npy")).unwrap();
    assert_eq!(kept.to_vec(), (0..42).collect::<Vec<i64>>());
    assert!(dir.join("run/sets.closed.npy").is_file());
}

#[test]
fn sensory_tracing_with_a_blind_environment_reports_failures() {
    let (_guard, dir) = temp();
    ok(&dir, &["explore", "--n", "6", "--out-dir", "."]);
    // A rich random environment traces most sets.
    let stderr = stderr(&ok(
        &dir,
        &[
            "trace",
            "--motors",
            "motors.npy",
            "--method",
            "sensory",
            "--env-seed",
            "2",
            "--points",
            "10",
            "--out",
            "sets.npy",
        ],
    ));
    assert!(stderr.contains("of 6 sets"), "{stderr}");
    // One light behind the base: nothing can be traced; the command says why.
    std::fs::write(dir.join("dark.json"), r#"{"lights": [[-3.0, 0.0]]}"#).unwrap();
    let stderr = fails(
        &dir,
        &[
            "trace",
            "--motors",
            "motors.npy",
            "--method",
            "sensory",
            "--env",
            "dark.json",
            "--out",
            "dark.npy",
        ],
    );
    assert!(stderr.contains("singular"), "{stderr}");
    assert!(!dir.join("dark.npy").exists());
}

#[test]
fn failed_sets_are_left_out_and_indexed() {
    let (_guard, dir) = temp();
    // Row 1 is the stretched arm: outside the working space.
    let motors = ndarray::array![
        [0.3, -1.0, 0.9, 0.2],
        [0.0, 0.0, 0.0, 0.0],
        [0.5, -0.9, 0.3, 1.0]
    ];
    write_npy(dir.join("m.npy"), &motors).unwrap();
    let stderr = stderr(&ok(
        &dir,
        &[
            "trace",
            "--motors",
            "m.npy",
            "--points",
            "8",
            "--step-control",
            "adaptive",
            "--workspace",
            "none",
            "--out",
            "s.npy",
        ],
    ));
    assert!(stderr.contains("1 failed"), "{stderr}");
    let kept: Array1<i64> = read_npy(dir.join("s.kept.npy")).unwrap();
    assert_eq!(kept.to_vec(), vec![0, 2]);
    let sets: Array3<f64> = read_npy(dir.join("s.npy")).unwrap();
    assert_eq!(sets.dim(), (2, 8, 4));
}

#[test]
fn toy_agents_environments_and_sensing() {
    let (_guard, dir) = temp();
    ok(
        &dir,
        &[
            "explore",
            "--agent",
            "toy-redundant",
            "--n",
            "5",
            "--out-dir",
            "toy",
        ],
    );
    ok(
        &dir,
        &[
            "trace",
            "--agent",
            "toy-redundant",
            "--motors",
            "toy/motors.npy",
            "--points",
            "7",
            "--out",
            "toy/sets.npy",
        ],
    );
    let sets: Array3<f64> = read_npy(dir.join("toy/sets.npy")).unwrap();
    let motors: Array2<f64> = read_npy(dir.join("toy/motors.npy")).unwrap();
    for (set, m) in sets.outer_iter().zip(motors.outer_iter()) {
        for p in set.outer_iter() {
            assert!((p[0] + p[1] - m[0] - m[1]).abs() < 1e-9);
        }
    }
    ok(
        &dir,
        &[
            "env",
            "--agent",
            "toy-line",
            "--env-seed",
            "4",
            "--out",
            "e.json",
        ],
    );
    let env: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("e.json")).unwrap()).unwrap();
    assert_eq!(env["lights"].as_array().unwrap().len(), 5);
    write_npy(dir.join("line.npy"), &ndarray::array![[0.0], [1.0]]).unwrap();
    ok(
        &dir,
        &[
            "sense", "--agent", "toy-line", "--motors", "line.npy", "--env", "e.json", "--out",
            "s.npy",
        ],
    );
    let s: Array2<f64> = read_npy(dir.join("s.npy")).unwrap();
    assert_eq!(s.dim(), (2, 2));
    assert!(s.iter().all(|v| v.is_finite() && *v > 0.0));
}

#[test]
fn agent_from_a_toml_file() {
    let (_guard, dir) = temp();
    std::fs::write(
        dir.join("arm.toml"),
        "[agent]\nkind = \"planar-arm\"\nlink_lengths = [1.0, 1.0, 1.0]\nretina_cells = 8\n[environment]\nlights = 12\nseed = 5\n",
    )
    .unwrap();
    ok(&dir, &["env", "--agent", "arm.toml", "--out", "e.json"]);
    let env: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("e.json")).unwrap()).unwrap();
    assert_eq!(env["lights"].as_array().unwrap().len(), 12);
    assert_eq!(env["seed"], 5);
}

#[test]
fn a_failing_command_leaves_its_earlier_outputs_alone() {
    let (_guard, dir) = temp();
    ok(
        &dir,
        &[
            "explore",
            "--agent",
            "planar-arm",
            "--n",
            "3",
            "--seed",
            "1",
            "--out-dir",
            "m",
        ],
    );
    // 254 bytes: a valid name, whose siblings (`<stem>.trace.json`, …) are too long.
    let name = format!("{}.npy", "s".repeat(250));
    std::fs::write(dir.join(&name), b"an earlier output").unwrap();
    let err = fails(
        &dir,
        &[
            "trace",
            "--agent",
            "planar-arm",
            "--motors",
            "m/motors.npy",
            "--out",
            &name,
        ],
    );
    assert!(err.contains("cannot write"), "{err}");
    assert_eq!(
        std::fs::read(dir.join(&name)).unwrap(),
        b"an earlier output"
    );
    let left: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".part"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn bad_inputs_give_clear_errors() {
    let (_guard, dir) = temp();
    let nan = ndarray::array![[0.1, 0.2, f64::NAN, 0.4]];
    write_npy(dir.join("nan.npy"), &nan).unwrap();
    write_npy(dir.join("three.npy"), &ndarray::array![[0.1, 0.2, 0.3]]).unwrap();
    write_npy(dir.join("ints.npy"), &ndarray::array![[1_i64, 2, 3, 4]]).unwrap();
    write_npy(
        dir.join("good.npy"),
        &ndarray::array![[0.3, -1.0, 0.9, 0.2]],
    )
    .unwrap();
    std::fs::write(
        dir.join("bad.toml"),
        "[agent]\nkind = \"planar-arm\"\nlink_lengths = [1.0, -1.0]\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("typo.toml"),
        "[agent]\nkind = \"planar-arm\"\nretina_cell = 6\n",
    )
    .unwrap();
    std::fs::write(dir.join("env.json"), "{\"lights\": [[1.0]]}").unwrap();
    // A header claiming 10^9 × 10^9 float64 over a 64-byte body.
    let mut bomb = b"\x93NUMPY\x01\x00".to_vec();
    let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000, 1000000000), }";
    let header = format!("{header:<117}\n");
    bomb.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bomb.extend_from_slice(header.as_bytes());
    bomb.extend_from_slice(&[0u8; 64]);
    std::fs::write(dir.join("bomb.npy"), bomb).unwrap();
    std::fs::write(dir.join("empty.npy"), b"").unwrap();

    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["embed", "--distances", "bomb.npy", "--out", "y.npy"],
            "not a complete .npy file",
        ),
        (
            vec!["distances", "--sets", "bomb.npy", "--out", "d.npy"],
            "header announces",
        ),
        (
            vec!["distances", "--sets", "empty.npy", "--out", "d.npy"],
            "the file is empty",
        ),
        (
            vec!["trace", "--motors", "missing.npy", "--out", "s.npy"],
            "cannot read missing.npy",
        ),
        (
            vec!["trace", "--motors", "nan.npy", "--out", "s.npy"],
            "non-finite value (NaN) at index (0, 2)",
        ),
        (
            vec!["trace", "--motors", "three.npy", "--out", "s.npy"],
            "three.npy has shape (1, 3), expected (M, 4)",
        ),
        (
            vec!["trace", "--motors", "ints.npy", "--out", "s.npy"],
            "astype(numpy.float64)",
        ),
        (
            vec![
                "trace", "--agent", "octopus", "--motors", "good.npy", "--out", "s.npy",
            ],
            "unknown agent 'octopus'",
        ),
        (
            vec![
                "trace",
                "--method",
                "telepathy",
                "--motors",
                "good.npy",
                "--out",
                "s.npy",
            ],
            "unknown tracing method 'telepathy'",
        ),
        (
            vec![
                "trace", "--points", "0", "--motors", "good.npy", "--out", "s.npy",
            ],
            "points = 0",
        ),
        (
            vec![
                "trace", "--step", "-0.1", "--motors", "good.npy", "--out", "s.npy",
            ],
            "step = -0.1",
        ),
        (
            vec![
                "trace",
                "--sensor-sigma",
                "loud",
                "--motors",
                "good.npy",
                "--out",
                "s.npy",
            ],
            "invalid sensor_sigma 'loud'; use \"auto\" or a standard deviation",
        ),
        (
            vec![
                "trace",
                "--sensor-sigma",
                "-0.1",
                "--motors",
                "good.npy",
                "--out",
                "s.npy",
            ],
            "sensor_sigma = -0.1",
        ),
        (
            vec![
                "trace", "--noise", "0.1", "--motors", "good.npy", "--out", "s.npy",
            ],
            "--noise is now --sensor-sigma",
        ),
        (
            vec!["simulate", "--noise", "0.01", "--out-dir", "log"],
            "write --relative-noise 0.01",
        ),
        (
            vec![
                "trace", "--method", "sensory", "--motors", "good.npy", "--out", "s.npy",
            ],
            "needs an environment",
        ),
        (
            vec![
                "trace", "--method", "sensory", "--env", "env.json", "--motors", "good.npy",
                "--out", "s.npy",
            ],
            "env.json is not a valid environment file",
        ),
        (
            vec![
                "trace", "--agent", "bad.toml", "--motors", "good.npy", "--out", "s.npy",
            ],
            "link_lengths = -1",
        ),
        (
            vec![
                "trace",
                "--agent",
                "typo.toml",
                "--motors",
                "good.npy",
                "--out",
                "s.npy",
            ],
            "retina_cell",
        ),
        (vec!["explore", "--n", "0", "--out-dir", "x"], "n = 0"),
        (
            vec!["explore", "--workspace", "1,2,3", "--out-dir", "x"],
            "CX,CY,DEPTH,WIDTH",
        ),
        (
            vec!["explore", "--workspace", "1,2,0,1", "--out-dir", "x"],
            "greater than zero",
        ),
        (
            vec![
                "explore",
                "--workspace",
                "9,0,1,1",
                "--n",
                "3",
                "--out-dir",
                "x",
            ],
            "working space",
        ),
        (
            vec!["--threads", "0", "env", "--out", "e.json"],
            "--threads must be at least 1",
        ),
        (
            vec!["--threads", "100000", "env", "--out", "e.json"],
            "per core",
        ),
        (
            vec![
                "explore",
                "--agent",
                "planar-arm",
                "--n",
                "1000",
                "--max-memory",
                "1000",
                "--out-dir",
                "x",
            ],
            "the explored configurations need 78.1 KiB but only 1000 B is available",
        ),
        (
            vec![
                "trace",
                "--agent",
                "planar-arm",
                "--motors",
                "good.npy",
                "--max-memory",
                "1000",
                "--out",
                "s.npy",
            ],
            // 100 points × 4 motors in float64 and the piece of every point: 4000 B.
            "the kernel sets need 3.9 KiB",
        ),
    ];
    for (args, expected) in cases {
        let stderr = fails(&dir, &args);
        assert!(
            stderr.contains(expected),
            "smspace {args:?}: expected '{expected}' in: {stderr}"
        );
        assert_eq!(
            stderr.lines().filter(|l| l.starts_with("error")).count(),
            1,
            "{stderr}"
        );
    }
    assert!(!dir.join("s.npy").exists(), "a failed run wrote output");
}

/// What an agent cannot give is refused with a clear error: 2-D kernels (an arm of four
/// links and a retina hinge), a probe grid without a working space.
#[test]
fn what_the_agent_cannot_give_is_refused() {
    let (_guard, dir) = temp();
    std::fs::write(
        dir.join("arm5.toml"),
        "[agent]\nkind = \"planar-arm\"\nlink_lengths = [1.0, 1.0, 1.0, 1.0]\n",
    )
    .unwrap();
    write_npy(
        dir.join("five.npy"),
        &ndarray::array![[0.3, -1.0, 0.9, 0.2, 0.1]],
    )
    .unwrap();
    // Five motors for a 3-D pose: 2-D kernels, covered and sampled (status covered,
    // a covering radius per set).
    ok(
        &dir,
        &[
            "trace",
            "--agent",
            "arm5.toml",
            "--motors",
            "five.npy",
            "--points",
            "30",
            "--cover-step",
            "0.4",
            "--workspace",
            "none",
            "--out",
            "surface.npy",
        ],
    );
    let report = std::fs::read_to_string(dir.join("surface.trace.json")).unwrap();
    assert!(
        report.contains("\"covered\"") && report.contains("\"covering_radius\""),
        "{report}"
    );
    assert!(dir.join("surface.components.npy").exists());
    // The curve metric reads polylines: on these surfaces `distances` refuses it (its
    // trace report says k = 2) and names the point metric.
    let stderr = fails(
        &dir,
        &[
            "distances",
            "--sets",
            "surface.npy",
            "--metric",
            "curve",
            "--out",
            "d.npy",
        ],
    );
    assert!(
        stderr.contains("k = 2") && stderr.contains("hausdorff"),
        "{stderr}"
    );
    assert!(!dir.join("d.npy").exists());
    let stderr = fails(
        &dir,
        &[
            "explore",
            "--agent",
            "toy-line",
            "--probes",
            "--out-dir",
            "x",
        ],
    );
    assert!(
        stderr.contains("the probe grid needs a working space"),
        "{stderr}"
    );
    assert!(!dir.join("s.npy").exists() && !dir.join("x").exists());
}

#[test]
fn the_version_is_the_workspace_version_and_the_changelog_names_it() {
    let (_dir, dir) = temp();
    let out = ok(&dir, &["--version"]);
    let version = env!("CARGO_PKG_VERSION");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        format!("smspace {version}\n")
    );
    // The newest entry of the changelog is this version.
    let changelog = include_str!("../../../CHANGELOG.md");
    let newest = changelog
        .lines()
        .find_map(|line| line.strip_prefix("## "))
        .expect("CHANGELOG.md has a version heading");
    assert_eq!(newest, version);
}

/// Runs `smspace ARGS` in `dir` with a progress line for every unit of work (stderr is
/// a pipe here, not a terminal).
fn with_progress_lines(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_smspace"))
        .args(args)
        .env("SMSPACE_PROGRESS_INTERVAL", "0")
        .current_dir(dir)
        .output()
        .expect("the binary runs")
}

#[test]
fn tracing_announces_the_kernel_dimension_and_its_time_and_shows_progress_in_a_log() {
    let (_guard, dir) = temp();
    ok(&dir, &["explore", "--n", "8", "--out-dir", "."]);
    let out = with_progress_lines(
        &dir,
        &[
            "--threads",
            "1",
            "trace",
            "--motors",
            "motors.npy",
            "--points",
            "10",
            "--step-control",
            "adaptive",
            "--out",
            "sets.npy",
        ],
    );
    let text = stderr(&out);
    assert!(out.status.success(), "{text}");
    // Before tracing: the kernel dimension (the arm's sets are curves)...
    let dimension = text
        .find("trace: 8 kernel sets of dimension k = 1 (4 motors, Jacobian rank 3): each set is a curve")
        .unwrap_or_else(|| panic!("no kernel dimension in {text}"));
    // ...then the time the rest will take, measured on the first set (one thread).
    let estimate = text
        .find("for the other 7 sets (the first 1 took")
        .unwrap_or_else(|| panic!("no estimate in {text}"));
    assert!(dimension < estimate, "{text}");
    // Not a terminal: plain progress lines instead of a bar, and the stage's end.
    assert!(text.contains("trace: 1 of 8 (12.5 %)"), "{text}");
    assert!(text.contains("trace: 8 of 8 done in"), "{text}");
    assert!(!text.contains('\r'), "a bar was drawn into a log: {text:?}");
}

#[test]
fn a_switch_to_covering_surfaces_is_announced() {
    let (_guard, dir) = temp();
    // Four links and the retina hinge: five motors for a 3-D pose, kernels of k = 2.
    std::fs::write(
        dir.join("arm4.toml"),
        "[agent]\nkind = \"planar-arm\"\nlink_lengths = [1.0, 1.0, 1.0, 1.0]\n",
    )
    .unwrap();
    write_npy(
        dir.join("m.npy"),
        &ndarray::array![[0.1, 0.2, 0.3, 0.4, 0.5], [1.0, -0.5, 0.8, 1.2, -2.0]],
    )
    .unwrap();
    let text = stderr(&ok(
        &dir,
        &[
            "trace",
            "--agent",
            "arm4.toml",
            "--motors",
            "m.npy",
            "--points",
            "20",
            "--cover-step",
            "0.4",
            "--workspace",
            "none",
            "--out",
            "s.npy",
        ],
    ));
    assert!(
        text.contains("trace: 2 kernel sets of dimension k = 2 (5 motors, Jacobian rank 3): each set is a 2-D surface, covered densely (tangent step 0.4 rad"),
        "{text}"
    );
    assert!(text.contains("far longer than curves"), "{text}");
}

#[test]
fn a_trace_that_keeps_too_few_sets_fails_naming_each_status_and_its_remedy() {
    let (_guard, dir) = temp();
    ok(&dir, &["explore", "--n", "4", "--out-dir", "."]);
    // A working space behind the base, where no explored start lies.
    let text = fails(
        &dir,
        &[
            "trace",
            "--motors",
            "motors.npy",
            "--points",
            "8",
            "--workspace=-2,0,0.2,0.2",
            "--out",
            "s.npy",
        ],
    );
    assert!(
        text.contains("only 0 of 4 sets were traced and kept (2 needed"),
        "{text}"
    );
    assert!(
        text.contains("4 outside-workspace (the starts lie outside the working space"),
        "{text}"
    );
    assert!(text.contains("Nothing was written."), "{text}");
    assert!(!dir.join("s.npy").exists());
    // The blind environment: every set singular, with what that suggests.
    std::fs::write(dir.join("dark.json"), r#"{"lights": [[-3.0, 0.0]]}"#).unwrap();
    let text = fails(
        &dir,
        &[
            "trace",
            "--motors",
            "motors.npy",
            "--method",
            "sensory",
            "--env",
            "dark.json",
            "--out",
            "dark.npy",
        ],
    );
    assert!(text.contains("singular (the Jacobian lost rank"), "{text}");
    assert!(text.contains("too few lights in view"), "{text}");
}

#[test]
fn an_output_that_names_an_input_is_refused_before_any_work() {
    let (_guard, dir) = temp();
    std::fs::create_dir(dir.join("log")).unwrap();
    let motors = Array2::from_shape_fn((50, 4), |(i, j)| 0.01 * (i + j) as f64);
    let sensors = Array2::from_shape_fn((50, 3), |(i, j)| (0.1 * (i * j) as f64).sin());
    write_npy(dir.join("log/motors.npy"), &motors).unwrap();
    write_npy(dir.join("log/sensors.npy"), &sensors).unwrap();
    write_npy(dir.join("starts.npy"), &motors).unwrap();
    let before = std::fs::read(dir.join("log/motors.npy")).unwrap();
    let learn = |out: &str| {
        fails(
            &dir,
            &[
                "learn",
                "--motors",
                "log/motors.npy",
                "--sensors",
                "log/sensors.npy",
                "--starts",
                "starts.npy",
                "--out",
                out,
            ],
        )
    };
    // By path, through `..`, by the other inputs, and as a hard link.
    std::fs::hard_link(dir.join("log/sensors.npy"), dir.join("linked.npy")).unwrap();
    for (out, input) in [
        ("log/motors.npy", "--motors"),
        ("log/../log/motors.npy", "--motors"),
        ("log/sensors.npy", "--sensors"),
        ("starts.npy", "--starts"),
        ("linked.npy", "--sensors"),
    ] {
        let err = learn(out);
        assert!(
            err.contains("refusing to write") && err.contains(input) && err.contains("elsewhere"),
            "{out}: {err}"
        );
    }
    assert_eq!(std::fs::read(dir.join("log/motors.npy")).unwrap(), before);
    // A missing output folder is found before learning.
    let err = learn("missing/sets.npy");
    assert!(
        err.contains("does not exist") && err.contains("mkdir"),
        "{err}"
    );
    assert!(!err.contains("learning from"), "{err}");
    // trace and sense alike.
    for command in ["trace", "sense"] {
        let err = fails(
            &dir,
            &[command, "--motors", "starts.npy", "--out", "./starts.npy"],
        );
        assert!(err.contains("the input --motors"), "{command}: {err}");
    }
    assert_eq!(
        read_npy::<_, Array2<f64>>(dir.join("starts.npy")).unwrap(),
        motors
    );
    // A run folder that holds the experiment file.
    std::fs::create_dir(dir.join("run")).unwrap();
    std::fs::write(
        dir.join("run/exp.toml"),
        "name = \"x\"\n[agent]\nkind = \"toy-redundant\"\n",
    )
    .unwrap();
    let err = fails(&dir, &["run", "run/exp.toml", "--out", "run"]);
    assert!(err.contains("holds the input experiment file"), "{err}");
}

#[test]
fn the_learned_route_reads_the_agent_within_its_budget_and_says_so() {
    let (_guard, dir) = temp();
    ok(&dir, &["explore", "--n", "6", "--out-dir", "."]);
    let args = |budget: &'static str| {
        vec![
            "trace",
            "--motors",
            "motors.npy",
            "--method",
            "learned",
            "--budget",
            budget,
            "--rounds",
            "1",
            "--env-seed",
            "1",
            "--points",
            "20",
            "--out",
            "sets.npy",
        ]
    };
    // Too small a budget: refused with the least that works, nothing written.
    let message = fails(&dir, &args("3000"));
    assert!(message.contains("raise budget to at least"), "{message}");
    assert!(!dir.join("sets.npy").exists());
    // No budget: the flag named.
    let message = fails(
        &dir,
        &[
            "trace",
            "--motors",
            "motors.npy",
            "--method",
            "learned",
            "--env-seed",
            "1",
            "--out",
            "sets.npy",
        ],
    );
    assert!(message.contains("--budget ROWS"), "{message}");
    // A budget: the rows spent in the report, never more than the budget.
    let stderr = stderr(&ok(&dir, &args("60000")));
    assert!(stderr.contains("sensor rows read in all"), "{stderr}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("sets.trace.json")).unwrap()).unwrap();
    assert_eq!(report["method"], "learned");
    let rows = &report["budget"]["rows"];
    assert!(rows["total"].as_u64().unwrap() <= 60_000, "{rows}");
    assert_eq!(rows["verify"].as_u64().unwrap() % 10, 0, "{rows}");
    assert!(rows["agent_rank"].as_u64().unwrap() > 0, "{rows}");
    assert_eq!(
        rows["babble"].as_u64().unwrap()
            + rows["agent_rank"].as_u64().unwrap()
            + rows["verify"].as_u64().unwrap(),
        rows["total"].as_u64().unwrap(),
        "{rows}"
    );
    assert!(report["law"].is_object());
    // A [learn] key without a flag, as learn.KEY: read by the table, its domain named.
    let mut bad = args("60000");
    bad.extend(["--param", "learn.first_round=2"]);
    let message = fails(&dir, &bad);
    assert!(message.contains("first_round"), "{message}");
}

#[test]
fn every_kernel_key_is_reachable_as_a_param_and_a_flag_keeps_its_key() {
    let (_guard, dir) = temp();
    ok(&dir, &["explore", "--n", "6", "--out-dir", "."]);
    let trace = |extra: &[&'static str]| {
        let mut args = vec!["trace", "--motors", "motors.npy", "--out", "sets.npy"];
        args.extend_from_slice(extra);
        args
    };
    // Three steps are too few to close a loop: no set is kept, and the run says why.
    let message = fails(&dir, &trace(&["--param", "max_steps=3"]));
    assert!(
        message.contains("max-steps") || message.contains("0 of 6"),
        "{message}"
    );
    assert!(!dir.join("sets.npy").exists());
    ok(
        &dir,
        &trace(&[
            "--param",
            "max_steps=20000",
            "--param",
            "jacobian=\"secant\"",
        ]),
    );
    for (param, expected) in [
        ("no_such_key=1", "no_such_key"),
        ("points=5", "--points"),
        ("max_steps=3", "given twice"),
        ("learn.first_round=0.3", "--method learned only"),
    ] {
        let mut args = trace(&["--param", param]);
        if expected == "given twice" {
            args.extend(["--param", "max_steps=4"]);
        }
        let message = fails(&dir, &args);
        assert!(message.contains(expected), "{param}: {message}");
    }
}

#[test]
fn every_exploration_key_is_reachable_as_a_param() {
    let (_guard, dir) = temp();
    ok(
        &dir,
        &[
            "explore",
            "--n",
            "6",
            "--param",
            "max_draws_per_kept=500",
            "--out-dir",
            ".",
        ],
    );
    let exploration: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("exploration.json")).unwrap())
            .unwrap();
    assert!(exploration.to_string().contains("500"), "{exploration}");
    for (param, expected) in [
        ("max_draws_per_kept=0", "max_draws_per_kept"),
        ("n=3", "--n"),
        ("workspace_size=[1.0, 1.0]", "--workspace"),
        ("no_such_key=1", "no_such_key"),
    ] {
        let message = fails(&dir, &["explore", "--param", param, "--out-dir", "."]);
        assert!(message.contains(expected), "{param}: {message}");
    }
}
