//! The pipeline as a library (no command-line tool): a small experiment end to end,
//! and the cache key of every stage.

use std::path::{Path, PathBuf};

use ndarray::Array2;
use ndarray_npy::read_npy;
use serde_json::Value;
use smspace::agent::{
    Agent, AgentError, AgentRegistry, Environment, LightRegion, MotorTopology, Pose,
};
use smspace::pipeline::{self, Recompute, RunObserver, RunOptions, RunSummary};
use smspace::progress::{Progress, Silent};

/// The redundant toy of section 2.3, small, in two environments so that the
/// invariance stage runs too.
const SMALL_TOY: &str = r#"
name = "small-toy"
description = "The redundant toy, small, for the library tests."

[agent]
kind = "toy-redundant"

[environment]
lights = 5
seed = 1

[[environment.compare]]
lights = 4
seed = 2

[exploration]
n = 210
seed = 1

[kernel]
method = "kinematic"
points = 20

[metric]
period = "none"

[embedding]
method = "mds"
dim = 1

[analysis]
max_homology_dim = 1
invariance_starts = 12

[report]
formats = "png"
sample_configurations = 5
sample_sets = 3
"#;

struct Quiet;

impl RunObserver for Quiet {
    fn progress(&self) -> &dyn Progress {
        &Silent
    }
}

fn experiment(dir: &Path) -> PathBuf {
    let path = dir.join("small-toy.toml");
    std::fs::write(&path, SMALL_TOY).unwrap();
    path
}

fn run(file: &Path, out: &Path, overrides: &[&str]) -> RunSummary {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let loaded = smspace::config::load_experiment(file, &overrides).unwrap();
    let plan = pipeline::check(&loaded).unwrap_or_else(|e| panic!("{e}"));
    let options = RunOptions {
        out_dir: out.to_owned(),
        recompute: Recompute::Changed,
        memory_limit_bytes: None,
        busy: smspace::pipeline::BusyFolder::Refuse,
    };
    pipeline::run(&plan, &options, &Quiet).unwrap_or_else(|e| panic!("{e}"))
}

/// Which stages the last run computed (the others were read back).
fn computed(out: &Path) -> Vec<String> {
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    manifest["stages"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["cached"] == false)
        .map(|s| s["stage"].as_str().unwrap().to_owned())
        .collect()
}

#[test]
fn an_experiment_larger_than_memory_is_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let loaded = smspace::config::load_experiment(&file, &[]).unwrap();
    let plan = pipeline::check(&loaded).unwrap();
    let out = dir.path().join("run");
    for (limit, what) in [(100, "explored configurations"), (20_000, "kernel sets")] {
        let options = RunOptions {
            out_dir: out.clone(),
            recompute: Recompute::Changed,
            memory_limit_bytes: Some(limit),
            busy: smspace::pipeline::BusyFolder::Refuse,
        };
        let err = pipeline::run(&plan, &options, &Quiet).unwrap_err();
        assert!(
            matches!(err, smspace::pipeline::PipelineError::OutOfMemory { .. }),
            "{err}"
        );
        assert!(err.to_string().contains(what), "{err}");
        assert!(!out.exists(), "nothing ran, nothing was written");
    }
}

#[test]
fn a_small_experiment_runs_from_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let out = dir.path().join("run");
    let summary = run(&file, &out, &[]);
    assert_eq!(summary.dir, out);
    // The kernel lines m1 + m2 = x give a 1-D manifold of one component.
    assert_eq!(summary.analysis.betti.first(), Some(&1));
    let twonn = summary.analysis.intrinsic_dimension.twonn;
    assert!((0.7..1.4).contains(&twonn), "TwoNN {twonn}");
    let d: Array2<f64> = read_npy(out.join("D.npy")).unwrap();
    let y: Array2<f64> = read_npy(out.join("Y.npy")).unwrap();
    assert_eq!(y.dim(), (d.nrows(), 1));
    assert_eq!(computed(&out).len(), 7, "every stage ran once");
    // Run again: nothing is computed, and the summary is the same.
    let again = run(&file, &out, &[]);
    assert!(computed(&out).is_empty(), "{:?}", computed(&out));
    assert_eq!(again.analysis, summary.analysis);
}

