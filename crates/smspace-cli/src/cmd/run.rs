//! `smspace run`: a whole experiment from its TOML file, with a cache.

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use smspace::progress::Progress;
use smspace_pipeline::config::load_experiment;
use smspace_pipeline::{
    self, manifest::StageRecord, BusyFolder, Recompute, RunObserver, RunOptions, StageId,
};

use crate::ui::Bar;
use smspace_pipeline::front::{
    default_run_dir, memory_limit, own_folder_line, stage_line, waiting_line, StageEvent,
};

/// Arguments of `smspace run`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The experiment file (TOML), e.g. experiments/paper-arm.toml.
    #[arg(value_name = "EXPERIMENT")]
    experiment: PathBuf,
    /// Run folder (default: runs/<experiment name>, or runs/<experiment name>-<hash>
    /// with --set, so that a run with overrides never replaces the unmodified one).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Override a parameter: stage.key=value, e.g. --set kernel.points=50
    /// --set embedding.method=isomap (repeatable).
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    overrides: Vec<String>,
    /// Recompute every stage, even those whose inputs and parameters did not change.
    #[arg(long)]
    force: bool,
    /// When another smspace run is writing the same folder, wait for it to end instead
    /// of refusing.
    #[arg(long)]
    wait: bool,
    /// Refuse a stage whose estimated peak memory is more than this many bytes, before
    /// it starts (default: the memory available, MemAvailable in /proc/meminfo). The
    /// distance matrix is also held to the experiment's [metric] memory_limit_bytes.
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
}

/// Prints one line per stage on stderr, with progress bars when it is a terminal.
struct StageLog {
    bar: Bar,
    terminal: bool,
}

impl RunObserver for StageLog {
    fn progress(&self) -> &dyn Progress {
        &self.bar
    }

    fn stage_started(&self, stage: StageId) {
        if !self.terminal {
            eprintln!("{}", stage_line(stage, StageEvent::Started));
        }
    }

    fn stage_finished(&self, stage: StageId, record: &StageRecord, summary: &str) {
        eprintln!(
            "{}",
            stage_line(stage, StageEvent::Finished { record, summary })
        );
    }

    fn stage_note(&self, stage: StageId, note: &str) {
        eprintln!("{}", stage_line(stage, StageEvent::Note(note)));
    }

    fn stage_skipped(&self, stage: StageId, why: &str) {
        eprintln!("{}", stage_line(stage, StageEvent::Skipped(why)));
    }

    fn waiting_for_folder(&self, lock: &std::path::Path) {
        eprintln!("{}", waiting_line(lock));
    }
}

/// Runs `smspace run`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let loaded = load_experiment(&args.experiment, &args.overrides)?;
    let plan = smspace_pipeline::check(&loaded)?;
    let out_dir = match args.out {
        Some(dir) => dir,
        None => {
            let dir = default_run_dir(&loaded.name, &args.overrides);
            if !args.overrides.is_empty() {
                eprintln!("{}", own_folder_line(&dir, &loaded.name, "--set", "--out"));
            }
            dir
        }
    };
    let options = RunOptions {
        out_dir,
        recompute: if args.force {
            Recompute::All
        } else {
            Recompute::Changed
        },
        memory_limit_bytes: memory_limit(args.max_memory),
        busy: if args.wait {
            BusyFolder::Wait
        } else {
            BusyFolder::Refuse
        },
    };
    let log = StageLog {
        bar: Bar::new(),
        terminal: std::io::stderr().is_terminal(),
    };
    eprintln!(
        "[smspace] experiment {} ({}) into {}",
        loaded.name,
        args.experiment.display(),
        options.out_dir.display()
    );
    let summary = smspace_pipeline::run(&plan, &options, &log)?;
    let computed = summary.manifest.stages.iter().filter(|s| !s.cached).count();
    eprintln!(
        "[smspace] done in {:.2} s ({computed} of {} stages computed): {}",
        summary.manifest.total_seconds,
        summary.manifest.stages.len(),
        summary.dir.join("report.html").display()
    );
    Ok(())
}
