//! Environment invariance (paper sections 2.2, 2.3 and 3.3): the kernel sets do not
//! depend on the environment, while the sensory manifold does.
//!
//! The same motor starts `m^i` are traced with the `sensory` method (only what the
//! agent measures) in environments `E_1, …, E_L` (different light seeds and counts).
//! Rows traced in every environment are kept. For every pair `(a, b)`:
//!
//! - **sets**: `max_i ρ(M^i_a, M^i_b)` and its mean, the Hausdorff distance between
//!   corresponding sets (0 if the sets do not depend on the environment), also relative
//!   to the median distance between different sets of `E_a`;
//! - **metric**: the Mantel correlation (Pearson over the pairs `i < j`) of the
//!   distance matrices `D_a`, `D_b`, and `max_ij |D_a − D_b|`, also relative to
//!   `max D_a`;
//! - **the converse** (section 2.2, "the same exploratory movements performed in a
//!   different environment will yield another sensory manifold"): the sensor values
//!   `s^i_e = σ_{E_e}(m^i)` of the same rows, their Mantel correlation (Euclidean
//!   distances between sensor vectors) and `max_i ‖s^i_a − s^i_b‖` relative to the
//!   mean sensor norm.
//!
//! Near-zero set figures and a Mantel correlation near 1 for the sets, against large
//! sensor differences, are the paper's claim in numbers.
//!
//! This is an experiment of its own, not an analysis of one distance matrix: it traces
//! and measures again, once per environment. It uses the statistics of
//! [`analysis::agreement`](crate::analysis::agreement).

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, ArrayView2, Axis};
use serde::{Deserialize, Serialize};

use crate::agent::{Agent, Environment, MotorSpace};
use crate::analysis::agreement::{pearson, upper_triangle};
use crate::explore::Workspace;
use crate::io::{self, IoError};
use crate::kernel::{trace_sets, TraceMethod, TraceValidParams, TracedSets};
use crate::metric::{
    distance_matrix_with, Closure, DistanceParams, MetricKind, Period, Periodicity, Periods,
    SetMetric, SetsView,
};
use crate::params::InvalidParameter;
use crate::progress::Progress;

/// Errors of the invariance experiment.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InvarianceError {
    /// A parameter is out of its domain.
    #[error(transparent)]
    Invalid(#[from] InvalidParameter),
    /// Too few starts were traced in every environment.
    #[error("invariance is undefined for these starts: {reason}")]
    TooFewCommon {
        /// How many were traced where.
        reason: String,
    },
    /// Tracing the sets to compare failed.
    #[error(transparent)]
    Kernel(#[from] crate::kernel::KernelError),
    /// Computing set distances failed.
    #[error(transparent)]
    Metric(#[from] crate::metric::MetricError),
}

impl InvarianceError {
    /// The parameter out of its domain, located by table and key, if this is one
    /// (also from the metric).
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            InvarianceError::Invalid(p) => Some(p),
            InvarianceError::Metric(e) => e.invalid_parameter(),
            _ => None,
        }
    }
}

/// One environment of the comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnvironmentSummary {
    /// The seed the lights were drawn from, if drawn.
    pub seed: Option<u64>,
    /// Number of lights.
    pub lights: usize,
    /// Sets traced in this environment.
    pub traced: usize,
}

/// Figures of one pair of environments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairInvariance {
    /// Index of the first environment.
    pub a: usize,
    /// Index of the second environment.
    pub b: usize,
    /// Largest Hausdorff distance between corresponding sets.
    pub max_set_distance: f64,
    /// Mean Hausdorff distance between corresponding sets.
    pub mean_set_distance: f64,
    /// `max_set_distance` over the median distance between different sets of `a`.
    pub max_set_distance_relative: f64,
    /// Mantel correlation of the two distance matrices.
    pub mantel: f64,
    /// Largest entry of `|D_a − D_b|`.
    pub max_distance_difference: f64,
    /// `max_distance_difference / max D_a`.
    pub max_distance_difference_relative: f64,
    /// Mantel correlation of the sensor-space distance matrices of the same rows.
    pub sensor_mantel: f64,
    /// `max_i ‖s^i_a − s^i_b‖` over the mean sensor norm.
    pub max_sensor_difference_relative: f64,
}

