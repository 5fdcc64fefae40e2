//! The peak memory of each stage, estimated before it starts, so that a run that would
//! not fit is refused with the key to lower instead of being killed by the system.
//!
//! A stage's peak is what the run holds when it starts (the outputs of the earlier
//! stages, which later stages read: explored configurations, kernel sets, `D`, the
//! embedding; [`Held`]) plus the stage's own working set at its largest. With `M` sets
//! and `D = 8 M²` bytes, the working sets are, in float64 (measured peak resident
//! memory and estimates for the paper's arm: `docs/RELIABILITY.md`):
//!
//! | stage | working set |
//! |---|---|
//! | `explore` | the exploration's arrays |
//! | `trace` | the kernel sets `(rows, P, N)`, twice (traced, then stacked), and the `piece_starts × N` seeds of the piece search |
//! | `distances` | `D`, and the prepared sets ([`smspace::metric::matrix_bytes`]) |
//! | `embed` | CCA: `D` in `f32` and the off-diagonal distances (`≈ 1 D`), its MDS start and the stress of every epoch; MDS: the squared copy and the eigensolver (`≈ 2 D`, `≈ 4 D` dense below 1000 points); Isomap: geodesics and their squares (`≈ 2 D`, landmarks `≈ 2 L M`) |
//! | `analyze` | the pair lists and ranks of the agreement with the poses, one ranking at a time (`≈ 4 D`), persistence of `max_points` landmarks (`≈ 8 L²`) |
//! | `invariance` | the starts' sets in every environment and their distance matrices |
//! | `report` | the sampled sets and figures (small next to `D`) |
//!
//! On the landmark path ([`super::scale`]) no stage holds `D`: `distances` holds the
//! `(M, L)` table, the `(L, L)` matrix and the kNN lists
//! ([`smspace::metric::landmarks::landmark_bytes`], [`smspace::metric::knn_bytes`]);
//! `embed` the method's working set on `L` points and a block of the extension;
//! `analyze` the agreement on the `L` landmarks (`≈ 5 · 8 L²`) and the persistence of
//! `min(L, max_points)` of them.

use crate::plan::Plan;
use crate::scale::ChosenPath;

/// Bytes of one float64.
const F64: u64 = 8;

/// A stage's estimated peak.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Peak {
    /// What needs the memory, with its sizes.
    pub what: String,
    /// Bytes at the peak, with what the run holds.
    pub bytes: u64,
    /// The keys that lower it.
    pub fix: &'static str,
}

/// What the run holds when a stage starts: the earlier stages' outputs.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Held {
    /// Bytes held.
    pub bytes: u64,
}

impl Held {
    /// Adds `bytes` (saturating).
    pub fn plus(self, bytes: u64) -> Held {
        Held {
            bytes: self.bytes.saturating_add(bytes),
        }
    }
}

fn product(factors: &[u64]) -> u64 {
    factors.iter().fold(1u64, |a, &b| a.saturating_mul(b))
}

/// Bytes of `D` for `m` sets.
fn matrix(m: u64) -> u64 {
    product(&[m, m, F64])
}

impl Plan {
    fn motors(&self) -> u64 {
        self.agent().motor_dim() as u64
    }

    /// Coordinates of the agent's poses (0 without a ground truth).
    fn pose_dim(&self) -> usize {
        self.agent()
            .ground_truth()
            .map_or(0, |observer| observer.pose_space().dim())
    }

    /// `explore`: its own arrays.
    pub(super) fn explore_peak(&self) -> Peak {
        let e = &self.explore.exploration;
        if let Some(data) = &self.world.data {
            return Peak {
                what: format!(
                    "stage `explore`: {} reference samples picked from {} logged samples",
                    e.n,
                    data.samples()
                ),
                bytes: data.bytes(),
                fix: "learn from fewer samples ([data.simulate] samples, or a shorter log)",
            };
        }
        Peak {
            what: format!(
                "stage `explore`: {} configurations of {} motors, with poses of {} coordinates",
                e.rows(),
                self.motors(),
                self.pose_dim()
            ),
            bytes: e.bytes(self.motors() as usize, self.pose_dim()),
            fix: "lower exploration.n or the probe grid",
        }
    }

