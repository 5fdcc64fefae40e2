//! `smspace compare`: runs side by side on one page (`smspace_pipeline::report::compare`).

use std::path::PathBuf;

use clap::Args as ClapArgs;

/// Arguments of `smspace compare`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Run folders (as `smspace run` writes them, e.g. runs/pupil runs/pupil-space), two
    /// or more, in the order of the page's columns.
    #[arg(value_name = "RUN", num_args = 2.., required = true)]
    runs: Vec<PathBuf>,
    /// The page (HTML, self-contained: the figures are embedded).
    #[arg(long, value_name = "FILE", default_value = "compare.html")]
    out: PathBuf,
}

/// Runs `smspace compare`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // The page must not replace a file of the runs it reads.
    let mut files = Vec::new();
    for run in &args.runs {
        if let Ok(entries) = std::fs::read_dir(run) {
            files.extend(entries.filter_map(|e| e.ok()).map(|e| e.path()));
        }
    }
    let inputs: Vec<(&str, Option<&std::path::Path>)> = files
        .iter()
        .map(|f| ("run file", Some(f.as_path())))
        .collect();
    super::common::spare_inputs(&[&args.out], &inputs)?;
    smspace_pipeline::report::compare::write_comparison(&args.runs, &args.out)?;
    eprintln!(
        "compared {} runs in {}",
        args.runs.len(),
        args.out.display()
    );
    Ok(())
}
