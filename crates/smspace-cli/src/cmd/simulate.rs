//! `smspace simulate`: a sensorimotor log of an agent (what a robot would record), for
//! trying `smspace learn` without a robot.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use smspace::learn::{simulate, LogRecord, SimulateParams, SimulatedLog};

use super::common::{AgentArgs, EnvArgs, WorkspaceArgs};

/// Arguments of `smspace simulate`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    agent: AgentArgs,
    /// Samples S of the log.
    #[arg(long, default_value_t = SimulateParams::default().samples)]
    n: usize,
    /// The Gaussian noise added to every sensor value: its standard deviation as a
    /// fraction of each sensor's spread (its standard deviation over the log), e.g. 0.01
    /// for 1 %. The [data.simulate] key relative_noise.
    #[arg(long, default_value_t = 0.0)]
    relative_noise: f64,
    /// The old name of --relative-noise: refused with the new one.
    #[arg(long = "noise", hide = true, allow_hyphen_values = true)]
    old_noise: Option<String>,
    /// Seed of the babbling and of the noise.
    #[arg(long, default_value_t = SimulateParams::default().seed)]
    seed: u64,
    #[command(flatten)]
    env: EnvArgs,
    #[command(flatten)]
    workspace: WorkspaceArgs,
    /// Folder for motors.npy (S, N), sensors.npy (S, K), poses.npy (S, d; for
    /// evaluation only, when the agent has a ground truth), environment.json, log.json.
    #[arg(long, value_name = "DIR")]
    out_dir: PathBuf,
    /// Refuse to start when the log needs more than this many bytes (default: the
    /// memory available, MemAvailable in /proc/meminfo).
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
}

/// Runs `smspace simulate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(value) = &args.old_noise {
        anyhow::bail!(
            "--noise is now --relative-noise (the noise added, as a fraction of each sensor's spread): write --relative-noise {value}"
        );
    }
    let written: Vec<PathBuf> = smspace::learn::SIMULATED_LOG_FILES
        .iter()
        .map(|f| args.out_dir.join(f))
        .collect();
    let written: Vec<&std::path::Path> = written.iter().map(PathBuf::as_path).collect();
    super::common::spare_inputs(
        &written,
        &[
            ("--env", args.env.env.as_deref()),
            ("--agent", args.agent.file()),
        ],
    )?;
    let (spec, agent) = args.agent.load()?;
    let environment = args.env.resolve_or_default(&spec, agent.as_ref())?;
    let workspace = args.workspace.resolve(agent.as_ref())?;
    let pose_dim = agent.ground_truth().map_or(0, |o| o.pose_space().dim());
    super::common::check_memory(
        "simulated log",
        SimulatedLog::bytes(args.n, agent.motor_dim(), agent.sensor_dim(), pose_dim),
        args.max_memory,
        "lower --n",
    )?;
    let params = SimulateParams {
        samples: args.n,
        noise: args.relative_noise,
        seed: args.seed,
        ..SimulateParams::default()
    };
    let log = simulate(agent.as_ref(), &environment, workspace, &params)?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("cannot create {}", args.out_dir.display()))?;
    let mut files = vec!["motors.npy", "sensors.npy"];
    if log.poses.is_some() {
        files.push("poses.npy");
    }
    files.extend(["environment.json", "log.json"]);
    let record = LogRecord {
        agent: spec.agent.clone(),
        simulate: params,
        workspace,
        files: files.iter().map(|f| f.to_string()).collect(),
    };
    log.save(&args.out_dir, &environment, &record)?;
    eprintln!(
        "simulated {} samples of the {} agent ({} motors, {} sensors, noise {} of the spread) into {}",
        log.motors.nrows(),
        agent.name(),
        agent.motor_dim(),
        agent.sensor_dim(),
        args.relative_noise,
        args.out_dir.display()
    );
    Ok(())
}
