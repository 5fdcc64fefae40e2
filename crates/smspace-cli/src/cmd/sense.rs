//! `smspace sense`: the sensor values `s = σ_E(m)` of motor configurations.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use smspace::io;

use super::common::{AgentArgs, EnvArgs};

/// Arguments of `smspace sense`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    agent: AgentArgs,
    /// Motor configurations (M, N).
    #[arg(long, value_name = "FILE")]
    motors: PathBuf,
    #[command(flatten)]
    env: EnvArgs,
    /// Output sensor values (M, K).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Runs `smspace sense`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::common::spare_inputs(
        &[&args.out],
        &[
            ("--motors", Some(args.motors.as_path())),
            ("--env", args.env.env.as_deref()),
            ("--agent", args.agent.file()),
        ],
    )?;
    io::check_output_folder(&args.out)?;
    let (spec, agent) = args.agent.load()?;
    let environment = args.env.resolve_or_default(&spec, agent.as_ref())?;
    let n = agent.motor_dim();
    let motors = io::read_matrix(&args.motors, Some(n), &format!("(M, {n})"))?;
    let sensors = smspace::agent::sense_rows(agent.as_ref(), &environment, motors.view())?;
    io::write_npy(&args.out, &sensors)?;
    eprintln!(
        "wrote sensor values {:?} to {}",
        sensors.dim(),
        args.out.display()
    );
    Ok(())
}
