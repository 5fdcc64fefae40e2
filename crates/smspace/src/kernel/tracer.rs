//! One tracing call, checked once: the agent's motor space and ground truth, the
//! level set of the method, and the dimension `k = N − rank(J)` of the kernel sets.
//!
//! With a ground truth, `rank(J)` is the number `C` of pose coordinates the motors
//! change ([`Observer::configuration_dim`]), for both methods: the sensors determine
//! the pose (paper section 2.1). The observer read is
//! [`Agent::sensed_configuration`], the ground truth unless the motors also change an
//! attribute of the sensor (a pupil's aperture, held fixed with the pose). Without one (the `sensory` method only), it is the
//! generic rank of the sensory Jacobian, estimated at every start (singular values
//! above `rank_tolerance` times the largest) and taken as the rank most starts show
//! (the larger on a tie): one start at a special spot (a sensor at its peak, a light
//! seen from one spot only, fewer lights in view) cannot decide the dimension of every
//! set. The starts of another rank are listed ([`SensoryRank`]) and warned about. Sets of
//! dimension 0 are single points, of dimension 1 curves the follower traces, of
//! larger dimension surfaces the covering samples (`cover.rs`).

use nalgebra::{DMatrix, SVD};
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use super::cover::{
    cover_piece, farthest_points, forecast_nodes, piece_seeds, project_seed, share_points,
    CoverSettings, Covering, Grid, Landing, FORECAST_MARGIN,
};
use super::curve::{doubled_back, resample, trace_branch, Curve, Scratch};
use super::gather::{self, Caller};
use super::level_set::{Kinematic, LevelSet, Linearization, Sensor, Sensory};
use super::noise::{ForecastShape, NoiseForecast, ProbedStart, FORECAST_STARTS};
use super::noisy::{probe, Probe};
use super::{
    Components, KernelError, RowPhase, SensorNoise, SensorRowPhases, SetReport, SetStatus,
    TraceMethod, TraceValidParams, MAX_DOUBLED,
};
use crate::agent::{Agent, Calling, Environment, MotorSpace, Observer, PoseSpace, Workspace};

/// A checked tracing call (see the module docs).
pub(super) struct Tracer<'a> {
    agent: &'a dyn Agent,
    observer: Option<&'a dyn Observer>,
    space: MotorSpace,
    poses: Option<PoseSpace>,
    environment: Option<&'a Environment>,
    workspace: Option<&'a Workspace>,
    params: &'a TraceValidParams,
    /// The kernel dimension `k`.
    dimension: usize,
    /// The seeds of the multi-start search for pieces (`N` values each).
    seeds: Vec<f64>,
    /// Sensor rows read at each start to estimate the rank (empty when it was not
    /// estimated).
    rank_rows: Vec<u64>,
    /// The rank estimated from the starts' sensors, when it was.
    sensory_rank: Option<SensoryRank>,
    /// Sensor rows read at each of the first starts to forecast the cost of noisy
    /// readings ([`Tracer::forecast_noise`]; empty when not forecast).
    forecast_rows: Vec<u64>,
    /// The starts the forecast found exact, with their reading: their sets start from
    /// it instead of reading the start twice again.
    exact_starts: Vec<(Vec<f64>, Vec<f64>)>,
}

/// The rank of the sensory Jacobian as the starts show it, for an agent without a
/// ground truth (see the module docs): the rank the sets are traced at, and the starts
/// that show another.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SensoryRank {
    /// The motors `N`.
    pub motors: usize,
    /// The rank most starts show; the sets are traced at dimension `N − rank`.
    pub rank: usize,
    /// The starts measured.
    pub starts: usize,
    /// `(start, its rank)` of every start (row, from 0) of another rank.
    pub disagreeing: Vec<(usize, usize)>,
}

impl SensoryRank {
    /// The rank most of `ranks` show (the larger on a tie), and the others.
    pub(super) fn of(ranks: &[usize], motors: usize) -> Self {
        let mut counts = std::collections::BTreeMap::new();
        for &r in ranks {
            *counts.entry(r).or_insert(0usize) += 1;
        }
        let rank = counts
            .iter()
            .max_by_key(|&(r, c)| (*c, *r))
            .map_or(0, |(r, _)| *r);
        Self {
            motors,
            rank,
            starts: ranks.len(),
            disagreeing: ranks
                .iter()
                .enumerate()
                .filter(|&(_, &r)| r != rank)
                .map(|(i, &r)| (i, r))
                .collect(),
        }
    }

    /// The warning when some starts show another rank than most.
    pub fn disagreement_warning(&self) -> Option<String> {
        if self.disagreeing.is_empty() {
            return None;
        }
        let listed: Vec<String> = self
            .disagreeing
            .iter()
            .take(20)
            .map(|(i, r)| format!("{i} (rank {r})"))
            .collect();
        Some(format!(
            "the sensors change along {} of the {} motor directions at {} of {} starts, and along another number at starts {}{}: a sensor at its peak or on a flat spot, or a sensor that reacts at a few configurations only, changes along fewer or more directions there. Every set is traced at the kernel dimension most starts show, k = {} − {} = {}; a set through a disagreeing start may fail or be of another shape. Trace from starts away from such spots, or check the sensors there",
            self.rank,
            self.motors,
            self.starts - self.disagreeing.len(),
            self.starts,
            listed.join(", "),
            if self.disagreeing.len() > 20 { ", …" } else { "" },
            self.motors,
            self.rank,
            self.motors - self.rank.min(self.motors)
        ))
    }

    /// The warning when every traced set (`points` of `total`) is a single point.
    pub fn points_warning(&self, points: usize, total: usize) -> String {
        format!(
            "every traced set ({points} of {total}) is a single point: the sensors change along all {} motor directions (the rank of their Jacobian is {}, at most starts), so no motor change leaves the sensations unchanged, the kernel dimension is k = 0 and the sets carry no shape",
            self.motors, self.rank
        )
    }
}