/// The report of [`invariance`], written by `smspace invariance`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InvarianceReport {
    /// The agent's name.
    pub agent: String,
    /// The environments, in order.
    pub environments: Vec<EnvironmentSummary>,
    /// Motor rows asked for.
    pub starts: usize,
    /// Rows traced in every environment (the ones compared).
    pub common_sets: usize,
    /// Every pair of environments.
    pub pairs: Vec<PairInvariance>,
    /// Worst case over the pairs: largest set distance.
    pub max_set_distance: f64,
    /// Worst case over the pairs: largest relative set distance.
    pub max_set_distance_relative: f64,
    /// Worst case over the pairs: smallest Mantel correlation of the set metric.
    pub min_mantel: f64,
    /// Worst case over the pairs: largest distance-matrix difference.
    pub max_distance_difference: f64,
    /// Over the pairs: largest Mantel correlation of the sensor metric.
    pub max_sensor_mantel: f64,
    /// Over the pairs: smallest relative sensor difference.
    pub min_sensor_difference_relative: f64,
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}

/// The periods of the point metric for motors of `space`: each hinge (periodic motor)
/// its period, each bounded motor none; the uniform [`Period`] when all are alike.
pub fn motor_periodicity(space: &MotorSpace) -> Periodicity {
    match Periods::new(space.periods()) {
        Ok(periods) => periods.into(),
        // A motor space has at least one motor with a checked period.
        Err(_) => Periodicity::Uniform(Period::None),
    }
}

/// The built-in metric `kind` under the point metric of `agent`'s motors
/// ([`motor_periodicity`]: hinges wrap, bounded motors do not), as [`invariance`]
/// measures sets with it.
pub fn agent_metric(kind: MetricKind, agent: &dyn Agent) -> Box<dyn SetMetric> {
    kind.with_period(motor_periodicity(&agent.motor_space()), Closure::Closed)
}

/// Traces `motors` (any strides) in every environment with `params` (which must use
/// the `sensory` method) and compares the results (see the module docs).
///
/// `metric` measures the sets: the paper's Hausdorff distance or the polyline one under
/// the agent's point metric ([`agent_metric`]), or any [`SetMetric`].
pub fn invariance(
    agent: &dyn Agent,
    motors: ArrayView2<'_, f64>,
    environments: &[Environment],
    workspace: Option<&Workspace>,
    params: &TraceValidParams,
    metric: &dyn SetMetric,
    progress: &dyn Progress,
) -> Result<InvarianceReport, InvarianceError> {
    invariance_measured(
        agent,
        motors,
        environments,
        workspace,
        params,
        metric,
        progress,
    )
    .map(|m| m.report)
}

/// What [`invariance_measured`] compares, besides the numbers: the per-environment
/// distance matrices and sensor values (for figures).
#[derive(Debug, Clone)]
pub struct InvarianceMeasured {
    /// The numbers.
    pub report: InvarianceReport,
    /// The rows of `motors` traced in every environment (`C` of them, increasing).
    pub common_rows: Vec<usize>,
    /// One `(C, C)` Hausdorff matrix per environment between the sets of those rows.
    pub set_distances: Vec<Array2<f64>>,
    /// One `(C, K)` array per environment: the sensor values `σ_E(m)` of those rows.
    pub sensors: Vec<Array2<f64>>,
}

impl InvarianceMeasured {
    /// Writes the report to `path` and, next to it, the compared matrices and sensor
    /// values ([`invariance_files`]), all together.
    pub fn save(&self, path: &Path) -> Result<Vec<PathBuf>, IoError> {
        write_invariance(path, &self.report, &self.set_distances, &self.sensors)
    }
}

/// The files beside the report `path` (`dir/invariance.json`) that hold, for
/// environment `e` (from 0), the distance matrix of its sets and its sensor values:
/// `dir/invariance-D-<e+1>.npy` and `dir/invariance-sensors-<e+1>.npy`.
pub fn invariance_files(path: &Path, environment: usize) -> [PathBuf; 2] {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let e = environment + 1;
    [
        path.with_file_name(format!("{stem}-D-{e}.npy")),
        path.with_file_name(format!("{stem}-sensors-{e}.npy")),
    ]
}

