//! Progress reporting without printing: long stages call an observer, and the caller
//! (the command-line tool draws a progress bar, or prints a line every few seconds
//! when its output is not a terminal) decides what to show.
//!
//! Besides the units of work done, a stage says what it is about to do before a long
//! piece of work, in [`Note`]s: tracing names the kernel dimension and how the sets are
//! sampled (curves traced, or k-D kernels covered densely, which takes far longer), and
//! the time the rest is expected to take, measured on its first sets. No stage runs
//! long without saying so first.

use std::fmt;

/// Receives progress of a long stage. Every method defaults to doing nothing.
///
/// Implementations must be `Sync`: parallel stages call them from worker threads.
pub trait Progress: Sync {
    /// A stage starts with `total` units of work.
    fn start(&self, _stage: &str, _total: u64) {}
    /// `done` more units of work are complete.
    fn advance(&self, _done: u64) {}
    /// The stage is over.
    fn finish(&self) {}
    /// What a stage is about to do, or how long it will take: one sentence for the
    /// user ([`Note`]'s `Display`), given before the work it describes.
    fn note(&self, _note: &Note) {}
}

/// What a stage tells its observer before a long piece of work.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Note {
    /// Tracing is about to start: the kernel dimension `k = N − rank(J)` and how sets
    /// of that dimension are sampled.
    KernelDimension {
        /// Sets to trace.
        sets: u64,
        /// Motors `N`.
        motors: usize,
        /// The kernel dimension `k`.
        dimension: usize,
        /// With `k ≥ 2`: the covering's tangent step (radians) and its node budget per
        /// set (`[kernel] cover_step`, `max_cover_points`).
        covering: Option<(f64, usize)>,
    },
    /// The time the rest of a stage is expected to take, from the time its first units
    /// of work took.
    Estimate {
        /// The stage (`trace`, …).
        stage: String,
        /// What a unit of work is (`sets`, …).
        unit: String,
        /// Units done when measured.
        done: u64,
        /// Units in all.
        total: u64,
        /// Seconds the first `done` units took.
        elapsed_seconds: f64,
        /// Seconds expected for the other `total − done`.
        remaining_seconds: f64,
    },
    /// Tracing noisy readings by the sensory method is about to start: what it is
    /// forecast to cost, as a sentence (the trace summary's `noise_forecast` holds
    /// the figures).
    NoiseForecast(String),
}

/// `1 h 05 min`, `3 min 20 s`, `12 s`, `0.4 s`: a duration as a reader wants it.
pub fn human_duration(seconds: f64) -> String {
    if !seconds.is_finite() || seconds < 0.0 {
        return "unknown".to_owned();
    }
    if seconds < 10.0 {
        return format!("{seconds:.1} s");
    }
    let s = seconds.round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, s % 3600 / 60),
    }
}

impl fmt::Display for Note {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Note::KernelDimension {
                sets,
                motors,
                dimension,
                covering,
            } => {
                let rank = motors.saturating_sub(*dimension);
                write!(
                    f,
                    "trace: {sets} kernel sets of dimension k = {dimension} ({motors} motors, Jacobian rank {rank}): "
                )?;
                match (dimension, covering) {
                    (0, _) => write!(f, "each set is a single point"),
                    (1, _) => write!(f, "each set is a curve, traced step by step"),
                    (k, Some((step, budget))) => write!(
                        f,
                        "each set is a {k}-D surface, covered densely (tangent step {step} rad, at most {budget} nodes a set) and sampled farthest first instead of traced as a curve; this takes far longer than curves"
                    ),
                    (k, None) => write!(f, "each set is a {k}-D surface, covered densely"),
                }
            }
            Note::Estimate {
                stage,
                unit,
                done,
                total,
                elapsed_seconds,
                remaining_seconds,
            } => write!(
                f,
                "{stage}: about {} for the other {} {unit} (the first {done} took {})",
                human_duration(*remaining_seconds),
                total.saturating_sub(*done),
                human_duration(*elapsed_seconds)
            ),
            Note::NoiseForecast(forecast) => write!(f, "trace: {forecast}"),
        }
    }
}

/// A [`Progress`] that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_as_a_person_would_say_them() {
        assert_eq!(human_duration(0.42), "0.4 s");
        assert_eq!(human_duration(12.4), "12 s");
        assert_eq!(human_duration(200.0), "3 min 20 s");
        assert_eq!(human_duration(3900.0), "1 h 05 min");
        assert_eq!(human_duration(f64::NAN), "unknown");
    }

    #[test]
    fn a_covering_is_announced_with_its_cost() {
        let note = Note::KernelDimension {
            sets: 40,
            motors: 5,
            dimension: 2,
            covering: Some((0.05, 100_000)),
        };
        let text = note.to_string();
        assert!(text.contains("dimension k = 2"), "{text}");
        assert!(text.contains("Jacobian rank 3"), "{text}");
        assert!(text.contains("covered densely"), "{text}");
        assert!(text.contains("far longer than curves"), "{text}");
        let curve = Note::KernelDimension {
            sets: 40,
            motors: 4,
            dimension: 1,
            covering: None,
        };
        assert!(curve.to_string().contains("a curve"));
    }
}