impl<'a> Tracer<'a> {
    /// Checks that the agent, its ground truth, the environment and the working space
    /// allow the method, and finds the kernel dimension (from `starts` when it must
    /// be estimated).
    pub(super) fn new(
        agent: &'a dyn Agent,
        environment: Option<&'a Environment>,
        starts: ArrayView2<'_, f64>,
        workspace: Option<&'a Workspace>,
        params: &'a TraceValidParams,
    ) -> Result<Self, KernelError> {
        let declared = check_agent_for(agent, params)?;
        let observer = agent.sensed_configuration();
        if params.method == TraceMethod::Sensory && environment.is_none() {
            return Err(KernelError::MissingEnvironment);
        }
        if workspace.is_some() && observer.is_none() {
            return Err(KernelError::NoGroundTruth {
                agent: agent.name().to_owned(),
                needs: "a working space",
                fix: "trace without one (--workspace none)",
            });
        }
        let mut tracer = Self {
            agent,
            observer,
            space: agent.motor_space(),
            poses: observer.map(|o| o.pose_space()),
            environment,
            workspace,
            params,
            dimension: 0,
            seeds: Vec::new(),
            rank_rows: Vec::new(),
            sensory_rank: None,
            forecast_rows: Vec::new(),
            exact_starts: Vec::new(),
        };
        tracer.seeds = piece_seeds(&tracer.space, params.piece_starts, params.piece_seed);
        tracer.dimension = match (declared, agent.sensory_rank()) {
            (Some(dimension), _) => dimension,
            (None, Some(rank)) => {
                let jacobian = format!(
                    "the sensory Jacobian, of rank {rank}: the rank the {} agent gives",
                    agent.name()
                );
                supported_dimension(agent, rank, jacobian)?
            }
            (None, None) => {
                let (ranks, rows, slope) = tracer.sensory_ranks(starts);
                tracer.rank_rows = rows;
                check_sensor_scale(slope, starts.nrows())?;
                let found = SensoryRank::of(&ranks, agent.motor_dim());
                let rank = found.rank;
                tracer.sensory_rank = Some(found);
                let jacobian = format!(
                    "the sensory Jacobian, of rank {rank}: the numerical rank most of the {} starts show (singular values above rank_tolerance = {} times the largest)",
                    starts.nrows(),
                    params.rank_tolerance
                );
                supported_dimension(agent, rank, jacobian)?
            }
        };
        Ok(tracer)
    }

    /// The kernel dimension `k` of every set.
    pub(super) fn dimension(&self) -> usize {
        self.dimension
    }

    /// The rank estimated from the starts' sensors, when it was.
    pub(super) fn sensory_rank(&self) -> Option<SensoryRank> {
        self.sensory_rank.clone()
    }

    /// Whether the covering of a k-D kernel (`k ≥ 2`) is forecast at more than
    /// [`FORECAST_MARGIN`] times `max_cover_points` nodes (see [`forecast_nodes`]):
    /// every set then fails at once as `cover-budget`.
    pub(super) fn covering_too_large(&self) -> bool {
        self.dimension >= 2
            && forecast_nodes(&self.space, self.dimension, self.params.cover_step)
                > FORECAST_MARGIN * self.params.max_cover_points as f64
    }

