//! `smspace learn`: kernel sets from recorded sensorimotor data. Learns the law `ŝ(m)`
//! from one or several logs (motors and sensors files, one pair per environment) and
//! traces `ŝ(m) = ŝ(m^i)` through each start with the sensory method; writes the files
//! of `smspace trace` and the law's report beside them.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use smspace::io;
use smspace::kernel::TraceParams;
use smspace::learn::{
    declared_space, law_trace_params, learn_with_progress, parse_motor_declarations, trace_learned,
    LawMethod, LawParams, LawValidParams, LogFiles, MotorDeclaration, RankSource, SensorimotorLog,
};
use smspace::progress::Progress;

use super::common::{split_params, with_table_params};
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
    /// The law: invariants (the functions of the motors that sensory neighbours share,
    /// in a Fourier basis of the motors: the kernels are their level sets; at most seven
    /// motors; the default), or local-quadratic or local-linear (regressions of the
    /// sensors around each configuration, which average them over their bandwidth).
    #[arg(long, default_value = "invariants", value_parser = parse_method)]
    method: LawMethod,
    /// With --method invariants: how many invariants to keep (default: those up to the
    /// largest gap of the eigenvalues below --invariance-threshold).
    #[arg(long, value_name = "COUNT")]
    invariants: Option<usize>,
    /// With --method invariants: the largest mean squared change of a kept invariant
    /// between sensory neighbours, relative to its variance (2 for unrelated values).
    #[arg(long, default_value_t = LawParams::default().invariance_threshold)]
    invariance_threshold: f64,
    /// The rank of the sensors' Jacobian when you know it, 1 to N − 1 for N motors: the
    /// kernels have dimension N − rank (3 on a 4-hinge arm whose sensor's pose is
    /// (x, y, heading): curves). Used in place of the rank read from the data, which is
    /// printed beside it (default: read from the data and the law).
    #[arg(long, value_name = "RANK")]
    rank: Option<usize>,
    /// Samples a typical fit holds (default 4p + 20, p the fit's coefficients).
    #[arg(long, value_name = "K")]
    neighbours: Option<usize>,
    /// Factor on the bandwidth.
    #[arg(long, default_value_t = LawParams::default().bandwidth_factor)]
    bandwidth_factor: f64,
    /// Step budget of one set (a set on a poor law may wander: it fails as not-closed).
    #[arg(long, default_value_t = law_trace_params().max_steps)]
    max_steps: usize,
    /// Loop-closure tolerance (torus distance); looser than the simulator's 1e-2, as the
    /// law's own error is larger.
    #[arg(long, default_value_t = law_trace_params().closure_tolerance)]
    closure_tolerance: f64,
    /// A key of the law's parameters that has no flag of its own (ridge,
    /// coverage_neighbours), or of the [kernel] table as kernel.KEY (kernel.step,
    /// kernel.max_step, …), the value in TOML; repeatable.
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = super::common::parse_param)]
    params: Vec<(String, toml::Value)>,
    /// Seed of the held-out samples.
    #[arg(long, default_value_t = LawParams::default().seed)]
    seed: u64,
    /// Output sets (M_kept, P, N); next to it `<stem>.kept.npy`, `<stem>.closed.npy`,
    /// `<stem>.trace.json` (as `smspace trace`) and `<stem>.law.json` (the law).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// The true sets through the same starts (as written by `smspace trace` on the
    /// simulated agent): the Hausdorff distance between each learned set and its true
    /// one (radians; curves as polylines, surfaces as tangent disks, under the motors'
    /// periods) is printed (median, 90th percentile) and written to
    /// `<stem>.errors.json`.
    #[arg(long, value_name = "FILE")]
    truth_sets: Option<PathBuf>,
    /// Samples of each log held out of the fit to measure the law's error (default
    /// min(S/10, 2000)).
    #[arg(long, value_name = "COUNT")]
    holdout: Option<usize>,
    /// Refuse to start when learning and the traced sets need more than this many bytes
    /// (default: the memory available, MemAvailable in /proc/meminfo, at most 16 GiB).
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
    /// Print how long each stage took (reading the logs, the noise, the k-d trees, the
    /// pairs and basis sums, the held-out samples, tracing) as it ends.
    #[arg(long)]
    verbose: bool,
}

/// Keys of the law's parameters that have a flag of their own.
const LAW_FLAGS: [(&str, &str); 8] = [
    ("method", "method"),
    ("neighbours", "neighbours"),
    ("bandwidth_factor", "bandwidth-factor"),
    ("seed", "seed"),
    ("holdout", "holdout"),
    ("invariants", "invariants"),
    ("invariance_threshold", "invariance-threshold"),
    ("rank", "rank"),
];

