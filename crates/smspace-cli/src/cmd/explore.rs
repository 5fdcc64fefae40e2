//! `smspace explore`: motor babbling in the working space, plus the probe grid.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use smspace::explore::{explore_in, ExploreParams, Probes};

use super::common::{AgentArgs, WorkspaceArgs};

/// Arguments of `smspace explore`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    agent: AgentArgs,
    /// Number of configurations to keep in the working space.
    #[arg(long, default_value_t = ExploreParams::default().n)]
    n: usize,
    /// Seed of the babbling.
    #[arg(long, default_value_t = ExploreParams::default().seed)]
    seed: u64,
    /// Append the probe grid (10 × 10 positions × 10 orientations by default).
    #[arg(long)]
    probes: bool,
    /// Probe positions along each side of the working space.
    #[arg(long, default_value_t = ExploreParams::default().probe_positions, requires = "probes")]
    probe_positions: usize,
    /// Probe orientations, evenly spaced from 0.
    #[arg(long, default_value_t = ExploreParams::default().probe_orientations, requires = "probes")]
    probe_orientations: usize,
    /// A key of the [exploration] table that has no flag of its own
    /// (max_draws_per_kept), the value in TOML; repeatable.
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = super::common::parse_param)]
    params: Vec<(String, toml::Value)>,
    #[command(flatten)]
    workspace: WorkspaceArgs,
    /// Folder for motors.npy, poses.npy (when the agent has a ground truth), probes.npy
    /// and exploration.json (created if needed).
    #[arg(long, value_name = "DIR")]
    out_dir: PathBuf,
    /// Refuse to start when the output needs more than this many bytes (default: the
    /// memory available, MemAvailable in /proc/meminfo).
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
}

/// [exploration] keys that have a flag of their own (the working space's: --workspace).
const EXPLORATION_FLAGS: [(&str, &str); 7] = [
    ("n", "n"),
    ("seed", "seed"),
    ("probes", "probes"),
    ("probe_positions", "probe-positions"),
    ("probe_orientations", "probe-orientations"),
    ("workspace_center", "workspace"),
    ("workspace_size", "workspace"),
];

/// Runs `smspace explore`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let written: Vec<PathBuf> = smspace::explore::EXPLORATION_FILES
        .iter()
        .map(|f| args.out_dir.join(f))
        .collect();
    let written: Vec<&std::path::Path> = written.iter().map(PathBuf::as_path).collect();
    super::common::spare_inputs(&written, &[("--agent", args.agent.file())])?;
    let (spec, agent) = args.agent.load()?;
    let workspace = args.workspace.resolve(agent.as_ref())?;
    let params = ExploreParams {
        n: args.n,
        seed: args.seed,
        workspace_center: workspace.map(|w| w.center),
        workspace_size: workspace.map(|w| w.size),
        probes: if args.probes {
            Probes::Grid
        } else {
            Probes::None
        },
        probe_positions: args.probe_positions,
        probe_orientations: args.probe_orientations,
        ..ExploreParams::default()
    };
    let params =
        super::common::with_table_params(&params, &args.params, &EXPLORATION_FLAGS, "exploration")?;
    let pose_dim = agent.ground_truth().map_or(0, |o| o.pose_space().dim());
    super::common::check_memory(
        "explored configurations",
        params.bytes(agent.motor_dim(), pose_dim),
        args.max_memory,
        "lower --n or the probe grid",
    )?;
    let exploration = explore_in(agent.as_ref(), &params, workspace)?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("cannot create {}", args.out_dir.display()))?;
    let dir = &args.out_dir;
    exploration.save(dir, &spec.agent, &params)?;
    let probe_count = exploration.probe_count();
    eprintln!(
        "explored {} configurations ({} babbled, {} probes) of the {} agent into {}",
        exploration.motors.nrows(),
        exploration.motors.nrows() - probe_count,
        probe_count,
        agent.name(),
        dir.display()
    );
    Ok(())
}
