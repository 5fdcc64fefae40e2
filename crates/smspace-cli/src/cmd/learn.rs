//! `smspace learn`: kernel sets from recorded sensorimotor data. Learns the law `ŝ(m)`
//! from one or several logs (motors and sensors files, one pair per environment) and
//! traces `ŝ(m) = ŝ(m^i)` through each start with the sensory method; writes the files
//! of `smspace trace` and the law's report beside them.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use smspace::io;
use smspace::kernel::TraceParams;
use smspace::learn::{
    declared_space, law_trace_params, learn, parse_motor_declarations, trace_learned, LawMethod,
    LawParams, LogFiles, SensorimotorLog,
};

use crate::ui::Bar;

/// Arguments of `smspace learn`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Motor commands of a log (S, N); repeat with --sensors for several logs (one per
    /// environment).
    #[arg(long, value_name = "FILE", required = true)]
    motors: Vec<PathBuf>,
    /// Sensor values of a log (S, K), one row per row of its motors file.
    #[arg(long, value_name = "FILE", required = true)]
    sensors: Vec<PathBuf>,
    /// Start configurations (M, N): one kernel set is traced through each row.
    #[arg(long, value_name = "FILE")]
    starts: PathBuf,
    /// Points per resampled set.
    #[arg(long, default_value_t = TraceParams::default().points)]
    points: usize,
    /// The motors: 2pi (hinges), none (bounded by the log's range), a period, a range
    /// LOW:HIGH, or a comma-separated list of these, one per motor.
    #[arg(long, default_value = "2pi")]
    period: String,
    /// The law: local-quadratic or local-linear (regressions of the sensors around each
    /// configuration), or invariants (the functions of the motors that sensory neighbours
    /// share, in a Fourier basis of the motors: the kernels are their level sets; at most
    /// seven motors).
    #[arg(long, default_value = "local-quadratic", value_parser = parse_method)]
    method: LawMethod,
    /// With --method invariants: how many invariants to keep (default: those up to the
    /// largest gap of the eigenvalues below --invariance-threshold).
    #[arg(long, value_name = "COUNT")]
    invariants: Option<usize>,
    /// With --method invariants: the largest mean squared change of a kept invariant
    /// between sensory neighbours, relative to its variance (2 for unrelated values).
    #[arg(long, default_value_t = LawParams::default().invariance_threshold)]
    invariance_threshold: f64,
    /// Samples a typical fit holds (default 4p + 20, p the fit's coefficients).
    #[arg(long, value_name = "K")]
    neighbours: Option<usize>,
    /// Factor on the bandwidth.
    #[arg(long, default_value_t = LawParams::default().bandwidth_factor)]
    bandwidth_factor: f64,
    /// Step budget of one set (a set on a poor law may wander: it fails as not-closed).
    #[arg(long, default_value_t = 3000)]
    max_steps: usize,
    /// Loop-closure tolerance (torus distance); looser than the simulator's 1e-2, as the
    /// law's own error is larger.
    #[arg(long, default_value_t = 0.03)]
    closure_tolerance: f64,
    /// Seed of the held-out samples.
    #[arg(long, default_value_t = LawParams::default().seed)]
    seed: u64,
    /// Output sets (M_kept, P, N); next to it `<stem>.kept.npy`, `<stem>.closed.npy`,
    /// `<stem>.trace.json` (as `smspace trace`) and `<stem>.law.json` (the law).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// The true sets through the same starts (as written by `smspace trace` on the
    /// simulated agent): the Hausdorff distance between each learned set and its true
    /// one (curve metric, radians) is printed (median, 90th percentile) and written to
    /// `<stem>.errors.json`.
    #[arg(long, value_name = "FILE")]
    truth_sets: Option<PathBuf>,
    /// Refuse to start when learning needs more than this many bytes (default: the
    /// memory available, MemAvailable in /proc/meminfo).
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
}

fn parse_method(s: &str) -> Result<LawMethod, String> {
    s.parse()
}

