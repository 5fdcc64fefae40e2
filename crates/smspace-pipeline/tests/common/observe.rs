//! What the pipeline tests share to run a plan quietly and read which stages it
//! computed.

use smspace::progress::{Progress, Silent};
use smspace_pipeline::{RunObserver, RunSummary};

/// An observer that shows nothing.
pub struct Quiet;

impl RunObserver for Quiet {
    fn progress(&self) -> &dyn Progress {
        &Silent
    }
}

/// Which stages a run computed (the others were read back).
pub fn computed(summary: &RunSummary) -> Vec<String> {
    summary
        .manifest
        .stages
        .iter()
        .filter(|s| !s.cached)
        .map(|s| s.stage.clone())
        .collect()
}