/// Writes an invariance report to `path` and the per-environment matrices and sensor
/// values beside it ([`invariance_files`]), all or none; returns the paths written.
/// `smspace invariance` and the pipeline's invariance stage write through here.
pub fn write_invariance(
    path: &Path,
    report: &InvarianceReport,
    set_distances: &[Array2<f64>],
    sensors: &[Array2<f64>],
) -> Result<Vec<PathBuf>, IoError> {
    let mut outputs = io::Outputs::new();
    stage_invariance(&mut outputs, path, report, set_distances, sensors)?;
    outputs.commit()
}

/// Stages the files of [`write_invariance`] into `outputs`, to be renamed into place
/// with the other files of a command or stage.
pub fn stage_invariance(
    outputs: &mut io::Outputs,
    path: &Path,
    report: &InvarianceReport,
    set_distances: &[Array2<f64>],
    sensors: &[Array2<f64>],
) -> Result<(), IoError> {
    outputs.json(path, report)?;
    for (e, (d, s)) in set_distances.iter().zip(sensors).enumerate() {
        let [d_path, s_path] = invariance_files(path, e);
        outputs.npy(&d_path, d)?;
        outputs.npy(&s_path, s)?;
    }
    Ok(())
}

/// What [`write_invariance`] writes: the report, and per environment the distance
/// matrix of its sets and its sensor values.
pub type InvarianceFiles = (InvarianceReport, Vec<Array2<f64>>, Vec<Array2<f64>>);

/// Reads back what [`write_invariance`] wrote for `environments` environments whose
/// agent has `sensors` sensors.
pub fn read_invariance(
    path: &Path,
    environments: usize,
    sensors: usize,
) -> Result<InvarianceFiles, IoError> {
    let report = io::read_json(path, "invariance report")?;
    let mut set_distances = Vec::with_capacity(environments);
    let mut sensor_values = Vec::with_capacity(environments);
    for e in 0..environments {
        let [d_path, s_path] = invariance_files(path, e);
        set_distances.push(io::read_matrix(&d_path, None, "(C, C)")?);
        sensor_values.push(io::read_matrix(&s_path, Some(sensors), "(C, K)")?);
    }
    Ok((report, set_distances, sensor_values))
}

/// Like [`invariance`], also returning the matrices and sensor values compared.
pub fn invariance_measured(
    agent: &dyn Agent,
    motors: ArrayView2<'_, f64>,
    environments: &[Environment],
    workspace: Option<&Workspace>,
    params: &TraceValidParams,
    metric: &dyn SetMetric,
    progress: &dyn Progress,
) -> Result<InvarianceMeasured, InvarianceError> {
    check_inputs(params, environments)?;
    let traced = environments
        .iter()
        .map(|env| trace_sets(agent, Some(env), motors, workspace, params, progress))
        .collect::<Result<Vec<_>, _>>()?;
    let common = common_rows(&traced, motors.nrows())?;
    let compared = Compared::new(
        agent,
        motors,
        environments,
        &traced,
        &common,
        metric,
        progress,
    )?;
    let mut pairs = Vec::new();
    for a in 0..environments.len() {
        for b in a + 1..environments.len() {
            pairs.push(compared.pair(a, b, metric)?);
        }
    }
    let report = summarise(
        agent,
        environments,
        &traced,
        motors.nrows(),
        common.len(),
        pairs,
    );
    Ok(InvarianceMeasured {
        report,
        common_rows: common,
        set_distances: compared.matrices,
        sensors: compared.sensors,
    })
}

fn check_inputs(
    params: &TraceValidParams,
    environments: &[Environment],
) -> Result<(), InvarianceError> {
    if params.method() != TraceMethod::Sensory {
        return Err(InvalidParameter::new(
            "kernel",
            "method",
            format!("{:?}", params.method()).to_lowercase(),
            "invariance traces with the sensory method, which sees the environment",
        )
        .into());
    }
    if environments.len() < 2 {
        return Err(InvalidParameter::new(
            "environment",
            "compare",
            environments.len(),
            "give at least 2 environments to compare",
        )
        .into());
    }
    Ok(())
}

