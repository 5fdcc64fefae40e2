//! `smspace`: the command-line front end of the smspace library.
//!
//! This binary only parses arguments, calls the library and reports errors; every
//! computation lives in the `smspace` crate.

mod cmd;
mod ui;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// A naive sensorimotor agent learns its own spatial configuration
/// (Laflaquière et al. 2015).
#[derive(Debug, Parser)]
#[command(name = "smspace", version, about, long_about = None)]
struct Cli {
    /// Worker threads for parallel stages (default: all cores).
    #[arg(long, global = true, value_name = "T")]
    threads: Option<usize>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a whole experiment (explore → trace → distances → embed → analyze → report)
    /// from a TOML file, with a cache: runs/<name>/report.html.
    Run(cmd::run::Args),
    /// Motor babbling in the working space (and the probe grid): motors.npy, poses.npy.
    Explore(cmd::explore::Args),
    /// Trace the kernel sets M^i through explored motor configurations: sets.npy.
    Trace(cmd::trace::Args),
    /// Draw an environment of point lights: env.json.
    Env(cmd::env::Args),
    /// Sensor values s = σ_E(m) of motor configurations: sensors.npy.
    Sense(cmd::sense::Args),
    /// Distances between kernel sets: the (periodic) Hausdorff matrix, a block of its
    /// rows, or the k nearest sets of every set.
    Distances(cmd::distances::Args),
    /// Embed a distance matrix in a few dimensions (CCA, Isomap or classical MDS).
    Embed(cmd::embed::Args),
    /// Topology, dimension and agreement with the poses of a distance matrix: report.json.
    Analyze(cmd::analyze::Args),
    /// The same starts traced in several environments, compared: invariance.json.
    Invariance(cmd::invariance::Args),
    /// A sensorimotor log of an agent (motors.npy, sensors.npy), as a robot would
    /// record it: the input of `smspace learn`.
    Simulate(cmd::simulate::Args),
    /// Kernel sets from recorded data: learn the law s(m) from logs and trace the sets
    /// through starts: sets.npy (as `smspace trace`) and sets.law.json.
    Learn(cmd::learn::Args),
    /// Runs side by side on one page: dimension, Betti numbers, agreement with the
    /// poses, compensability d per base point and the embeddings (compare.html).
    Compare(cmd::compare::Args),
}

fn run(cli: Cli) -> anyhow::Result<()> {
    ui::init_threads(cli.threads)?;
    match cli.command {
        Command::Run(args) => cmd::run::run(args),
        Command::Explore(args) => cmd::explore::run(args),
        Command::Trace(args) => cmd::trace::run(args),
        Command::Env(args) => cmd::env::run(args),
        Command::Sense(args) => cmd::sense::run(args),
        Command::Distances(args) => cmd::distances::run(args),
        Command::Embed(args) => cmd::embed::run(args),
        Command::Analyze(args) => cmd::analyze::run(args),
        Command::Invariance(args) => cmd::invariance::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
        Command::Learn(args) => cmd::learn::run(args),
        Command::Compare(args) => cmd::compare::run(args),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            if ui::is_broken_pipe(&error) {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