    /// The numerical rank of the sensory Jacobian at every start (0 where it is not
    /// finite), the sensor rows read at each start, and the largest absolute finite
    /// entry of the Jacobians (`None` where none was read).
    fn sensory_ranks(&self, starts: ArrayView2<'_, f64>) -> (Vec<usize>, Vec<u64>, Option<f64>) {
        let Some(environment) = self.environment else {
            return (vec![0; starts.nrows()], vec![0; starts.nrows()], None);
        };
        let n = self.agent.motor_dim();
        let rows: Vec<Vec<f64>> = starts.outer_iter().map(|r| r.to_vec()).collect();
        let rank = |caller: Option<&Caller<'_>>, _: &mut Scratch, start: &[f64]| {
            let mut set = Sensory::new(self.agent, environment, caller, start, self.params, 1);
            let mut r = vec![0.0; set.rows()];
            // A singular linearisation still fills the Jacobian: its rank is what is asked.
            let _ = set.linearize(start, &mut r);
            let (jacobian, rows) = set.jacobian();
            let finite = jacobian.iter().all(|v| v.is_finite());
            let rank = if finite {
                null_space(jacobian, rows, n, self.params.rank_tolerance).rank
            } else {
                0
            };
            let slope = finite.then(|| jacobian.iter().fold(0.0_f64, |a, v| a.max(v.abs())));
            (rank, set.sensor_rows(), slope)
        };
        // A start whose coroutine could not be given a stack counts as rank 0.
        match self.map_starts(&rows, rank, &|| {}) {
            Ok(ranks) => (
                ranks.iter().map(|r| r.0).collect(),
                ranks.iter().map(|r| r.1).collect(),
                ranks.iter().filter_map(|r| r.2).reduce(f64::max),
            ),
            Err(_) => (vec![0; starts.nrows()], vec![0; starts.nrows()], None),
        }
    }

    /// Adds to `report` the sensor rows read at start `i` to estimate the rank of the
    /// sensory Jacobian and to forecast the cost of noisy readings (none when neither
    /// was done there), in its start phase.
    pub(super) fn add_rank_rows(&self, report: &mut SetReport, i: usize) {
        let rows = self.rank_rows.get(i).copied().unwrap_or(0)
            + self.forecast_rows.get(i).copied().unwrap_or(0);
        report.sensor_rows += rows;
        if let Some(phases) = &mut report.sensor_row_phases {
            phases.add(RowPhase::Start, false, rows);
        }
    }

    /// The sensory method on an agent's own readings (not a law learned from data,
    /// whose readings are exact) with `noise` not 0: probes the first
    /// [`FORECAST_STARTS`] starts as a set's trace does (two readings, and with noise
    /// the first regression and the target, see `noisy.rs`), timing them, and
    /// forecasts the cost of tracing `motors.nrows()` sets ([`NoiseForecast`]); `None`
    /// when every probed start reads exactly. The rows read are added to those
    /// starts' sets ([`add_rank_rows`](Self::add_rank_rows)), and a start found exact
    /// is not probed again when its set is traced.
    pub(super) fn forecast_noise(&mut self, motors: ArrayView2<'_, f64>) -> Option<NoiseForecast> {
        let environment = self.environment?;
        let exact = matches!(self.params.noise, SensorNoise::Sigma(sigma) if sigma == 0.0);
        if self.params.method != TraceMethod::Sensory
            || exact
            || self.agent.sensory_rank().is_some()
            || self.covering_too_large()
        {
            return None;
        }
        let rows: Vec<Vec<f64>> = motors
            .outer_iter()
            .take(FORECAST_STARTS)
            .map(|r| r.to_vec())
            .collect();
        let probe_start = |caller: Option<&Caller<'_>>, _: &mut Scratch, start: &[f64]| {
            let sensor = Sensor::new(self.agent, environment, caller);
            match probe(sensor, start, self.params, self.dimension) {
                Probe::Exact(sensor, reading) => ProbedStart {
                    noise: None,
                    start_rows: sensor.rows,
                    exact_reading: reading,
                },
                Probe::Noisy(set) => ProbedStart {
                    noise: set.noise(),
                    start_rows: set.sensor_rows(),
                    exact_reading: None,
                },
                Probe::Failed(_, noise, sensor) => ProbedStart {
                    noise: (noise.repeats > 0).then_some(noise),
                    start_rows: sensor.rows,
                    exact_reading: None,
                },
            }
        };
        let clock = std::time::Instant::now();
        let probed = self.map_starts(&rows, probe_start, &|| {}).ok()?;
        let seconds = clock.elapsed().as_secs_f64();
        self.forecast_rows = probed.iter().map(|p| p.start_rows).collect();
        self.exact_starts = rows
            .iter()
            .zip(&probed)
            .filter_map(|(start, p)| Some((start.clone(), p.exact_reading.clone()?)))
            .collect();
        let diagonal = self
            .space
            .motors()
            .iter()
            .map(|motor| {
                let (low, high) = motor.range();
                (high - low).powi(2)
            })
            .sum::<f64>()
            .sqrt();
        let shape = ForecastShape {
            motors: self.agent.motor_dim(),
            dimension: self.dimension,
            diagonal,
            max_step: self.params.max_step_or(super::DEFAULT_MAX_STEP),
            points: self.params.points,
            piece_starts: self.params.piece_starts,
            covering_nodes: if self.dimension >= 2 {
                forecast_nodes(&self.space, self.dimension, self.params.cover_step)
            } else {
                0.0
            },
            sets: motors.nrows(),
        };
        NoiseForecast::of(&probed, &shape, seconds)
    }

    /// `work` on every row, in the rows' order, with a scratch space per caller, and
    /// `done` after each: on the rayon pool, or on the callers of gathered rounds
    /// ([`gather`]) when the agent asks for it ([`Calling::Gathered`]) and the method
    /// senses.
    pub(super) fn map_starts<T: Send>(
        &self,
        rows: &[Vec<f64>],
        work: impl Fn(Option<&Caller<'_>>, &mut Scratch, &[f64]) -> T + Sync,
        done: &(dyn Fn() + Sync),
    ) -> Result<Vec<T>, KernelError> {
        match (self.agent.calling(), self.params.method, self.environment) {
            (Calling::Gathered { callers }, TraceMethod::Sensory, Some(environment)) => {
                gather::map_gathered(
                    self.agent,
                    environment,
                    self.observer,
                    callers,
                    rows.len(),
                    Scratch::default,
                    |caller, scratch, i| work(Some(caller), scratch, &rows[i]),
                    done,
                )
            }
            _ => Ok(rows
                .par_iter()
                .map_init(Scratch::default, |scratch, row| {
                    let result = work(None, scratch, row);
                    done();
                    result
                })
                .collect()),
        }
    }

    /// Traces and resamples the set through `start`: its points `(P × N)` and their
    /// pieces when traced, and its report line (`index` 0).
    /// Readings go through `caller` when given (a gathered round).
    pub(super) fn trace(
        &self,
        start: &[f64],
        caller: Option<&Caller<'_>>,
        scratch: &mut Scratch,
    ) -> SetResult {
        let mut report = SetReport {
            index: 0,
            status: SetStatus::Closed,
            steps: 0,
            length: 0.0,
            max_residual: 0.0,
            max_pose_deviation: self.observer.map(|_| 0.0),
            dimension: self.dimension,
            pieces: 0,
            unvisited_pieces: 0,
            piece_landings: Vec::new(),
            covering_radius: None,
            sensor_rows: 0,
            sensor_row_phases: (self.params.method == TraceMethod::Sensory)
                .then(SensorRowPhases::default),
            noise: None,
        };
        if self.covering_too_large() {
            report.status = SetStatus::CoverBudget;
            return SetResult::failed(report);
        }
        let start_pose = self.observer.map(|o| {
            let motors = ArrayView2::from_shape((1, start.len()), start).expect("one start");
            self.poses(o, caller, motors).row(0).to_vec()
        });
        if let (Some(w), Some(pose)) = (self.workspace, &start_pose) {
            if !w.contains(pose) {
                report.status = SetStatus::OutsideWorkspace;
                return SetResult::failed(report);
            }
        }
        if !self.agent.covers(start) {
            report.status = SetStatus::LeftData;
            return SetResult::failed(report);
        }
        let mut kinematic;
        let mut sensory;
        let mut noisy;
        let set: &mut dyn LevelSet = match (self.params.method, self.observer, self.environment) {
            (TraceMethod::Kinematic, Some(observer), _) => {
                kinematic = Kinematic::new(observer, start, self.params.pose_tolerance);
                &mut kinematic
            }
            (_, _, Some(environment)) => {
                let sensor = Sensor::new(self.agent, environment, caller);
                // (A start the forecast found exact is not read again: its rows are
                // the forecast's, added to the set's start phase.)
                let known = self
                    .exact_starts
                    .iter()
                    .find(|(s, _)| s.as_slice() == start)
                    .map(|(_, reading)| reading.clone());
                let probed = match known {
                    Some(reading) => Probe::Exact(sensor, Some(reading)),
                    None => probe(sensor, start, self.params, self.dimension),
                };
                match probed {
                    Probe::Exact(sensor, reading) => {
                        sensory = match reading {
                            Some(target) => Sensory::with_target(
                                sensor,
                                target,
                                start,
                                self.params,
                                self.dimension,
                            ),
                            None => Sensory::new(
                                self.agent,
                                environment,
                                caller,
                                start,
                                self.params,
                                self.dimension,
                            ),
                        };
                        &mut sensory
                    }
                    Probe::Noisy(set) => {
                        noisy = set;
                        noisy.as_mut()
                    }
                    Probe::Failed(status, noise, sensor) => {
                        report.status = status;
                        report.noise = Some(noise);
                        report.sensor_rows = sensor.rows;
                        report.sensor_row_phases = Some(sensor.phases);
                        return SetResult::failed(report);
                    }
                }
            }
            _ => unreachable!("Tracer::new checked the method's needs"),
        };
        set.set_phase(RowPhase::Trace);
        let mut result = self.trace_on(set, start, start_pose.as_deref(), caller, report, scratch);
        result.report.sensor_rows = set.sensor_rows();
        result.report.sensor_row_phases = set.sensor_row_phases();
        result
    }

    /// [`trace`](Self::trace) on the level set through `start`.
    fn trace_on(
        &self,
        set: &mut dyn LevelSet,
        start: &[f64],
        start_pose: Option<&[f64]>,
        caller: Option<&Caller<'_>>,
        mut report: SetReport,
        scratch: &mut Scratch,
    ) -> SetResult {
        report.noise = set.noise();
        let found = match self.find_pieces(set, start, scratch) {
            Ok(found) => found,
            Err((status, steps)) => {
                report.status = status;
                report.steps = steps;
                return SetResult::failed(report);
            }
        };
        if let Some(noise) = report.noise.as_mut() {
            // Noisy readings: a trace that ran back over its own path is no loop.
            let used = match self.params.components {
                Components::All => found.curves.len(),
                Components::Connected => found.curves.len().min(1),
            };
            noise.doubled = found.curves[..used]
                .iter()
                .map(|c| doubled_back(&self.space, c))
                .fold(0.0, f64::max);
            if noise.doubled > MAX_DOUBLED {
                report.status = SetStatus::Retraced;
                report.steps = found.steps;
                report.pieces = found.count();
                return SetResult::failed(report);
            }
        }
        report.pieces = found.count();
        report.piece_landings = found.landings.clone();
        report.unvisited_pieces = found.failed
            + match self.params.components {
                Components::Connected => found.count() - 1,
                Components::All => 0,
            };
        report.steps = found.steps;
        match self.sample(set, found, &mut report, scratch) {
            Ok((mut points, pieces)) => {
                if let Some(pose) = start_pose {
                    report.max_pose_deviation = Some(self.pose_deviation(&points, pose, caller));
                }
                self.space.wrap_points(&mut points);
                SetResult {
                    points: Some(points),
                    pieces,
                    report,
                }
            }
            Err(status) => {
                report.status = status;
                SetResult::failed(report)
            }
        }
    }

    /// The piece through `start`, then (unless `piece_starts` is 0) the pieces the
    /// multi-start search finds (see [`super::cover`]).
    fn find_pieces(
        &self,
        set: &mut dyn LevelSet,
        start: &[f64],
        scratch: &mut Scratch,
    ) -> Result<Found, (SetStatus, usize)> {
        let n = start.len();
        let mut found = Found::new(&self.space, self.params);
        self.add_piece(set, start, &mut found, scratch)?;
        let mut r = vec![0.0; set.rows()];
        let mut delta = vec![0.0; n];
        let mut m = vec![0.0; n];
        for seed in self.seeds.chunks_exact(n) {
            m.copy_from_slice(seed);
            // A seed's path to the set does not matter, only where it lands: secant
            // updates (a sensory set with `jacobian = "secant"`) are enough.
            let _ = set.set_linearization(Linearization::Secant);
            set.set_phase(RowPhase::Search);
            // (Noisy readings: a point on the set is only known to within a few
            // position uncertainties, on either curve.)
            let tolerance = self
                .params
                .piece_tolerance
                .max(PIECE_NOISE * set.position_noise());
            let mut known = |m: &[f64]| {
                let mut wrapped = m.to_vec();
                self.space.wrap_points(&mut wrapped);
                found.contains(&self.space, &wrapped, self.params, SETTLED * tolerance)
            };
            let landing = project_seed(
                set,
                &mut m,
                &self.space,
                (&mut r, &mut delta),
                SETTLE_STEP * tolerance,
                &mut known,
            );
            set.set_phase(RowPhase::Trace);
            let _ = set.set_linearization(Linearization::Exact);
            if landing == Landing::Known {
                found.count_landing(&self.space, &m, SETTLED * tolerance);
            }
            if landing != Landing::OnSet {
                continue;
            }
            self.space.wrap_points(&mut m);
            if found.contains(&self.space, &m, self.params, tolerance) {
                found.count_landing(&self.space, &m, tolerance);
                continue;
            }
            set.set_phase(RowPhase::Search);
            let confirmed = set.confirms_piece(&m);
            set.set_phase(RowPhase::Trace);
            if !confirmed {
                continue;
            }
            if self.add_piece(set, &m, &mut found, scratch).is_err() {
                // A piece that cannot be traced is still a piece: remember where.
                found.failed += 1;
                found.failed_points.extend_from_slice(&m);
            } else if self.dimension <= 1 {
                found.landings.push(1);
            }
        }
        Ok(found)
    }

    /// Traces (k = 1) or covers (k ≥ 2) the piece through `m`, a point on the level set.
    fn add_piece(
        &self,
        set: &mut dyn LevelSet,
        m: &[f64],
        found: &mut Found,
        scratch: &mut Scratch,
    ) -> Result<(), (SetStatus, usize)> {
        match self.dimension {
            0 => {
                let mut p = m.to_vec();
                self.space.wrap_points(&mut p);
                found.points.extend_from_slice(&p);
            }
            1 => {
                let (curve, steps, residual) =
                    trace_curve(set, m, self.params, &self.space, scratch)?;
                found.steps += steps;
                found.max_residual = found.max_residual.max(residual);
                found.curves.push(curve);
            }
            k => {
                let settings = CoverSettings {
                    step: self.params.cover_step,
                    max_nodes: self.params.max_cover_points,
                    max_rows: self.params.max_rows,
                    max_iterations: self.params.max_corrector_iterations,
                    dimension: k,
                };
                let grid = found.grid.get_or_insert_with(|| {
                    Grid::new(
                        &self.space,
                        PIECE_REACH * self.params.cover_step + self.params.piece_tolerance,
                    )
                });
                let before = found.covering.nodes.len();
                let piece = found.covering.piece.last().map_or(0, |&p| p + 1);
                let result = cover_piece(
                    set,
                    m,
                    &self.space,
                    &settings,
                    grid,
                    &mut found.covering,
                    scratch,
                );
                found.steps += (found.covering.nodes.len() - before) / m.len();
                if let Err(status) = result {
                    return Err((status, found.steps));
                }
                found.covering_pieces = piece + 1;
            }
        }
        Ok(())
    }

    /// Shares the `P` points among the pieces to sample (all with `components =
    /// "all"`, the first otherwise) and samples them: the points (unwrapped for
    /// curves) and the piece of every point. Sets the status, length, residual and
    /// covering radius of `report`.
    fn sample(
        &self,
        set: &mut dyn LevelSet,
        found: Found,
        report: &mut SetReport,
        scratch: &mut Scratch,
    ) -> Result<(Vec<f64>, Vec<i64>), SetStatus> {
        let n = self.agent.motor_dim();
        let p = self.params.points;
        let used = match self.params.components {
            Components::All => found.count(),
            Components::Connected => 1,
        }
        .min(p);
        report.max_residual = found.max_residual.max(found.covering.max_residual);
        set.set_phase(RowPhase::Resample);
        match self.dimension {
            0 => {
                report.status = SetStatus::Point;
                let counts = share_points(p, &vec![1.0; used], &vec![1; used]);
                let mut points = Vec::with_capacity(p * n);
                let mut pieces = Vec::with_capacity(p);
                for (i, &c) in counts.iter().enumerate() {
                    for _ in 0..c {
                        points.extend_from_slice(&found.points[i * n..(i + 1) * n]);
                        pieces.push(i as i64);
                    }
                }
                Ok((points, pieces))
            }
            1 => self.sample_curves(set, found.curves, used, report, scratch),
            _ => {
                report.status = SetStatus::Covered;
                Ok(self.sample_covering(&found.covering, used, report))
            }
        }
    }

    /// Resamples the first `used` curves with their share of the points. A single
    /// piece is resampled as before (`P` points of a loop or a segment); with several,
    /// a closed piece ends with a copy of its first point, so that each piece is one
    /// run of consecutive points (the `curve` metric's pieces).
    fn sample_curves(
        &self,
        set: &mut dyn LevelSet,
        curves: Vec<Curve>,
        used: usize,
        report: &mut SetReport,
        scratch: &mut Scratch,
    ) -> Result<(Vec<f64>, Vec<i64>), SetStatus> {
        let n = self.agent.motor_dim();
        let p = self.params.points;
        let curves = &curves[..used];
        let iterations = self.params.max_corrector_iterations;
        if used == 1 {
            let (points, length, residual) = resample(set, &curves[0], p, iterations, scratch)?;
            report.status = if curves[0].closed {
                SetStatus::Closed
            } else {
                SetStatus::Open
            };
            report.length = length;
            report.max_residual = report.max_residual.max(residual);
            return Ok((points, vec![0; p]));
        }
        let lengths: Vec<f64> = curves
            .iter()
            .map(|c| polyline_length(&c.nodes, n))
            .collect();
        let minimum: Vec<usize> = curves
            .iter()
            .map(|c| if c.closed { 2 } else { 1 })
            .collect();
        let counts = share_points(p, &lengths, &minimum);
        let mut points = Vec::with_capacity(p * n);
        let mut pieces = Vec::with_capacity(p);
        for (i, (curve, &count)) in curves.iter().zip(&counts).enumerate() {
            let drawn = if curve.closed { count - 1 } else { count };
            let (piece, length, residual) = resample(set, curve, drawn, iterations, scratch)?;
            report.length += length;
            report.max_residual = report.max_residual.max(residual);
            points.extend_from_slice(&piece);
            if curve.closed {
                points.extend_from_slice(&piece[..n]);
            }
            pieces.extend(std::iter::repeat_n(i as i64, count));
        }
        report.status = SetStatus::Pieces;
        Ok((points, pieces))
    }

    /// Farthest-point samples of the first `used` pieces of the covering, the `P`
    /// points shared in proportion to their node counts; the covering radius is the
    /// largest over the pieces.
    fn sample_covering(
        &self,
        covering: &Covering,
        used: usize,
        report: &mut SetReport,
    ) -> (Vec<f64>, Vec<i64>) {
        let n = self.agent.motor_dim();
        let p = self.params.points;
        let mut sizes = vec![0.0; used];
        for &piece in &covering.piece {
            if piece < used {
                sizes[piece] += 1.0;
            }
        }
        let counts = share_points(p, &sizes, &vec![1; used]);
        let mut points = Vec::with_capacity(p * n);
        let mut pieces = Vec::with_capacity(p);
        let mut radius: f64 = 0.0;
        for (piece, &count) in counts.iter().enumerate() {
            let members: Vec<usize> = (0..covering.piece.len())
                .filter(|&i| covering.piece[i] == piece)
                .collect();
            let nodes: Vec<f64> = members
                .iter()
                .flat_map(|&i| covering.nodes[i * n..(i + 1) * n].iter().copied())
                .collect();
            let (picks, r) = farthest_points(&self.space, &nodes, n, 0, count);
            radius = radius.max(r);
            for &i in &picks {
                points.extend_from_slice(&nodes[i * n..(i + 1) * n]);
            }
            pieces.extend(std::iter::repeat_n(piece as i64, count));
        }
        report.covering_radius = Some(radius);
        (points, pieces)
    }

    /// The observer's poses of the motor rows `(B, N)`, `(B, d)`: in one call of the
    /// observer, or of a gathered round through `caller`.
    fn poses(
        &self,
        observer: &dyn Observer,
        caller: Option<&Caller<'_>>,
        motors: ArrayView2<'_, f64>,
    ) -> Array2<f64> {
        let mut poses = Array2::zeros((motors.nrows(), observer.pose_space().dim()));
        match caller {
            Some(caller) => caller.pose_batch(motors, poses.view_mut()),
            None => observer.pose_batch(motors, poses.view_mut()),
        }
        poses
    }

    /// The largest deviation of a point's pose from `start_pose`, over the tangent
    /// coordinates the motors change (the observer's check of a traced set).
    fn pose_deviation(
        &self,
        points: &[f64],
        start_pose: &[f64],
        caller: Option<&Caller<'_>>,
    ) -> f64 {
        let (Some(observer), Some(poses)) = (self.observer, &self.poses) else {
            return 0.0;
        };
        let c = observer.configuration_dim();
        let n = self.agent.motor_dim();
        let motors = ArrayView2::from_shape((points.len() / n, n), points).expect("P × N points");
        let all = self.poses(observer, caller, motors);
        let mut difference = vec![0.0; poses.tangent_dim()];
        let mut deviation: f64 = 0.0;
        for pose in all.outer_iter() {
            let pose = pose.as_slice().expect("a standard-layout row");
            poses.difference(pose, start_pose, &mut difference);
            for v in &difference[..c] {
                deviation = deviation.max(v.abs());
            }
        }
        deviation
    }
}

