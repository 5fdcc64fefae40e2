//! `smspace run`: a small experiment end to end, the cache, and bad experiment files.

mod common;

use std::path::{Path, PathBuf};

use common::{fails_with, ok, smspace, stderr};
use ndarray::{Array2, Array3};
use ndarray_npy::read_npy;
use serde_json::Value;

/// A small arm experiment: 150 babbled configurations and a 3 × 3 × 3 probe grid.
const SMALL_ARM: &str = r#"
name = "small-arm"
description = "A small arm run for the tests."

[agent]
kind = "planar-arm"

[environment]
seed = 1

[[environment.compare]]
seed = 2
lights = 8

[exploration]
n = 150
seed = 3
probes = "grid"
probe_positions = 3
probe_orientations = 3

[kernel]
points = 30

[embedding]
method = "cca"
dim = 3
epochs = 10

[analysis]
max_points = 200
invariance_starts = 40

[report]
sample_configurations = 10
sample_sets = 5
formats = "png"
"#;

/// [`SMALL_ARM`] cut down to 40 babbled sets without probes, embedded by MDS in `dim`
/// dimensions.
fn tiny_mds(dim: usize) -> String {
    SMALL_ARM
        .replace("n = 150", "n = 40")
        .replace("probes = \"grid\"", "probes = \"none\"")
        .replace("method = \"cca\"", "method = \"mds\"")
        .replace("epochs = 10\n", "")
        .replace("dim = 3", &format!("dim = {dim}"))
}

fn write_experiment(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn stage<'a>(manifest: &'a Value, name: &str) -> &'a Value {
    manifest["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == name)
        .unwrap_or_else(|| panic!("no stage {name} in {manifest}"))
}

fn in_range(value: &Value, low: f64, high: f64, what: &str) {
    let v = value
        .as_f64()
        .unwrap_or_else(|| panic!("{what} is {value}"));
    assert!(
        (low..=high).contains(&v),
        "{what} = {v} not in [{low}, {high}]"
    );
}

