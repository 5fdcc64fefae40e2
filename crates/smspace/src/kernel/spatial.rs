//! Spatial kernel sets (issue 15, `[kernel] spatial = "compensable"`): each traced
//! `M^i` extended along the motors the compensability analysis found non-spatial
//! ([`crate::analysis::compensability`]).
//!
//! The paper's `M^i` is the set of configurations with the sensation of `m^i`; with a
//! pupil, the sensation fixes the aperture, and the manifold of sets is
//! `(x, y, alpha) × aperture`. The set of configurations whose sensor is in the same
//! *spatial* configuration is `M^i` moved along every non-spatial direction: for a
//! motor `j` whose axis is such a direction (the pupil's aperture),
//!
//! ```text
//! M^i_spatial = { m + (a − m_j) e_j : m ∈ M^i, a ∈ range of motor j } ,
//! ```
//!
//! a set of dimension `k + 1` (here 2: a kernel curve × the aperture range).
//!
//! **Sampling (a product, stated).** Each traced point is repeated at `samples` values
//! of the motor's range, the same for every set: `low + (high − low) t / (samples − 1)`,
//! `t = 0 … samples − 1`, for a bounded motor, and `period · t / samples` around the
//! traced value for a periodic one. A set of `P` points becomes `P · samples` points
//! (`aperture` slowest), each copy keeping its piece. Because the grid is shared, the
//! Hausdorff distance between two extended sets is that of their traced curves in the
//! other motors: the non-spatial motor no longer separates sets. Only motors whose
//! axis is the non-spatial direction are supported (the analysis reports which); the
//! extended sets have dimension `k + 1`, so the `curve` metric refuses them
//! (`metric = "hausdorff"`).

use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};

use super::{KernelError, TracedSets};
use crate::agent::{Motor, MotorSpace};
use crate::error::InvalidParameter;

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

/// The values of motor `motor` that every point is repeated at (module docs), around
/// `traced` for a periodic motor.
fn grid(motor: Motor, samples: usize, traced: f64) -> Vec<f64> {
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
            .map(|t| traced + period * t as f64 / samples as f64)
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
        out = extend_one(out, motor, j, samples);
    }
    Ok(out)
}

fn extend_one(traced: TracedSets, motor: Motor, j: usize, samples: usize) -> TracedSets {
    let (m, p, n) = traced.sets.dim();
    let mut sets = Array3::zeros((m, p * samples, n));
    let mut pieces = Array2::zeros((m, p * samples));
    for s in 0..m {
        let start = traced.sets[[s, 0, j]];
        for (t, value) in grid(motor, samples, start).into_iter().enumerate() {
            for q in 0..p {
                let target = t * p + q;
                for c in 0..n {
                    sets[[s, target, c]] = traced.sets[[s, q, c]];
                }
                sets[[s, target, j]] = value;
                pieces[[s, target]] = traced.pieces[[s, q]];
            }
        }
    }
    let mut report = traced.report;
    report.points = p * samples;
    report.extended_along.push(j);
    for set in &mut report.sets {
        set.dimension += 1;
    }
    TracedSets {
        sets,
        kept: traced.kept,
        closure: traced.closure,
        pieces,
        report,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::{Closure, SetReport, SetStatus, StepControl, TraceMethod, TraceReport};

    /// One set of two points in 3 motors, the last bounded in `[0.5, 1.5]`.
    fn traced() -> TracedSets {
        let set = SetReport {
            index: 0,
            status: SetStatus::Closed,
            steps: 1,
            length: 1.0,
            max_residual: 0.0,
            max_pose_deviation: None,
            dimension: 1,
            pieces: 1,
            unvisited_pieces: 0,
            covering_radius: None,
        };
        TracedSets {
            sets: Array3::from_shape_vec((1, 2, 3), vec![0.1, 0.2, 0.9, 0.3, 0.4, 0.9]).unwrap(),
            kept: vec![0],
            closure: vec![Closure::Closed],
            pieces: Array2::zeros((1, 2)),
            report: TraceReport {
                agent: "test".into(),
                method: TraceMethod::Kinematic,
                step_control: StepControl::Fixed,
                points: 2,
                summary: Default::default(),
                sets: vec![set],
                extended_along: Vec::new(),
            },
        }
    }

    #[test]
    fn every_point_is_repeated_along_the_motor_range() {
        let space = MotorSpace::new(vec![
            Motor::HINGE,
            Motor::HINGE,
            Motor::Bounded {
                low: 0.5,
                high: 1.5,
            },
        ])
        .unwrap();
        let out = extend_along(traced(), &space, &[2], 3).unwrap();
        assert_eq!(out.sets.dim(), (1, 6, 3));
        let apertures: Vec<f64> = (0..6).map(|p| out.sets[[0, p, 2]]).collect();
        assert_eq!(apertures, vec![0.5, 0.5, 1.0, 1.0, 1.5, 1.5]);
        assert_eq!(out.sets[[0, 3, 0]], 0.3);
        assert_eq!((out.report.points, out.report.sets[0].dimension), (6, 2));
        assert_eq!(out.report.extended_along, vec![2]);
        // Nothing to extend along: the sets as they were.
        assert_eq!(
            extend_along(traced(), &space, &[], 3).unwrap().sets,
            traced().sets
        );
        assert!(extend_along(traced(), &space, &[2], 0).is_err());
        assert!(extend_along(traced(), &space, &[7], 3).is_err());
    }
}
