//! Terminal concerns: thread pool set-up, progress bars, broken pipes.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use smspace::progress::{human_duration, Note};

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

/// Seconds between two progress lines when stderr is not a terminal (a log file, a
/// CI job); `SMSPACE_PROGRESS_INTERVAL` sets another (0: a line per unit of work).
const DEFAULT_LINE_INTERVAL: f64 = 5.0;

/// Progress on stderr, fed by the library's [`smspace::progress::Progress`] observer:
/// a bar when stderr is a terminal; otherwise (a log, a pipe) a plain line every few
/// seconds, `trace: 120 of 2500 (4.8 %), 12 s so far, about 4 min 02 s left`, and a
/// last one when such a stage ends. The library's notes (the kernel dimension, the
/// estimated time) are printed as they come, either way.
///
/// With timings ([`Bar::with_timings`]) every stage prints how long it took as it ends:
/// `pairs: 900000 in 12 s`.
pub struct Bar {
    state: Mutex<Option<Shown>>,
    terminal: bool,
    interval: f64,
    timings: bool,
}

/// What is on screen for the current stage.
enum Shown {
    /// The bar, the stage and when it started.
    Bar(ProgressBar, String, Instant),
    Lines(Lines),
}

/// The plain lines of a stage when stderr is not a terminal.
struct Lines {
    stage: String,
    total: u64,
    done: u64,
    started: Instant,
    /// Seconds after `started` of the last line printed, if any.
    last: Option<f64>,
}

impl Default for Bar {
    fn default() -> Self {
        Self::new()
    }
}

impl Bar {
    /// A bar with no stage yet, drawn as a bar or as lines depending on stderr.
    pub fn new() -> Self {
        let interval = std::env::var("SMSPACE_PROGRESS_INTERVAL")
            .ok()
            .and_then(|v| v.trim().parse::<f64>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
            .unwrap_or(DEFAULT_LINE_INTERVAL);
        Self {
            state: Mutex::new(None),
            terminal: std::io::stderr().is_terminal(),
            interval,
            timings: false,
        }
    }

    /// A bar that also prints every stage's duration as it ends.
    pub fn with_timings() -> Self {
        Self {
            timings: true,
            ..Self::new()
        }
    }
}

/// One progress line: `stage: done of total (p %), elapsed so far, about r left`.
fn progress_line(stage: &str, done: u64, total: u64, elapsed: f64) -> String {
    let share = if total > 0 {
        done as f64 / total as f64
    } else {
        1.0
    };
    let left = if done > 0 && done < total {
        format!(
            ", about {} left",
            human_duration(elapsed * (total - done) as f64 / done as f64)
        )
    } else {
        String::new()
    };
    format!(
        "{stage}: {done} of {total} ({:.1} %), {} so far{left}",
        100.0 * share,
        human_duration(elapsed)
    )
}

impl Lines {
    /// The line to print after `done` more units at `now` seconds, if one is due
    /// (`interval` seconds after the last one, or after the start).
    fn advance(&mut self, done: u64, now: f64, interval: f64) -> Option<String> {
        self.done = (self.done + done).min(self.total);
        let since = now - self.last.unwrap_or(0.0);
        (since >= interval).then(|| {
            self.last = Some(now);
            progress_line(&self.stage, self.done, self.total, now)
        })
    }
}

impl smspace::progress::Progress for Bar {
    fn start(&self, stage: &str, total: u64) {
        let shown = if self.terminal {
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(
                    "{msg:>10} [{bar:40}] {pos}/{len} {per_sec} (eta {eta})",
                )
                .expect("the template is valid")
                .progress_chars("=> "),
            );
            bar.set_message(stage.to_owned());
            Shown::Bar(bar, stage.to_owned(), Instant::now())
        } else {
            Shown::Lines(Lines {
                stage: stage.to_owned(),
                total,
                done: 0,
                started: Instant::now(),
                last: None,
            })
        };
        *self.state.lock().expect("progress lock") = Some(shown);
    }

    fn advance(&self, done: u64) {
        let line = match self.state.lock().expect("progress lock").as_mut() {
            Some(Shown::Bar(bar, _, _)) => {
                bar.inc(done);
                None
            }
            Some(Shown::Lines(lines)) => {
                let now = lines.started.elapsed().as_secs_f64();
                lines.advance(done, now, self.interval)
            }
            None => None,
        };
        if let Some(line) = line {
            eprintln!("{line}");
        }
    }

    fn finish(&self) {
        match self.state.lock().expect("progress lock").take() {
            Some(Shown::Bar(bar, stage, started)) => {
                bar.finish_and_clear();
                if self.timings {
                    eprintln!(
                        "{stage}: {} in {}",
                        bar.position(),
                        human_duration(started.elapsed().as_secs_f64())
                    );
                }
            }
            // A stage that printed lines (or is timed) says that it ended.
            Some(Shown::Lines(lines)) if lines.last.is_some() || self.timings => {
                let elapsed = lines.started.elapsed().as_secs_f64();
                eprintln!(
                    "{}: {} of {} done in {}",
                    lines.stage,
                    lines.done,
                    lines.total,
                    human_duration(elapsed)
                );
            }
            _ => {}
        }
    }

    fn note(&self, note: &Note) {
        let state = self.state.lock().expect("progress lock");
        match state.as_ref() {
            Some(Shown::Bar(bar, _, _)) => bar.println(note.to_string()),
            _ => eprintln!("{note}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_progress_line_says_how_far_and_how_long() {
        let line = progress_line("trace", 120, 2500, 12.0);
        assert_eq!(
            line,
            "trace: 120 of 2500 (4.8 %), 12 s so far, about 3 min 58 s left"
        );
        // Done: no time left to guess.
        assert_eq!(
            progress_line("trace", 10, 10, 3.0),
            "trace: 10 of 10 (100.0 %), 3.0 s so far"
        );
    }

    #[test]
    fn lines_come_every_interval_and_not_more_often() {
        let mut lines = Lines {
            stage: "trace".to_owned(),
            total: 100,
            done: 0,
            started: Instant::now(),
            last: None,
        };
        // Nothing before the first interval, then one line, then none until the next.
        assert_eq!(lines.advance(1, 1.0, 5.0), None);
        assert!(lines
            .advance(1, 5.5, 5.0)
            .unwrap()
            .starts_with("trace: 2 of 100"));
        assert_eq!(lines.advance(1, 9.0, 5.0), None);
        assert!(lines
            .advance(1, 10.6, 5.0)
            .unwrap()
            .starts_with("trace: 4 of 100"));
        // An interval of 0: a line for every unit.
        assert!(lines.advance(1, 10.7, 0.0).is_some());
        assert!(lines
            .advance(200, 10.8, 0.0)
            .unwrap()
            .starts_with("trace: 100 of 100"));
    }
}
