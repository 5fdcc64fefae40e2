//! Exploration: motor babbling in a working space, and the probe grid of paper Fig. 5d.
//!
//! **Babbling** (paper section 3.2, step 1): motor configurations are drawn uniformly in
//! the motor range (`[-π, π)^N` for hinges) from a ChaCha8 stream seeded with `seed`, and
//! kept only where the observer sees the sensor inside the working space, a rectangle
//! `|x − c_x| ≤ w_x/2, |y − c_y| ≤ w_y/2` (the paper's: centre `(1.75, 0)`, 1.5 deep
//! along `x` and 2 wide along `y`). Draws continue until `n` are kept.
//!
//! **Probes** (paper section 3.3, Fig. 5d): a grid of `positions × positions` points at
//! the centres of the cells of the working space, times `orientations` orientations
//! `alpha = 2πk/orientations` (0° to 324° by 36° for 10), each turned into a motor
//! configuration by the agent's inverse kinematics. Probes are appended after the
//! babbled configurations and marked in [`Exploration::probes`].

use ndarray::{Array2, Axis};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub use crate::agent::Workspace;
use crate::agent::{Agent, AgentConfig, Pose};
use crate::io::{self, IoError};

/// Errors of exploration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExploreError {
    /// A parameter is out of its domain.
    #[error("invalid exploration parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter, as in the configuration file.
        name: &'static str,
        /// The value given.
        value: String,
        /// What a valid value looks like.
        reason: &'static str,
    },
    /// A parameter is out of its domain (located by table and key).
    #[error(transparent)]
    Parameter(#[from] crate::error::InvalidParameter),
    /// Too few random configurations landed in the working space.
    #[error("only {kept} of {wanted} configurations landed in the working space after {draws} draws; is the working space (centre {center:?}, size {size:?}) reachable by the agent?")]
    WorkspaceUnreachable {
        /// Configurations kept.
        kept: usize,
        /// Configurations wanted.
        wanted: usize,
        /// Random draws made.
        draws: u64,
        /// Working-space centre.
        center: [f64; 2],
        /// Working-space size.
        size: [f64; 2],
    },
    /// The agent cannot reach a probe pose.
    #[error("probe pose (x = {x:.3}, y = {y:.3}, alpha = {alpha:.3}) is out of the agent's reach (or the agent has no inverse kinematics)")]
    ProbeUnreachable {
        /// Probe x.
        x: f64,
        /// Probe y.
        y: f64,
        /// Probe orientation, radians.
        alpha: f64,
    },
    /// The probe grid needs a working space.
    #[error("the probe grid needs a working space; set workspace_center and workspace_size")]
    ProbesWithoutWorkspace,
}

/// Whether to add the probe grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Probes {
    /// Babbled configurations only.
    #[default]
    None,
    /// Add the grid of positions × orientations (paper Fig. 5d).
    Grid,
}

/// Parameters of exploration (the `[exploration]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExploreParams {
    /// Number of babbled configurations to keep. Default 2500 (the paper's).
    pub n: usize,
    /// Seed of the babbling stream. Default 1.
    pub seed: u64,
    /// Working-space centre; `None` (with `workspace_size`) keeps every draw. Default
    /// the paper's `[1.75, 0.0]` for the arm and none for the toys.
    pub workspace_center: Option<[f64; 2]>,
    /// Working-space size `[depth, width]`. Default the paper's `[1.5, 2.0]` for the arm.
    pub workspace_size: Option<[f64; 2]>,
    /// Whether to append the probe grid. Default `none`.
    pub probes: Probes,
    /// Grid positions along each side of the working space. Default 10.
    pub probe_positions: usize,
    /// Grid orientations, evenly spaced from 0. Default 10 (0° to 324° by 36°).
    pub probe_orientations: usize,
    /// Draws allowed per kept configuration before giving up. Default 10 000.
    pub max_draws_per_kept: u64,
}

impl Default for ExploreParams {
    fn default() -> Self {
        Self {
            n: 2500,
            seed: 1,
            workspace_center: None,
            workspace_size: None,
            probes: Probes::None,
            probe_positions: 10,
            probe_orientations: 10,
            max_draws_per_kept: 10_000,
        }
    }
}

impl ExploreParams {
    /// The working space these parameters name, or the agent's default (the paper's for
    /// the arm, none for the toys).
    pub fn workspace(&self, agent: &dyn Agent) -> Result<Option<Workspace>, ExploreError> {
        let workspace = match (self.workspace_center, self.workspace_size) {
            (Some(center), Some(size)) => Some(Workspace { center, size }),
            (None, None) => default_workspace(agent),
            (Some(_), None) | (None, Some(_)) => {
                return Err(ExploreError::InvalidParameter {
                    name: "workspace_center/workspace_size",
                    value: "only one of them".into(),
                    reason: "give both or neither",
                })
            }
        };
        if let Some(w) = &workspace {
            w.check()?;
        }
        Ok(workspace)
    }