/// Checks what can be checked of a tracing method on an agent before any start is
/// known: the `kinematic` method needs a ground truth, and with a ground truth the
/// kernel dimension `k = N − C` must be one the tracer samples. Returns that `k`, or
/// `None` when it is to be estimated from the sensory Jacobian at the starts.
pub(super) fn check_agent_for(
    agent: &dyn Agent,
    params: &TraceValidParams,
) -> Result<Option<usize>, KernelError> {
    crate::agent::check_agent(agent)?;
    let Some(observer) = agent.sensed_configuration() else {
        if params.method == TraceMethod::Kinematic {
            return Err(KernelError::NoGroundTruth {
                agent: agent.name().to_owned(),
                needs: "the kinematic method",
                fix: "use method = \"sensory\" (the agent's own sensors)",
            });
        }
        return Ok(None);
    };
    let (n, c) = (agent.motor_dim(), observer.configuration_dim());
    if n < c {
        return Err(KernelError::TooFewMotors {
            agent: agent.name().to_owned(),
            motors: n,
            configuration: c,
        });
    }
    let which = match params.method {
        TraceMethod::Kinematic => "the pose Jacobian",
        TraceMethod::Sensory | TraceMethod::Learned => "the sensory Jacobian",
    };
    let jacobian = format!(
        "{which}, of rank {c}: the pose coordinates its ground truth says the motors change"
    );
    supported_dimension(agent, c, jacobian).map(Some)
}