/// The motor rows traced in every environment (at least 2).
fn common_rows(traced: &[TracedSets], starts: usize) -> Result<Vec<usize>, InvarianceError> {
    let common: Vec<usize> = traced[0]
        .kept
        .iter()
        .copied()
        .filter(|row| traced.iter().all(|t| t.kept.binary_search(row).is_ok()))
        .collect();
    if common.len() < 2 {
        return Err(InvarianceError::TooFewCommon {
            reason: format!(
                "only {} of {starts} starts were traced in every environment (traced per environment: {:?}); at least 2 are needed",
                common.len(),
                traced.iter().map(|t| t.kept.len()).collect::<Vec<_>>()
            ),
        });
    }
    Ok(common)
}

/// What is compared, per environment, over the common rows.
struct Compared {
    /// The sets of the common rows.
    sets: Vec<Array3<f64>>,
    /// Their closures.
    closures: Vec<Vec<Closure>>,
    /// The `(C, C)` distance matrices and their upper triangles.
    matrices: Vec<Array2<f64>>,
    upper: Vec<Vec<f64>>,
    /// The `(C, K)` sensor values and the upper triangles of their distances.
    sensors: Vec<Array2<f64>>,
    sensor_upper: Vec<Vec<f64>>,
}

impl Compared {
    fn new(
        agent: &dyn Agent,
        motors: ArrayView2<'_, f64>,
        environments: &[Environment],
        traced: &[TracedSets],
        common: &[usize],
        metric: &dyn SetMetric,
        progress: &dyn Progress,
    ) -> Result<Self, InvarianceError> {
        let (sets, closures): (Vec<_>, Vec<Vec<Closure>>) = traced
            .iter()
            .map(|t| {
                let positions: Vec<usize> = common
                    .iter()
                    .map(|row| t.kept.binary_search(row).expect("common rows are kept"))
                    .collect();
                let closure = positions.iter().map(|&p| t.closure[p]).collect();
                (t.sets.select(Axis(0), &positions), closure)
            })
            .unzip();
        let matrices = sets
            .iter()
            .zip(&closures)
            .map(|(s, c)| {
                let sets = SetsView::new(s.view()).with_closure(c);
                distance_matrix_with(sets, metric, &DistanceParams::new(), progress)
                    .map(|d| d.into_array())
            })
            .collect::<Result<Vec<_>, _>>()?;
        let upper = matrices.iter().map(|d| upper_triangle(d.view())).collect();
        let rows = motors.select(Axis(0), common);
        let sensors: Vec<Array2<f64>> = environments
            .iter()
            .map(|env| {
                let mut s = Array2::zeros((rows.nrows(), agent.sensor_dim()));
                agent.sense_batch(env, rows.view(), s.view_mut());
                s
            })
            .collect();
        let sensor_upper = sensors.iter().map(|s| sensor_distances(s.view())).collect();
        Ok(Self {
            sets,
            closures,
            matrices,
            upper,
            sensors,
            sensor_upper,
        })
    }

