//! A run from a sensorimotor log (`[data]`, issue 16): a log simulated from the agent,
//! a log read from files without any agent, the cache keyed on the files' contents, and
//! the tables a log constrains.

#[path = "common/observe.rs"]
mod observe;

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3};
use ndarray_npy::{read_npy, write_npy};
use observe::{computed, Quiet};
use serde_json::Value;
use smspace::agent::{AgentConfig, EnvironmentConfig};
use smspace::learn::{simulate, SimulateParams};
use smspace_pipeline::{Recompute, RunOptions, RunSummary};

/// The redundant toy (sensors read `x = m1 + m2`), its sets traced on a law learned
/// from a log of 5000 samples it simulates.
const SIMULATED_SOURCE: &str = r#"
[agent]
kind = "toy-redundant"

[environment]
lights = 5
seed = 1

[data.simulate]
samples = 5000
relative_noise = 0.0
seed = 4
"#;

/// The same, from the files `log/motors.npy` and `log/sensors.npy` and no `[agent]`.
const FILES_SOURCE: &str = r#"
[data]
motors = ["log/motors.npy"]
sensors = ["log/sensors.npy"]
period = "none"
"#;

/// The stages' tables both experiments share.
const STAGES: &str = r#"
[exploration]
n = 40
seed = 2

[kernel]
method = "sensory"
points = 16
closure_tolerance = 0.03
max_steps = 3000
piece_starts = 0

[metric]
period = "none"

[embedding]
method = "mds"
dim = 1

[analysis]
max_homology_dim = 1

[report]
formats = "svg"
sample_configurations = 3
sample_sets = 3
"#;

fn simulated() -> String {
    format!("{SIMULATED_SOURCE}{STAGES}")
}

fn from_files() -> String {
    format!("{FILES_SOURCE}{STAGES}")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn check(file: &Path, overrides: &[&str]) -> Result<smspace_pipeline::Plan, String> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let loaded =
        smspace_pipeline::config::load_experiment(file, &overrides).map_err(|e| e.to_string())?;
    smspace_pipeline::check(&loaded).map_err(|e| e.to_string())
}

fn run(file: &Path, out: &Path) -> RunSummary {
    let plan = check(file, &[]).unwrap_or_else(|e| panic!("{e}"));
    let options = RunOptions {
        out_dir: out.to_owned(),
        recompute: Recompute::Changed,
        memory_limit_bytes: None,
        busy: smspace_pipeline::BusyFolder::Refuse,
    };
    smspace_pipeline::run(&plan, &options, &Quiet).unwrap_or_else(|e| panic!("{e}"))
}

/// Every kept set keeps `m1 + m2` of its start (the toy's kernel) to `tolerance`.
fn sets_follow_the_kernel(out: &Path, tolerance: f64) -> usize {
    let sets: Array3<f64> = read_npy(out.join("sets.npy")).unwrap();
    let kept: ndarray::Array1<i64> = read_npy(out.join("sets.kept.npy")).unwrap();
    let motors: Array2<f64> = read_npy(out.join("motors.npy")).unwrap();
    assert_eq!(sets.dim().0, kept.len());
    for (set, &row) in sets.outer_iter().zip(kept.iter()) {
        let x = motors[[row as usize, 0]] + motors[[row as usize, 1]];
        for p in set.outer_iter() {
            assert!(
                (p[0] + p[1] - x).abs() < tolerance,
                "{} vs {x}",
                p[0] + p[1]
            );
        }
    }
    kept.len()
}

fn law_report(out: &Path) -> Value {
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sets.trace.json")).unwrap())
            .unwrap();
    assert_eq!(report["agent"], "learned");
    report["law"].clone()
}

#[test]
fn a_simulated_log_is_learned_and_traced_with_the_agent_as_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "simulated.toml", &simulated());
    let out = dir.path().join("run");
    let summary = run(&file, &out);
    let kept = sets_follow_the_kernel(&out, 0.05);
    assert!(kept >= 30, "{kept} of 40 sets kept");
    let law = law_report(&out);
    assert_eq!(law["rank"], 1, "{law}");
    assert!(law["logs"][0]["held_out_relative_rms"].as_f64().unwrap() < 0.05);
    // The references are 40 distinct samples, and their poses the agent's.
    let poses: Array2<f64> = read_npy(out.join("poses.npy")).unwrap();
    assert_eq!(poses.nrows(), 40);
    let probes: Array2<i64> = read_npy(out.join("probes.npy")).unwrap();
    assert!(probes.iter().all(|&p| p == -1));
    // One segment of sets: one component, agreeing with the poses.
    assert_eq!(summary.analysis.betti[0], 1);
    // The learned sets against the agent's own through the same starts: every kept set
    // compared, and close (the curve metric, radians).
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sets.trace.json")).unwrap())
            .unwrap();
    let truth = &report["summary"]["truth"];
    assert_eq!(truth["compared"].as_u64(), Some(kept as u64), "{truth}");
    let (median, p90) = (
        truth["median"].as_f64().unwrap(),
        truth["p90"].as_f64().unwrap(),
    );
    assert!(median <= p90 && p90 < 0.1, "{truth}");
    // The report names the law and its held-out error.
    let markdown = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        markdown.contains("learned law (method, rank of its Jacobian)")
            && markdown.contains("invariants, rank 1")
            && markdown.contains("held-out error of the law"),
        "{markdown}"
    );
    let again = run(&file, &out);
    assert!(computed(&again).is_empty(), "{:?}", computed(&again));
}