/// `k = N − rank` (any `k`: points, curves, and coverings of k-D kernels).
fn supported_dimension(
    agent: &dyn Agent,
    rank: usize,
    _jacobian: String,
) -> Result<usize, KernelError> {
    let n = agent.motor_dim();
    Ok(n - rank.min(n))
}

/// A fixed direction with no special relation to any axis; the first tangent of every
/// set is oriented along it (`t·w > 0`), so both methods traverse a set the same way.
fn orientation_reference(n: usize) -> Vec<f64> {
    let golden = 0.5 * (1.0 + 5f64.sqrt());
    (0..n).map(|k| golden.powi(-(k as i32))).collect()
}

/// A seed's projection stops next to a piece found once its undamped step is at most
/// this fraction of `piece_tolerance` and the point it leads to is within
/// [`SETTLED`] `piece_tolerance` of the piece (the piece's Hermite curve, see
/// [`near_curve`]): Gauss–Newton's remaining steps are a small fraction of the last
/// one (at most half), so the seed would land within `0.75 piece_tolerance` of that
/// piece, where it counts as found anyway.
const SETTLE_STEP: f64 = 0.5;
/// See [`SETTLE_STEP`].
const SETTLED: f64 = 0.5;

/// A projected seed within this many `cover_step`s (plus `piece_tolerance`) of a
/// covering's node lies on its piece.
const PIECE_REACH: f64 = 1.5;