    /// `trace`: the sets of every explored row, twice.
    pub(super) fn trace_peak(&self, held: Held, rows: u64) -> Peak {
        let sets = self.trace.kernel.sets_bytes(rows, self.motors() as usize);
        let seeds = self.trace.kernel.seeds_bytes(self.motors() as usize);
        let what = format!(
            "stage `trace`: kernel sets ({rows} × {} points × {} motors) and {} seeds of the piece search",
            self.trace.kernel.stored_points(),
            self.motors(),
            self.trace.kernel.piece_starts
        );
        let bytes = held
            .bytes
            .saturating_add(sets.saturating_mul(2))
            .saturating_add(seeds);
        match &self.world.data {
            Some(data) => Peak {
                what: format!(
                    "{what}, and the law learned from {} logged samples",
                    data.samples()
                ),
                bytes: bytes.saturating_add(data.bytes()),
                fix: "learn from fewer samples ([data.simulate] samples, or a shorter log), or lower exploration.n or kernel.points",
            },
            None => Peak {
                what,
                bytes,
                fix: "lower exploration.n, the probe grid or kernel.points",
            },
        }
    }

    /// `distances`: `D` and the prepared sets of `m` sets, or the landmark path's
    /// table and kNN lists.
    pub(super) fn distances_peak(&self, held: Held, m: u64) -> Peak {
        // The points every set holds: `P`, or `(P + 1) × spatial_samples` for spatial sets.
        let (stored, motors) = (self.trace.kernel.stored_points(), self.motors() as usize);
        if self.distances.path(m as usize) == ChosenPath::Landmarks {
            let scale = &self.distances.scale;
            let l = (scale.landmarks as u64).min(m);
            let working = smspace::metric::landmarks::landmark_bytes(
                m as usize,
                stored,
                motors,
                &scale.landmark_params(),
            )
            .saturating_add(m.saturating_mul(scale.knn as u64 * 16 + 16));
            return Peak {
                what: format!(
                    "stage `distances` (landmark path): {m} sets to {l} landmarks, and their {} nearest",
                    scale.knn
                ),
                bytes: held.bytes.saturating_add(working),
                fix: "lower scale.landmarks (L) or scale.knn, or exploration.n (M)",
            };
        }
        let mut working = smspace::metric::matrix_bytes(m as usize, stored, motors, m as usize);
        // What the metric prepares once per matrix (e.g. the surface metric's disks).
        working = working.saturating_add(
            self.distances
                .set_metric()
                .prepared_bytes(m as usize, stored, motors),
        );
        Peak {
            what: format!("stage `distances`: the {m} × {m} distance matrix"),
            bytes: held.bytes.saturating_add(working),
            fix: "lower exploration.n or the probe grid (M, the number of sets)",
        }
    }

    /// What the run holds after `distances` of `m` sets: `D`, or the landmark table,
    /// matrix and kNN lists.
    pub(super) fn distances_held(&self, m: u64) -> u64 {
        match self.distances.path(m as usize) {
            ChosenPath::Dense => matrix(m),
            ChosenPath::Landmarks => {
                let scale = &self.distances.scale;
                let l = (scale.landmarks as u64).min(m);
                product(&[m, l, F64])
                    .saturating_add(matrix(l))
                    .saturating_add(product(&[m, scale.knn as u64, 2 * F64]))
            }
        }
    }