#[test]
fn a_small_experiment_runs_end_to_end_and_is_cached() {
    let dir = tempfile::tempdir().unwrap();
    write_experiment(dir.path(), "small.toml", SMALL_ARM);
    let out = ok(dir.path(), &["run", "small.toml", "--threads", "2"]);
    let log = stderr(&out);
    let run = dir.path().join("runs/small-arm");

    // Every output exists, with the contract's shapes.
    let motors: Array2<f64> = read_npy(run.join("motors.npy")).unwrap();
    assert_eq!(motors.dim(), (150 + 27, 4));
    let poses: Array2<f64> = read_npy(run.join("poses.npy")).unwrap();
    assert_eq!(poses.dim(), (177, 3));
    let probes: Array2<i64> = read_npy(run.join("probes.npy")).unwrap();
    assert_eq!(probes.iter().filter(|&&p| p >= 0).count(), 27 * 3);
    let sets: Array3<f64> = read_npy(run.join("sets.npy")).unwrap();
    let m = sets.dim().0;
    assert!(
        m > 150 && sets.dim().1 == 30 && sets.dim().2 == 4,
        "{:?}",
        sets.dim()
    );
    let d: Array2<f64> = read_npy(run.join("D.npy")).unwrap();
    assert_eq!(d.dim(), (m, m));
    let y: Array2<f64> = read_npy(run.join("Y.npy")).unwrap();
    assert_eq!(y.dim(), (m, 3));
    let dydx: Array2<f64> = read_npy(run.join("Y.dydx.npy")).unwrap();
    assert_eq!(dydx.ncols(), 2);
    for file in [
        "exploration.json",
        "environment.json",
        "environment-2.json",
        "sets.kept.npy",
        "sets.trace.json",
        "Y.embed.json",
        "invariance.json",
        "invariance-D-1.npy",
        "invariance-D-2.npy",
        "config.resolved.toml",
        "report.html",
        "report.md",
        "report.json",
    ] {
        assert!(run.join(file).is_file(), "{file} missing; log: {log}");
    }
    // The embedding report has the format `smspace embed` writes.
    let embed: smspace::embed::EmbedFile =
        serde_json::from_str(&std::fs::read_to_string(run.join("Y.embed.json")).unwrap())
            .expect("Y.embed.json reads as an EmbedFile");
    assert_eq!(embed.report.points, m);
    assert_eq!(embed.dydx.as_ref().map(|s| s.pairs), Some(dydx.nrows()));
    assert!(embed.quality.is_some() && embed.seconds.is_none());
    let figures = std::fs::read_dir(run.join("figures")).unwrap().count();
    assert!(figures >= 5, "only {figures} figures");

    // The report's numbers are in range.
    let analysis = json(&run.join("analysis.json"));
    assert_eq!(analysis["betti"][0], 1, "{}", analysis["betti"]);
    in_range(&analysis["intrinsic_dimension"]["twonn"], 1.5, 5.0, "TwoNN");
    in_range(&analysis["intrinsic_dimension"]["mle"], 1.5, 5.0, "MLE");
    in_range(&analysis["agreement"]["spearman"], 0.3, 1.0, "Spearman");
    in_range(&analysis["agreement"]["trustworthiness"], 0.7, 1.0, "T");
    let invariance = json(&run.join("invariance.json"));
    in_range(&invariance["max_set_distance"], 0.0, 1e-3, "set difference");
    in_range(&invariance["min_mantel"], 0.999, 1.0, "Mantel");
    let markdown = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(markdown.contains("small-arm"), "{markdown}");

    // The manifest: version, seeds, hash, every stage computed once.
    let manifest = json(&run.join("manifest.json"));
    assert_eq!(manifest["status"]["state"], "complete");
    assert_eq!(manifest["seeds"]["exploration"], 3);
    assert_eq!(manifest["config_hash"].as_str().unwrap().len(), 64);
    for name in [
        "explore",
        "trace",
        "distances",
        "embed",
        "analyze",
        "invariance",
        "report",
    ] {
        assert_eq!(stage(&manifest, name)["cached"], false, "{name}");
    }

    // A second run reuses every stage and writes nothing, not even the manifest.
    let before = std::fs::read(run.join("D.npy")).unwrap();
    let manifest_before = std::fs::read(run.join("manifest.json")).unwrap();
    let out = ok(dir.path(), &["run", "small.toml"]);
    let log = stderr(&out);
    assert!(log.contains("0 of 7 stages computed"), "{log}");
    for name in [
        "explore",
        "trace",
        "distances",
        "embed",
        "analyze",
        "report",
    ] {
        assert!(
            log.lines()
                .any(|l| l.contains(&format!("] {name} ")) && l.contains("reused")),
            "{name}: {log}"
        );
    }
    assert_eq!(std::fs::read(run.join("D.npy")).unwrap(), before);
    assert_eq!(
        std::fs::read(run.join("manifest.json")).unwrap(),
        manifest_before
    );

    // A changed embedding parameter recomputes the embedding and what depends on it.
    ok(
        dir.path(),
        &[
            "run",
            "small.toml",
            "--set",
            "embedding.epochs=5",
            "--out",
            "runs/small-arm",
        ],
    );
    let manifest = json(&run.join("manifest.json"));
    for (name, cached) in [
        ("explore", true),
        ("trace", true),
        ("distances", true),
        ("embed", false),
        ("analyze", true),
        ("report", false),
    ] {
        assert_eq!(stage(&manifest, name)["cached"], cached, "{name}");
    }

    // A modified output is noticed and recomputed; --force recomputes everything.
    std::fs::write(run.join("D.npy"), b"not a matrix").unwrap();
    ok(
        dir.path(),
        &[
            "run",
            "small.toml",
            "--set",
            "embedding.epochs=5",
            "--out",
            "runs/small-arm",
        ],
    );
    let manifest = json(&run.join("manifest.json"));
    assert_eq!(stage(&manifest, "trace")["cached"], true);
    assert_eq!(stage(&manifest, "distances")["cached"], false);
    assert_eq!(std::fs::read(run.join("D.npy")).unwrap(), before);
    ok(
        dir.path(),
        &["run", "small.toml", "--force", "--out", "again"],
    );
    let manifest = json(&dir.path().join("again/manifest.json"));
    assert!(manifest["stages"]
        .as_array()
        .unwrap()
        .iter()
        .all(|s| s["cached"] == false));
    // An output in a format this version no longer reads (the hash still matching) is
    // recomputed instead of failing the run.
    let again = dir.path().join("again");
    std::fs::write(
        again.join("Y.embed.json"),
        br#"{"report": {}, "dydx_pairs": 1}"#,
    )
    .unwrap();
    let mut manifest = json(&again.join("manifest.json"));
    let hash = smspace_pipeline::manifest::hash_file(&again.join("Y.embed.json")).unwrap();
    for record in manifest["stages"].as_array_mut().unwrap() {
        if record["stage"] == "embed" {
            record["outputs"]["Y.embed.json"] = serde_json::Value::String(hash.clone());
        }
    }
    std::fs::write(
        again.join("manifest.json"),
        serde_json::to_string(&manifest).unwrap(),
    )
    .unwrap();
    ok(dir.path(), &["run", "small.toml", "--out", "again"]);
    let manifest = json(&again.join("manifest.json"));
    assert_eq!(stage(&manifest, "distances")["cached"], true);
    assert_eq!(stage(&manifest, "embed")["cached"], false);
    let _: smspace::embed::EmbedFile =
        serde_json::from_str(&std::fs::read_to_string(again.join("Y.embed.json")).unwrap())
            .unwrap();
    // The same experiment gives the same arrays in another folder, and with one thread.
    assert_eq!(
        std::fs::read(dir.path().join("again/D.npy")).unwrap(),
        before
    );
    ok(
        dir.path(),
        &["run", "small.toml", "--out", "one-thread", "--threads", "1"],
    );
    for file in [
        "sets.npy",
        "D.npy",
        "Y.npy",
        "analysis.json",
        "invariance.json",
    ] {
        let one = std::fs::read(dir.path().join("one-thread").join(file)).unwrap();
        let many = std::fs::read(dir.path().join("again").join(file)).unwrap();
        assert!(one == many, "{file} differs between 1 thread and 2");
    }
}

