//! Spatial kernel sets (`[kernel] spatial = "compensable"`): each traced
//! `M^i` extended along the motors the compensability analysis found non-spatial
//! ([`crate::analysis::compensability`]).
//!
//! The paper's `M^i` (section 3.2) is the set of configurations with the sensation of
//! `m^i`; with a pupil, the sensation fixes the aperture, and the manifold of sets is
//! `(x, y, alpha) × aperture`. The set of configurations whose sensor is in the same
//! *spatial* configuration is `M^i` moved along every non-spatial direction: for a
//! motor `j` whose axis is such a direction (the pupil's aperture),
//!
//! ```text
//! M^i_spatial = { m + (a − m_j) e_j : m ∈ M^i, a ∈ range of motor j } ,
//! ```
//!
//! a set of dimension `k + 1` (here 2: a kernel curve `C^i` × the aperture range `I`).
//!
//! # Sampling: slices, each a piece
//!
//! Each traced set is repeated at `samples` values `a_t` of the motor, the same grid for
//! every set: `low + (high − low) t / (samples − 1)`, `t = 0 … samples − 1`, for a
//! bounded motor (the middle for one sample), and `−T/2 + T t / samples` for a periodic
//! one of period `T`. Slice `t` is the traced set with `m_j = a_t`; it keeps the traced
//! set's polylines, each as its own **piece** (slice `t` of a set of `c` pieces holds
//! pieces `t c … t c + c − 1`, [`TracedSets::pieces`]), so the extended set is the union
//! of `samples · c` polylines, written as one open set of several pieces (a closed loop
//! ends with a copy of its first point, the tracer's convention for pieces). Every slice
//! has the same number of points: `P + 1` when some kept set is a single closed loop
//! (the copy; the other sets repeat their last point, a segment of length 0), else `P`.
//! A set of `P` points becomes `samples · (P or P + 1)` points, the slices in order.
//!
//! # What the metrics measure on them
//!
//! The `curve` metric ([`crate::metric`]) reads each piece as a polyline: between two
//! extended sets it is the Hausdorff distance between the unions of their slices'
//! polylines. The point metric `g` adds the squared difference in `m_j` to that in the
//! other motors, so the point of `B`'s slices nearest to a point of `A`'s slice `t` is
//! on `B`'s slice `t` (same `a_t`, shared grid), and
//!
//! ```text
//! ρ_c(∪_t C^A × {a_t}, ∪_t C^B × {a_t}) = ρ_c(C^A, C^B) = ρ(C^A × I, C^B × I) ,
//! ```
//!
//! the distance between the traced curves with `m_j` left out, which is also the
//! Hausdorff distance between the continuous 2-D sets `C × I` (the same argument for
//! every `a ∈ I`). That is the right distance between spatial sets: two configurations
//! whose sensors are in the same spatial configuration are at distance 0 whatever their
//! apertures, so the aperture no longer separates sets, and what is left is the
//! paper's distance between curves (the `curve` metric reads them as curves, not as
//! point samples: no sampling gap). The point metric `hausdorff` gives the
//! same between the sampled points, whatever the number of slices.
//!
//! **Limit.** Between slices the set is not interpolated: the metrics see the union of
//! the slices, not the 2-D set. The equality above holds because the sets are products
//! with a shared grid; a set that is not a product (a non-spatial direction that is not
//! a motor axis, refused by the trace stage) would need its slices joined into a
//! surface, and its sampled distance would be off by up to half a slice spacing. The
//! `curve` metric applies only where every slice is a polyline: traced kernels of
//! dimension `k ≤ 1` ([`TraceReport::kernel_shape`]); slices of `k ≥ 2` coverings are point
//! clouds (`hausdorff`).

use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};

use super::{Closure, KernelError, TraceParams, TraceReport, TracedSets};
use crate::agent::{Motor, MotorSpace};
use crate::params::InvalidParameter;
use crate::sets::KernelShape;

/// Which kernel sets the pipeline compares (`[kernel] spatial`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Spatial {
    /// The traced sets as they are (the paper's).
    #[default]
    Kernel,
    /// The traced sets extended along the motors found non-spatial by the
    /// compensability analysis (module docs).
    Compensable,
}

