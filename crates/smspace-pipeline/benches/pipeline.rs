//! The whole pipeline of an experiment, end to end: `cargo bench -p smspace-pipeline
//! --bench pipeline` runs `experiments/paper-arm.toml` (3500 sets: 2500 babbled + the
//! probe grid; figures and report included) `SMSPACE_BENCH_RUNS` times (default 3) with
//! every stage recomputed, into a temporary folder, and prints the time of each stage
//! (explore, trace, distances, embed, analyze, report) and of the whole run (best and
//! median), the CPU time of the process per run, its peak resident memory, the CPU
//! model with its SIMD extensions and the SIMD level of the metric kernels, and the
//! load average (other work on the machine stretches wall times: the CPU time much
//! less). `SMSPACE_BENCH_EXPERIMENT=path.toml` times another experiment, e.g.
//! `SMSPACE_BENCH_EXPERIMENT=experiments/arm-100k.toml SMSPACE_BENCH_RUNS=1`. The
//! targets on 2 cores with AVX2: paper-arm at most 5 s with its report at most 0.6 s,
//! arm-100k at most 10 minutes and 4 GiB.

use std::path::PathBuf;
use std::sync::Mutex;

use smspace::progress::{Progress, Silent};
use smspace_pipeline::config::load_experiment;
use smspace_pipeline::manifest::{StageId, StageRecord};
use smspace_pipeline::{Recompute, RunObserver, RunOptions};

/// Prints nothing; keeps the CPU time of the process spent in each stage.
#[derive(Default)]
struct Quiet {
    /// The CPU seconds when the running stage started.
    started: Mutex<f64>,
    /// `(stage, CPU seconds)` of each stage finished.
    cpu: Mutex<Vec<(String, f64)>>,
}

impl RunObserver for Quiet {
    fn progress(&self) -> &dyn Progress {
        &Silent
    }

    fn stage_started(&self, _stage: StageId) {
        *self.started.lock().unwrap() = cpu_seconds();
    }

    fn stage_finished(&self, _stage: StageId, record: &StageRecord, _summary: &str) {
        let spent = cpu_seconds() - *self.started.lock().unwrap();
        self.cpu.lock().unwrap().push((record.stage.clone(), spent));
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
    println!("  {}", cpu_description());
    println!("  load average before: {}", load_average());
    let mut totals = Vec::new();
    let mut cpu = Vec::new();
    // Per stage: wall seconds and CPU seconds of each run.
    let mut per_stage: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    for _ in 0..runs {
        let options = RunOptions {
            out_dir: dir.path().join("run"),
            recompute: Recompute::All,
            memory_limit_bytes: None,
            busy: smspace_pipeline::BusyFolder::Refuse,
        };
        let cpu_before = cpu_seconds();
        let observer = Quiet::default();
        let summary = smspace_pipeline::run(&plan, &options, &observer).expect("the pipeline runs");
        totals.push(summary.manifest.total_seconds);
        cpu.push(cpu_seconds() - cpu_before);
        let stage_cpu = observer.cpu.into_inner().unwrap();
        for record in &summary.manifest.stages {
            let spent = stage_cpu
                .iter()
                .find(|(s, _)| *s == record.stage)
                .map_or(f64::NAN, |(_, c)| *c);
            match per_stage.iter_mut().find(|(s, _, _)| *s == record.stage) {
                Some((_, times, cpus)) => {
                    times.push(record.seconds);
                    cpus.push(spent);
                }
                None => per_stage.push((record.stage.clone(), vec![record.seconds], vec![spent])),
            }
        }
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[0], v[v.len() / 2])
    };
    println!("  wall time per stage, and the CPU time of the process during it (all threads)");
    for (stage, times, cpus) in &mut per_stage {
        let (best, median) = stats(times);
        let (_, cpu_median) = stats(cpus);
        println!("  {stage:<11} best {best:7.3} s   median {median:7.3} s   CPU median {cpu_median:7.3} s");
    }
    let (best, median) = stats(&mut totals);
    println!(
        "  {:<11} best {best:7.3} s   median {median:7.3} s",
        "total"
    );
    let (best, median) = stats(&mut cpu);
    println!(
        "  {:<11} best {best:7.3} s   median {median:7.3} s   (CPU time of the process, all threads)",
        "total CPU"
    );
    println!("  load average after: {}", load_average());
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

/// The CPU model and the SIMD extensions the metric kernels can use, from
/// `/proc/cpuinfo` (Linux; elsewhere, what is known).
fn cpu_description() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |name: &str| {
        info.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_once(':'))
            .map(|(_, v)| v.trim().to_owned())
    };
    let model = field("model name").unwrap_or_else(|| std::env::consts::ARCH.to_owned());
    let flags = field("flags").unwrap_or_default();
    let has: Vec<&str> = ["avx2", "fma", "avx512f", "avx512bw", "avx512vl"]
        .into_iter()
        .filter(|f| flags.split_whitespace().any(|g| g == *f))
        .collect();
    format!(
        "CPU: {model}, {} cores seen; SIMD extensions: {}",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        if has.is_empty() {
            "none of avx2, fma, avx512".to_owned()
        } else {
            has.join(", ")
        }
    )
}

/// The first three numbers of `/proc/loadavg` (1, 5 and 15 minutes), or `unknown`.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".to_owned())
}

/// CPU seconds (user and system) this process has used so far, from
/// `/proc/self/stat` (0 where it cannot be read).
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which may hold spaces, in parentheses): utime
    // and stime are the 14th and 15th fields of the line, in clock ticks (100 a second
    // on Linux).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |k: usize| {
        fields
            .get(k)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}