#[test]
fn bad_experiment_files_are_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let unknown = SMALL_ARM.replace("points = 30", "points = 30\npoints_per_set = 4");
    write_experiment(d, "unknown.toml", &unknown);
    let err = fails_with(d, &["run", "unknown.toml"], "points_per_set");
    assert!(
        err.contains("unknown.toml") && err.contains("line"),
        "{err}"
    );

    let wrong_type = SMALL_ARM.replace("points = 30", "points = \"thirty\"");
    write_experiment(d, "type.toml", &wrong_type);
    let err = fails_with(d, &["run", "type.toml"], "points");
    assert!(err.contains("type.toml") && err.contains("line"), "{err}");

    let impossible = SMALL_ARM.replace("points = 30", "points = 0");
    write_experiment(d, "impossible.toml", &impossible);
    let line = impossible
        .lines()
        .position(|l| l.trim() == "points = 0")
        .unwrap()
        + 1;
    fails_with(
        d,
        &["run", "impossible.toml"],
        &format!("impossible.toml, line {line}: [kernel]"),
    );
    fails_with(d, &["run", "unknown-table.toml"], "unknown-table.toml");
    write_experiment(
        d,
        "table.toml",
        "[agent]\nkind = \"planar-arm\"\n[embeding]\ndim = 3\n",
    );
    fails_with(d, &["run", "table.toml"], "embeding");
    write_experiment(d, "ok.toml", SMALL_ARM);
    fails_with(
        d,
        &["run", "ok.toml", "--set", "kernel.points=0"],
        "--set kernel.points=0",
    );
    fails_with(d, &["run", "ok.toml", "--set", "kernl.points=3"], "kernl");
    fails_with(
        d,
        &["run", "ok.toml", "--set", "kernel.points"],
        "stage.key=value",
    );
    fails_with(
        d,
        &["run", "ok.toml", "--set", "embedding.method=tsne"],
        "tsne",
    );
    // Sizes past the stated limits are refused before anything is allocated.
    for (set, needle) in [
        (
            "exploration.n=1000000000",
            "at most 100000000 configurations",
        ),
        ("exploration.probe_positions=1000000", "probe grid"),
        ("kernel.points=1000000000000", "at most 100000 points"),
        ("environment.lights=100000000", "at most 2000 random lights"),
        ("agent.retina_cells=1000000000000", "at most 10000"),
        (
            "kernel.piece_starts=1000000000",
            "at most 10000 seeds per set",
        ),
        ("embedding.epochs=4000000000", "at most 100000"),
    ] {
        fails_with(d, &["run", "ok.toml", "--set", set], needle);
    }
    // One set: nothing to compare, said before anything is traced.
    let err = fails_with(
        d,
        &[
            "run",
            "ok.toml",
            "--set",
            "exploration.n=1",
            "--set",
            "exploration.probes=\"none\"",
        ],
        "at least 2 sets",
    );
    assert!(!err.contains("could be traced"), "{err}");
    write_experiment(
        d,
        "newline.toml",
        &SMALL_ARM.replace("name = \"small-arm\"", "name = \"a\\nb\""),
    );
    fails_with(d, &["run", "newline.toml"], "the name becomes the folder");
    // Nothing ran, so nothing was written.
    assert!(!d.join("runs").exists());
}