impl Spatial {
    /// Whether this is the default (`kernel`): the key of a run that does not use it
    /// is unchanged.
    pub fn is_kernel(&self) -> bool {
        *self == Spatial::Kernel
    }
}

/// Most samples along a non-spatial motor.
pub const MAX_SPATIAL_SAMPLES: usize = 1_000;

impl TraceParams {
    /// Points of every set the trace stage hands on: `points`, and with `spatial =
    /// "compensable"` `(points + 1) · spatial_samples` (the slices of one non-spatial
    /// motor, each with room for a loop's closing copy, module docs; a pupil has one).
    /// The memory estimates count these (saturating).
    pub fn stored_points(&self) -> usize {
        match self.spatial {
            Spatial::Kernel => self.points,
            Spatial::Compensable => self
                .points
                .saturating_add(1)
                .saturating_mul(self.spatial_samples),
        }
    }
}

impl TraceReport {
    /// The shape of the traced kernels, as a metric asks for it: the largest kernel
    /// dimension `k` of a set, and the motors the sets were extended along (their
    /// slices are traced kernels of dimension `k − extended`, module docs).
    pub fn kernel_shape(&self) -> KernelShape {
        KernelShape {
            dimension: self.sets.iter().map(|s| s.dimension).max().unwrap_or(0),
            extended: self.extended_along.len(),
        }
    }
}

/// The values of motor `motor` every set is repeated at (module docs), the same for
/// every set.
fn grid(motor: Motor, samples: usize) -> Vec<f64> {
    match motor {
        Motor::Bounded { low, high } => (0..samples)
            .map(|t| {
                if samples == 1 {
                    0.5 * (low + high)
                } else {
                    low + (high - low) * t as f64 / (samples - 1) as f64
                }
            })
            .collect(),
        Motor::Periodic { period } => (0..samples)
            .map(|t| -0.5 * period + period * t as f64 / samples as f64)
            .collect(),
    }
}

/// `traced` extended along `motors` (module docs), `samples` values each.
pub fn extend_along(
    traced: TracedSets,
    space: &MotorSpace,
    motors: &[usize],
    samples: usize,
) -> Result<TracedSets, KernelError> {
    if motors.is_empty() {
        return Ok(traced);
    }
    if samples == 0 || samples > MAX_SPATIAL_SAMPLES {
        return Err(InvalidParameter::new(
            "kernel",
            "spatial_samples",
            samples,
            "1 to 1000 values of each non-spatial motor per traced point",
        )
        .into());
    }
    let mut out = traced;
    for &j in motors {
        let Some(&motor) = space.motors().get(j) else {
            return Err(InvalidParameter::new(
                "kernel",
                "spatial",
                format!("motor {j}"),
                format!("the agent has {} motors", space.dim()),
            )
            .into());
        };
        out = extend_one(out, j, &grid(motor, samples));
    }
    Ok(out)
}

/// Points of one slice: room for a closing copy when some set is a single closed loop.
fn slice_points(traced: &TracedSets) -> usize {
    let p = traced.sets.dim().1;
    if traced.closure.contains(&Closure::Closed) {
        p + 1
    } else {
        p
    }
}

