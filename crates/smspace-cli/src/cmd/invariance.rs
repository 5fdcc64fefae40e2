//! `smspace invariance`: the same starts traced with the sensory method in several
//! environments, compared set by set and matrix by matrix, against the sensor values.

use anyhow::Context;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use smspace::agent::EnvironmentConfig;
use smspace::invariance::invariance_measured;
use smspace::io;
use smspace::kernel::{TraceMethod, TraceParams};

use smspace::metric::{MetricRegistry, Periodicity};
use smspace_pipeline::front::{self, MetricRequest};

use super::common::{AgentArgs, WorkspaceArgs};
use crate::ui::Bar;

/// Arguments of `smspace invariance`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    agent: AgentArgs,
    /// Motor configurations (M, N) to trace in every environment.
    #[arg(long, value_name = "FILE")]
    motors: PathBuf,
    /// Seeds of the random environments, comma-separated (at least two).
    #[arg(long, value_name = "S1,S2,...", value_delimiter = ',', required = true)]
    env_seeds: Vec<u64>,
    /// Lights of the environments: one count for all, or one per seed
    /// (default: the agent's).
    #[arg(long, value_name = "L1,L2,...", value_delimiter = ',')]
    lights: Vec<usize>,
    /// Trace only the first N rows of the motors file (as `[analysis]
    /// invariance_starts` in `smspace run`); default: every row.
    #[arg(long, value_name = "N")]
    starts: Option<usize>,
    /// Points per traced set.
    #[arg(long, default_value_t = smspace::kernel::TraceParams::default().points)]
    points: usize,
    /// Distance between two sets: a registered metric, as in `smspace distances` (curve,
    /// the default: the traced loops and segments as polylines; hausdorff or
    /// mean-hausdorff, between the sampled points). An unknown name lists them.
    #[arg(long, value_name = "NAME", default_value = smspace::metric::DEFAULT_METRIC.name())]
    metric: String,
    /// A parameter of the metric, as in an experiment's [metric.params] table
    /// (e.g. --param radius_scale=0.5); repeatable.
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = super::common::parse_param)]
    params: Vec<(String, toml::Value)>,
    /// Period of the motor coordinates, as an experiment's [metric] period: 2pi,
    /// none, motors (the agent's own: hinges 2pi, bounded motors none) or one entry per
    /// motor separated by commas.
    #[arg(long, value_name = "2pi|none|motors|LIST", default_value_t = Periodicity::default(), value_parser = parse_period)]
    period: Periodicity,
    #[command(flatten)]
    workspace: WorkspaceArgs,
    /// Report (JSON); beside it, for environment e (from 1), OUT_STEM-D-e.npy (the
    /// distance matrix of its sets) and OUT_STEM-sensors-e.npy (its sensor values), as
    /// `smspace run` writes them.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// `--period`: as `Periodicity::parse` reads it (`motors` resolved against the agent).
fn parse_period(text: &str) -> Result<Periodicity, String> {
    Periodicity::parse(text).map_err(|e| e.to_string())
}

/// Runs `smspace invariance`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::common::spare_inputs(
        &[&args.out],
        &[
            ("--motors", Some(args.motors.as_path())),
            ("--agent", args.agent.file()),
        ],
    )?;
    let (spec, agent) = args.agent.load()?;
    anyhow::ensure!(
        args.env_seeds.len() >= 2,
        "--env-seeds {:?}: give at least two seeds to compare, e.g. --env-seeds 1,2,3",
        args.env_seeds
    );
    anyhow::ensure!(
        args.lights.len() <= 1 || args.lights.len() == args.env_seeds.len(),
        "--lights has {} counts for {} seeds; give one count for all or one per seed",
        args.lights.len(),
        args.env_seeds.len()
    );
    let params = TraceParams {
        method: TraceMethod::Sensory,
        points: args.points,
        ..TraceParams::default()
    }
    .check()?;
    let n = agent.motor_dim();
    let motors = io::read_matrix(&args.motors, Some(n), &format!("(M, {n})"))?;
    let rows = match args.starts {
        Some(0) => anyhow::bail!(
            "--starts 0: give at least one start (or leave --starts out to trace every row)"
        ),
        Some(starts) => starts.min(motors.nrows()),
        None => motors.nrows(),
    };
    let motors = motors.slice_axis(ndarray::Axis(0), ndarray::Slice::from(..rows));
    let base = spec.environment.clone().unwrap_or_default();
    let environments = args
        .env_seeds
        .iter()
        .enumerate()
        .map(|(i, &seed)| {
            let lights = match args.lights.as_slice() {
                [] => base.lights,
                [all] => Some(*all),
                each => Some(each[i]),
            };
            EnvironmentConfig {
                seed,
                lights,
                ..base.clone()
            }
            .build(agent.as_ref())
        })
        .collect::<Result<Vec<_>, _>>()?;
    let workspace = args.workspace.resolve(agent.as_ref())?;
    let bar = Bar::new();
    let period = front::resolve_period(agent.as_ref(), &args.period).context("--period")?;
    let request = MetricRequest {
        params: args.params.iter().cloned().collect(),
        ..MetricRequest::new(&args.metric, period)
    };
    let built =
        front::metric(&MetricRegistry::builtin(), request).context("--metric and --param")?;
    let metric = built.metric;
    let measured = invariance_measured(
        agent.as_ref(),
        motors,
        &environments,
        workspace.as_ref(),
        &params,
        metric.as_ref(),
        &bar,
    )?;
    // The invariance stage's writer: the report and, beside it, the compared matrices
    // and sensor values.
    measured.save(&args.out)?;
    let report = &measured.report;
    eprintln!(
        "{} sets traced in all {} environments: sets differ by at most {:.3e} ({:.2e} of the median set distance), metric Mantel >= {:.6}; sensor values differ by >= {:.3} of their norm, sensor Mantel <= {:.3}",
        report.common_sets,
        report.environments.len(),
        report.max_set_distance,
        report.max_set_distance_relative,
        report.min_mantel,
        report.min_sensor_difference_relative,
        report.max_sensor_mantel
    );
    Ok(())
}