#[test]
fn a_failing_stage_keeps_the_earlier_outputs_and_names_itself() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // MDS to more dimensions than there are sets fails in the embed stage.
    let text = tiny_mds(60);
    write_experiment(d, "fail.toml", &text);
    let out = smspace(d, &["run", "fail.toml"]);
    let log = stderr(&out);
    assert!(!out.status.success());
    assert!(!log.contains("panicked"), "{log}");
    assert!(log.contains("stage `embed` failed"), "{log}");
    let run = d.join("runs/small-arm");
    assert!(run.join("D.npy").is_file() && run.join("sets.npy").is_file());
    assert!(!run.join("Y.npy").exists());
    let manifest = json(&run.join("manifest.json"));
    assert_eq!(manifest["status"]["state"], "failed");
    assert_eq!(manifest["status"]["stage"], "embed");
    assert_eq!(stage(&manifest, "distances")["cached"], false);
    // Fixing the parameter reuses what was done.
    let out = ok(
        d,
        &[
            "run",
            "fail.toml",
            "--set",
            "embedding.dim=2",
            "--out",
            "runs/small-arm",
        ],
    );
    let log = stderr(&out);
    assert!(log.contains("distances") && log.contains("reused"), "{log}");
}

#[test]
fn a_run_folder_has_one_writer_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = tiny_mds(2);
    write_experiment(d, "small.toml", &text);
    let run = d.join("runs/small-arm");
    std::fs::create_dir_all(&run).unwrap();
    // Another writer (here: this test) holds the folder.
    let held = std::fs::File::create(run.join(".smspace.lock")).unwrap();
    held.lock().unwrap();
    let out = smspace(d, &["run", "small.toml"]);
    let log = stderr(&out);
    assert!(!out.status.success());
    assert!(
        log.contains("error: another smspace run is writing"),
        "{log}"
    );
    assert!(!run.join("config.resolved.toml").exists());
    assert!(!run.join("manifest.json").exists());
    // A temporary file an interrupted writer left behind.
    std::fs::write(run.join(".smspace-interrupted.part"), [0u8; 100]).unwrap();
    // And one a report killed while writing plotly.js left in assets/.
    std::fs::create_dir_all(run.join("assets")).unwrap();
    std::fs::write(run.join("assets/.smspace-plotly.part"), [0u8; 100]).unwrap();
    // --wait queues behind it and runs once it is released.
    let mut waiting = std::process::Command::new(env!("CARGO_BIN_EXE_smspace"))
        .args(["run", "small.toml", "--wait"])
        .current_dir(d)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    assert!(waiting.try_wait().unwrap().is_none(), "it must wait");
    assert!(!run.join("config.resolved.toml").exists());
    drop(held);
    let out = waiting.wait_with_output().unwrap();
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("waiting for it to end"), "{log}");
    assert_eq!(
        json(&run.join("manifest.json"))["status"]["state"],
        "complete"
    );
    assert!(!run.join(".smspace-interrupted.part").exists());
    assert!(!run.join("assets/.smspace-plotly.part").exists());
}

