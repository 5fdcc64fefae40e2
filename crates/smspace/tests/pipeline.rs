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

/// Which stages a run computed (the others were read back).
fn computed(summary: &RunSummary) -> Vec<String> {
    summary
        .manifest
        .stages
        .iter()
        .filter(|s| !s.cached)
        .map(|s| s.stage.clone())
        .collect()
}

/// Which stages the manifest in `out` records as computed by the run that wrote it.
fn computed_on_disk(out: &Path) -> Vec<String> {
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
    assert_eq!(computed(&summary).len(), 7, "every stage ran once");
    assert_eq!(computed_on_disk(&out).len(), 7);
    // Run again: nothing is computed, and the summary is the same.
    let again = run(&file, &out, &[]);
    assert!(computed(&again).is_empty(), "{:?}", computed(&again));
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
        let changed = run(&file, &out, &[overriding]);
        let ran = computed(&changed);
        assert_eq!(computed_on_disk(&out), ran, "the manifest records that run");
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

/// Runs the experiment `file` into `out` with `overrides` and the run-wide memory
/// limit `limit`; the error, if any.
fn try_run(
    file: &Path,
    out: &Path,
    overrides: &[&str],
    limit: Option<u64>,
) -> Result<RunSummary, pipeline::PipelineError> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let loaded = smspace::config::load_experiment(file, &overrides).unwrap();
    let plan = pipeline::check(&loaded).unwrap_or_else(|e| panic!("{e}"));
    let options = RunOptions {
        out_dir: out.to_owned(),
        recompute: Recompute::Changed,
        memory_limit_bytes: limit,
        busy: smspace::pipeline::BusyFolder::Refuse,
    };
    pipeline::run(&plan, &options, &Quiet)
}

/// Every file under `dir`, with what any write would change: its length, its
/// modification time and (on Unix) its inode, which an atomic rename replaces.
fn snapshot(dir: &Path) -> Vec<(PathBuf, u64, std::time::SystemTime, u64)> {
    let mut files = Vec::new();
    let mut folders = vec![dir.to_owned()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let entry = entry.unwrap();
            let meta = entry.metadata().unwrap();
            if meta.is_dir() {
                folders.push(entry.path());
                continue;
            }
            #[cfg(unix)]
            let inode = std::os::unix::fs::MetadataExt::ino(&meta);
            #[cfg(not(unix))]
            let inode = 0;
            files.push((entry.path(), meta.len(), meta.modified().unwrap(), inode));
        }
    }
    files.sort();
    files
}

/// Makes every file and folder under `dir` read-only, or writable again.
fn set_read_only(dir: &Path, read_only: bool) {
    let mut folders = vec![dir.to_owned()];
    let mut paths = Vec::new();
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                folders.push(path.clone());
            }
            paths.push(path);
        }
    }
    paths.push(dir.to_owned());
    // Folders last when locking (their entries must still be reachable), first when
    // unlocking.
    if !read_only {
        paths.reverse();
    }
    for path in paths {
        let mut permissions = std::fs::metadata(&path).unwrap().permissions();
        #[allow(
            clippy::permissions_set_readonly_false,
            reason = "the test's own temporary folder, made writable again to delete it"
        )]
        permissions.set_readonly(read_only);
        std::fs::set_permissions(&path, permissions).unwrap();
    }
}

#[test]
fn a_finished_run_is_reused_from_a_read_only_folder_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let out = dir.path().join("run");
    run(&file, &out, &[]);
    let before = snapshot(&out);
    set_read_only(&out, true);
    // Root may write anyway: then the snapshot is what shows that nothing was written.
    let truly_read_only = std::fs::write(out.join("probe"), b"").is_err();
    let again = try_run(&file, &out, &[], None);
    let changed = try_run(&file, &out, &["report.sample_sets=2"], None);
    set_read_only(&out, false);
    let again = again.unwrap_or_else(|e| panic!("{e}"));
    assert!(computed(&again).is_empty(), "{:?}", computed(&again));
    if truly_read_only {
        // A run that has to compute something says why it cannot, writing nothing.
        let err = changed.unwrap_err();
        assert!(
            matches!(err, pipeline::PipelineError::ReadOnly { .. }),
            "{err}"
        );
        let message = err.to_string();
        assert!(
            message.contains("stage `report` must be computed") && message.contains("--out"),
            "{message}"
        );
        assert_eq!(snapshot(&out), before);
    } else {
        eprintln!("note: the folder stays writable for this user (root): only the absence of writes is checked");
        let _ = std::fs::remove_file(out.join("probe"));
        let after = snapshot(&out);
        assert_ne!(after, before, "the changed run wrote its report");
        // Back to the first settings: the report is recomputed, then nothing again.
        run(&file, &out, &[]);
        let before = snapshot(&out);
        run(&file, &out, &[]);
        assert_eq!(snapshot(&out), before);
        return;
    }
    assert_eq!(snapshot(&out), before, "a reused run writes nothing");
}

