//! The report's figures, each a [`Figure`](super::plot::Figure) drawn on PNG, SVG and
//! the text recorder alike.
//!
//! What each one shows, and the paper figure it mirrors:
//!
//! | file | paper | content |
//! |---|---|---|
//! | `fig1-sensory-manifolds` | Fig. 1 (2.2) | `s = σ_E(m)` along a motor sweep, one curve per environment |
//! | `fig2-kernel-lines` | Fig. 2 (2.3) | kernel sets `M^i` in the motor plane `(m1, m2)`, coloured by the pose `x` |
//! | `fig2-learned-manifold` | Fig. 2 (2.3) | the 1-D embedding against `x` (or the first two coordinates) |
//! | `fig5a-configurations` | Fig. 5a (3.3) | explored arm configurations, working space and lights |
//! | `fig5b-kernel-sets-3d` | Fig. 5b (3.3) | kernel sets in motor space, two 3-D projections of the motor torus |
//! | `fig5d-embedding-probes` | Fig. 5d (3.3) | the embedding (grey) with one probe sheet per orientation, coloured by alpha, seen obliquely and along the ring's axis |
//! | `embedding-pose` | — | the embedding coloured by each pose coordinate, and how well each is recovered |
//! | `persistence-diagram` | — | Rips persistence of the set metric, Betti numbers |
//! | `dydx` | — | CCA's `dy–dx` plot (embedded against learned distances) |
//! | `invariance` | 2.3 | set and sensor distances in two environments |
//! | `cca-stress` | — | CCA stress per epoch |
//!
//! Sizes: one panel is `panel_width_in × panel_height_in` (3.5 × 2.8 in by default,
//! one journal column), a figure of two panels side by side is two columns wide (7 in,
//! a page), at `dpi` pixels per inch (300); text is at least 9 pt at that size.

mod arm;
mod diagnostics;
mod embedding;
mod toys;

use std::collections::BTreeMap;
use std::ops::Range;

use ndarray::ArrayView2;

pub(super) use arm::{Configurations, KernelSets3d, MAX_LOOPS};
pub(super) use diagnostics::{DyDx, Invariance, PersistenceDiagram, StressTrace};
pub(super) use embedding::{
    recovery, ring_frame, EmbeddingPose, EmbeddingProbes, PoseViews, Recovery, RECOVERY_NEIGHBOURS,
};
pub(super) use toys::{KernelLines, LearnedManifold, SensoryManifolds};

use super::plot::{padded, Print};
use smspace::agent::{wrap_period, Motor, MotorSpace};

/// Most points a scatter draws (evenly spaced rows beyond that), so that SVG files stay
/// small and drawing stays fast.
pub(super) const MAX_SCATTER_POINTS: usize = 20_000;

/// The names of the pose coordinates, with units.
pub(super) const POSE_LABELS: [&str; 3] = ["x (m)", "y (m)", "alpha (rad)"];

/// The name of column `c` of the sets' poses: `x`, `y`, `alpha`, then the attribute
/// motors the agent declares (a pupil's `aperture`, [`smspace::agent::Agent::attribute_motors`]).
pub(super) fn coordinate_name(c: usize) -> &'static str {
    ["x", "y", "alpha"].get(c).copied().unwrap_or("aperture")
}

/// The axis label of column `c` of the sets' poses.
pub(super) fn coordinate_label(c: usize) -> &'static str {
    POSE_LABELS.get(c).copied().unwrap_or("aperture")
}

/// The size of one panel and the print geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Panel {
    /// Width in pixels.
    pub(super) width: u32,
    /// Height in pixels.
    pub(super) height: u32,
    /// Points to pixels.
    pub(super) print: Print,
}

impl Panel {
    /// The pixel size of a figure of `columns × rows` panels.
    pub(super) fn grid(self, columns: u32, rows: u32) -> (u32, u32) {
        (self.width * columns, self.height * rows)
    }

    /// The pixel size of a figure of one panel, `height_factor` times as high.
    pub(super) fn tall(self, height_factor: f64) -> (u32, u32) {
        (
            self.width,
            (f64::from(self.height) * height_factor).round() as u32,
        )
    }
}

/// The axis range of a motor coordinate: its period's range when periodic (`[−π, π]`
/// for a hinge), the values' when bounded.
fn motor_range(motor: Motor, values: impl IntoIterator<Item = f64>) -> Range<f64> {
    match motor {
        Motor::Periodic { .. } => {
            let (low, high) = motor.range();
            low..high
        }
        Motor::Bounded { .. } => padded(values),
    }
}