    /// Validates the parameters for `agent` before anything runs, and returns the
    /// working space they name (see [`workspace`](Self::workspace)).
    pub fn check(&self, agent: &dyn Agent) -> Result<Option<Workspace>, ExploreError> {
        let workspace = self.workspace(agent)?;
        self.check_counts(workspace.as_ref())?;
        Ok(workspace)
    }

    /// Rows the exploration makes: `n` babbled plus the probe grid's cells (saturating).
    pub fn rows(&self) -> u64 {
        let probes = match self.probes {
            Probes::Grid => (self.probe_positions as u64)
                .saturating_mul(self.probe_positions as u64)
                .saturating_mul(self.probe_orientations as u64),
            Probes::None => 0,
        };
        (self.n as u64).saturating_add(probes)
    }

    /// Bytes of the exploration's arrays for an agent with `motor_dim` motors: motors
    /// `(rows, N)`, poses `(rows, 3)` and probe labels `(rows, 3)` (saturating).
    pub fn bytes(&self, motor_dim: usize) -> u64 {
        self.rows()
            .saturating_mul(motor_dim as u64 + 6)
            .saturating_mul(8)
    }

    /// The checks that do not depend on the agent: counts, and the probe grid's need of
    /// a working space.
    fn check_counts(&self, workspace: Option<&Workspace>) -> Result<(), ExploreError> {
        if let Some(w) = workspace {
            w.check()?;
        }
        if self.n == 0 && self.probes == Probes::None {
            return Err(ExploreError::InvalidParameter {
                name: "n",
                value: "0".into(),
                reason: "explore at least one configuration (or ask for probes)",
            });
        }
        if self.n > MAX_CONFIGURATIONS {
            return Err(ExploreError::InvalidParameter {
                name: "n",
                value: self.n.to_string(),
                reason: "must be at most 100000000 configurations (the paper explores 2500)",
            });
        }
        if self.max_draws_per_kept == 0 {
            return Err(ExploreError::InvalidParameter {
                name: "max_draws_per_kept",
                value: "0".into(),
                reason: "must be at least 1",
            });
        }
        if self.probes == Probes::Grid {
            if workspace.is_none() {
                return Err(ExploreError::ProbesWithoutWorkspace);
            }
            for (name, value) in [
                ("probe_positions", self.probe_positions),
                ("probe_orientations", self.probe_orientations),
            ] {
                if value == 0 {
                    return Err(ExploreError::InvalidParameter {
                        name,
                        value: "0".into(),
                        reason: "must be at least 1",
                    });
                }
            }
            // `rows` saturates, so an overflowing grid is refused too.
            if self.rows() > MAX_CONFIGURATIONS as u64 {
                return Err(ExploreError::InvalidParameter {
                    name: "probe_positions",
                    value: format!(
                        "{} × {} positions × {} orientations",
                        self.probe_positions, self.probe_positions, self.probe_orientations
                    ),
                    reason: "the probe grid and n together must be at most 100000000 configurations (the paper's grid is 10 × 10 × 10)",
                });
            }
        }
        Ok(())
    }
}

/// Most configurations (babbled and probes together) one exploration may make.
pub const MAX_CONFIGURATIONS: usize = 100_000_000;

/// The working space an agent explores by default: [`Agent::default_workspace`] (the
/// paper's scaled with the arm's reach, none for the toys: their whole motor range).
pub fn default_workspace(agent: &dyn Agent) -> Option<Workspace> {
    agent.default_workspace()
}

/// The result of exploration.
#[derive(Debug, Clone)]
pub struct Exploration {
    /// Motor configurations `(M, N)`: the babbled ones, then the probes.
    pub motors: Array2<f64>,
    /// The observer's poses `(M, 3)` as `(x, y, alpha)`.
    pub poses: Array2<f64>,
    /// `(M, 3)` int64: for probe rows `(orientation index, x index, y index)`, for babbled
    /// rows `(-1, -1, -1)`.
    pub probes: Array2<i64>,
    /// The working space used.
    pub workspace: Option<Workspace>,
}

/// The files [`Exploration::save`] writes, in a folder.
pub const EXPLORATION_FILES: [&str; 4] =
    ["motors.npy", "poses.npy", "probes.npy", "exploration.json"];