    /// `embed` of `m` sets: the method on all of them, or on the landmarks with the
    /// extension's coordinates and block.
    pub(super) fn embed_peak(&self, held: Held, m: u64) -> Peak {
        if self.distances.path(m as usize) == ChosenPath::Landmarks {
            let l = (self.distances.scale.landmarks as u64).min(m);
            let dim = self.embed.method().dim() as u64;
            let block = smspace::embed::landmarks::EXTEND_BLOCK as u64;
            let on_landmarks = self.embed_working(l).0;
            let extension = product(&[m, dim, F64]).saturating_add(product(&[block, l, F64]));
            return Peak {
                what: format!(
                    "stage `embed` (landmark path): fit on {l} landmarks, {m} sets placed"
                ),
                bytes: held
                    .bytes
                    .saturating_add(on_landmarks)
                    .saturating_add(extension),
                fix: "lower scale.landmarks (L)",
            };
        }
        let (working, method, fix) = self.embed_working(m);
        Peak {
            what: format!("stage `embed`: {method} of {m} points"),
            bytes: held.bytes.saturating_add(working),
            fix,
        }
    }

    /// The embedding method's working set on `m` points, its name and the keys that
    /// lower it ([`Embedding::working_bytes`]: the method says).
    fn embed_working(&self, m: u64) -> (u64, &'static str, &'static str) {
        let method = self.embed.method();
        (
            method.working_bytes(m as usize),
            method.name(),
            method.memory_fix(),
        )
    }

    /// `analyze` of `m` sets.
    pub(super) fn analyze_peak(&self, held: Held, m: u64) -> Peak {
        let a = &self.analyze.analysis;
        if self.distances.path(m as usize) == ChosenPath::Landmarks {
            let l = (self.distances.scale.landmarks as u64).min(m);
            let homology = l.min(a.max_points as u64);
            let working = matrix(l)
                .saturating_mul(5)
                .saturating_add(matrix(homology).saturating_mul(8));
            return Peak {
                what: format!(
                    "stage `analyze` (landmark path): agreement of {l} landmarks with their poses, persistence of {homology}"
                ),
                bytes: held.bytes.saturating_add(working),
                fix: "lower scale.landmarks (L) or analysis.max_points",
            };
        }
        let landmarks = m.min(a.max_points as u64);
        let working = matrix(m)
            .saturating_mul(5)
            .saturating_add(matrix(landmarks).saturating_mul(8));
        Peak {
            what: format!(
                "stage `analyze`: agreement of {m} sets with their poses, persistence of {landmarks} landmarks"
            ),
            bytes: held.bytes.saturating_add(working),
            fix: "lower exploration.n (M) or analysis.max_points",
        }
    }

    /// `invariance`: the starts in every environment.
    pub(super) fn invariance_peak(&self, held: Held) -> Option<Peak> {
        let stage = self.invariance.as_ref()?;
        let starts = stage.starts as u64;
        let environments = self.world.environments.len() as u64;
        let sets = stage.kernel.sets_bytes(starts, self.motors() as usize);
        let per_environment = sets
            .saturating_mul(2)
            .saturating_add(matrix(starts))
            .saturating_add(stage.kernel.seeds_bytes(self.motors() as usize));
        Some(Peak {
            what: format!("stage `invariance`: {starts} starts in {environments} environments"),
            bytes: held
                .bytes
                .saturating_add(per_environment.saturating_mul(environments)),
            fix: "lower analysis.invariance_starts",
        })
    }

    /// `report` of `m` sets.
    pub(super) fn report_peak(&self, held: Held, m: u64) -> Peak {
        let r = &self.report.report;
        let sampled = self
            .trace
            .kernel
            .sets_bytes(r.sample_sets as u64, self.motors() as usize);
        // Pixels of the figures drawn at once (one per thread, RGB), and the per-set
        // derived data (poses, colours, the 3-D view's points).
        let (panel_width, panel_height) = r.panel_pixels();
        let pixels = product(&[
            panel_width,
            panel_height,
            3 * 4,
            rayon::current_num_threads() as u64,
        ]);
        // Above `max_sets` the figures draw a sample: its sets are copied once.
        let drawn = m.min(r.max_sets as u64);
        let copied = if drawn < m {
            self.trace.kernel.sets_bytes(drawn, self.motors() as usize)
        } else {
            0
        };
        Peak {
            what: format!("stage `report`: figures of {drawn} of {m} sets"),
            bytes: held
                .bytes
                .saturating_add(sampled)
                .saturating_add(copied)
                .saturating_add(pixels)
                .saturating_add(product(&[drawn, 64 * F64])),
            fix: "lower report.max_sets, report.sample_sets or the panel size",
        }
    }
}