/// Changing a parameter that a stage reads reruns that stage (and what follows it),
/// never the stages before it.
#[test]
fn every_stage_reruns_when_a_parameter_it_reads_changes() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let out = dir.path().join("run");
    run(&file, &out, &[]);
    let dydx_before = std::fs::read(out.join("Y.dydx.npy")).unwrap();
    // (override, the stage it belongs to, stages before it that must be reused)
    let cases: [(&str, &str, &[&str]); 13] = [
        ("environment.seed=7", "explore", &[]),
        ("exploration.seed=2", "explore", &[]),
        ("kernel.points=21", "trace", &["explore"]),
        ("kernel.method=\"sensory\"", "trace", &["explore"]),
        ("metric.period=\"2pi\"", "distances", &["explore", "trace"]),
        (
            "embedding.method=\"isomap\"",
            "embed",
            &["explore", "trace", "distances", "analyze"],
        ),
        (
            "metric.metric=\"mean-hausdorff\"",
            "distances",
            &["explore", "trace"],
        ),
        (
            "embedding.seed=5",
            "embed",
            &["explore", "trace", "distances"],
        ),
        // The dy–dx sample of the embed stage is drawn with the report's seed: it is
        // part of the embed stage's key.
        ("report.seed=2", "embed", &["explore", "trace", "distances"]),
        (
            "analysis.mle_neighbors=6",
            "analyze",
            &["explore", "trace", "distances", "embed"],
        ),
        (
            "analysis.invariance_starts=10",
            "invariance",
            &["explore", "trace", "distances", "embed"],
        ),
        (
            "report.sample_sets=2",
            "report",
            &[
                "explore",
                "trace",
                "distances",
                "embed",
                "analyze",
                "invariance",
            ],
        ),
        (
            "report.formats=\"svg\"",
            "report",
            &["explore", "trace", "embed"],
        ),
    ];
    for (overriding, stage, reused) in cases {
        // From the base run each time: the override is the only change.
        run(&file, &out, &[]);
        run(&file, &out, &[overriding]);
        let ran = computed(&out);
        assert!(
            ran.iter().any(|s| s == stage),
            "--set {overriding}: {stage} was reused (computed: {ran:?})"
        );
        for before in reused {
            assert!(
                !ran.iter().any(|s| s == before),
                "--set {overriding}: {before} was recomputed (computed: {ran:?})"
            );
        }
        if overriding == "report.seed=2" {
            let dydx = std::fs::read(out.join("Y.dydx.npy")).unwrap();
            assert_ne!(dydx, dydx_before, "the dy–dx sample follows report.seed");
        }
    }
}

/// An agent written outside the crate: a cart on a rail driven by two geared motors
/// (`x = m1 + gear·m2`), with two light sensors on the cart. Its kernel sets are the
/// lines `m1 + gear·m2 = x`: the manifold of sets is 1-D, the cart's position.
#[derive(Debug)]
struct GearedCart {
    gear: f64,
}

/// Its `[agent]` table.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
struct GearedCartParams {
    gear: f64,
}

impl Default for GearedCartParams {
    fn default() -> Self {
        Self { gear: 0.5 }
    }
}

impl Agent for GearedCart {
    fn motor_dim(&self) -> usize {
        2
    }
    fn sensor_dim(&self) -> usize {
        2
    }
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        let x = self.pose(motors).x;
        for (s, offset) in sensors.iter_mut().zip([-0.25, 0.25]) {
            *s = environment
                .lights
                .iter()
                .map(|l| 1.0 / ((l[0] - x - offset).powi(2) + l[1].powi(2)))
                .sum();
        }
    }
    fn pose(&self, motors: &[f64]) -> Pose {
        Pose {
            x: motors[0] + self.gear * motors[1],
            y: 0.0,
            alpha: 0.0,
        }
    }
    fn name(&self) -> &str {
        "geared-cart"
    }
    fn configuration_dim(&self) -> usize {
        1
    }
    fn motor_topology(&self) -> MotorTopology {
        MotorTopology::Bounded {
            low: -1.0,
            high: 1.0,
        }
    }
    fn default_light_region(&self) -> LightRegion {
        LightRegion {
            center: [0.0, 2.0],
            half_size: [3.0, 1.0],
            exclusion_half_size: [0.0, 0.0],
        }
    }
    fn default_light_count(&self) -> usize {
        4
    }
}

#[test]
fn a_user_defined_agent_runs_through_the_whole_pipeline() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cart.toml");
    std::fs::write(
        &file,
        r#"
name = "cart"
[agent]
kind = "geared-cart"
gear = 0.75
[exploration]
n = 120
[kernel]
points = 20
[metric]
period = "none"
[embedding]
method = "mds"
dim = 1
[report]
formats = "png"
sample_configurations = 4
sample_sets = 3
"#,
    )
    .unwrap();
    let loaded = smspace::config::load_experiment(&file, &[]).unwrap();
    // Without its registration the kind is unknown, and the error lists the kinds.
    let err = pipeline::check(&loaded).unwrap_err().to_string();
    assert!(
        err.contains("geared-cart") && err.contains("planar-arm"),
        "{err}"
    );
    let mut agents = AgentRegistry::builtin();
    agents.register_params(
        "geared-cart",
        "a cart on a rail, two geared motors",
        |p: &GearedCartParams| -> Result<Box<dyn Agent>, AgentError> {
            Ok(Box::new(GearedCart { gear: p.gear }))
        },
    );
    let plan = pipeline::check_with(&loaded, &agents).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(plan.agent().name(), "geared-cart");
    let out = dir.path().join("run");
    let options = RunOptions {
        out_dir: out.clone(),
        recompute: Recompute::Changed,
        memory_limit_bytes: None,
        busy: smspace::pipeline::BusyFolder::Refuse,
    };
    let summary = pipeline::run(&plan, &options, &Quiet).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.analysis.betti.first(), Some(&1));
    let twonn = summary.analysis.intrinsic_dimension.twonn;
    assert!((0.7..1.4).contains(&twonn), "TwoNN {twonn}");
    let spearman = summary.analysis.agreement.as_ref().unwrap().spearman;
    assert!(spearman > 0.9, "Spearman {spearman}");
    // The resolved configuration records the kind and its parameter.
    let resolved = std::fs::read_to_string(out.join("config.resolved.toml")).unwrap();
    assert!(resolved.contains("kind = \"geared-cart\"") && resolved.contains("gear = 0.75"));
    assert!(out.join("report.html").is_file());
}
