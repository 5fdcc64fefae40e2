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
    smspace_pipeline::report::compare::write_comparison(&args.runs, &args.out)?;
    eprintln!(
        "compared {} runs in {}",
        args.runs.len(),
        args.out.display()
    );
    Ok(())
}