/// Runs `smspace learn`.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.motors.len() == args.sensors.len(),
        "{} --motors files but {} --sensors files: give one pair per log",
        args.motors.len(),
        args.sensors.len()
    );
    let declarations = parse_motor_declarations(&args.period)
        .map_err(|reason| anyhow::anyhow!("--period {}: {reason}", args.period))?;
    let params = LawParams {
        method: args.method,
        neighbours: args.neighbours,
        bandwidth_factor: args.bandwidth_factor,
        seed: args.seed,
        invariants: args.invariants,
        invariance_threshold: args.invariance_threshold,
        ..LawParams::default()
    }
    .check()?;
    let limit = args.max_memory.or_else(super::common::memory_available);
    let on_disk: u64 = args
        .motors
        .iter()
        .chain(&args.sensors)
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    super::common::check_memory(
        "logs",
        on_disk,
        limit,
        "learn from fewer samples (cut the logs)",
    )?;
    let first = io::read_matrix(&args.motors[0], None, "(S, N)")?;
    let space = declared_space(&declarations, first.view(), &args.motors[0])?;
    drop(first);
    let logs = args
        .motors
        .iter()
        .zip(&args.sensors)
        .map(|(motors, sensors)| {
            SensorimotorLog::load(
                LogFiles {
                    motors: motors.clone(),
                    sensors: sensors.clone(),
                },
                &space,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let samples: usize = logs.iter().map(SensorimotorLog::samples).sum();
    let periodic = space.motors().iter().filter(|m| m.is_periodic()).count();
    let needed: u64 = logs
        .iter()
        .map(|l| params.bytes(l.samples(), space.dim(), l.sensors.ncols(), periodic))
        .sum();
    eprintln!(
        "learning from {samples} samples ({} logs, {space}): at most {} of memory",
        logs.len(),
        smspace::metric::human_bytes(needed)
    );
    let starts = io::read_matrix(
        &args.starts,
        Some(space.dim()),
        &format!("(M, {})", space.dim()),
    )?;
    let trace = TraceParams {
        points: args.points,
        max_steps: args.max_steps,
        closure_tolerance: args.closure_tolerance,
        ..law_trace_params()
    };
    trace.check()?;
    super::common::check_memory(
        "kernel sets",
        trace.sets_bytes(starts.nrows() as u64, space.dim()),
        args.max_memory,
        "trace fewer starts per call, or lower --points",
    )?;
    let law = learn(&logs, &space, &params, limit)?;
    print_law(law.report());
    let bar = Bar::new();
    let traced = trace_learned(&law, starts.view(), &trace, &bar)?;
    traced
        .report
        .summary
        .require(starts.nrows().min(2))
        .map_err(|e| anyhow::anyhow!("{e}. Nothing was written."))?;
    let errors = match &args.truth_sets {
        Some(path) => Some(truth_errors(&traced, path, &space)?),
        None => None,
    };
    // The writer of `smspace trace`, and the law's report, all together.
    let mut outputs = io::Outputs::new();
    traced.write_into(&mut outputs, &args.out)?;
    outputs.json(&io::sibling(&args.out, "law.json"), law.report())?;
    if let Some(errors) = &errors {
        outputs.json(&io::sibling(&args.out, "errors.json"), errors)?;
    }
    outputs.commit()?;
    if let Some(errors) = &errors {
        eprintln!(
            "set error against the truth ({} sets in both): median {:.4} rad, 90th percentile {:.4} rad",
            errors.compared, errors.median, errors.p90
        );
    }
    let summary = &traced.report.summary;
    eprintln!(
        "traced {} of {} sets on the learned law (rank {}); {} failed {:?}",
        summary.traced,
        summary.total,
        law.report().rank,
        summary.failed,
        summary.by_status
    );
    Ok(())
}

/// What learning found, on stderr: each log's bandwidth, held-out error and noise, the
/// rank the data show, for the invariants law its eigenvalues and `λ`, and the warnings.
fn print_law(report: &smspace::learn::LawReport) {
    for log in &report.logs {
        eprintln!(
            "{}: bandwidth {:.4}, held-out error {:.2e} of the sensors' spread ({} samples held out)",
            log.motors, log.bandwidth, log.held_out_relative_rms, log.held_out
        );
        if let Some(noise) = &log.noise {
            eprintln!(
                "  noise σ̂ {:.2} % of the sensors' spread{} (per sensor {}; the data resolve {:.2} %)",
                100.0 * noise.relative_overall,
                if noise.measurable() { "" } else { ", below the resolution" },
                noise
                    .relative
                    .iter()
                    .map(|r| format!("{:.2}", 100.0 * r))
                    .collect::<Vec<_>>()
                    .join(" "),
                100.0 * noise.resolution
            );
        }
    }
    if let Some(rank) = &report.data_rank {
        eprintln!(
            "rank of the sensors in the data: {} (slope spectrum {}; noise floor {:.1e})",
            rank.rank,
            rank.spectrum
                .iter()
                .map(|b| format!("{b:.3}"))
                .collect::<Vec<_>>()
                .join(" "),
            rank.floor
        );
    }
    if let Some(found) = &report.invariants {
        eprintln!(
            "{} invariants of {} basis functions (eigenvalues λ {}); λ on the fitted pairs {:.3}, held out {}",
            found.invariants,
            found.features,
            found
                .eigenvalues
                .iter()
                .map(|l| format!("{l:.3}"))
                .collect::<Vec<_>>()
                .join(" "),
            found.fitted_lambda,
            found
                .held_out_lambda
                .map_or("-".to_owned(), |l| format!("{l:.3}"))
        );
    }
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
}

/// The set errors of the learned sets against the true ones in `path` (the same
/// starts), under the motors' period (all hinges: `2pi`; no periodic motor: `none`).
fn truth_errors(
    traced: &smspace::kernel::TracedSets,
    path: &std::path::Path,
    space: &smspace::agent::MotorSpace,
) -> anyhow::Result<smspace::learn::SetErrors> {
    let truth = smspace::kernel::TracedSets::load(path)?;
    let Some(period) = smspace::learn::comparison_period(&space.periods()) else {
        anyhow::bail!(
            "--truth-sets compares sets of all-hinge (2pi) or all-bounded motors; these motors are {space}"
        );
    };
    smspace::learn::set_errors(traced, &truth, period)
        .map_err(|e| anyhow::anyhow!("--truth-sets {}: {e}", path.display()))
}