/// The periods of the motors `axes` of `space` (`None` for bounded ones), for
/// [`wrap_curve`].
fn periods<const K: usize>(space: &MotorSpace, axes: [usize; K]) -> [Option<f64>; K] {
    axes.map(|a| space.motor(a).period())
}

/// A curve cut where it crosses the faces `±π` of the motor box (periodic coordinates
/// wrap there): the pieces, each ending or starting exactly on a face, and the
/// crossing points (on both faces) to mark.
pub(super) struct WrappedCurve<const K: usize> {
    /// The pieces to draw.
    pub(super) pieces: Vec<Vec<[f64; K]>>,
    /// Where the curve leaves a face and re-enters at the opposite one.
    pub(super) crossings: Vec<[f64; K]>,
}

/// Cuts the curve through `points` (coordinate `k` in `[−T/2, T/2)` when
/// `periods[k] = Some(T)`; a closed loop when `closed`) at the faces of the periodic
/// coordinates it crosses. A step longer than `T/2` in a periodic coordinate is read as
/// the short way round through the face; the crossing point is interpolated on the
/// face, so that each piece reaches the face and the next starts on the opposite one.
pub(super) fn wrap_curve<const K: usize>(
    points: &[[f64; K]],
    periods: [Option<f64>; K],
    closed: bool,
) -> WrappedCurve<K> {
    let mut pieces: Vec<Vec<[f64; K]>> = Vec::new();
    let mut crossings = Vec::new();
    let mut current: Vec<[f64; K]> = Vec::new();
    let n = points.len();
    let steps = if closed && n > 2 {
        n
    } else {
        n.saturating_sub(1)
    };
    if let Some(&first) = points.first() {
        current.push(first);
    }
    let jumps = |a: &[f64; K], b: &[f64; K]| {
        (0..K).any(|k| periods[k].is_some_and(|t| (b[k] - a[k]).abs() > t / 2.0))
    };
    for s in 0..steps {
        let (a, b) = (points[s], points[(s + 1) % n]);
        if jumps(&a, &b) {
            let (leave, enter) = face_crossing(a, b, periods);
            current.push(leave);
            crossings.push(leave);
            crossings.push(enter);
            pieces.push(std::mem::take(&mut current));
            current.push(enter);
        }
        current.push(b);
    }
    if closed && !pieces.is_empty() {
        // The loop's first piece continues its last one.
        let first = pieces.remove(0);
        current.extend(first.into_iter().skip(1));
    }
    if current.len() > 1 || (pieces.is_empty() && !current.is_empty()) {
        pieces.push(current);
    }
    WrappedCurve { pieces, crossings }
}

/// Where the step from `a` to `b` (the short way round, through a face of a periodic
/// coordinate) leaves the box, and where it re-enters at the opposite face.
fn face_crossing<const K: usize>(
    a: [f64; K],
    b: [f64; K],
    periods: [Option<f64>; K],
) -> ([f64; K], [f64; K]) {
    let mut step = [0.0; K];
    let mut t = 1.0_f64;
    for k in 0..K {
        step[k] = b[k] - a[k];
        if let Some(period) = periods[k] {
            let half = period / 2.0;
            step[k] = wrap_period(step[k], period);
            let end = a[k] + step[k];
            if end > half {
                t = t.min((half - a[k]) / step[k]);
            } else if end < -half {
                t = t.min((-half - a[k]) / step[k]);
            }
        }
    }
    let t = t.clamp(0.0, 1.0);
    let leave: [f64; K] = std::array::from_fn(|k| a[k] + t * step[k]);
    let enter: [f64; K] = std::array::from_fn(|k| match periods[k] {
        Some(period) if leave[k] >= period / 2.0 - 1e-12 * period => leave[k] - period,
        Some(period) if leave[k] <= -period / 2.0 + 1e-12 * period => leave[k] + period,
        _ => leave[k],
    });
    (leave, enter)
}

/// One probe orientation: its cells `(ix, iy) → set` and mean orientation.
pub(super) struct ProbeSurface {
    /// Mean pose alpha of its cells (radians).
    pub(super) alpha: f64,
    /// Grid cell → set index.
    pub(super) cells: BTreeMap<(i64, i64), usize>,
}

impl ProbeSurface {
    /// Grid squares whose four corners are present, as sets in order round the square.
    pub(super) fn quads(&self) -> Vec<[usize; 4]> {
        self.cells
            .iter()
            .filter_map(|(&(ix, iy), &a)| {
                let b = *self.cells.get(&(ix + 1, iy))?;
                let c = *self.cells.get(&(ix + 1, iy + 1))?;
                let d = *self.cells.get(&(ix, iy + 1))?;
                Some([a, b, c, d])
            })
            .collect()
    }

