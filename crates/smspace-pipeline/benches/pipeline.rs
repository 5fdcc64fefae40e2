//! The whole pipeline of an experiment, end to end: `cargo bench -p smspace --bench
//! pipeline` runs `experiments/paper-arm.toml` (3500 sets: 2500 babbled + the probe
//! grid; figures and report included) `SMSPACE_BENCH_RUNS` times (default 3) with every
//! stage recomputed, into a temporary folder, and prints the time of each stage and of
//! the whole run (best and median), with the peak resident memory of the process and the
//! SIMD level of the metric kernels. `SMSPACE_BENCH_EXPERIMENT=path.toml` times another
//! experiment, e.g. `SMSPACE_BENCH_EXPERIMENT=experiments/arm-100k.toml
//! SMSPACE_BENCH_RUNS=1`. Issue 18's targets on 2 cores with AVX2: paper-arm at most 5 s,
//! arm-100k at most 10 minutes and 4 GiB.

use std::path::PathBuf;

use smspace::progress::{Progress, Silent};
use smspace_pipeline::config::load_experiment;
use smspace_pipeline::{Recompute, RunObserver, RunOptions};

struct Quiet;

impl RunObserver for Quiet {
    fn progress(&self) -> &dyn Progress {
        &Silent
    }
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument that names nothing here skips.
    if std::env::args()
        .skip(1)
        .any(|a| !a.starts_with('-') && a != "pipeline")
    {
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let experiment = std::env::var("SMSPACE_BENCH_EXPERIMENT")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("experiments/paper-arm.toml"));
    let runs: usize = std::env::var("SMSPACE_BENCH_RUNS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(3);
    let loaded = load_experiment(&experiment, &[]).expect("the experiment loads");
    let plan = smspace_pipeline::check(&loaded).expect("the experiment is valid");
    let dir = tempfile::tempdir().expect("a temporary folder");
    println!(
        "pipeline of {} ({} threads, metric kernels: {}), {runs} runs, every stage recomputed",
        experiment.display(),
        rayon::current_num_threads(),
        smspace::metric::simd_level()
    );
    let mut totals = Vec::new();
    let mut per_stage: Vec<(String, Vec<f64>)> = Vec::new();
    for _ in 0..runs {
        let options = RunOptions {
            out_dir: dir.path().join("run"),
            recompute: Recompute::All,
            memory_limit_bytes: None,
            busy: smspace_pipeline::BusyFolder::Refuse,
        };
        let summary = smspace_pipeline::run(&plan, &options, &Quiet).expect("the pipeline runs");
        totals.push(summary.manifest.total_seconds);
        for record in &summary.manifest.stages {
            match per_stage.iter_mut().find(|(s, _)| *s == record.stage) {
                Some((_, times)) => times.push(record.seconds),
                None => per_stage.push((record.stage.clone(), vec![record.seconds])),
            }
        }
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[0], v[v.len() / 2])
    };
    for (stage, times) in &mut per_stage {
        let (best, median) = stats(times);
        println!("  {stage:<11} best {best:7.3} s   median {median:7.3} s");
    }
    let (best, median) = stats(&mut totals);
    println!(
        "  {:<11} best {best:7.3} s   median {median:7.3} s",
        "total"
    );
    // Peak resident memory of this process (all runs), from /proc/self/status.
    if let Some(peak) = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .map(|l| l.trim_start_matches("VmHWM:").trim().to_owned())
        })
    {
        println!("  peak resident memory {peak}");
    }
}
