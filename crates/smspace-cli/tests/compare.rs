//! `smspace compare`: two small runs (the pupil arm and its spatial sets) side by side,
//! and bad run folders; `smspace distances --metric curve` on the spatial sets of a run.

mod common;

use std::path::Path;

use common::{fails_with, ok};

/// The overrides that make `experiments/pupil*.toml` a few seconds' run.
const SMALL: [&str; 14] = [
    "--set",
    "exploration.n=40",
    "--set",
    "kernel.points=15",
    "--set",
    "analysis.max_points=40",
    "--set",
    "analysis.compensability.base_points=12",
    "--set",
    "embedding.epochs=2",
    "--set",
    "report.sample_configurations=4",
    "--set",
    "report.sample_sets=3",
];

fn experiment(name: &str) -> String {
    format!("{}/../../experiments/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// Runs `experiments/<name>.toml`, reduced, into `dir/<name>`.
fn small_run(dir: &Path, name: &str, extra: &[&str]) {
    let file = experiment(&format!("{name}.toml"));
    let mut args = vec!["run", file.as_str(), "--out", name];
    args.extend(SMALL);
    args.extend(extra);
    ok(dir, &args);
}

#[test]
fn two_runs_share_one_page() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_run(d, "pupil", &["--set", "kernel.spatial_samples=3"]);
    small_run(d, "pupil-space", &["--set", "kernel.spatial_samples=3"]);
    ok(
        d,
        &["compare", "pupil", "pupil-space", "--out", "both.html"],
    );
    let page = std::fs::read_to_string(d.join("both.html")).unwrap();
    // One column per run, in order, with its numbers from its analysis.json.
    let first = page.find("<th>pupil<br>").expect("pupil's column");
    let second = page
        .find("<th>pupil-space<br>")
        .expect("pupil-space's column");
    assert!(first < second);
    for quantity in [
        "Betti numbers",
        "TwoNN dimension",
        "MLE dimension",
        "trustworthiness vs poses",
        "compensable dimension d (most frequent)",
        "spatial dimension",
    ] {
        assert!(page.contains(quantity), "{quantity} missing");
    }
    for run in ["pupil", "pupil-space"] {
        let analysis: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.join(run).join("analysis.json")).unwrap(),
        )
        .unwrap();
        let twonn = analysis["intrinsic_dimension"]["twonn"].as_f64().unwrap();
        assert!(
            page.contains(&format!("<td>{twonn:.2}</td>")),
            "{run}: {twonn}"
        );
        // d per base point: every d seen has its row, with this run's count.
        let histogram = analysis["compensability"]["histogram"].as_array().unwrap();
        for (k, n) in histogram.iter().enumerate() {
            if n.as_u64().unwrap() > 0 {
                assert!(page.contains(&format!("base points with d = {k}")), "{k}");
            }
        }
    }
    // The spatial run says what its sets are.
    assert!(page.contains("spatial sets: spanned along motor(s) [4]"));
    // Both embeddings, embedded in the page.
    assert_eq!(page.matches("data:image/png;base64,").count(), 2);
    // `smspace distances` reads the spatial sets' slices as the run did (their trace
    // report says they were extended: the curve metric applies to the slices).
    ok(
        d,
        &[
            "distances",
            "--sets",
            "pupil-space/sets.npy",
            "--metric",
            "curve",
            "--period",
            "2pi,2pi,2pi,2pi,none",
            "--out",
            "D.npy",
        ],
    );
    let cli: ndarray::Array2<f64> = ndarray_npy::read_npy(d.join("D.npy")).unwrap();
    let run: ndarray::Array2<f64> = ndarray_npy::read_npy(d.join("pupil-space/D.npy")).unwrap();
    assert_eq!(cli, run);
}

#[test]
fn a_missing_run_folder_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("empty")).unwrap();
    fails_with(
        d,
        &["compare", "empty", "runs/nowhere"],
        "run folder empty: ",
    );
    let text = fails_with(d, &["compare", "runs/nowhere", "empty"], "runs/nowhere");
    assert!(text.contains("no such folder"), "{text}");
    let text = fails_with(
        d,
        &["compare", "empty", "empty"],
        "analysis.json is missing",
    );
    assert!(text.contains("smspace run"), "{text}");
    // One run is not a comparison (clap: two or more).
    let out = common::smspace(d, &["compare", "empty"]);
    assert!(!out.status.success());
    assert!(!d.join("compare.html").exists());
}