#[test]
fn logged_files_need_no_agent_and_key_the_run_by_their_contents() {
    let dir = tempfile::tempdir().unwrap();
    let agent = AgentConfig::preset("toy-redundant")
        .unwrap()
        .build()
        .unwrap();
    let params = SimulateParams {
        samples: 5000,
        noise: 0.0,
        seed: 4,
        ..SimulateParams::default()
    };
    let environment = EnvironmentConfig::default().build(agent.as_ref()).unwrap();
    let log = simulate(agent.as_ref(), &environment, None, &params).unwrap();
    std::fs::create_dir(dir.path().join("log")).unwrap();
    write_npy(dir.path().join("log/motors.npy"), &log.motors).unwrap();
    write_npy(dir.path().join("log/sensors.npy"), &log.sensors).unwrap();
    let file = write(dir.path(), "files.toml", &from_files());
    let out = dir.path().join("run");
    let summary = run(&file, &out);
    assert!(sets_follow_the_kernel(&out, 0.05) >= 30);
    assert_eq!(law_report(&out)["rank"], 1);
    assert!(!out.join("poses.npy").exists(), "no agent, no ground truth");
    let report = std::fs::read_to_string(out.join("sets.trace.json")).unwrap();
    assert!(!report.contains("\"truth\""), "files have no true sets");
    assert_eq!(summary.analysis.betti[0], 1);
    // The references are rows of the log.
    let motors: Array2<f64> = read_npy(out.join("motors.npy")).unwrap();
    for row in motors.outer_iter() {
        assert!(log.motors.outer_iter().any(|r| r == row));
    }
    // Unchanged files: nothing recomputed. A changed log: everything from explore on.
    assert!(computed(&run(&file, &out)).is_empty());
    let mut sensors = log.sensors.clone();
    sensors[[0, 0]] += 1e-3;
    write_npy(dir.path().join("log/sensors.npy"), &sensors).unwrap();
    let changed = computed(&run(&file, &out));
    assert!(
        changed.contains(&"explore".to_owned()) && changed.contains(&"trace".to_owned()),
        "{changed:?}"
    );
}

#[test]
fn a_log_constrains_the_tables_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "simulated.toml", &simulated());
    let cases: [(&[&str], &str); 6] = [
        (&["kernel.method=kinematic"], "method = \"sensory\""),
        (&["data.law.rank=0"], "rank = 0: must be at least 1"),
        (&["data.law.rank=2"], "must be in 1..=1 for 2 motors"),
        (&["exploration.probes=grid"], "probes = \"none\""),
        (&["exploration.n=6000"], "choose 1 to 5000"),
        (
            &["data.motors=[\"m.npy\"]", "data.sensors=[\"s.npy\"]"],
            "not both",
        ),
    ];
    for (overrides, expected) in cases {
        let error = match check(&file, overrides) {
            Ok(plan) => {
                // `n` is checked against the log when the references are picked.
                let options = RunOptions {
                    out_dir: dir.path().join("bad"),
                    recompute: Recompute::Changed,
                    memory_limit_bytes: None,
                    busy: smspace_pipeline::BusyFolder::Refuse,
                };
                smspace_pipeline::run(&plan, &options, &Quiet)
                    .map(|_| ())
                    .map_err(|e| e.to_string())
                    .expect_err("a bad table must fail")
            }
            Err(e) => e,
        };
        assert!(error.contains(expected), "{overrides:?}: {error}");
    }
    // Files that do not exist, and no source at all.
    let missing = write(dir.path(), "missing.toml", &from_files());
    let error = check(&missing, &[]).unwrap_err();
    assert!(error.contains("log/motors.npy"), "{error}");
    let none = write(
        dir.path(),
        "none.toml",
        &from_files().replace(
            "motors = [\"log/motors.npy\"]\nsensors = [\"log/sensors.npy\"]\n",
            "",
        ),
    );
    let error = check(&none, &[]).unwrap_err();
    assert!(error.contains("[data.simulate]"), "{error}");
    // A simulated log needs an agent.
    let no_agent = write(
        dir.path(),
        "no-agent.toml",
        &simulated().replace("[agent]\nkind = \"toy-redundant\"\n", ""),
    );
    let error = check(&no_agent, &[]).unwrap_err();
    assert!(error.contains("[agent]"), "{error}");
}
