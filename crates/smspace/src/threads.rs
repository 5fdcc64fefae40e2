//! The size of the worker pool: at most [`MAX_THREADS_PER_CORE`] threads per core,
//! however it is asked for (the command line's `--threads`, or the `RAYON_NUM_THREADS`
//! variable that the pool reads when nobody sets it up).
//!
//! Threads beyond a few per core only slow a run down, and a pool of `10⁵` threads
//! takes minutes (and gigabytes of stacks) to start: such a request is refused with
//! the limit, before any thread starts.

/// Most worker threads per core.
pub const MAX_THREADS_PER_CORE: usize = 4;

/// The variable the worker pool reads when its size is not set up.
pub const THREADS_VARIABLE: &str = "RAYON_NUM_THREADS";

/// A thread count beyond the limit (or zero).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ThreadsError {
    /// More threads than [`MAX_THREADS_PER_CORE`] per core.
    #[error("{source_name} = {threads} is more than {MAX_THREADS_PER_CORE} threads per core ({cap} on this machine's {cores} cores): more threads only slow the run down; give at most {cap}, or leave it unset to use every core")]
    TooMany {
        /// Where the count came from (`--threads`, `RAYON_NUM_THREADS`).
        source_name: String,
        /// The count asked for.
        threads: usize,
        /// The limit on this machine.
        cap: usize,
        /// The machine's cores.
        cores: usize,
    },
    /// Zero threads.
    #[error("{source_name} must be at least 1, got 0")]
    Zero {
        /// Where the count came from.
        source_name: String,
    },
}

/// The machine's cores (1 when unknown).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The most threads this machine accepts: [`MAX_THREADS_PER_CORE`] per core.
pub fn max_threads() -> usize {
    MAX_THREADS_PER_CORE.saturating_mul(cores())
}

/// `threads` when it is within [`max_threads`]; `source_name` names where it came from
/// in the error.
pub fn check_threads(threads: usize, source_name: &str) -> Result<usize, ThreadsError> {
    if threads == 0 {
        return Err(ThreadsError::Zero {
            source_name: source_name.to_owned(),
        });
    }
    let cap = max_threads();
    if threads > cap {
        return Err(ThreadsError::TooMany {
            source_name: source_name.to_owned(),
            threads,
            cap,
            cores: cores(),
        });
    }
    Ok(threads)
}

/// The thread count of the value `text` of [`THREADS_VARIABLE`]: `None` for a value
/// the pool ignores (empty, `0`, or not a number: the pool then uses every core),
/// the count when it is within the limit, an error beyond it.
pub fn check_variable_value(text: &str) -> Result<Option<usize>, ThreadsError> {
    match text.trim().parse::<usize>() {
        Ok(0) | Err(_) => {
            // A count too large for `usize` is still a count: refuse it.
            let text = text.trim();
            let digits = !text.is_empty() && text.bytes().all(|b| b.is_ascii_digit());
            if digits && !text.trim_start_matches('0').is_empty() {
                return Err(ThreadsError::TooMany {
                    source_name: THREADS_VARIABLE.to_owned(),
                    threads: usize::MAX,
                    cap: max_threads(),
                    cores: cores(),
                });
            }
            Ok(None)
        }
        Ok(n) => check_threads(n, THREADS_VARIABLE).map(Some),
    }
}

/// [`check_variable_value`] of the process's [`THREADS_VARIABLE`] (`None` when unset).
pub fn check_variable() -> Result<Option<usize>, ThreadsError> {
    match std::env::var(THREADS_VARIABLE) {
        Ok(text) => check_variable_value(&text),
        Err(_) => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_counts_beyond_four_per_core_are_refused() {
        let cap = max_threads();
        assert_eq!(check_threads(cap, "--threads").unwrap(), cap);
        assert!(check_threads(0, "--threads").is_err());
        let error = check_threads(cap + 1, "--threads").unwrap_err().to_string();
        assert!(error.contains("more than 4 threads per core"), "{error}");
        assert_eq!(check_variable_value("").unwrap(), None);
        assert_eq!(check_variable_value("0").unwrap(), None);
        assert_eq!(check_variable_value("lots").unwrap(), None);
        assert_eq!(check_variable_value("1").unwrap(), Some(1));
        let error = check_variable_value("100000").unwrap_err().to_string();
        assert!(error.contains("RAYON_NUM_THREADS = 100000"), "{error}");
        assert!(check_variable_value("99999999999999999999999999").is_err());
    }
}
