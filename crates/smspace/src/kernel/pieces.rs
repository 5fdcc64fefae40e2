//! How reliably the multi-start search finds a level set's further pieces, estimated
//! from the seeds that landed on the pieces it found.
//!
//! Every set projects the same `S` seeds (`piece_starts`) onto its level set. Say a
//! further piece (not the start's) draws each seed with probability `q`, independently,
//! so that the seeds landing on it are binomial `B(S, q)`. The search misses that piece
//! with probability `(1 − q)^S`. Only the pieces it found can be seen, and for them the
//! count of seeds `h ≥ 1` follows the zero-truncated law, of mean
//!
//! ```text
//! E[h | h ≥ 1] = S q / (1 − (1 − q)^S) ,
//! ```
//!
//! which rises from 1 (at `q → 0`) to `S` (at `q = 1`) and is solved for `q` from the
//! mean `h̄` over the further pieces found, by bisection. The estimate of a miss is
//! `(1 − q)^S`; `S' = ln 0.01 / ln(1 − q)` seeds miss 1 % of such pieces. A set that
//! misses a piece its neighbours have is far from them in the Hausdorff distance (the
//! piece's points have no partner), so a frequent miss breaks the learned manifold
//! apart.
//!
//! The estimate assumes the seeds land independently. The design spreads them over
//! the motor space, which makes a piece drawn by one seed in every set (`h̄ = 1`) look
//! rare when its basin is in fact always met: with few seeds (up to `2^N`) read the
//! estimate as an upper bound.

use serde::{Deserialize, Serialize};

/// A miss probability above this is reported ([`PieceSearch::warning`]).
pub const MAX_PIECE_MISS: f64 = 0.05;

/// The multi-start search's landings on the further pieces it found, over the traced
/// sets, and the share of such pieces it is estimated to miss (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PieceSearch {
    /// Seeds of the search per set (`piece_starts`).
    pub seeds: usize,
    /// Further pieces found (not the start's), over the traced sets.
    pub pieces: usize,
    /// The mean number of seeds that landed on each of them (at least 1).
    pub mean_landings: f64,
    /// The estimated probability `q` that one seed lands on a further piece.
    pub landing_probability: f64,
    /// The estimated probability `(1 − q)^S` that a set misses such a piece.
    pub miss_probability: f64,
}

impl PieceSearch {
    /// The estimate from the landings of every further piece found (one count per
    /// piece, each at least 1) with `seeds` seeds per set; `None` when no further piece
    /// was found.
    pub fn of(landings: &[u32], seeds: usize) -> Option<Self> {
        if landings.is_empty() || seeds == 0 {
            return None;
        }
        let mean =
            landings.iter().map(|&h| f64::from(h.max(1))).sum::<f64>() / landings.len() as f64;
        let q = landing_probability(mean, seeds);
        Some(Self {
            seeds,
            pieces: landings.len(),
            mean_landings: mean,
            landing_probability: q,
            miss_probability: (1.0 - q).powi(seeds.min(i32::MAX as usize) as i32),
        })
    }

    /// The seeds per set that would miss 1 % of such pieces; `None` when no seed
    /// count would do on this evidence (`q = 0`).
    pub fn seeds_for_one_percent(&self) -> Option<usize> {
        let q = self.landing_probability;
        (q > 0.0).then(|| (0.01f64.ln() / (-q).ln_1p()).ceil().max(1.0) as usize)
    }

    /// A sentence for the user when the search misses more than [`MAX_PIECE_MISS`] of
    /// the further pieces; `None` otherwise.
    pub fn warning(&self) -> Option<String> {
        if self.miss_probability <= MAX_PIECE_MISS {
            return None;
        }
        let remedy = match self.seeds_for_one_percent() {
            Some(more) => format!("raise [kernel] piece_starts to about {more} (1 % missed)"),
            None => "raise [kernel] piece_starts many times".to_owned(),
        };
        Some(format!(
            "the search for pieces found {} further pieces, each landed on by {:.2} of its {} seeds on average: a set misses such a piece with probability about {:.0} % (zero-truncated binomial estimate, an upper bound with few seeds), and a set that misses a piece its neighbours have lies apart from them in the metric, so the learned manifold can break into parts; {remedy}",
            self.pieces,
            self.mean_landings,
            self.seeds,
            100.0 * self.miss_probability
        ))
    }
}

/// The `q ∈ [0, 1]` with `S q / (1 − (1 − q)^S) = mean` (`1 ≤ mean ≤ S`; 0 at
/// `mean ≤ 1`, 1 at `mean ≥ S`), by bisection.
fn landing_probability(mean: f64, seeds: usize) -> f64 {
    let s = seeds as f64;
    let f = |q: f64| s * q / -(s * (-q).ln_1p()).exp_m1();
    if mean.is_nan() || mean <= 1.0 {
        return 0.0;
    }
    if mean >= s {
        return 1.0;
    }
    let (mut low, mut high) = (1e-15, 1.0 - 1e-15);
    for _ in 0..100 {
        let mid = 0.5 * (low + high);
        if f(mid) < mean {
            low = mid;
        } else {
            high = mid;
        }
    }
    0.5 * (low + high)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn the_truncated_mean_is_inverted() {
        for seeds in [2, 16, 128] {
            for q in [0.001_f64, 0.05, 0.3, 0.9] {
                let s = seeds as f64;
                let mean = s * q / (1.0 - (1.0 - q).powi(seeds));
                let back = landing_probability(mean, seeds as usize);
                assert!((back - q).abs() < 1e-9, "{seeds} seeds, q {q}: {back}");
            }
        }
        assert_eq!(landing_probability(1.0, 16), 0.0);
        assert_eq!(landing_probability(f64::NAN, 16), 0.0);
        assert_eq!(landing_probability(16.0, 16), 1.0);
    }

    #[test]
    fn the_miss_rate_of_a_simulated_search_is_recovered() {
        // 4 000 sets, each with a further piece drawing each of 64 seeds with
        // probability q: the sets that found it give back the share that did not.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for q in [0.005, 0.02, 0.05, 0.3] {
            let seeds = 64;
            let counts: Vec<u32> = (0..4000)
                .map(|_| (0..seeds).filter(|_| rng.random_bool(q)).count() as u32)
                .collect();
            let found: Vec<u32> = counts.iter().copied().filter(|&h| h > 0).collect();
            let missed = 1.0 - found.len() as f64 / counts.len() as f64;
            let search = PieceSearch::of(&found, seeds).unwrap();
            assert!(
                (search.miss_probability - missed).abs() < 0.05,
                "q {q}: estimated {} against {missed}",
                search.miss_probability
            );
            assert_eq!(
                search.warning().is_some(),
                search.miss_probability > MAX_PIECE_MISS
            );
        }
        let reliable = PieceSearch::of(&[20, 25, 18], 64).unwrap();
        assert!(reliable.miss_probability < 1e-6 && reliable.warning().is_none());
        let rare = PieceSearch::of(&[1, 1, 2, 1], 128).unwrap();
        let warning = rare.warning().unwrap();
        assert!(
            warning.contains("piece_starts") && warning.contains("128 seeds"),
            "{warning}"
        );
        assert!(PieceSearch::of(&[], 16).is_none());
    }
}