impl Exploration {
    /// How many rows are probe grid cells.
    pub fn probe_count(&self) -> usize {
        self.probes.column(0).iter().filter(|&&o| o >= 0).count()
    }

    /// Writes [`EXPLORATION_FILES`] into `dir`: the three arrays, and
    /// `exploration.json` with the agent, the parameters and the row counts.
    pub fn save(
        &self,
        dir: &std::path::Path,
        agent: &AgentConfig,
        params: &ExploreParams,
    ) -> Result<(), IoError> {
        // All four or none (see `io::Outputs`).
        let mut outputs = io::Outputs::new();
        self.write_into(&mut outputs, dir, agent, params)?;
        outputs.commit()?;
        Ok(())
    }

    /// Stages the files of [`save`](Self::save) into `outputs`, to be renamed into place
    /// with the other files of a command or stage.
    pub fn write_into(
        &self,
        outputs: &mut io::Outputs,
        dir: &std::path::Path,
        agent: &AgentConfig,
        params: &ExploreParams,
    ) -> Result<(), IoError> {
        let [motors, poses, probes, summary] = EXPLORATION_FILES.map(|f| dir.join(f));
        outputs.npy(&motors, &self.motors)?;
        outputs.npy(&poses, &self.poses)?;
        outputs.npy(&probes, &self.probes)?;
        let probe_rows = self.probe_count();
        outputs.json(
            &summary,
            &serde_json::json!({
                "agent": agent,
                "params": params,
                "workspace": self.workspace,
                "rows": self.motors.nrows(),
                "babbled": self.motors.nrows() - probe_rows,
                "probes": probe_rows,
            }),
        )
    }

    /// Reads the arrays [`save`](Self::save) wrote for an agent with `motor_dim`
    /// motors, explored in `workspace`.
    pub fn load(
        dir: &std::path::Path,
        motor_dim: usize,
        workspace: Option<Workspace>,
    ) -> Result<Self, IoError> {
        let [motors, poses, probes, _] = EXPLORATION_FILES.map(|f| dir.join(f));
        let motors = io::read_matrix(&motors, Some(motor_dim), &format!("(M, {motor_dim})"))?;
        let poses = io::read_matrix(&poses, Some(3), "(M, 3)")?;
        let labels = io::read_i64(&probes)?;
        let shape = labels.shape().to_vec();
        let probes = labels
            .into_dimensionality()
            .ok()
            .filter(|p: &Array2<i64>| p.dim() == (motors.nrows(), 3))
            .ok_or_else(|| IoError::Shape {
                path: probes.clone(),
                found: io::shape_string(&shape),
                expected: format!("({}, 3)", motors.nrows()),
            })?;
        Ok(Self {
            motors,
            poses,
            probes,
            workspace,
        })
    }
}

/// Babbles `params.n` motor configurations inside the working space, and appends the
/// probe grid when asked.
///
/// ```
/// use smspace::agent::AgentConfig;
/// use smspace::explore::{explore, ExploreParams};
/// let agent = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
/// let params = ExploreParams { n: 20, ..ExploreParams::default() };
/// let found = explore(agent.as_ref(), &params).unwrap();
/// assert_eq!(found.motors.dim(), (20, 4));
/// assert!(found.poses.column(0).iter().all(|&x| (1.0..=2.5).contains(&x)));
/// ```
pub fn explore(agent: &dyn Agent, params: &ExploreParams) -> Result<Exploration, ExploreError> {
    let workspace = params.workspace(agent)?;
    explore_in(agent, params, workspace)
}

