//! The working space: the rectangle of sensor positions an agent explores, in the
//! observer's frame (paper section 3.2, step 1). It bounds the first two coordinates
//! of the observer's pose, which must then be linear (the sensor's position); for a
//! sensor in 3-D it may also bound the third (`z_range`: then a box).

use serde::{Deserialize, Serialize};

use super::{CoordinateKind, PoseSpace};
use crate::params::InvalidParameter;

/// The rectangular working space, in the observer's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Workspace {
    /// Centre `(x, y)`.
    pub center: [f64; 2],
    /// Full extents `(depth along x, width along y)`.
    pub size: [f64; 2],
    /// The interval `[low, high]` of heights `z` (the pose's third coordinate) for a
    /// sensor in 3-D; `None` (the default): any height.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z_range: Option<[f64; 2]>,
}

impl Workspace {
    /// The paper's working space: centre `(1.75, 0)`, 1.5 deep, 2 wide (for its arm of
    /// reach 3).
    pub const PAPER: Workspace = Workspace {
        center: [1.75, 0.0],
        size: [1.5, 2.0],
        z_range: None,
    };

    /// The working space scaled by `factor` about the origin (centre and extents).
    pub fn scaled(self, factor: f64) -> Workspace {
        Workspace {
            center: self.center.map(|c| c * factor),
            size: self.size.map(|s| s * factor),
            z_range: self.z_range.map(|z| z.map(|v| v * factor)),
        }
    }

    /// Whether the position `(pose[0], pose[1])` (and `pose[2]` with a `z_range`) lies
    /// in the working space (boundary included).
    pub fn contains(&self, pose: &[f64]) -> bool {
        (pose[0] - self.center[0]).abs() <= self.size[0] / 2.0
            && (pose[1] - self.center[1]).abs() <= self.size[1] / 2.0
            && self
                .z_range
                .is_none_or(|[low, high]| (low..=high).contains(&pose[2]))
    }

    /// Whether poses of `space` can be tested against a working space: their first two
    /// coordinates are linear (a position).
    pub fn fits(space: &PoseSpace) -> bool {
        let c = space.coordinates();
        c.len() >= 2 && c[..2].iter().all(|c| c.kind == CoordinateKind::Linear)
    }

    /// Checks that the centre is finite and both extents are finite and positive.
    pub fn check(&self) -> Result<(), InvalidParameter> {
        if !self.center.iter().all(|v| v.is_finite()) {
            return Err(InvalidParameter::new(
                "exploration",
                "workspace_center",
                format!("{:?}", self.center),
                "must be two finite numbers",
            ));
        }
        if !self.size.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(InvalidParameter::new(
                "exploration",
                "workspace_size",
                format!("{:?}", self.size),
                "must be two finite numbers greater than zero",
            ));
        }
        if let Some(z) = self.z_range {
            if !(z.iter().all(|v| v.is_finite()) && z[0] < z[1]) {
                return Err(InvalidParameter::new(
                    "agent",
                    "workspace",
                    format!("z from {} to {}", z[0], z[1]),
                    "the heights of a working space are two finite numbers [low, high] with low < high",
                ));
            }
        }
        Ok(())
    }
}