/// [kernel] keys that have a flag of their own.
const KERNEL_FLAGS: [(&str, &str); 3] = [
    ("points", "points"),
    ("max_steps", "max-steps"),
    ("closure_tolerance", "closure-tolerance"),
];

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
    let inputs: Vec<(&str, Option<&std::path::Path>)> = args
        .motors
        .iter()
        .map(|p| ("--motors", Some(p.as_path())))
        .chain(
            args.sensors
                .iter()
                .map(|p| ("--sensors", Some(p.as_path()))),
        )
        .chain([
            ("--starts", Some(args.starts.as_path())),
            ("--truth-sets", args.truth_sets.as_deref()),
        ])
        .collect();
    super::common::spare_inputs(&[&args.out], &inputs)?;
    // A folder that cannot take the output is found now, not after learning.
    io::check_output_folder(&args.out)?;
    let declarations = parse_motor_declarations(&args.period)
        .map_err(|reason| anyhow::anyhow!("--period {}: {reason}", args.period))?;
    let (params, trace) = tables(&args)?;
    let limit = smspace_pipeline::front::learn_memory_limit(args.max_memory);
    let bar = if args.verbose {
        Bar::with_timings()
    } else {
        Bar::new()
    };
    check_memory_first(&args, &declarations, (&params, &trace), limit)?;
    let first = io::read_matrix(&args.motors[0], None, "(S, N)")?;
    let space = declared_space(&declarations, first.view(), &args.motors[0])?;
    drop(first);
    let logs = read_logs(&args, &space, &bar)?;
    let starts = io::read_matrix(
        &args.starts,
        Some(space.dim()),
        &format!("(M, {})", space.dim()),
    )?;
    let law = learn_with_progress(&logs, &space, &params, Some(limit), &bar)?;
    drop(logs);
    print_law(law.report());
    let traced = trace_learned(&law, starts.view(), &trace, &bar)?;
    // The law's report with what tracing showed (the closure rate, its warning, a rank
    // tried again).
    let report = match traced
        .report
        .law
        .clone()
        .map(serde_json::from_value::<smspace::learn::LawReport>)
    {
        Some(Ok(report)) => report,
        _ => law.report().with_trace(&traced.report.summary),
    };
    if let Some(choice) = &report.rank_choice {
        for tried in &choice.tried {
            eprintln!(
                "every one of the {} sets failed at rank {} ({:?}): traced again at rank {}",
                tried.total, tried.rank, tried.by_status, choice.rank
            );
        }
    }
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
    let mut outputs = io::Outputs::sparing(&super::common::present(&inputs));
    traced.write_into(&mut outputs, &args.out)?;
    outputs.json(&io::sibling(&args.out, "law.json"), &report)?;
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
    print_traced(&traced, &report, law.report().warnings.len());
    Ok(())
}

/// The law's parameters and the `[kernel]` table the flags and `--param`s give
/// (`kernel.KEY` for the latter), both checked.
fn tables(args: &Args) -> anyhow::Result<(LawValidParams, TraceParams)> {
    let params = LawParams {
        method: args.method,
        neighbours: args.neighbours,
        bandwidth_factor: args.bandwidth_factor,
        seed: args.seed,
        holdout: args.holdout,
        invariants: args.invariants,
        invariance_threshold: args.invariance_threshold,
        rank: args.rank,
        ..LawParams::default()
    };
    let (kernel_params, law_params) = split_params(&args.params, "kernel.");
    let params = with_table_params(&params, &law_params, &LAW_FLAGS, "law")?.check()?;
    let trace = TraceParams {
        points: args.points,
        max_steps: args.max_steps,
        closure_tolerance: args.closure_tolerance,
        ..law_trace_params()
    };
    let trace = with_table_params(&trace, &kernel_params, &KERNEL_FLAGS, "kernel")?;
    trace.check()?;
    Ok((params, trace))
}

/// What tracing on the law gave, on stderr, and the warnings it added to the law's own
/// (the first `law_warnings` were printed with the law).
fn print_traced(
    traced: &smspace::kernel::TracedSets,
    report: &smspace::learn::LawReport,
    law_warnings: usize,
) {
    let summary = &traced.report.summary;
    eprintln!(
        "traced {} of {} sets on the learned law (rank {}); {} failed {:?}{}",
        summary.traced,
        summary.total,
        report.rank,
        summary.failed,
        summary.by_status,
        report
            .quality
            .closure_rate
            .map_or(String::new(), |r| format!(
                "; {:.1} % of the curves closed",
                100.0 * r
            ))
    );
    // Only the warnings tracing added: the law's own were printed before it.
    for warning in report.warnings.iter().skip(law_warnings) {
        eprintln!("warning: {warning}");
    }
}