/// Every stage's outputs of two run folders, byte for byte: every file but the
/// manifest and `report.html`/`report.md` (they hold the run's timings).
fn assert_same_outputs(expected: &Path, found: &Path, case: &str) {
    let names = |dir: &Path| -> Vec<PathBuf> {
        snapshot(dir)
            .into_iter()
            .map(|(path, ..)| path.strip_prefix(dir).unwrap().to_owned())
            .filter(|p| {
                !["manifest.json", "report.html", "report.md"]
                    .iter()
                    .any(|skip| p == Path::new(skip))
            })
            .collect()
    };
    let listed = names(expected);
    assert_eq!(listed, names(found), "{case}: the files differ");
    for name in listed {
        let a = std::fs::read(expected.join(&name)).unwrap();
        let b = std::fs::read(found.join(&name)).unwrap();
        assert!(a == b, "{case}: {} differs", name.display());
    }
}

/// What a run folder's manifest may say after any interruption: `complete` only
/// next to the configuration it ran.
fn assert_manifest_true_to_its_configuration(out: &Path, case: &str) {
    let Ok(text) = std::fs::read_to_string(out.join("manifest.json")) else {
        return;
    };
    let manifest: Value = serde_json::from_str(&text).unwrap();
    if manifest["status"]["state"] == "complete" {
        let config = std::fs::read(out.join("config.resolved.toml")).unwrap();
        assert_eq!(
            manifest["config_hash"].as_str().unwrap(),
            pipeline::manifest::hash_parts(&[&config]),
            "{case}: a complete manifest next to another configuration"
        );
    }
}

/// The variables that make [`aborting_child`] abort.
const ABORT_DIR: &str = "SMSPACE_TEST_ABORT_DIR";
const ABORT_AT: &str = "SMSPACE_TEST_ABORT_AT";

/// Aborts the process (no destructor, no clean-up: as `kill -9` would) at one point.
struct AbortAt(String);

impl RunObserver for AbortAt {
    fn progress(&self) -> &dyn Progress {
        &Silent
    }
    fn stage_started(&self, stage: pipeline::StageId) {
        if self.0 == format!("started:{}", stage.name()) {
            std::process::abort();
        }
    }
    fn stage_finished(
        &self,
        stage: pipeline::StageId,
        _: &pipeline::manifest::StageRecord,
        _: &str,
    ) {
        if self.0 == format!("finished:{}", stage.name()) {
            std::process::abort();
        }
    }
}

/// The child process of [`an_interrupted_run_resumes_to_a_clean_runs_outputs`]: runs
/// the small experiment into `$SMSPACE_TEST_ABORT_DIR` and aborts at
/// `$SMSPACE_TEST_ABORT_AT`: `started:STAGE` (the stages before it recorded) or
/// `finished:STAGE` (its files and record in place).
#[test]
#[ignore = "the aborting child process that an_interrupted_run_resumes_to_a_clean_runs_outputs starts"]
fn aborting_child() {
    let (Some(out), Some(at)) = (std::env::var_os(ABORT_DIR), std::env::var(ABORT_AT).ok()) else {
        panic!("run by an_interrupted_run_resumes_to_a_clean_runs_outputs, with {ABORT_DIR} and {ABORT_AT}");
    };
    let out = PathBuf::from(out);
    let file = experiment(out.parent().unwrap());
    let loaded = smspace::config::load_experiment(&file, &[]).unwrap();
    let plan = pipeline::check(&loaded).unwrap();
    let options = RunOptions {
        out_dir: out,
        recompute: Recompute::Changed,
        memory_limit_bytes: None,
        busy: smspace::pipeline::BusyFolder::Refuse,
    };
    let _ = pipeline::run(&plan, &options, &AbortAt(at.clone()));
    panic!("{at} was never reached");
}

