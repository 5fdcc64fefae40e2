//! Exploration: motor babbling in a working space, and the probe grid of paper Fig. 5d.
//!
//! **Babbling** (paper section 3.2, step 1): motor configurations are drawn uniformly,
//! each coordinate from its own range of the agent's [`MotorSpace`] (`[-π, π)` for a
//! hinge, `[low, high)` for a bounded motor), from a ChaCha8 stream seeded with `seed`,
//! and kept only where the observer sees the sensor inside the working space, a
//! rectangle `|x − c_x| ≤ w_x/2, |y − c_y| ≤ w_y/2` of the first two pose coordinates
//! (the paper's: centre `(1.75, 0)`, 1.5 deep along `x` and 2 wide along `y`). Draws
//! continue until `n` are kept. An agent without a ground truth babbles over its whole
//! motor space (no working space) and its exploration has no poses.
//!
//! **Probes** (paper section 3.3, Fig. 5d): a grid of `positions × positions` points at
//! the centres of the cells of the working space, times `orientations` orientations
//! `alpha = 2πk/orientations` (0° to 324° by 36° for 10), each turned into a motor
//! configuration by the observer's inverse kinematics (so the grid needs the planar
//! pose `(x, y, alpha)`). Probes are appended after the babbled configurations and
//! marked in [`Exploration::probes`].
//!
//! [`MotorSpace`]: crate::agent::MotorSpace

use ndarray::{Array2, ArrayView1, ArrayView2};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

pub use crate::agent::Workspace;
use crate::agent::{Agent, AgentConfig, AgentError, GroundTruth, Observer, Pose};
use crate::io::{self, IoError};
use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;

/// Errors of exploration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExploreError {
    /// A parameter is out of its domain (located by table and key).
    #[error(transparent)]
    Parameter(#[from] InvalidParameter),
    /// The agent answered something impossible (an inverse kinematics of the wrong
    /// length).
    #[error(transparent)]
    Agent(#[from] AgentError),
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
    #[error("probe pose (x = {x:.3}, y = {y:.3}, alpha = {alpha:.3}): the observer found no motor configuration for it, so it is out of the agent's reach, or the agent has no inverse kinematics (the probe grid needs one: the planar arm and planar arm-shaped chains have it, other chains and 3-D bodies do not); shrink the working space, or set [exploration] probes = \"none\"")]
    ProbeUnreachable {
        /// Probe x.
        x: f64,
        /// Probe y.
        y: f64,
        /// Probe orientation, radians.
        alpha: f64,
    },
}

impl ExploreError {
    /// The parameter this error is about, when it is one of the `[exploration]` table
    /// (or of the agent).
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            ExploreError::Parameter(p) => Some(p),
            ExploreError::Agent(e) => e.invalid_parameter(),
            _ => None,
        }
    }
}