/// Readings with noise: a seed lands on a piece already found within this many
/// position uncertainties of it (or `piece_tolerance`, whichever is larger): the
/// corrector leaves a point within a few of them of the set, on the piece traced
/// and on the seed alike.
const PIECE_NOISE: f64 = 10.0;

/// Follows a 1-D level set through `start` both ways (or once round a loop): the
/// curve, the steps taken and the largest corrector residual.
fn trace_curve(
    set: &mut dyn LevelSet,
    start: &[f64],
    params: &TraceValidParams,
    space: &MotorSpace,
    scratch: &mut Scratch,
) -> Result<(Curve, usize, f64), (SetStatus, usize)> {
    let n = start.len();
    scratch.prepare(set.rows(), n);
    let mut r = vec![0.0; set.rows()];
    set.linearize(start, &mut r)
        .map_err(|_| (SetStatus::Singular, 0))?;
    let mut t0 = vec![0.0; n];
    set.null_vector(&orientation_reference(n), &mut t0);
    let forward = trace_branch(set, start, &t0, params, space, scratch)?;
    let mut steps = forward.steps;
    let mut max_residual = forward.max_residual;
    let curve = if let Some(image) = forward.closes_at {
        let mut nodes = forward.nodes;
        let mut tangents = forward.tangents;
        let mut jacobians = forward.jacobians;
        nodes.extend_from_slice(&image);
        tangents.extend_from_slice(&t0);
        // (The closing image is the start: its linearisation is the first node's.)
        let per_node = jacobians.len() / (nodes.len() / n - 1).max(1);
        if per_node > 0 {
            jacobians.extend_from_within(..per_node);
        }
        Curve {
            nodes,
            tangents,
            jacobians,
            closed: true,
        }
    } else {
        // An open segment: trace the other way too and join the branches.
        set.linearize(start, &mut r)
            .map_err(|_| (SetStatus::Singular, steps))?;
        let backward_direction: Vec<f64> = t0.iter().map(|x| -x).collect();
        let backward = trace_branch(set, start, &backward_direction, params, space, scratch)
            .map_err(|(status, taken)| (status, steps + taken))?;
        steps += backward.steps;
        max_residual = max_residual.max(backward.max_residual);
        let mut nodes = Vec::with_capacity(forward.nodes.len() + backward.nodes.len());
        let mut tangents = Vec::with_capacity(nodes.capacity());
        let back_count = backward.nodes.len() / n;
        let per_node = backward.jacobians.len() / back_count.max(1);
        let mut jacobians = Vec::with_capacity(forward.jacobians.len() + backward.jacobians.len());
        for i in (1..back_count).rev() {
            nodes.extend_from_slice(&backward.nodes[i * n..(i + 1) * n]);
            tangents.extend(backward.tangents[i * n..(i + 1) * n].iter().map(|x| -x));
            jacobians.extend_from_slice(
                backward
                    .jacobians
                    .get(i * per_node..(i + 1) * per_node)
                    .unwrap_or(&[]),
            );
        }
        nodes.extend_from_slice(&forward.nodes);
        tangents.extend_from_slice(&forward.tangents);
        jacobians.extend_from_slice(&forward.jacobians);
        if jacobians.len() != per_node * (nodes.len() / n) {
            jacobians.clear();
        }
        for v in [
            forward.nodes,
            forward.tangents,
            forward.jacobians,
            backward.nodes,
            backward.tangents,
            backward.jacobians,
        ] {
            scratch.give(v);
        }
        Curve {
            nodes,
            tangents,
            jacobians,
            closed: false,
        }
    };
    Ok((curve, steps, max_residual))
}

