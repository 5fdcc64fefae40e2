//! One tracing call, checked once: the agent's motor space and ground truth, the
//! level set of the method, and the dimension `k = N − rank(J)` of the kernel sets.
//!
//! With a ground truth, `rank(J)` is the number `C` of pose coordinates the motors
//! change ([`Observer::configuration_dim`]), for both methods: the sensors determine
//! the pose (paper section 2.1). Without one (the `sensory` method only), it is the
//! generic rank of the sensory Jacobian, estimated as its largest numerical rank over
//! the starts (singular values above `rank_tolerance` times the largest; a start
//! where fewer lights are in view has a lower rank, never a higher one). Sets of
//! dimension 0 are single points, of dimension 1 curves the follower traces; a
//! larger `k` is refused with [`KernelError::UnsupportedDimension`].

use nalgebra::{DMatrix, SVD};
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use super::curve::{resample, trace_branch, Curve, Scratch};
use super::level_set::{Kinematic, LevelSet, Sensory};
use super::{KernelError, SetReport, SetStatus, TraceMethod, TraceValidParams};
use crate::agent::{Agent, Environment, MotorSpace, Observer, PoseSpace, Workspace};

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
        let observer = agent.ground_truth();
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
        };
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
                let rank = tracer.generic_sensory_rank(starts);
                let jacobian = format!(
                    "the sensory Jacobian, of rank {rank}: its largest numerical rank over the {} starts (singular values above rank_tolerance = {} times the largest)",
                    starts.nrows(),
                    params.rank_tolerance
                );
                supported_dimension(agent, rank, jacobian)?
            }
        };
        Ok(tracer)
    }

    /// The largest numerical rank of the sensory Jacobian over the starts (0 where it
    /// is not finite).
    fn generic_sensory_rank(&self, starts: ArrayView2<'_, f64>) -> usize {
        let rows: Vec<Vec<f64>> = starts.outer_iter().map(|r| r.to_vec()).collect();
        rows.par_iter()
            .map(|start| {
                tangent_space(self.agent, self.environment, start, self.params)
                    .map_or(0, |t| t.rank)
            })
            .max()
            .unwrap_or(0)
    }

    /// Traces and resamples the set through `start`: its points `(P × N)` when traced,
    /// and its report line (`index` 0).
    pub(super) fn trace(
        &self,
        start: &[f64],
        scratch: &mut Scratch,
    ) -> (Option<Vec<f64>>, SetReport) {
        let mut report = SetReport {
            index: 0,
            status: SetStatus::Closed,
            steps: 0,
            length: 0.0,
            max_residual: 0.0,
            max_pose_deviation: self.observer.map(|_| 0.0),
            dimension: self.dimension,
        };
        let start_pose = self.observer.map(|o| {
            let mut pose = vec![0.0; o.pose_space().dim()];
            o.pose(start, &mut pose);
            pose
        });
        if let (Some(w), Some(pose)) = (self.workspace, &start_pose) {
            if !w.contains(pose) {
                report.status = SetStatus::OutsideWorkspace;
                return (None, report);
            }
        }
        if !self.agent.covers(start) {
            report.status = SetStatus::LeftData;
            return (None, report);
        }
        if self.dimension == 0 {
            report.status = SetStatus::Point;
            let mut points: Vec<f64> = start.repeat(self.params.points);
            self.space.wrap_points(&mut points);
            return (Some(points), report);
        }
        let mut kinematic;
        let mut sensory;
        let set: &mut dyn LevelSet = match (self.params.method, self.observer, self.environment) {
            (TraceMethod::Kinematic, Some(observer), _) => {
                kinematic = Kinematic::new(observer, start, self.params.pose_tolerance);
                &mut kinematic
            }
            (_, _, Some(environment)) => {
                sensory = Sensory::new(self.agent, environment, start, self.params, self.dimension);
                &mut sensory
            }
            _ => unreachable!("Tracer::new checked the method's needs"),
        };
        match trace_set(set, start, self.params, &self.space, scratch) {
            Ok(mut traced) => {
                if let Some(pose) = &start_pose {
                    report.max_pose_deviation = Some(self.pose_deviation(&traced.points, pose));
                }
                self.space.wrap_points(&mut traced.points);
                report.status = if traced.closed {
                    SetStatus::Closed
                } else {
                    SetStatus::Open
                };
                report.steps = traced.steps;
                report.length = traced.length;
                report.max_residual = traced.max_residual;
                (Some(traced.points), report)
            }
            Err((status, steps)) => {
                report.status = status;
                report.steps = steps;
                (None, report)
            }
        }
    }

    /// The largest deviation of a point's pose from `start_pose`, over the tangent
    /// coordinates the motors change (the observer's check of a traced set).
    fn pose_deviation(&self, points: &[f64], start_pose: &[f64]) -> f64 {
        let (Some(observer), Some(poses)) = (self.observer, &self.poses) else {
            return 0.0;
        };
        let c = observer.configuration_dim();
        let mut pose = vec![0.0; poses.dim()];
        let mut difference = vec![0.0; poses.tangent_dim()];
        let mut deviation: f64 = 0.0;
        for p in points.chunks_exact(self.agent.motor_dim()) {
            observer.pose(p, &mut pose);
            poses.difference(&pose, start_pose, &mut difference);
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
    let Some(observer) = agent.ground_truth() else {
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
        TraceMethod::Sensory => "the sensory Jacobian",
    };
    let jacobian = format!(
        "{which}, of rank {c}: the pose coordinates its ground truth says the motors change"
    );
    supported_dimension(agent, c, jacobian).map(Some)
}

/// `k = N − rank`, or [`KernelError::UnsupportedDimension`] for `k ≥ 2`.
fn supported_dimension(
    agent: &dyn Agent,
    rank: usize,
    jacobian: String,
) -> Result<usize, KernelError> {
    let n = agent.motor_dim();
    let dimension = n - rank.min(n);
    if dimension > 1 {
        return Err(KernelError::UnsupportedDimension {
            agent: agent.name().to_owned(),
            motors: n,
            rank,
            dimension,
            jacobian,
        });
    }
    Ok(dimension)
}

/// A fixed direction with no special relation to any axis; the first tangent of every
/// set is oriented along it (`t·w > 0`), so both methods traverse a set the same way.
fn orientation_reference(n: usize) -> Vec<f64> {
    let golden = 0.5 * (1.0 + 5f64.sqrt());
    (0..n).map(|k| golden.powi(-(k as i32))).collect()
}

/// A traced and resampled 1-D set.
struct Traced {
    /// `P × N` points, unwrapped.
    points: Vec<f64>,
    /// Arc length.
    length: f64,
    steps: usize,
    max_residual: f64,
    /// A loop (else a segment between two bounds).
    closed: bool,
}

/// Follows a 1-D level set through `start` both ways (or once round a loop) and
/// resamples it.
fn trace_set(
    set: &mut dyn LevelSet,
    start: &[f64],
    params: &TraceValidParams,
    space: &MotorSpace,
    scratch: &mut Scratch,
) -> Result<Traced, (SetStatus, usize)> {
    let n = start.len();
    scratch.prepare(set.rows(), n);
    let mut r = vec![0.0; set.rows()];
    set.linearize(start, &mut r)
        .map_err(|_| (SetStatus::Singular, 0))?;
    let mut t0 = vec![0.0; n];
    set.null_vector(&orientation_reference(n), &mut t0);
    let forward =
        trace_branch(set, start, &t0, params, space, scratch).map_err(|status| (status, 0))?;
    let mut steps = forward.steps;
    let mut max_residual = forward.max_residual;
    let curve = if let Some(image) = forward.closes_at {
        let mut nodes = forward.nodes;
        let mut tangents = forward.tangents;
        nodes.extend_from_slice(&image);
        tangents.extend_from_slice(&t0);
        Curve {
            nodes,
            tangents,
            closed: true,
        }
    } else {
        // An open segment: trace the other way too and join the branches.
        set.linearize(start, &mut r)
            .map_err(|_| (SetStatus::Singular, steps))?;
        let backward_direction: Vec<f64> = t0.iter().map(|x| -x).collect();
        let backward = trace_branch(set, start, &backward_direction, params, space, scratch)
            .map_err(|status| (status, steps))?;
        steps += backward.steps;
        max_residual = max_residual.max(backward.max_residual);
        let mut nodes = Vec::with_capacity(forward.nodes.len() + backward.nodes.len());
        let mut tangents = Vec::with_capacity(nodes.capacity());
        let back_count = backward.nodes.len() / n;
        for i in (1..back_count).rev() {
            nodes.extend_from_slice(&backward.nodes[i * n..(i + 1) * n]);
            tangents.extend(backward.tangents[i * n..(i + 1) * n].iter().map(|x| -x));
        }
        nodes.extend_from_slice(&forward.nodes);
        tangents.extend_from_slice(&forward.tangents);
        for v in [
            forward.nodes,
            forward.tangents,
            backward.nodes,
            backward.tangents,
        ] {
            scratch.give(v);
        }
        Curve {
            nodes,
            tangents,
            closed: false,
        }
    };
    let closed = curve.closed;
    let resampled = resample(
        set,
        &curve,
        params.points,
        params.max_corrector_iterations,
        scratch,
    );
    scratch.give(curve.nodes);
    scratch.give(curve.tangents);
    let (points, length, residual) = resampled.map_err(|status| (status, steps))?;
    Ok(Traced {
        points,
        length,
        steps,
        max_residual: max_residual.max(residual),
        closed,
    })
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
    crate::agent::check_motor_count(agent, motors.len())?;
    let n = motors.len();
    let mut kinematic;
    let mut sensory;
    let (set, tolerance): (&mut dyn LevelSet, f64) = match params.method {
        TraceMethod::Kinematic => {
            let observer = agent.ground_truth().ok_or(KernelError::NoGroundTruth {
                agent: agent.name().to_owned(),
                needs: "the kinematic method",
                fix: "use method = \"sensory\" (the agent's own sensors)",
            })?;
            kinematic = Kinematic::new(observer, motors, params.pose_tolerance);
            (&mut kinematic, 1e-7)
        }
        TraceMethod::Sensory => {
            let environment = environment.ok_or(KernelError::MissingEnvironment)?;
            sensory = Sensory::new(agent, environment, motors, params, 1);
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