fn copy_folder(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_dir() {
            copy_folder(&entry.path(), &to.join(entry.file_name()));
        } else {
            std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
}

/// A run killed before or after any stage, over a finished run of other settings,
/// leaves a folder whose next run resumes and ends byte for byte as a clean run.
#[test]
fn an_interrupted_run_resumes_to_a_clean_runs_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let clean = dir.path().join("clean");
    run(&file, &clean, &[]);
    // A finished run of other settings (every stage's key differs), which the
    // interrupted run was replacing.
    let other = dir.path().join("other");
    run(&file, &other, &["environment.seed=7"]);
    for stage in pipeline::StageId::ALL {
        for point in ["started", "finished"] {
            let case = format!("{point}:{}", stage.name());
            let work = dir.path().join(case.replace(':', "-"));
            copy_folder(&other, &work);
            let child = std::process::Command::new(std::env::current_exe().unwrap())
                .args(["aborting_child", "--exact", "--ignored", "--test-threads=1"])
                .env(ABORT_DIR, &work)
                .env(ABORT_AT, &case)
                .output()
                .unwrap();
            #[cfg(unix)]
            assert_eq!(
                std::os::unix::process::ExitStatusExt::signal(&child.status),
                Some(6),
                "{case}: the child did not abort there: {}",
                String::from_utf8_lossy(&child.stderr)
            );
            assert!(!child.status.success(), "{case}");
            assert_manifest_true_to_its_configuration(&work, &case);
            let resumed = run(&file, &work, &[]);
            // What was finished before the interruption is not computed again.
            let done = pipeline::StageId::ALL
                .iter()
                .position(|s| *s == stage)
                .unwrap()
                + usize::from(point == "finished");
            for earlier in &pipeline::StageId::ALL[..done] {
                assert!(
                    !computed(&resumed).iter().any(|s| s == earlier.name()),
                    "{case}: {} was computed again",
                    earlier.name()
                );
            }
            assert_same_outputs(&clean, &work, &case);
            assert!(
                snapshot(&work)
                    .iter()
                    .all(|(p, ..)| !p.to_string_lossy().ends_with(".part")),
                "{case}: temporary files left"
            );
        }
    }
}

/// Makes `name` in `out` a folder, so that the next write of that file fails (after
/// the other files of its stage were written in full).
fn block(out: &Path, name: &str) {
    let path = out.join(name);
    std::fs::remove_file(&path).unwrap();
    std::fs::create_dir(&path).unwrap();
    std::fs::write(path.join("in-the-way"), b"").unwrap();
}

#[test]
fn the_invariance_and_report_files_appear_together_or_not_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let out = dir.path().join("run");
    run(&file, &out, &[]);
    for (overriding, blocked, stage, kept) in [
        (
            "analysis.invariance_starts=10",
            "invariance-sensors-2.npy",
            "invariance",
            &[
                "invariance.json",
                "invariance-D-1.npy",
                "invariance-D-2.npy",
            ][..],
        ),
        (
            "report.sample_sets=2",
            "report.md",
            "report",
            &[
                "report.html",
                "report.json",
                "figures/fig2-kernel-lines.png",
            ][..],
        ),
    ] {
        assert!(out.join(kept[2]).is_file(), "{} is not an output", kept[2]);
        let before: Vec<Vec<u8>> = kept
            .iter()
            .map(|f| std::fs::read(out.join(f)).unwrap())
            .collect();
        block(&out, blocked);
        let err = try_run(&file, &out, &[overriding], None).unwrap_err();
        assert!(
            err.to_string().contains(&format!("stage `{stage}` failed")),
            "{err}"
        );
        for (f, old) in kept.iter().zip(&before) {
            assert!(
                &std::fs::read(out.join(f)).unwrap() == old,
                "{f} was replaced although {blocked} could not be"
            );
        }
        std::fs::remove_dir_all(out.join(blocked)).unwrap();
        run(&file, &out, &[]);
    }
}

#[test]
fn every_stage_is_held_to_the_memory_limit_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let file = experiment(dir.path());
    let out = dir.path().join("run");
    // The experiment's own limit of the distance matrix is honoured.
    let err = try_run(&file, &out, &["metric.memory_limit_bytes=1000"], None).unwrap_err();
    assert!(err.to_string().contains("stage `distances`"), "{err}");
    // The run's limit: every stage is estimated; the first one that does not fit is
    // refused before it starts, naming what to lower.
    let full = run(&file, &out, &["analysis.max_points=300"]);
    assert!(full.manifest.stages.len() == 7);
    let mut refused = Vec::new();
    for limit in [30_000, 300_000, 1_000_000, 3_000_000, 10_000_000] {
        let fresh = dir.path().join(format!("limit-{limit}"));
        match try_run(&file, &fresh, &[], Some(limit)) {
            Ok(_) => break,
            Err(err) => {
                let message = err.to_string();
                assert!(
                    matches!(err, pipeline::PipelineError::OutOfMemory { .. }),
                    "{message}"
                );
                assert!(message.contains("lower"), "{message}");
                refused.push(message);
            }
        }
    }
    assert!(!refused.is_empty(), "no limit was too small");
}
