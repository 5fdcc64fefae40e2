//! The memory learning needs, estimated from the logs' shapes and the law's parameters
//! before anything is built, so that a log too large for the limit is refused with the
//! figure and what to lower instead of being killed by the system.
//!
//! With `S` samples of a log (`S_f` fitted), `N` motors (`P` periodic), `K` sensors, `T`
//! worker threads and float64 values (8 bytes), the parts at their largest are:
//!
//! | part | bytes |
//! |---|---|
//! | the log | `8 S (N + K)`, and the local fits' copy of the sensors, `8 S K` |
//! | k-d trees | the tree of the fitted samples with their periodic images (at most `1.5^P` per sample: the bandwidth is below a quarter period), `S_f 1.5^P (8N + 8)`; the plain tree of the bandwidth, `S_f (8N + 8)`; for `invariants`, the larger of the sensor tree (`S_f (8K + 8)`) and the tree of the invariants (`S_f (8 · 32 + 8)`), and the pairs `8 S_f` |
//! | basis | `invariants`: eight `F × F` matrices (`64 F²`, `F = 3^N − 1`: the sums, `Σ`, `C`, the factor, the whitened `C`, its eigenvectors, scratch), a group of blocks' sums (64 MiB, or one block's `16 F²`), and the `P_p` pairs' rows, kept rows and changes (`24 P_p`; `P_p = S_f` up to five motors, about 140 000 past) |
//! | per thread | `invariants`: one block's `φ` and `Δ` (`2 · 2^21` values, `32 MiB`); local fits: the samples of one fit and the candidates of the next (`(1.5^P + 2) · neighbours · (3 + N + 2p + 2K) · 8`, `p` the fit's coefficients); times `T` (the law's report gives one thread's: it is the same for any thread count) |
//! | traced sets | `(M, P_s, N)` float64 and the piece of every point (`8 M P_s (N + 1)`), given by the caller |
//!
//! The estimate is an upper bound for the trees (the images are counted at their most)
//! and counts every part as held at once.

use serde::{Deserialize, Serialize};

use super::invariants::{pair_count, InvariantModel, MAX_INVARIANTS};
use super::tree::KdTree;
use super::{LawMethod, LawValidParams};

/// Default limit on what learning may need, in GiB (`[data] memory_limit_gib`, and
/// `smspace learn` unless `--max-memory` is given): 16 GiB, which a log of ten million
/// samples of the paper's arm stays well under.
pub const DEFAULT_MEMORY_LIMIT_GIB: f64 = 16.0;

/// What learning needs, part by part (see the module docs), in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct MemoryEstimate {
    /// The logs' arrays and their copies.
    pub log_bytes: u64,
    /// The k-d trees (periodic images included) and the sensory pairs.
    pub tree_bytes: u64,
    /// The invariants' basis sums and matrices (0 for the local fits).
    pub basis_bytes: u64,
    /// One worker thread's buffers.
    pub bytes_per_thread: u64,
    /// The traced sets (0 until the caller adds them: [`MemoryEstimate::with_sets`]).
    pub sets_bytes: u64,
    /// Worker threads counted in the total; `None` in the law's report, which is the
    /// same for any thread count (the total then counts one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
}

impl MemoryEstimate {
    /// Every worker thread's buffers together.
    pub fn threads_bytes(&self) -> u64 {
        self.bytes_per_thread
            .saturating_mul(self.threads.unwrap_or(1) as u64)
    }

    /// The sum of the parts.
    pub fn total_bytes(&self) -> u64 {
        [
            self.log_bytes,
            self.tree_bytes,
            self.basis_bytes,
            self.threads_bytes(),
            self.sets_bytes,
        ]
        .into_iter()
        .fold(0, u64::saturating_add)
    }

    /// The same with the traced sets' `bytes`.
    pub fn with_sets(self, bytes: u64) -> Self {
        Self {
            sets_bytes: bytes,
            ..self
        }
    }

    /// `log 128 MiB, trees 512 MiB, basis 1 MiB, 2 threads 2 MiB, sets 8 MiB`.
    pub fn parts(&self) -> String {
        let human = crate::metric::human_bytes;
        let mut text = format!(
            "log {}, trees {}",
            human(self.log_bytes),
            human(self.tree_bytes)
        );
        if self.basis_bytes > 0 {
            text.push_str(&format!(", basis {}", human(self.basis_bytes)));
        }
        match self.threads {
            Some(threads) => text.push_str(&format!(
                ", {threads} threads {}",
                human(self.threads_bytes())
            )),
            None => text.push_str(&format!(", {} per thread", human(self.bytes_per_thread))),
        }
        if self.sets_bytes > 0 {
            text.push_str(&format!(", sets {}", human(self.sets_bytes)));
        }
        text
    }

    /// What to lower when the total is over a limit: the largest part's remedy.
    pub fn fix(&self) -> &'static str {
        let parts = [
            (self.log_bytes.saturating_add(self.tree_bytes), 0),
            (self.basis_bytes, 1),
            (self.threads_bytes(), 2),
            (self.sets_bytes, 3),
        ];
        let largest = parts.iter().max_by_key(|p| p.0).map_or(0, |p| p.1);
        match largest {
            1 => "the invariants' basis of 3^N − 1 functions dominates (its F × F matrices do not shrink with the log): use method = local-quadratic (no basis), or raise the limit ([data] memory_limit_gib, smspace learn --max-memory)",
            2 => "the worker threads' buffers dominate: use fewer threads (--threads), or raise the limit ([data] memory_limit_gib, smspace learn --max-memory)",
            3 => "the traced sets dominate: trace fewer starts, or fewer points per set ([kernel] points, --points)",
            _ => "the log and its k-d trees dominate: learn from fewer samples (cut the log: the error of the law falls slowly with the samples), hold more of them out ([data.law] holdout, --holdout), or raise the limit ([data] memory_limit_gib, smspace learn --max-memory)",
        }
    }
}