#[test]
fn devices_fifos_and_thread_counts_beyond_the_limit_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    if Path::new("/dev/zero").exists() {
        fails_with(d, &["run", "/dev/zero"], "not a regular file");
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_smspace"))
        .args(["env", "--out", "e.json"])
        .env("RAYON_NUM_THREADS", "100000")
        .current_dir(d)
        .output()
        .unwrap();
    let log = stderr(&out);
    assert!(!out.status.success());
    assert!(
        log.contains("RAYON_NUM_THREADS = 100000 is more than 4 threads per core"),
        "{log}"
    );
    // A run folder whose D.npy became a link to a device or a FIFO: the next run
    // recomputes it rather than read it (which would never end).
    write_experiment(d, "small.toml", &tiny_mds(2));
    ok(d, &["run", "small.toml"]);
    let run = d.join("runs/small-arm");
    let good = std::fs::read(run.join("D.npy")).unwrap();
    #[cfg(unix)]
    {
        std::fs::remove_file(run.join("D.npy")).unwrap();
        std::os::unix::fs::symlink("/dev/zero", run.join("D.npy")).unwrap();
        ok(d, &["run", "small.toml"]);
        assert_eq!(std::fs::read(run.join("D.npy")).unwrap(), good);
        std::fs::remove_file(run.join("D.npy")).unwrap();
        let made = std::process::Command::new("mkfifo")
            .arg(run.join("D.npy"))
            .status();
        if made.is_ok_and(|s| s.success()) {
            ok(d, &["run", "small.toml"]);
            assert_eq!(std::fs::read(run.join("D.npy")).unwrap(), good);
        }
    }
    // Read as an input, a device is refused too.
    if Path::new("/dev/zero").exists() {
        fails_with(
            d,
            &["embed", "--distances", "/dev/zero", "--out", "Y.npy"],
            "not a regular file",
        );
    }
}

#[test]
fn the_toy_experiments_run() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    let dir = tempfile::tempdir().unwrap();
    for (file, n) in [
        ("paper-toy-line.toml", "60"),
        ("paper-toy-redundant.toml", "60"),
    ] {
        let path = root.join(file);
        let out_dir = dir.path().join(file);
        ok(
            dir.path(),
            &[
                "run",
                path.to_str().unwrap(),
                "--out",
                out_dir.to_str().unwrap(),
                "--set",
                &format!("exploration.n={n}"),
                "--set",
                "analysis.invariance_starts=30",
            ],
        );
        let analysis = json(&out_dir.join("analysis.json"));
        assert_eq!(analysis["betti"][0], 1, "{file}: {analysis}");
        if file == "paper-toy-redundant.toml" {
            // Kernel lines m1 + m2 = x: a 1-D manifold without holes.
            assert_eq!(analysis["betti"], serde_json::json!([1, 0]), "{analysis}");
            in_range(&analysis["intrinsic_dimension"]["twonn"], 0.7, 1.4, "TwoNN");
            in_range(&analysis["agreement"]["spearman"], 0.95, 1.0, "Spearman");
        } else {
            let invariance = json(&out_dir.join("invariance.json"));
            // The sensory manifolds differ between the environments.
            in_range(
                &invariance["min_sensor_difference_relative"],
                0.05,
                100.0,
                "sensor difference",
            );
        }
        assert!(out_dir.join("report.html").is_file());
    }
}

#[test]
fn the_shipped_experiments_are_valid() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    let mut found = 0;
    for entry in std::fs::read_dir(&root).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let loaded = smspace_pipeline::config::load_experiment(&path, &[])
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            smspace_pipeline::check(&loaded).unwrap_or_else(|e| panic!("{e}"));
            found += 1;
        }
    }
    assert!(found >= 4, "{found} experiments in {}", root.display());
}