/// Bytes the run holds for `rows` explored configurations of `motors` motors.
pub(super) fn exploration_bytes(rows: u64, motors: u64) -> u64 {
    product(&[rows, motors + 6, F64])
}

/// Bytes of `m` kernel sets of `points` points of `motors` motors, with the piece of
/// every point and their records.
pub(super) fn sets_bytes(m: u64, points: u64, motors: u64) -> u64 {
    product(&[m, points, motors.saturating_add(1), F64]).saturating_add(product(&[m, 2 * F64]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The pupil arm's spatial sets (`spatial = "compensable"`, 2 samples of the aperture).
    fn pupil_space_plan(overrides: &[&str]) -> Plan {
        let source =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/pupil-space.toml");
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        let loaded = crate::config::load_experiment(&source, &overrides).unwrap();
        crate::check(&loaded).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn the_trace_and_embed_estimates_count_the_piece_seeds_and_the_epochs() {
        let plan = |seeds: usize, epochs: usize| {
            pupil_space_plan(&[
                &format!("kernel.piece_starts={seeds}"),
                "embedding.method=\"cca\"",
                &format!("embedding.epochs={epochs}"),
            ])
        };
        let (few, many) = (plan(0, 50), plan(10_000, 100_000));
        let motors = few.motors();
        let trace = |p: &Plan| p.trace_peak(Held::default(), 100).bytes;
        assert_eq!(trace(&many) - trace(&few), 10_000 * motors * 8);
        let embed = |p: &Plan| p.embed_peak(Held::default(), 100).bytes;
        assert_eq!(embed(&many) - embed(&few), (100_000 - 50) * 8);
        assert!(many
            .trace_peak(Held::default(), 100)
            .what
            .contains("10000 seeds"));
    }

    #[test]
    fn the_distances_estimate_counts_the_points_spatial_sets_hold_on_both_paths() {
        let m = 20_000u64;
        for path in ["dense", "landmarks"] {
            let plan = pupil_space_plan(&[&format!("scale.path={path}")]);
            let kernel = &plan.trace.kernel;
            // (P + 1) × spatial_samples points per set, not P.
            assert_eq!(kernel.stored_points(), (kernel.points + 1) * 2);
            let motors = plan.motors() as usize;
            let peak = plan.distances_peak(Held::default(), m);
            let expected = if path == "landmarks" {
                let scale = &plan.distances.scale;
                smspace::metric::landmarks::landmark_bytes(
                    m as usize,
                    kernel.stored_points(),
                    motors,
                    &scale.landmark_params(),
                )
                .saturating_add(m * (scale.knn as u64 * 16 + 16))
            } else {
                smspace::metric::matrix_bytes(
                    m as usize,
                    kernel.stored_points(),
                    motors,
                    m as usize,
                )
            };
            assert_eq!(peak.bytes, expected, "{path}");
            // The prepared sets alone are larger than sets of P points would be.
            let smaller = match path {
                "landmarks" => smspace::metric::landmarks::landmark_bytes(
                    m as usize,
                    kernel.points,
                    motors,
                    &plan.distances.scale.landmark_params(),
                ),
                _ => smspace::metric::matrix_bytes(m as usize, kernel.points, motors, m as usize),
            };
            assert!(peak.bytes > smaller, "{path}: {} ≤ {smaller}", peak.bytes);
        }
    }
}