/// Length of the polyline through `nodes` (`N` values each, unwrapped).
fn polyline_length(nodes: &[f64], n: usize) -> f64 {
    nodes
        .chunks_exact(n)
        .zip(nodes.chunks_exact(n).skip(1))
        .map(|(a, b)| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
                .sqrt()
        })
        .sum()
}

/// The result of one set: its points and their pieces when traced, and its report.
pub(super) struct SetResult {
    /// `P × N` points, periodic coordinates wrapped.
    pub points: Option<Vec<f64>>,
    /// The piece of every point (`P`), empty when not traced.
    pub pieces: Vec<i64>,
    /// The report line (`index` 0).
    pub report: SetReport,
}

impl SetResult {
    fn failed(report: SetReport) -> Self {
        Self {
            points: None,
            pieces: Vec::new(),
            report,
        }
    }
}

/// The pieces of one level set found so far (one kind of storage per dimension).
struct Found {
    /// k = 0: one point per piece (wrapped).
    points: Vec<f64>,
    /// k = 1: the traced curves (unwrapped nodes).
    curves: Vec<Curve>,
    /// k ≥ 2: the covering of every piece and its grid.
    covering: Covering,
    grid: Option<Grid>,
    covering_pieces: usize,
    /// Pieces found that could not be traced, and a point of each (wrapped).
    failed: usize,
    failed_points: Vec<f64>,
    /// Points and curves: the seeds that landed on each piece after the first.
    landings: Vec<u32>,
    steps: usize,
    max_residual: f64,
    n: usize,
}

impl Found {
    fn new(space: &MotorSpace, _params: &TraceValidParams) -> Self {
        Self {
            points: Vec::new(),
            curves: Vec::new(),
            covering: Covering::default(),
            grid: None,
            covering_pieces: 0,
            failed: 0,
            failed_points: Vec::new(),
            landings: Vec::new(),
            steps: 0,
            max_residual: 0.0,
            n: space.dim(),
        }
    }

    /// Counts a seed that landed at `m` (wrapped) on the point or curve piece after the
    /// first that it lies within `tolerance` of, if any (the first such piece).
    fn count_landing(&mut self, space: &MotorSpace, m: &[f64], tolerance: f64) {
        let n = self.n;
        let piece = if self.curves.is_empty() {
            self.points
                .chunks_exact(n)
                .position(|p| space.distance(p, m) <= tolerance)
        } else {
            self.curves
                .iter()
                .position(|c| near_curve(space, c, n, m, tolerance))
        };
        if let Some(later) = piece.and_then(|p| p.checked_sub(1)) {
            if let Some(count) = self.landings.get_mut(later) {
                *count += 1;
            }
        }
    }

    /// Pieces traced (failed ones not counted).
    fn count(&self) -> usize {
        self.points.len() / self.n.max(1) + self.curves.len() + self.covering_pieces
    }

    /// Whether `m` (wrapped, on the level set) lies on a piece already found: within
    /// `tolerance` (`piece_tolerance`, or less) of a traced curve, of a point piece or
    /// of a failed piece's point, or within `1.5 cover_step + tolerance` of a
    /// covering's node (the covering leaves no hole wider than about `cover_step`).
    fn contains(
        &self,
        space: &MotorSpace,
        m: &[f64],
        params: &TraceValidParams,
        tolerance: f64,
    ) -> bool {
        let n = self.n;
        let near_point = |points: &[f64]| {
            points
                .chunks_exact(n)
                .any(|p| space.distance(p, m) <= tolerance)
        };
        if near_point(&self.points) || near_point(&self.failed_points) {
            return true;
        }
        if self
            .curves
            .iter()
            .any(|c| near_curve(space, c, n, m, tolerance))
        {
            return true;
        }
        let nodes = &self.covering.nodes;
        self.grid.as_ref().is_some_and(|grid| {
            grid.any_near(m, |i| {
                space.distance(&nodes[i * n..(i + 1) * n], m)
                    <= PIECE_REACH * params.cover_step + tolerance
            })
        })
    }
}

/// Chords of a traced curve's Hermite segments are at most this long (radians) where
/// a point is tested against the curve ([`near_curve`]): a chord of length `c` strays
/// from an arc of curvature `κ` by `κ c² / 8`, a small fraction of `piece_tolerance`
/// here, where the nodes of long adaptive steps (`0.2`) stray by a few thousandths.
const NEAR_CHORD: f64 = 0.05;

/// Whether the curve through `curve`'s nodes (unwrapped), each segment the cubic
/// Hermite segment of its nodes and tangents cut into chords of at most
/// [`NEAR_CHORD`], passes within `tolerance` of `m` (torus distance).
fn near_curve(space: &MotorSpace, curve: &Curve, n: usize, m: &[f64], tolerance: f64) -> bool {
    let nodes = &curve.nodes;
    let count = nodes.len() / n;
    let mut image = vec![0.0; n];
    let (mut from, mut to) = (vec![0.0; n], vec![0.0; n]);
    for i in 0..count {
        let a = &nodes[i * n..(i + 1) * n];
        let d = space.distance(a, m);
        if d <= tolerance {
            return true;
        }
        if i + 1 < count {
            let b = &nodes[(i + 1) * n..(i + 2) * n];
            let length = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
                .sqrt();
            // (A Hermite segment stays within its chord's length of its first node.)
            if d > tolerance + length {
                continue;
            }
            // The image of m nearest to a, then the closest point of every chord.
            for ((o, &x), (&ai, motor)) in image.iter_mut().zip(m).zip(a.iter().zip(space.motors()))
            {
                *o = ai + motor.difference(x, ai);
            }
            let chords = (length / NEAR_CHORD).ceil().max(1.0) as usize;
            if chords == 1 || curve.tangents.len() != nodes.len() {
                if super::curve::closest_on_segment(a, b, &image).1 <= tolerance {
                    return true;
                }
                continue;
            }
            let (ta, tb) = (
                &curve.tangents[i * n..(i + 1) * n],
                &curve.tangents[(i + 1) * n..(i + 2) * n],
            );
            from.copy_from_slice(a);
            for c in 1..=chords {
                let s = c as f64 / chords as f64;
                super::curve::hermite(a, b, ta, tb, length, s, &mut to);
                if super::curve::closest_on_segment(&from, &to, &image).1 <= tolerance {
                    return true;
                }
                std::mem::swap(&mut from, &mut to);
            }
        }
    }
    false
}