    /// The mean embedding of its sets (first three coordinates, zeros beyond `d`).
    pub(super) fn centre(&self, embedding: ArrayView2<'_, f64>) -> [f64; 3] {
        let mut c = [0.0; 3];
        let n = self.cells.len().max(1) as f64;
        for &i in self.cells.values() {
            for (k, ck) in c.iter_mut().enumerate().take(embedding.ncols().min(3)) {
                *ck += embedding[[i, k]] / n;
            }
        }
        c
    }
}

/// Groups the probe rows among the kept sets by orientation.
pub(super) fn probe_surfaces(
    probes: ArrayView2<'_, i64>,
    kept: &[usize],
    set_poses: &ndarray::Array2<f64>,
) -> Vec<ProbeSurface> {
    /// Cells, and the sums of `sin alpha` and `cos alpha`.
    type Accumulated = (BTreeMap<(i64, i64), usize>, f64, f64);
    let mut by: BTreeMap<i64, Accumulated> = BTreeMap::new();
    for (set, &row) in kept.iter().enumerate() {
        let label = probes.row(row);
        if smspace::explore::is_babbled(label) {
            continue;
        }
        let entry = by.entry(label[0]).or_default();
        entry.0.insert((label[1], label[2]), set);
        // Circular mean of the orientation.
        let alpha = set_poses[[set, 2]];
        entry.1 += alpha.sin();
        entry.2 += alpha.cos();
    }
    by.into_iter()
        .map(|(_, (cells, s, c))| ProbeSurface {
            alpha: s.atan2(c),
            cells,
        })
        .collect()
}

/// The embedding's first three coordinates of row `i` (zeros beyond its dimension).
pub(super) fn point3(embedding: ArrayView2<'_, f64>, i: usize) -> [f64; 3] {
    std::array::from_fn(|k| {
        if k < embedding.ncols() {
            embedding[[i, k]]
        } else {
            0.0
        }
    })
}

#[cfg(test)]
mod tests {
    use std::f64::consts::{PI, TAU};

    use super::*;

    #[test]
    fn a_loop_through_a_face_is_cut_on_both_faces_and_stays_closed() {
        // A loop round the first coordinate's circle: it crosses the face once.
        let pts: Vec<[f64; 2]> = (0..8)
            .map(|k| [smspace::agent::wrap_angle(0.5 + k as f64 * PI / 4.0), 0.3])
            .collect();
        let w = wrap_curve(&pts, [Some(TAU); 2], true);
        assert_eq!(w.pieces.len(), 1, "one piece from face to face");
        assert_eq!(w.crossings.len(), 2);
        let piece = &w.pieces[0];
        let (first, last) = (piece[0], piece[piece.len() - 1]);
        assert!((first[0].abs() - PI).abs() < 1e-12 && (last[0].abs() - PI).abs() < 1e-12);
        assert!((first[0] + last[0]).abs() < 1e-12, "opposite faces");
        // A loop that crosses no face closes on itself.
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let w = wrap_curve(&square, [Some(TAU); 2], true);
        assert_eq!((w.pieces.len(), w.pieces[0].len()), (1, 5));
        assert!(w.crossings.is_empty());
        // An open curve is not closed.
        assert_eq!(wrap_curve(&square, [None; 2], false).pieces[0].len(), 4);
        // A periodic coordinate of another period wraps at its own faces; a bounded
        // one beside it never does.
        let line = [[0.9, 5.0], [-0.9, -5.0]];
        let w = wrap_curve(&line, [Some(2.0), None], false);
        assert_eq!((w.pieces.len(), w.crossings.len()), (2, 2));
        assert!((w.crossings[0][0] - 1.0).abs() < 1e-12 && (w.crossings[1][0] + 1.0).abs() < 1e-12);
        assert!((w.crossings[0][1] - w.crossings[1][1]).abs() < 1e-12);
    }

    #[test]
    fn probe_surface_quads_join_grid_neighbours() {
        let mut cells = BTreeMap::new();
        cells.insert((0, 0), 0);
        cells.insert((1, 0), 1);
        cells.insert((0, 1), 2);
        cells.insert((1, 1), 3);
        let s = ProbeSurface { alpha: 0.0, cells };
        assert_eq!(s.quads(), vec![[0, 1, 3, 2]]);
    }
}
