//! `smspace env`: draw an environment of point lights and save it as JSON.

use std::path::PathBuf;

use clap::Args as ClapArgs;

use super::common::{AgentArgs, EnvArgs};

/// Arguments of `smspace env`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    agent: AgentArgs,
    #[command(flatten)]
    env: EnvArgs,
    /// Output JSON file.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Runs `smspace env`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::common::spare_inputs(
        &[&args.out],
        &[
            ("--env", args.env.env.as_deref()),
            ("--agent", args.agent.file()),
        ],
    )?;
    let (spec, agent) = args.agent.load()?;
    let environment = args.env.resolve_or_default(&spec, agent.as_ref())?;
    environment.save(&args.out)?;
    eprintln!(
        "wrote {} lights for the {} agent to {}",
        environment.lights.len(),
        agent.name(),
        args.out.display()
    );
    Ok(())
}