/// The tangent space of the kernel set at a configuration: the null space of the
/// method's Jacobian `J` there (the pose Jacobian's rows held fixed for `kinematic`,
/// the sensory Jacobian for `sensory`), from the singular value decomposition of `J`.
#[derive(Debug, Clone, PartialEq)]
pub struct TangentSpace {
    /// `rank(J)`: the singular values above the tolerance times the largest (`1e-7`
    /// for the pose Jacobian, `rank_tolerance` for the sensory one).
    pub rank: usize,
    /// The singular values of `J`, largest first (`N` of them, zeros included).
    pub singular_values: Vec<f64>,
    /// An orthonormal basis of the null space, `(k, N)` with `k = N − rank`: the
    /// directions along which the kernel set extends.
    pub basis: Array2<f64>,
}

impl TangentSpace {
    /// The dimension `k = N − rank(J)` of the kernel set there.
    pub fn dimension(&self) -> usize {
        self.basis.nrows()
    }
}

/// The tangent space of the kernel set through `motors` (see [`TangentSpace`]); the
/// `sensory` method needs the environment.
///
/// ```
/// use smspace::agent::AgentConfig;
/// use smspace::kernel::{tangent_space, TraceParams};
/// let arm = AgentConfig::preset("planar-arm")?.build()?;
/// let params = TraceParams::default().check()?;
/// let tangent = tangent_space(arm.as_ref(), None, &[0.3, -1.2, 2.0, 0.5], &params)?;
/// // Four hinges, a 3-D pose: the kernel set is a curve.
/// assert_eq!((tangent.rank, tangent.dimension()), (3, 1));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn tangent_space(
    agent: &dyn Agent,
    environment: Option<&Environment>,
    motors: &[f64],
    params: &TraceValidParams,
) -> Result<TangentSpace, KernelError> {
    tangent_space_via(agent, environment, None, motors, params)
}

/// [`tangent_space`], the `sensory` method's readings through `caller` when given.
fn tangent_space_via<'a>(
    agent: &'a dyn Agent,
    environment: Option<&'a Environment>,
    caller: Option<&'a Caller<'a>>,
    motors: &[f64],
    params: &TraceValidParams,
) -> Result<TangentSpace, KernelError> {
    crate::agent::check_motor_count(agent, motors.len())?;
    let n = motors.len();
    let mut kinematic;
    let mut sensory;
    let (set, tolerance): (&mut dyn LevelSet, f64) = match params.method {
        TraceMethod::Kinematic => {
            let observer = agent
                .sensed_configuration()
                .ok_or(KernelError::NoGroundTruth {
                    agent: agent.name().to_owned(),
                    needs: "the kinematic method",
                    fix: "use method = \"sensory\" (the agent's own sensors)",
                })?;
            kinematic = Kinematic::new(observer, motors, params.pose_tolerance);
            (&mut kinematic, 1e-7)
        }
        TraceMethod::Sensory | TraceMethod::Learned => {
            let environment = environment.ok_or(KernelError::MissingEnvironment)?;
            sensory = Sensory::new(agent, environment, caller, motors, params, 1);
            (&mut sensory, params.rank_tolerance)
        }
    };
    let mut r = vec![0.0; set.rows()];
    // A singular linearisation still fills the Jacobian: its rank is what is asked.
    let _ = set.linearize(motors, &mut r);
    let (jacobian, rows) = set.jacobian();
    if !jacobian.iter().all(|v| v.is_finite()) {
        return Err(KernelError::NonFiniteJacobian {
            method: params.method,
            motors: motors.to_vec(),
        });
    }
    Ok(null_space(jacobian, rows, n, tolerance))
}

/// The sensory Jacobian's largest absolute entry at the starts (`slope`) within the
/// range the tracer's squared norms hold: `[1e-150, 1e150]` (a Jacobian that is zero
/// at every start is left to the rank's own report).
fn check_sensor_scale(slope: Option<f64>, starts: usize) -> Result<(), KernelError> {
    const LOWEST: f64 = 1e-150;
    const HIGHEST: f64 = 1e150;
    match slope {
        Some(slope) if slope > HIGHEST || (slope > 0.0 && slope < LOWEST) => {
            Err(KernelError::SensorScale { slope, starts })
        }
        _ => Ok(()),
    }
}

/// The null space of the `rows × n` matrix `jacobian` (row-major, finite) by SVD,
/// zero rows added so that every right singular vector is computed.
fn null_space(jacobian: &[f64], rows: usize, n: usize, relative_tolerance: f64) -> TangentSpace {
    let mut matrix = DMatrix::<f64>::zeros(rows.max(n), n);
    for i in 0..rows {
        for j in 0..n {
            matrix[(i, j)] = jacobian[i * n + j];
        }
    }
    let svd = SVD::new(matrix, false, true);
    let singular_values: Vec<f64> = svd.singular_values.iter().copied().collect();
    let largest = singular_values.first().copied().unwrap_or(0.0);
    let rank = singular_values
        .iter()
        .filter(|&&s| largest > 0.0 && s > relative_tolerance * largest)
        .count();
    let v_t = svd.v_t.expect("right singular vectors were asked for");
    let basis = Array2::from_shape_fn((n - rank, n), |(i, j)| v_t[(rank + i, j)]);
    TangentSpace {
        rank,
        singular_values,
        basis,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn the_null_space_is_orthonormal_and_annihilated() {
        // J = [[1, 1, 0, 0], [0, 0, 1, 2]]: rank 2, a 2-D null space.
        let j = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0];
        let t = null_space(&j, 2, 4, 1e-9);
        assert_eq!((t.rank, t.dimension()), (2, 2));
        for a in 0..2 {
            for b in 0..2 {
                let dot: f64 = (0..4).map(|k| t.basis[[a, k]] * t.basis[[b, k]]).sum();
                assert_abs_diff_eq!(dot, if a == b { 1.0 } else { 0.0 }, epsilon = 1e-12);
            }
            for row in j.chunks(4) {
                let image: f64 = (0..4).map(|k| row[k] * t.basis[[a, k]]).sum();
                assert_abs_diff_eq!(image, 0.0, epsilon = 1e-12);
            }
        }
        // More rows than columns, and a zero matrix.
        let tall = [1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        assert_eq!(null_space(&tall, 3, 2, 1e-9).rank, 2);
        let zero = null_space(&[0.0; 6], 2, 3, 1e-9);
        assert_eq!((zero.rank, zero.dimension()), (0, 3));
    }
}