/// The sets repeated at every value of `grid` along motor `j`, each slice its own
/// pieces (module docs).
fn extend_one(traced: TracedSets, j: usize, grid: &[f64]) -> TracedSets {
    let (m, p, n) = traced.sets.dim();
    let slice = slice_points(&traced);
    let mut sets = Array3::zeros((m, slice * grid.len(), n));
    let mut pieces = Array2::zeros((m, slice * grid.len()));
    for s in 0..m {
        let count = traced.pieces.row(s).iter().max().map_or(1, |&c| c + 1);
        // The point that fills the slice: the first (a loop's closing copy) or the last.
        let filler = match traced.closure[s] {
            Closure::Closed => 0,
            Closure::Open => p - 1,
        };
        let sources = (0..p).chain(std::iter::repeat_n(filler, slice - p));
        for (t, &value) in grid.iter().enumerate() {
            for (i, q) in sources.clone().enumerate() {
                let target = t * slice + i;
                for c in 0..n {
                    sets[[s, target, c]] = traced.sets[[s, q, c]];
                }
                sets[[s, target, j]] = value;
                // The filler belongs to the piece it closes or ends.
                let piece = traced.pieces[[s, if i < p { q } else { p - 1 }]];
                pieces[[s, target]] = t as i64 * count + piece;
            }
        }
    }
    let mut report = traced.report;
    report.points = slice * grid.len();
    report.extended_along.push(j);
    for set in &mut report.sets {
        set.dimension += 1;
    }
    TracedSets {
        sets,
        kept: traced.kept,
        closure: vec![Closure::Open; m],
        pieces,
        report,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::{SetReport, SetStatus, StepControl, TraceMethod};
    use crate::metric::{distance_matrix, DistanceParams, MetricKind, Period, SetsView};
    use crate::progress::Silent;

    fn set_report(index: usize, status: SetStatus) -> SetReport {
        SetReport {
            index,
            status,
            steps: 1,
            length: 1.0,
            max_residual: 0.0,
            max_pose_deviation: None,
            dimension: 1,
            pieces: 1,
            unvisited_pieces: 0,
            piece_landings: Vec::new(),
            covering_radius: None,
            sensor_rows: 0,
            sensor_row_phases: None,
            noise: None,
        }
    }

    /// Sets of `P` points in 3 motors (the last the aperture), with their closures and
    /// pieces.
    fn traced(points: Array3<f64>, closure: Vec<Closure>, pieces: Array2<i64>) -> TracedSets {
        let (m, p, _) = points.dim();
        let sets = closure
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let status = match c {
                    Closure::Closed => SetStatus::Closed,
                    Closure::Open => SetStatus::Open,
                };
                set_report(i, status)
            })
            .collect();
        TracedSets {
            sets: points,
            kept: (0..m).collect(),
            closure,
            pieces,
            report: TraceReport {
                agent: "test".into(),
                method: TraceMethod::Kinematic,
                step_control: StepControl::Fixed,
                points: p,
                summary: Default::default(),
                sets,
                extended_along: Vec::new(),
                law: None,
                budget: None,
            },
        }
    }

    /// Two motors and an aperture bounded in `[0.5, 1.5]`.
    fn space() -> MotorSpace {
        MotorSpace::new(vec![
            Motor::HINGE,
            Motor::HINGE,
            Motor::Bounded {
                low: 0.5,
                high: 1.5,
            },
        ])
        .unwrap()
    }

    /// A square of half-diagonal `r` around the origin in motors 0 and 1 (vertices on
    /// the axes), at aperture `a`: one closed loop.
    fn square(r: f64, a: f64) -> [[f64; 3]; 4] {
        [[r, 0.0, a], [0.0, r, a], [-r, 0.0, a], [0.0, -r, a]]
    }

    /// Set 0: a closed square of half-diagonal 1 at aperture 0.7; set 1: an open
    /// polyline of two pieces at aperture 1.3.
    fn two_sets() -> TracedSets {
        let a = square(1.0, 0.7);
        let b = [
            [0.3, 0.0, 1.3],
            [0.0, 0.3, 1.3],
            [-0.3, 0.0, 1.3],
            [0.0, -0.3, 1.3],
        ];
        traced(
            Array3::from_shape_fn(
                (2, 4, 3),
                |(s, p, n)| if s == 0 { a[p][n] } else { b[p][n] },
            ),
            vec![Closure::Closed, Closure::Open],
            ndarray::array![[0_i64, 0, 0, 0], [0, 0, 1, 1]],
        )
    }

    #[test]
    fn every_set_is_repeated_along_the_motor_range() {
        let out = extend_along(two_sets(), &space(), &[2], 3).unwrap();
        // Slices of 5 points: room for the square's closing copy.
        assert_eq!(out.sets.dim(), (2, 15, 3));
        let apertures: Vec<f64> = (0..15).map(|p| out.sets[[0, p, 2]]).collect();
        let expected: Vec<f64> = [0.5, 1.0, 1.5].iter().flat_map(|&a| [a; 5]).collect();
        assert_eq!(apertures, expected);
        assert_eq!(out.sets[[0, 6, 1]], 1.0);
        assert_eq!((out.report.points, out.report.sets[0].dimension), (15, 2));
        assert_eq!(out.report.extended_along, vec![2]);
        assert_eq!(out.closure, vec![Closure::Open; 2]);
        let shape = out.report.kernel_shape();
        assert_eq!(shape.dimension - shape.extended, 1);
        // Nothing to extend along: the sets as they were.
        let same = extend_along(two_sets(), &space(), &[], 3).unwrap();
        assert_eq!(same.sets, two_sets().sets);
        assert!(extend_along(two_sets(), &space(), &[2], 0).is_err());
        assert!(extend_along(two_sets(), &space(), &[7], 3).is_err());
    }

    #[test]
    fn spatial_sets_are_counted_with_their_slices() {
        let kernel = TraceParams::default();
        assert_eq!(kernel.stored_points(), 100);
        let spatial = TraceParams {
            spatial: Spatial::Compensable,
            spatial_samples: 4,
            ..TraceParams::default()
        };
        assert_eq!(spatial.stored_points(), 404);
        // The points' coordinates and the piece of every point.
        assert_eq!(spatial.sets_bytes(10, 5), 10 * 404 * (5 + 1) * 8);
    }

    #[test]
    fn the_pieces_of_a_spatial_set_are_its_slices() {
        let out = extend_along(two_sets(), &space(), &[2], 3).unwrap();
        // The loop: one piece per slice, ending with a copy of its first point.
        let loop_pieces: Vec<i64> = [0, 1, 2].iter().flat_map(|&t| [t; 5]).collect();
        assert_eq!(out.pieces.row(0).to_vec(), loop_pieces);
        for t in 0..3 {
            for c in 0..3 {
                assert_eq!(out.sets[[0, 5 * t + 4, c]], out.sets[[0, 5 * t, c]]);
            }
        }
        // The two-piece polyline: pieces 2t and 2t + 1, its last point repeated.
        let open_pieces: Vec<i64> = [0, 2, 4]
            .iter()
            .flat_map(|&t| [t, t, t + 1, t + 1, t + 1])
            .collect();
        assert_eq!(out.pieces.row(1).to_vec(), open_pieces);
        assert_eq!(out.sets[[1, 4, 0]], out.sets[[1, 3, 0]]);
        // Every piece lies in one slice, pieces numbered in runs (the file's rule).
        let curve = MetricKind::Curve.with_period(Period::None, Closure::Closed);
        let view = |s: &TracedSets| {
            let v = SetsView::new(s.sets.view()).with_pieces(s.pieces.view());
            curve.check_sets(&v, &s.report.extended_along)
        };
        view(&out).unwrap();
        let dir = tempfile::tempdir().unwrap();
        out.save(&dir.path().join("sets.npy")).unwrap();
        let back = TracedSets::load(&dir.path().join("sets.npy")).unwrap();
        assert_eq!(back.pieces, out.pieces);
        assert_eq!(back.closure, out.closure);
        // Sets extended before slices were pieces (one piece across slices) are refused.
        let mut stale = out;
        stale.pieces.fill(0);
        let message = view(&stale).unwrap_err().to_string();
        assert!(message.contains("hausdorff"), "{message}");
    }

    /// The `curve` matrix of `sets` (no period: the test sets stay inside one period).
    fn curve(sets: &TracedSets) -> crate::metric::DistanceMatrix {
        let params = DistanceParams::new()
            .metric(MetricKind::Curve)
            .period(Period::None);
        let view = SetsView::new(sets.sets.view())
            .with_closure(&sets.closure)
            .with_pieces(sets.pieces.view());
        distance_matrix(view, &params, &Silent).unwrap()
    }

    #[test]
    fn the_curve_metric_between_spatial_sets_is_that_between_the_traced_curves() {
        // Two concentric squares, half-diagonals 1 and 0.4, at apertures 0.7 and 1.3.
        // Between the polylines at one aperture the Hausdorff distance is 1 − 0.4: a
        // vertex of the outer square is 0.6 from the inner one (its nearest point is the
        // inner vertex on the same axis, the inner square being convex), every other
        // point of the outer square is nearer, and the inner square lies inside the
        // outer one with its points at most 0.6 · cos(π/4) from it. Slice t of one set
        // is nearest to slice t of the other (the aperture difference only adds), so
        // the extended sets are 0.6 apart whatever the number of slices, while the
        // traced sets are √(0.6² + 0.6²) apart (the aperture separates them).
        let (a, b) = (square(1.0, 0.7), square(0.4, 1.3));
        let squares = || {
            traced(
                Array3::from_shape_fn(
                    (2, 4, 3),
                    |(s, p, n)| if s == 0 { a[p][n] } else { b[p][n] },
                ),
                vec![Closure::Closed; 2],
                Array2::zeros((2, 4)),
            )
        };
        let traced_d = curve(&squares())[[0, 1]];
        approx::assert_abs_diff_eq!(traced_d, 0.72_f64.sqrt(), epsilon = 1e-12);
        for samples in [1, 2, 5] {
            let out = extend_along(squares(), &space(), &[2], samples).unwrap();
            let d = curve(&out);
            approx::assert_abs_diff_eq!(d[[0, 1]], 0.6, epsilon = 1e-12);
            approx::assert_abs_diff_eq!(d[[1, 0]], 0.6, epsilon = 1e-12);
            // Deterministic: the same sets, the same matrix, bit for bit.
            let again = extend_along(squares(), &space(), &[2], samples).unwrap();
            assert_eq!(again.sets, out.sets);
            assert_eq!(curve(&again).view(), d.view());
        }
    }

    #[test]
    fn the_curve_metric_is_the_minimum_over_slice_polylines() {
        // The two sets of `two_sets`, extended at 2 slices: the directed distance from
        // every vertex of one to the other's polylines, computed directly (point to
        // segment, minimum over the slices' segments), its maximum over vertices and
        // over the segments' points (densely), equals the metric.
        let out = extend_along(two_sets(), &space(), &[2], 2).unwrap();
        let d = curve(&out)[[0, 1]];
        let segments = |s: usize| -> Vec<([f64; 3], [f64; 3])> {
            let p = out.sets.dim().1;
            (0..p - 1)
                .filter(|&q| out.pieces[[s, q]] == out.pieces[[s, q + 1]])
                .map(|q| {
                    let at = |i: usize| std::array::from_fn(|c| out.sets[[s, i, c]]);
                    (at(q), at(q + 1))
                })
                .collect()
        };
        let to_segment = |x: [f64; 3], (u, v): ([f64; 3], [f64; 3])| -> f64 {
            let w: [f64; 3] = std::array::from_fn(|c| v[c] - u[c]);
            let len2: f64 = w.iter().map(|e| e * e).sum();
            let t = if len2 > 0.0 {
                ((0..3).map(|c| (x[c] - u[c]) * w[c]).sum::<f64>() / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (0..3)
                .map(|c| (x[c] - u[c] - t * w[c]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let directed = |from: usize, to: usize| -> f64 {
            let targets = segments(to);
            segments(from)
                .into_iter()
                .flat_map(|(u, v)| {
                    (0..=200).map(move |k| {
                        let t = k as f64 / 200.0;
                        std::array::from_fn::<f64, 3, _>(|c| u[c] + t * (v[c] - u[c]))
                    })
                })
                .map(|x| {
                    targets
                        .iter()
                        .map(|&seg| to_segment(x, seg))
                        .fold(f64::INFINITY, f64::min)
                })
                .fold(0.0, f64::max)
        };
        let direct = directed(0, 1).max(directed(1, 0));
        // Dense sampling of the segments finds the maximum from below, to within the
        // step (the distance is 1-Lipschitz along a segment of length ≤ √2).
        assert!(
            direct <= d + 1e-12 && d - direct < 2.0_f64.sqrt() / 200.0,
            "{d} {direct}"
        );
        // No segment joins two slices or two pieces: the square's 4 per slice, the
        // polyline's 1 + 1 and the repeated last point's (length 0).
        let square_slices = segments(0);
        assert_eq!(square_slices.len(), 2 * 4);
        assert_eq!(segments(1).len(), 2 * 3);
    }
}