fn invalid(
    key: &'static str,
    value: impl std::fmt::Display,
    reason: impl Into<String>,
) -> ExploreError {
    InvalidParameter::new("exploration", key, value, reason).into()
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
    /// The working space these parameters name, or the agent's default (the paper's
    /// scaled to the arm, none for the toys), checked against the agent's ground truth.
    pub fn workspace(&self, agent: &dyn Agent) -> Result<Option<Workspace>, ExploreError> {
        self.check_params()?.workspace(agent)
    }

    /// Validates the parameters for `agent` before anything runs (the probe grid's
    /// need of a working space and of the planar pose included), and returns the
    /// working space they name (see [`workspace`](Self::workspace)).
    pub fn check(&self, agent: &dyn Agent) -> Result<Option<Workspace>, ExploreError> {
        let valid = self.check_params()?;
        let workspace = valid.workspace(agent)?;
        valid.check_for(agent, workspace.as_ref())?;
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

    /// Bytes of the exploration's arrays for an agent with `motor_dim` motors and
    /// poses of `pose_dim` coordinates (0 without a ground truth): motors `(rows, N)`,
    /// poses `(rows, d)` and probe labels `(rows, 3)` (saturating).
    pub fn bytes(&self, motor_dim: usize, pose_dim: usize) -> u64 {
        self.rows()
            .saturating_mul((motor_dim as u64).saturating_add(pose_dim as u64 + 3))
            .saturating_mul(8)
    }
}

/// Checked [`ExploreParams`]: counts within their limits and an explicit working space
/// (if any) valid. What depends on the agent (its default working space, its ground
/// truth) is checked by [`ExploreValidParams::workspace`] and
/// [`ExploreValidParams::check_for`].
#[derive(Debug, Clone, PartialEq)]
pub struct ExploreValidParams {
    n: usize,
    seed: u64,
    workspace: Option<Workspace>,
    probes: Probes,
    probe_positions: usize,
    probe_orientations: usize,
    max_draws_per_kept: u64,
}

impl CheckParams for ExploreParams {
    type Valid = ExploreValidParams;
    type Error = ExploreError;

    fn check_params(&self) -> Result<ExploreValidParams, ExploreError> {
        let workspace = match (self.workspace_center, self.workspace_size) {
            (Some(center), Some(size)) => Some(Workspace {
                center,
                size,
                z_range: None,
            }),
            (None, None) => None,
            (Some(center), None) => {
                return Err(invalid(
                    "workspace_center",
                    format!("{center:?}"),
                    "given without workspace_size: give both or neither",
                ))
            }
            (None, Some(size)) => {
                return Err(invalid(
                    "workspace_size",
                    format!("{size:?}"),
                    "given without workspace_center: give both or neither",
                ))
            }
        };
        if let Some(w) = &workspace {
            w.check()?;
        }
        if self.n == 0 && self.probes == Probes::None {
            return Err(invalid(
                "n",
                0,
                "explore at least one configuration (or ask for probes)",
            ));
        }
        if self.n > MAX_CONFIGURATIONS {
            return Err(invalid(
                "n",
                self.n,
                "must be at most 100000000 configurations (the paper explores 2500)",
            ));
        }
        if self.max_draws_per_kept == 0 {
            return Err(invalid("max_draws_per_kept", 0, "must be at least 1"));
        }
        if self.probes == Probes::Grid {
            self.check_grid()?;
        }
        Ok(ExploreValidParams {
            n: self.n,
            seed: self.seed,
            workspace,
            probes: self.probes,
            probe_positions: self.probe_positions,
            probe_orientations: self.probe_orientations,
            max_draws_per_kept: self.max_draws_per_kept,
        })
    }
}

impl ExploreParams {
    /// The probe grid's counts: at least one of each, within the configuration limit.
    fn check_grid(&self) -> Result<(), ExploreError> {
        for (key, value) in [
            ("probe_positions", self.probe_positions),
            ("probe_orientations", self.probe_orientations),
        ] {
            if value == 0 {
                return Err(invalid(key, 0, "must be at least 1"));
            }
        }
        // `rows` saturates, so an overflowing grid is refused too.
        if self.rows() > MAX_CONFIGURATIONS as u64 {
            return Err(invalid(
                "probe_positions",
                format!(
                    "{} × {} positions × {} orientations",
                    self.probe_positions, self.probe_positions, self.probe_orientations
                ),
                "the probe grid and n together must be at most 100000000 configurations (the paper's grid is 10 × 10 × 10)",
            ));
        }
        Ok(())
    }
}

impl ExploreValidParams {
    /// The working space: the one the parameters name, else the agent's default. A
    /// working space bounds the sensor's position, so it needs the agent's ground
    /// truth with a position first.
    pub fn workspace(&self, agent: &dyn Agent) -> Result<Option<Workspace>, ExploreError> {
        let workspace = self.workspace.or_else(|| default_workspace(agent));
        if let Some(w) = &workspace {
            w.check()?;
            let fits = agent
                .ground_truth()
                .is_some_and(|o| Workspace::fits(&o.pose_space()));
            if !fits {
                return Err(invalid(
                    "workspace_center",
                    format!("{:?}", w.center),
                    format!(
                        "a working space bounds the sensor's position (the first two coordinates of the observer's pose), and the {} agent has {}; remove workspace_center and workspace_size",
                        agent.name(),
                        match agent.ground_truth() {
                            None => "no ground truth".to_owned(),
                            Some(_) => "no position first in its pose".to_owned(),
                        }
                    ),
                ));
            }
        }
        Ok(workspace)
    }

    /// The checks that need the agent and the working space: the probe grid needs a
    /// working space and the planar pose `(x, y, alpha)`.
    pub fn check_for(
        &self,
        agent: &dyn Agent,
        workspace: Option<&Workspace>,
    ) -> Result<(), ExploreError> {
        if self.probes != Probes::Grid {
            return Ok(());
        }
        if workspace.is_none() {
            return Err(invalid(
                "probes",
                "\"grid\"",
                "the probe grid needs a working space; set workspace_center and workspace_size",
            ));
        }
        if !agent
            .ground_truth()
            .is_some_and(|o| o.pose_space().is_planar())
        {
            return Err(invalid(
                "probes",
                "\"grid\"",
                format!(
                    "the probe grid places the sensor at positions × orientations (x, y, alpha), and the {} agent has no planar ground truth; remove probes",
                    agent.name()
                ),
            ));
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
    /// The observer's poses `(M, d)` of every row, when the agent has a ground truth.
    pub ground_truth: Option<GroundTruth>,
    /// `(M, 3)` int64: for probe rows `(orientation index, x index, y index)`, for babbled
    /// rows `(-1, -1, -1)`.
    pub probes: Array2<i64>,
    /// The working space used.
    pub workspace: Option<Workspace>,
}

/// The files [`Exploration::save`] writes, in a folder (`poses.npy` only when the agent
/// has a ground truth).
pub const EXPLORATION_FILES: [&str; 4] =
    ["motors.npy", "poses.npy", "probes.npy", "exploration.json"];

/// Whether a row of [`Exploration::probes`] labels a babbled configuration
/// (`(-1, -1, -1)`) rather than a probe grid cell (`(orientation, x, y)` indices, all
/// `≥ 0`).
pub fn is_babbled(label: ArrayView1<'_, i64>) -> bool {
    label.first().is_none_or(|&orientation| orientation < 0)
}

/// The babbled rows of a `(M, 3)` probe label array ([`Exploration::probes`]), in order.
pub fn babbled_rows(probes: ArrayView2<'_, i64>) -> Vec<usize> {
    (0..probes.nrows())
        .filter(|&row| is_babbled(probes.row(row)))
        .collect()
}

impl Exploration {
    /// How many rows are probe grid cells.
    pub fn probe_count(&self) -> usize {
        self.probes.nrows() - self.babbled_rows().len()
    }

    /// The babbled rows, in order ([`babbled_rows`]).
    pub fn babbled_rows(&self) -> Vec<usize> {
        babbled_rows(self.probes.view())
    }

    /// The poses as `(M, 3)` `(x, y, alpha)` when the agent's ground truth is the
    /// planar pose; `None` otherwise (no ground truth, or poses of another layout). What
    /// the figures of planar poses draw.
    pub fn planar_poses(&self) -> Option<ndarray::ArrayView2<'_, f64>> {
        self.ground_truth.as_ref().and_then(GroundTruth::planar)
    }

    /// The files [`save`](Self::save) writes: [`EXPLORATION_FILES`], without
    /// `poses.npy` when there is no ground truth.
    pub fn files(&self) -> Vec<&'static str> {
        EXPLORATION_FILES
            .into_iter()
            .filter(|&f| f != "poses.npy" || self.ground_truth.is_some())
            .collect()
    }

    /// Writes [`files`](Self::files) into `dir`: the arrays, and `exploration.json` with
    /// the agent, the parameters and the row counts.
    pub fn save(
        &self,
        dir: &std::path::Path,
        agent: &AgentConfig,
        params: &ExploreParams,
    ) -> Result<(), IoError> {
        // All or none (see `io::Outputs`).
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
        if let Some(truth) = &self.ground_truth {
            outputs.npy(&poses, truth.poses())?;
        }
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

    /// Reads the arrays [`save`](Self::save) wrote for `agent` (its motors, and its
    /// poses when it has a ground truth), explored in `workspace`.
    pub fn load(
        dir: &std::path::Path,
        agent: &dyn Agent,
        workspace: Option<Workspace>,
    ) -> Result<Self, IoError> {
        let [motors, poses, probes, _] = EXPLORATION_FILES.map(|f| dir.join(f));
        let n = agent.motor_dim();
        let motors = io::read_matrix(&motors, Some(n), &format!("(M, {n})"))?;
        let rows = motors.nrows();
        let ground_truth = match agent.ground_truth() {
            Some(observer) => {
                let space = observer.pose_space();
                let d = space.dim();
                let values = io::read_matrix(&poses, Some(d), &format!("(M, {d})"))?;
                if values.nrows() != rows {
                    return Err(IoError::Shape {
                        path: poses,
                        found: io::shape_string(values.shape()),
                        expected: format!("({rows}, {d}), one pose per row of motors.npy"),
                    });
                }
                Some(
                    GroundTruth::new(space, values).map_err(|e| IoError::Invalid {
                        path: poses.clone(),
                        what: "poses",
                        reason: e.to_string(),
                    })?,
                )
            }
            None => None,
        };
        let labels = io::read_i64(&probes)?;
        let shape = labels.shape().to_vec();
        let probes = labels
            .into_dimensionality()
            .ok()
            .filter(|p: &Array2<i64>| p.dim() == (rows, 3))
            .ok_or_else(|| IoError::Shape {
                path: probes.clone(),
                found: io::shape_string(&shape),
                expected: format!("({rows}, 3)"),
            })?;
        Ok(Self {
            motors,
            ground_truth,
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
/// let poses = found.planar_poses().unwrap();
/// assert!(poses.column(0).iter().all(|&x| (1.0..=2.5).contains(&x)));
/// ```
pub fn explore(agent: &dyn Agent, params: &ExploreParams) -> Result<Exploration, ExploreError> {
    let workspace = params.workspace(agent)?;
    explore_in(agent, params, workspace)
}

/// Like [`explore`], in the given working space (`None`: the whole motor space),
/// ignoring the parameters' `workspace_center` and `workspace_size`.
pub fn explore_in(
    agent: &dyn Agent,
    params: &ExploreParams,
    workspace: Option<Workspace>,
) -> Result<Exploration, ExploreError> {
    explore_with(agent, params, workspace, &crate::progress::Silent)
}

/// Like [`explore_in`], reporting to `progress`: one unit per configuration kept
/// (babbled or on the probe grid), in batches of [`PROGRESS_BATCH`].
pub fn explore_with(
    agent: &dyn Agent,
    params: &ExploreParams,
    workspace: Option<Workspace>,
    progress: &dyn Progress,
) -> Result<Exploration, ExploreError> {
    let valid = params.check_params()?;
    if let Some(w) = &workspace {
        // An explicit working space of the caller's, checked like the parameters'.
        let explicit = ExploreValidParams {
            workspace: Some(*w),
            ..valid.clone()
        };
        explicit.workspace(agent)?;
    }
    valid.check_for(agent, workspace.as_ref())?;
    let observer = agent.ground_truth();
    let pose_dim = observer.map_or(0, |o| o.pose_space().dim());
    let grid = match (valid.probes, observer, &workspace) {
        (Probes::Grid, Some(_), Some(_)) => {
            valid.probe_positions * valid.probe_positions * valid.probe_orientations
        }
        _ => 0,
    };
    progress.start("explore", (valid.n + grid) as u64);
    let mut rows = babble(
        agent,
        observer,
        &valid,
        workspace.as_ref(),
        pose_dim,
        progress,
    )?;
    let mut probes = vec![-1_i64; valid.n * 3];
    if let (Probes::Grid, Some(observer), Some(w)) = (valid.probes, observer, &workspace) {
        probe_grid(agent, observer, &valid, w, &mut rows, &mut probes)?;
        progress.advance(grid as u64);
    }
    progress.finish();
    let count = probes.len() / 3;
    let to_array = |v: Vec<f64>, cols: usize| {
        Array2::from_shape_vec((count, cols), v).expect("rows × cols values were pushed")
    };
    let ground_truth = observer
        .map(|o| GroundTruth::new(o.pose_space(), to_array(rows.poses, pose_dim)))
        .transpose()?;
    Ok(Exploration {
        motors: to_array(rows.motors, agent.motor_dim()),
        ground_truth,
        probes: Array2::from_shape_vec((count, 3), probes).expect("three indices per row"),
        workspace,
    })
}

/// Kept configurations between two reports to a [`Progress`].
pub const PROGRESS_BATCH: usize = 1024;

/// Motor rows and their poses, row-major, as they are explored.
struct Rows {
    motors: Vec<f64>,
    poses: Vec<f64>,
}

/// The babbled rows: each coordinate drawn from its own range until `n` rows whose
/// pose lies in the working space are kept.
fn babble(
    agent: &dyn Agent,
    observer: Option<&dyn Observer>,
    params: &ExploreValidParams,
    workspace: Option<&Workspace>,
    pose_dim: usize,
    progress: &dyn Progress,
) -> Result<Rows, ExploreError> {
    let ranges: Vec<(f64, f64)> = agent
        .motor_space()
        .motors()
        .iter()
        .map(|m| m.range())
        .collect();
    let n_motors = ranges.len();
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let mut rows = Rows {
        motors: Vec::with_capacity(params.n * n_motors),
        poses: Vec::with_capacity(params.n * pose_dim),
    };
    let budget = params.max_draws_per_kept.saturating_mul(params.n as u64);
    let (mut draws, mut kept) = (0_u64, 0);
    let mut m = vec![0.0; n_motors];
    let mut pose = vec![0.0; pose_dim];
    while kept < params.n {
        if draws >= budget {
            let w = workspace.copied().unwrap_or(Workspace::PAPER);
            return Err(ExploreError::WorkspaceUnreachable {
                kept,
                wanted: params.n,
                draws,
                center: w.center,
                size: w.size,
            });
        }
        draws += 1;
        for (v, &(low, high)) in m.iter_mut().zip(&ranges) {
            *v = rng.random_range(low..high);
        }
        if let Some(observer) = observer {
            observer.pose(&m, &mut pose);
        }
        if workspace.is_none_or(|w| w.contains(&pose)) {
            rows.motors.extend_from_slice(&m);
            rows.poses.extend_from_slice(&pose);
            kept += 1;
            if kept % PROGRESS_BATCH == 0 {
                progress.advance(PROGRESS_BATCH as u64);
            }
        }
    }
    progress.advance((kept % PROGRESS_BATCH) as u64);
    Ok(rows)
}

/// Appends the probe grid (paper Fig. 5d): every cell centre of the working space at
/// every orientation, put in place by the observer's inverse kinematics.
fn probe_grid(
    agent: &dyn Agent,
    observer: &dyn Observer,
    params: &ExploreValidParams,
    w: &Workspace,
    rows: &mut Rows,
    probes: &mut Vec<i64>,
) -> Result<(), ExploreError> {
    let k = params.probe_positions;
    let mut pose = vec![0.0; observer.pose_space().dim()];
    for o in 0..params.probe_orientations {
        let alpha = crate::agent::wrap_angle(
            2.0 * std::f64::consts::PI * o as f64 / params.probe_orientations as f64,
        );
        for ix in 0..k {
            for iy in 0..k {
                let x = w.center[0] - w.size[0] / 2.0 + w.size[0] * (ix as f64 + 0.5) / k as f64;
                let y = w.center[1] - w.size[1] / 2.0 + w.size[1] * (iy as f64 + 0.5) / k as f64;
                let target = Pose { x, y, alpha };
                let q = observer
                    .inverse_kinematics(&target.to_array())
                    .ok_or(ExploreError::ProbeUnreachable { x, y, alpha })?;
                crate::agent::check_motor_count(agent, q.len())?;
                observer.pose(&q, &mut pose);
                rows.motors.extend_from_slice(&q);
                rows.poses.extend_from_slice(&pose);
                probes.extend_from_slice(&[o as i64, ix as i64, iy as i64]);
            }
        }
    }
    Ok(())
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
        for p in a.planar_poses().unwrap().rows() {
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
        let poses = e.planar_poses().unwrap();
        approx::assert_abs_diff_eq!(poses[[row, 0]], 1.075, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(poses[[row, 1]], 0.9, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(poses[[row, 2]], 108f64.to_radians(), epsilon = 1e-9);
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

    /// A hinge and a slider in `[0, 0.5]`, with no ground truth.
    #[derive(Debug)]
    struct Slider;

    impl Agent for Slider {
        fn motor_dim(&self) -> usize {
            2
        }
        fn sensor_dim(&self) -> usize {
            1
        }
        fn sense(&self, _: &crate::agent::Environment, m: &[f64], s: &mut [f64]) {
            s[0] = m[0].cos() + m[1];
        }
        fn name(&self) -> &str {
            "slider"
        }
        fn motor_space(&self) -> crate::agent::MotorSpace {
            use crate::agent::Motor;
            crate::agent::MotorSpace::new(vec![
                Motor::HINGE,
                Motor::Bounded {
                    low: 0.0,
                    high: 0.5,
                },
            ])
            .unwrap()
        }
    }

    #[test]
    fn each_motor_is_drawn_from_its_own_range_without_a_ground_truth() {
        let params = ExploreParams {
            n: 2000,
            ..ExploreParams::default()
        };
        let e = explore(&Slider, &params).unwrap();
        assert!(e.ground_truth.is_none() && e.planar_poses().is_none());
        let pi = std::f64::consts::PI;
        let hinge = e.motors.column(0);
        let slider = e.motors.column(1);
        assert!(hinge.iter().all(|v| (-pi..pi).contains(v)));
        assert!(hinge.iter().any(|&v| v < -3.0) && hinge.iter().any(|&v| v > 3.0));
        assert!(slider.iter().all(|v| (0.0..0.5).contains(v)));
        assert!(slider.iter().any(|&v| v < 0.01) && slider.iter().any(|&v| v > 0.49));
        // Written and read back without poses.npy.
        let dir = tempfile::tempdir().unwrap();
        let agent = AgentConfig {
            kind: "slider".into(),
            params: toml::Table::new(),
        };
        e.save(dir.path(), &agent, &params).unwrap();
        assert_eq!(
            e.files(),
            vec!["motors.npy", "probes.npy", "exploration.json"]
        );
        assert!(!dir.path().join("poses.npy").exists());
        let back = Exploration::load(dir.path(), &Slider, None).unwrap();
        assert_eq!(back.motors, e.motors);
        assert!(back.ground_truth.is_none());
        // A working space and the probe grid need the observer's pose.
        let with_workspace = ExploreParams {
            workspace_center: Some([0.0, 0.0]),
            workspace_size: Some([1.0, 1.0]),
            ..params.clone()
        };
        let err = explore(&Slider, &with_workspace).unwrap_err();
        let located = err.invalid_parameter().unwrap();
        assert_eq!(located.key, "workspace_center");
        assert!(err.to_string().contains("no ground truth"), "{err}");
        let grid = ExploreParams {
            probes: Probes::Grid,
            ..params
        };
        let err = grid.check(&Slider).unwrap_err();
        assert_eq!(err.invalid_parameter().unwrap().key, "probes");
    }

    #[test]
    fn poses_are_written_and_read_back_with_the_ground_truth() {
        let params = ExploreParams {
            n: 30,
            ..ExploreParams::default()
        };
        let arm = arm();
        let e = explore(arm.as_ref(), &params).unwrap();
        let dir = tempfile::tempdir().unwrap();
        e.save(
            dir.path(),
            &AgentConfig::preset("planar-arm").unwrap(),
            &params,
        )
        .unwrap();
        let back = Exploration::load(dir.path(), arm.as_ref(), e.workspace).unwrap();
        assert_eq!(back.ground_truth, e.ground_truth);
        assert_eq!(back.planar_poses().unwrap().dim(), (30, 3));
        // Poses of the wrong number of rows are refused.
        let three = e.ground_truth.as_ref().unwrap().select(&[0, 1, 2]);
        crate::io::write_npy(&dir.path().join("poses.npy"), three.poses()).unwrap();
        let err = Exploration::load(dir.path(), arm.as_ref(), e.workspace).unwrap_err();
        assert!(err.to_string().contains("one pose per row"), "{err}");
    }
}