/// Like [`explore`], in the given working space (`None`: the whole motor range),
/// ignoring the parameters' `workspace_center` and `workspace_size`.
pub fn explore_in(
    agent: &dyn Agent,
    params: &ExploreParams,
    workspace: Option<Workspace>,
) -> Result<Exploration, ExploreError> {
    params.check_counts(workspace.as_ref())?;
    let n_motors = agent.motor_dim();
    let (low, high) = agent.motor_topology().range();
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let mut motors: Vec<f64> = Vec::with_capacity(params.n * n_motors);
    let mut poses: Vec<f64> = Vec::with_capacity(params.n * 3);
    let budget = params.max_draws_per_kept.saturating_mul(params.n as u64);
    let mut draws = 0_u64;
    let mut m = vec![0.0; n_motors];
    while poses.len() < params.n * 3 {
        if draws >= budget {
            let w = workspace.unwrap_or(Workspace::PAPER);
            return Err(ExploreError::WorkspaceUnreachable {
                kept: poses.len() / 3,
                wanted: params.n,
                draws,
                center: w.center,
                size: w.size,
            });
        }
        draws += 1;
        for v in m.iter_mut() {
            *v = rng.gen_range(low..high);
        }
        let pose = agent.pose(&m);
        if workspace.is_none_or(|w| w.contains(pose)) {
            motors.extend_from_slice(&m);
            poses.extend_from_slice(&pose.to_array());
        }
    }
    let mut probes = vec![-1_i64; params.n * 3];
    if params.probes == Probes::Grid {
        let w = workspace.ok_or(ExploreError::ProbesWithoutWorkspace)?;
        let k = params.probe_positions;
        for o in 0..params.probe_orientations {
            let alpha = crate::agent::wrap_angle(
                2.0 * std::f64::consts::PI * o as f64 / params.probe_orientations as f64,
            );
            for ix in 0..k {
                for iy in 0..k {
                    let x =
                        w.center[0] - w.size[0] / 2.0 + w.size[0] * (ix as f64 + 0.5) / k as f64;
                    let y =
                        w.center[1] - w.size[1] / 2.0 + w.size[1] * (iy as f64 + 0.5) / k as f64;
                    let target = Pose { x, y, alpha };
                    let q = agent
                        .inverse_kinematics(target)
                        .ok_or(ExploreError::ProbeUnreachable { x, y, alpha })?;
                    motors.extend_from_slice(&q);
                    poses.extend_from_slice(&agent.pose(&q).to_array());
                    probes.extend_from_slice(&[o as i64, ix as i64, iy as i64]);
                }
            }
        }
    }
    let rows = poses.len() / 3;
    let to_array = |v: Vec<f64>, cols: usize| {
        Array2::from_shape_vec((rows, cols), v).expect("rows × cols values were pushed")
    };
    Ok(Exploration {
        motors: to_array(motors, n_motors),
        poses: to_array(poses, 3),
        probes: Array2::from_shape_vec((rows, 3), probes).expect("three indices per row"),
        workspace,
    })
}

/// The observer's poses `(M, 3)` of motor configurations `(M, N)`.
pub fn poses_of(agent: &dyn Agent, motors: &Array2<f64>) -> Array2<f64> {
    let mut poses = Array2::zeros((motors.nrows(), 3));
    for (row, mut out) in motors.axis_iter(Axis(0)).zip(poses.axis_iter_mut(Axis(0))) {
        let p = agent.pose(row.as_slice().expect("C-order rows")).to_array();
        out.assign(&ndarray::aview1(&p));
    }
    poses
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::AgentConfig;

    fn arm() -> Box<dyn Agent> {
        AgentConfig::preset("planar-arm").unwrap().build().unwrap()
    }

    #[test]
    fn babbling_is_seeded_and_stays_in_the_workspace() {
        let params = ExploreParams {
            n: 200,
            ..ExploreParams::default()
        };
        let a = explore(arm().as_ref(), &params).unwrap();
        let b = explore(arm().as_ref(), &params).unwrap();
        assert_eq!(a.motors, b.motors);
        for p in a.poses.rows() {
            assert!((1.0..=2.5).contains(&p[0]) && (-1.0..=1.0).contains(&p[1]));
        }
        assert!(a
            .motors
            .iter()
            .all(|m| (-std::f64::consts::PI..std::f64::consts::PI).contains(m)));
        assert!(a.probes.iter().all(|&v| v == -1));
    }

    #[test]
    fn probe_grid_has_the_paper_layout() {
        let params = ExploreParams {
            n: 5,
            probes: Probes::Grid,
            ..ExploreParams::default()
        };
        let e = explore(arm().as_ref(), &params).unwrap();
        assert_eq!(e.motors.nrows(), 5 + 1000);
        // Probe (orientation 3, ix 0, iy 9): alpha = 108°, x = 1.075, y = 0.9.
        let row = 5 + 3 * 100 + 9;
        assert_eq!(e.probes.row(row).to_vec(), vec![3, 0, 9]);
        approx::assert_abs_diff_eq!(e.poses[[row, 0]], 1.075, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(e.poses[[row, 1]], 0.9, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(e.poses[[row, 2]], 108f64.to_radians(), epsilon = 1e-9);
    }

    #[test]
    fn unreachable_workspace_is_an_error() {
        let params = ExploreParams {
            n: 10,
            workspace_center: Some([10.0, 0.0]),
            workspace_size: Some([1.0, 1.0]),
            max_draws_per_kept: 10,
            ..ExploreParams::default()
        };
        let err = explore(arm().as_ref(), &params).unwrap_err();
        assert!(err.to_string().contains("only 0 of 10"), "{err}");
    }
}