    /// The figures of environments `a` and `b`.
    fn pair(
        &self,
        a: usize,
        b: usize,
        metric: &dyn SetMetric,
    ) -> Result<PairInvariance, InvarianceError> {
        let mut set_distances = Vec::with_capacity(self.sets[a].len_of(Axis(0)));
        for (s, (x, y)) in self.sets[a]
            .outer_iter()
            .zip(self.sets[b].outer_iter())
            .enumerate()
        {
            // The same start traced in two environments, measured as a pair of sets
            // (each with its own closure).
            let mut both = Array3::zeros((2, x.nrows(), x.ncols()));
            both.index_axis_mut(Axis(0), 0).assign(&x);
            both.index_axis_mut(Axis(0), 1).assign(&y);
            let closure = [self.closures[a][s], self.closures[b][s]];
            let d = distance_matrix_with(
                SetsView::new(both.view()).with_closure(&closure),
                metric,
                &DistanceParams::new(),
                &crate::progress::Silent,
            )?;
            set_distances.push(d[[0, 1]]);
        }
        let (upper_a, upper_b) = (&self.upper[a], &self.upper[b]);
        let (sensors_a, sensors_b) = (&self.sensors[a], &self.sensors[b]);
        let max_set = set_distances.iter().copied().fold(0.0, f64::max);
        let mean_set = set_distances.iter().sum::<f64>() / set_distances.len() as f64;
        let typical = median(upper_a.clone());
        let largest = upper_a.iter().copied().fold(0.0, f64::max);
        let max_difference = upper_a
            .iter()
            .zip(upper_b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        let sensor_norm = sensors_a
            .outer_iter()
            .chain(sensors_b.outer_iter())
            .map(|s| s.dot(&s).sqrt())
            .sum::<f64>()
            / (2 * sensors_a.nrows()) as f64;
        let max_sensor = sensors_a
            .outer_iter()
            .zip(sensors_b.outer_iter())
            .map(|(x, y)| distance(x.as_slice(), y.as_slice()))
            .fold(0.0, f64::max);
        Ok(PairInvariance {
            a,
            b,
            max_set_distance: max_set,
            mean_set_distance: mean_set,
            max_set_distance_relative: ratio(max_set, typical),
            mantel: mantel(upper_a, upper_b),
            max_distance_difference: max_difference,
            max_distance_difference_relative: ratio(max_difference, largest),
            sensor_mantel: mantel(&self.sensor_upper[a], &self.sensor_upper[b]),
            max_sensor_difference_relative: ratio(max_sensor, sensor_norm),
        })
    }
}

/// Euclidean distances between the rows of `s`, over the pairs `i < j`.
fn sensor_distances(s: ArrayView2<'_, f64>) -> Vec<f64> {
    let n = s.nrows();
    let mut out = Vec::with_capacity(n * (n - 1) / 2);
    for i in 0..n {
        for j in i + 1..n {
            out.push(distance(s.row(i).as_slice(), s.row(j).as_slice()));
        }
    }
    out
}

/// The report: every environment, and the extremes over the pairs.
fn summarise(
    agent: &dyn Agent,
    environments: &[Environment],
    traced: &[TracedSets],
    starts: usize,
    common_sets: usize,
    pairs: Vec<PairInvariance>,
) -> InvarianceReport {
    let fold = |f: fn(&PairInvariance) -> f64, init: f64, pick: fn(f64, f64) -> f64| {
        pairs.iter().map(f).fold(init, pick)
    };
    InvarianceReport {
        agent: agent.name().to_owned(),
        environments: environments
            .iter()
            .zip(traced)
            .map(|(e, t)| EnvironmentSummary {
                seed: e.seed,
                lights: e.lights.len(),
                traced: t.kept.len(),
            })
            .collect(),
        starts,
        common_sets,
        max_set_distance: fold(|p| p.max_set_distance, 0.0, f64::max),
        max_set_distance_relative: fold(|p| p.max_set_distance_relative, 0.0, f64::max),
        min_mantel: fold(|p| p.mantel, f64::INFINITY, f64::min),
        max_distance_difference: fold(|p| p.max_distance_difference, 0.0, f64::max),
        max_sensor_mantel: fold(|p| p.sensor_mantel, f64::NEG_INFINITY, f64::max),
        min_sensor_difference_relative: fold(
            |p| p.max_sensor_difference_relative,
            f64::INFINITY,
            f64::min,
        ),
        pairs,
    }
}

fn distance(a: Option<&[f64]>, b: Option<&[f64]>) -> f64 {
    let (a, b) = (
        a.expect("rows of a standard array"),
        b.expect("rows of a standard array"),
    );
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// `x / y`, 0 when both are 0.
fn ratio(x: f64, y: f64) -> f64 {
    if x == 0.0 {
        0.0
    } else {
        x / y
    }
}

/// Pearson correlation of two distance lists; 1 when they are equal (constant lists
/// included).
fn mantel(a: &[f64], b: &[f64]) -> f64 {
    if a == b {
        1.0
    } else {
        pearson(a, b).unwrap_or(0.0)
    }
}
