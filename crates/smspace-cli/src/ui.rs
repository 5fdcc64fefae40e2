//! Terminal concerns: thread pool set-up, progress bars, broken pipes.

use std::sync::Mutex;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};

/// Sets the size of rayon's global pool (`None`: `RAYON_NUM_THREADS` when set, else one
/// thread per core); refuses more than
/// [`smspace::threads::MAX_THREADS_PER_CORE`] per core, from either.
pub fn init_threads(threads: Option<usize>) -> anyhow::Result<()> {
    let threads = match threads {
        Some(threads) => Some(smspace::threads::check_threads(threads, "--threads")?),
        None => smspace::threads::check_variable()?,
    };
    if let Some(threads) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .context("cannot set up the thread pool")?;
    }
    Ok(())
}

/// True when the error chain holds a broken pipe (output piped into `head`, say).
pub fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// A progress bar on stderr, drawn only when stderr is a terminal (indicatif hides
/// itself otherwise), fed by the library's [`smspace::progress::Progress`] observer.
#[derive(Default)]
pub struct Bar {
    bar: Mutex<Option<ProgressBar>>,
}

#[allow(dead_code, reason = "used by the subcommands as they are added")]
impl Bar {
    /// A bar with no stage yet.
    pub fn new() -> Self {
        Self::default()
    }
}

impl smspace::progress::Progress for Bar {
    fn start(&self, stage: &str, total: u64) {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} {per_sec} (eta {eta})")
                .expect("the template is valid")
                .progress_chars("=> "),
        );
        bar.set_message(stage.to_owned());
        *self.bar.lock().expect("progress lock") = Some(bar);
    }

    fn advance(&self, done: u64) {
        if let Some(bar) = self.bar.lock().expect("progress lock").as_ref() {
            bar.inc(done);
        }
    }

    fn finish(&self) {
        if let Some(bar) = self.bar.lock().expect("progress lock").take() {
            bar.finish_and_clear();
        }
    }
}