#[test]
fn a_run_with_overrides_gets_its_own_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_experiment(d, "small.toml", &tiny_mds(2));
    ok(d, &["run", "small.toml"]);
    let plain = d.join("runs/small-arm");
    let before = std::fs::read(plain.join("Y.npy")).unwrap();
    let out = ok(d, &["run", "small.toml", "--set", "embedding.dim=3"]);
    let log = stderr(&out);
    let folders: Vec<String> = std::fs::read_dir(d.join("runs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "small-arm")
        .collect();
    assert_eq!(folders.len(), 1, "{folders:?}");
    let own = &folders[0];
    assert!(
        own.starts_with("small-arm-") && own.len() == "small-arm-".len() + 8,
        "{own}"
    );
    assert!(
        log.contains(own.as_str()) && log.contains("its own folder"),
        "{log}"
    );
    // The unmodified experiment's run is untouched; the same overrides find their
    // folder again (and reuse it).
    assert_eq!(std::fs::read(plain.join("Y.npy")).unwrap(), before);
    let y: Array2<f64> = read_npy(d.join("runs").join(own).join("Y.npy")).unwrap();
    assert_eq!(y.ncols(), 3);
    let out = ok(d, &["run", "small.toml", "--set", "embedding.dim=3"]);
    let log = stderr(&out);
    assert!(log.contains("0 of 7 stages computed"), "{log}");
}

/// Two runs of different settings into one folder at once, many times: each waits for
/// the other, and afterwards each configuration's rerun equals a fresh run of it byte
/// for byte (no output of one is ever recorded under the other's key).
#[test]
fn concurrent_runs_into_one_folder_never_mix_their_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_experiment(d, "small.toml", &tiny_mds(2));
    let settings: [&[&str]; 2] = [&[], &["--set", "embedding.method=\"isomap\""]];
    let args = |extra: &[&str], out: &str| -> Vec<String> {
        let mut args: Vec<String> = ["run", "small.toml", "--wait", "--out", out]
            .map(String::from)
            .to_vec();
        args.extend(extra.iter().map(|s| s.to_string()));
        args
    };
    for (i, extra) in settings.iter().enumerate() {
        let fresh = format!("fresh-{i}");
        let a = args(extra, &fresh);
        ok(d, &a.iter().map(String::as_str).collect::<Vec<_>>());
    }
    for round in 0..20 {
        let children: Vec<std::process::Child> = settings
            .iter()
            .map(|extra| {
                std::process::Command::new(env!("CARGO_BIN_EXE_smspace"))
                    .args(args(extra, "shared"))
                    .current_dir(d)
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for child in children {
            let out = child.wait_with_output().unwrap();
            assert!(out.status.success(), "round {round}: {}", stderr(&out));
        }
        // The manifest vouches only for the files as they are.
        let manifest = json(&d.join("shared/manifest.json"));
        assert_eq!(manifest["status"]["state"], "complete", "round {round}");
        for record in manifest["stages"].as_array().unwrap() {
            for (file, hash) in record["outputs"].as_object().unwrap() {
                let found = smspace_pipeline::manifest::hash_file(&d.join("shared").join(file));
                assert_eq!(
                    found.ok().as_deref(),
                    hash.as_str(),
                    "round {round}: {file}"
                );
            }
        }
    }
    for (i, extra) in settings.iter().enumerate() {
        let a = args(extra, "shared");
        ok(d, &a.iter().map(String::as_str).collect::<Vec<_>>());
        for file in [
            "motors.npy",
            "sets.npy",
            "D.npy",
            "Y.npy",
            "Y.dydx.npy",
            "Y.embed.json",
            "analysis.json",
            "report.json",
            "config.resolved.toml",
        ] {
            let shared = std::fs::read(d.join("shared").join(file)).unwrap();
            let fresh = std::fs::read(d.join(format!("fresh-{i}")).join(file)).unwrap();
            assert!(
                shared == fresh,
                "settings {i}: {file} differs from a fresh run"
            );
        }
    }
}
