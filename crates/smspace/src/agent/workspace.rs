//! The working space: the rectangle of sensor positions an agent explores, in the
//! observer's frame (paper section 3.2, step 1).

use serde::{Deserialize, Serialize};

use super::Pose;
use crate::error::InvalidParameter;

/// The rectangular working space, in the observer's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Workspace {
    /// Centre `(x, y)`.
    pub center: [f64; 2],
    /// Full extents `(depth along x, width along y)`.
    pub size: [f64; 2],
}

impl Workspace {
    /// The paper's working space: centre `(1.75, 0)`, 1.5 deep, 2 wide (for its arm of
    /// reach 3).
    pub const PAPER: Workspace = Workspace {
        center: [1.75, 0.0],
        size: [1.5, 2.0],
    };

    /// The working space scaled by `factor` about the origin (centre and extents).
    pub fn scaled(self, factor: f64) -> Workspace {
        Workspace {
            center: self.center.map(|c| c * factor),
            size: self.size.map(|s| s * factor),
        }
    }

    /// Whether the pose's position lies in the working space (boundary included).
    pub fn contains(&self, pose: Pose) -> bool {
        (pose.x - self.center[0]).abs() <= self.size[0] / 2.0
            && (pose.y - self.center[1]).abs() <= self.size[1] / 2.0
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
        Ok(())
    }
}