/// The memory learning and tracing need, from the shapes the files' headers announce
/// (nothing read yet), on stderr; refused above `limit` with the parts and what to
/// lower. Files whose header does not parse are left to the readers, which say why.
fn check_memory_first(
    args: &Args,
    declarations: &[MotorDeclaration],
    (params, trace): (&LawValidParams, &TraceParams),
    limit: u64,
) -> anyhow::Result<()> {
    let mut shapes = Vec::with_capacity(args.motors.len());
    let mut motors = 0;
    for (m, s) in args.motors.iter().zip(&args.sensors) {
        match (io::npy_shape(m)?, io::npy_shape(s)?) {
            (Some(m), Some(s)) if m.len() == 2 && s.len() == 2 => {
                motors = m[1];
                shapes.push((m[0], s[1]));
            }
            _ => return Ok(()),
        }
    }
    let periodic = if declarations.len() == 1 {
        usize::from(matches!(declarations[0], MotorDeclaration::Periodic(_))) * motors
    } else {
        declarations
            .iter()
            .filter(|d| matches!(d, MotorDeclaration::Periodic(_)))
            .count()
    };
    let starts = io::npy_shape(&args.starts)?
        .and_then(|s| s.first().copied())
        .unwrap_or(0);
    let estimate = params
        .memory(&shapes, motors, periodic, rayon::current_num_threads())
        .with_sets(trace.sets_bytes(starts as u64, motors));
    let samples: usize = shapes.iter().map(|s| s.0).sum();
    eprintln!(
        "learning from {samples} samples ({} logs, {motors} motors) and tracing {starts} sets need about {} ({}); the limit is {}",
        shapes.len(),
        smspace::metric::human_bytes(estimate.total_bytes()),
        estimate.parts(),
        smspace::metric::human_bytes(limit)
    );
    estimate.check(samples, limit)?;
    Ok(())
}

/// Reads and checks every log, as the stage `log` of `bar`.
fn read_logs(
    args: &Args,
    space: &smspace::agent::MotorSpace,
    bar: &Bar,
) -> anyhow::Result<Vec<SensorimotorLog>> {
    bar.start("log", args.motors.len() as u64);
    let logs = args
        .motors
        .iter()
        .zip(&args.sensors)
        .map(|(motors, sensors)| {
            let log = SensorimotorLog::load(
                LogFiles {
                    motors: motors.clone(),
                    sensors: sensors.clone(),
                },
                space,
            );
            bar.advance(1);
            log
        })
        .collect::<Result<Vec<_>, _>>();
    bar.finish();
    Ok(logs?)
}

/// What learning found, on stderr: each log's bandwidth, held-out error and noise, the
/// rank the data show, for the invariants law its eigenvalues and `λ`, and the warnings.
fn print_law(report: &smspace::learn::LawReport) {
    for log in &report.logs {
        eprintln!(
            "{}: bandwidth {:.4}, held-out error {:.2e} of the sensors' spread ({} samples held out)",
            log.motors, log.bandwidth, log.held_out_relative_rms, log.held_out
        );
        if log.repeated > 0 {
            eprintln!(
                "  {} of {} samples repeat an earlier motor command and were learned from once",
                log.repeated, log.samples
            );
        }
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
    if let Some(choice) = &report.rank_choice {
        eprintln!(
            "rank: {} ({}; kernels of dimension {}): {}",
            choice.rank,
            match choice.source {
                RankSource::Given => "given",
                RankSource::Data => "the data's spectrum",
                RankSource::Invariants => "the invariants' Jacobian",
                RankSource::Law => "the law's Jacobian",
                RankSource::Retried => "retried",
                RankSource::Agent => "the agent's own slope",
            },
            // `rank_counts` has N + 1 entries.
            report
                .rank_counts
                .len()
                .saturating_sub(1)
                .saturating_sub(choice.rank),
            choice.reason
        );
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
        if let Some(best) = rank.held_out_rank {
            eprintln!(
                "held-out prediction: best at rank {best} (errors {} at ranks 0 to {}, relative to the sensors' spread)",
                rank.held_out
                    .iter()
                    .map(|e| format!("{e:.4}"))
                    .collect::<Vec<_>>()
                    .join(" "),
                rank.held_out.len().saturating_sub(1)
            );
        }
        if report.rank_source == RankSource::Invariants && report.rank < rank.rank {
            let probed: usize = report.rank_counts.iter().sum();
            eprintln!(
                "the invariants change along {} directions at {} of {probed} probed samples: the kernels are traced at rank {} (the slopes' rank {} counts the sensors' curvature across the samples' spacing, or directions the invariants miss)",
                report.rank,
                report.rank_counts.get(report.rank).copied().unwrap_or(0),
                report.rank,
                rank.rank
            );
        }
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
    let quality = &report.quality;
    if let (Some(per), Some(dimension)) =
        (quality.samples_per_dimension, quality.resolved_dimension)
    {
        eprintln!("{per:.0} fitted samples per dimension (of {dimension})");
    }
    if let (Some(change), Some(ratio)) = (quality.neighbour_change, quality.held_out_ratio) {
        eprintln!(
            "the invariants change by {change:.3} of their spread between held-out sensory neighbours ({ratio:.2}× the fitted pairs' λ)"
        );
    }
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
}

/// The set errors of the learned sets against the true ones in `path` (the same
/// starts), under the motors' periods (hinges wrapped by `2π`, bounded motors not).
fn truth_errors(
    traced: &smspace::kernel::TracedSets,
    path: &std::path::Path,
    space: &smspace::agent::MotorSpace,
) -> anyhow::Result<smspace::learn::SetErrors> {
    let truth = smspace::kernel::TracedSets::load(path)?;
    let period = smspace::learn::comparison_period(&space.periods())?;
    smspace::learn::set_errors(traced, &truth, &period)
        .map_err(|e| anyhow::anyhow!("--truth-sets {}: {e}", path.display()))
}