/// Bytes of a [`DEFAULT_MEMORY_LIMIT_GIB`]-style limit given in GiB (saturating;
/// negative or NaN: 0).
pub fn gib_bytes(gib: f64) -> u64 {
    let bytes = gib * (1u64 << 30) as f64;
    if bytes.is_nan() || bytes <= 0.0 {
        0
    } else if bytes >= u64::MAX as f64 {
        u64::MAX
    } else {
        bytes as u64
    }
}

impl LawValidParams {
    /// What learning from logs of `shapes` (`(S, K)` per log) of `n` motors, `periodic`
    /// of them periodic, needs on `threads` worker threads (see the module docs). The
    /// traced sets are not counted ([`MemoryEstimate::with_sets`]).
    pub fn memory(
        &self,
        shapes: &[(usize, usize)],
        n: usize,
        periodic: usize,
        threads: usize,
    ) -> MemoryEstimate {
        let mut estimate = MemoryEstimate {
            threads: Some(threads),
            ..MemoryEstimate::default()
        };
        let add = |a: &mut u64, b: u64| *a = a.saturating_add(b);
        let images = 1.5f64.powi(periodic as i32);
        let fitted_total: u64 = shapes
            .iter()
            .map(|&(s, _)| (s - self.holdout(s)) as u64)
            .sum();
        for &(samples, k) in shapes {
            let s = samples as u64;
            let fitted = (samples - self.holdout(samples)) as u64;
            let copies = if self.method == LawMethod::Invariants {
                1
            } else {
                2
            };
            add(
                &mut estimate.log_bytes,
                s.saturating_mul(8 * (n + copies * k) as u64),
            );
            let image_points = (fitted as f64 * images).ceil() as u64;
            add(&mut estimate.tree_bytes, KdTree::bytes(image_points, n));
            let own = match self.method {
                LawMethod::Invariants => KdTree::bytes(fitted, k)
                    .max(KdTree::bytes(fitted, MAX_INVARIANTS))
                    .saturating_add(fitted.saturating_mul(8)),
                _ => KdTree::bytes(fitted, n),
            };
            add(&mut estimate.tree_bytes, own);
        }
        match self.method {
            LawMethod::Invariants => {
                let features = 3usize.saturating_pow(n as u32) - 1;
                let pairs = pair_count(features, fitted_total as usize) as u64;
                estimate.basis_bytes = InvariantModel::shared_bytes(n, pairs);
                estimate.bytes_per_thread = InvariantModel::thread_bytes();
            }
            LawMethod::LocalLinear | LawMethod::LocalQuadratic => {
                let k = shapes.iter().map(|s| s.1).max().unwrap_or(0) as u64;
                let p = self.coefficients(n) as u64;
                let held = ((images + 2.0) * self.neighbours(n) as f64).ceil() as u64;
                estimate.bytes_per_thread = held
                    .saturating_mul(3 + n as u64 + 2 * p + 2 * k)
                    .saturating_mul(8);
            }
        }
        estimate
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::LawParams;

    #[test]
    fn the_paper_arm_at_a_million_samples_fits_the_default_limit() {
        let params = LawParams {
            method: LawMethod::Invariants,
            ..LawParams::default()
        }
        .check()
        .unwrap();
        let estimate = params.memory(&[(1_000_000, 6)], 4, 4, 2);
        // The log: 10⁶ × 10 float64.
        assert_eq!(estimate.log_bytes, 80_000_000);
        let total = estimate.total_bytes();
        assert!(total > 400 << 20 && total < 2 << 30, "{estimate:?}");
        assert!(total < gib_bytes(DEFAULT_MEMORY_LIMIT_GIB));
        assert!(
            estimate.parts().starts_with("log 76.3 MiB"),
            "{}",
            estimate.parts()
        );
        // Ten times the samples: ten times the log and trees.
        let larger = params.memory(&[(10_000_000, 6)], 4, 4, 2);
        assert!(larger.log_bytes == 10 * estimate.log_bytes);
        assert!(larger.tree_bytes > 9 * estimate.tree_bytes);
    }

    #[test]
    fn the_largest_part_names_its_remedy() {
        let params = LawParams {
            method: LawMethod::Invariants,
            ..LawParams::default()
        }
        .check()
        .unwrap();
        // Seven motors: 2186 functions, whose matrices dominate a log of 10⁵ samples.
        let estimate = params.memory(&[(100_000, 6)], 7, 7, 2);
        assert!(estimate.basis_bytes > estimate.tree_bytes, "{estimate:?}");
        assert!(estimate.fix().contains("basis"));
        let sets = MemoryEstimate::default().with_sets(1 << 30);
        assert!(sets.fix().contains("fewer starts"));
        assert_eq!(gib_bytes(1.5), 3 << 29);
        assert_eq!(gib_bytes(f64::NAN), 0);
    }
}
