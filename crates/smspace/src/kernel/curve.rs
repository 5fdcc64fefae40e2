//! Predictor–corrector continuation of a 1-D level set, closure, and arc-length
//! resampling.

use super::level_set::{LevelSet, Linearization};
use super::{SetStatus, StepControl, TraceValidParams};
use crate::agent::MotorSpace;

/// Smallest step the adaptive control may take before it gives up.
const MIN_ADAPTIVE_STEP: f64 = 1e-7;
/// Readings with noise: the adaptive step stays above this many position
/// uncertainties ([`LevelSet::position_noise`]).
const MIN_STEP_NOISE: f64 = 4.0;
/// Readings with noise: a first correction of at most this many position
/// uncertainties is noise, not a sign that the step was too long.
const QUIET_NOISE: f64 = 3.0;
/// Readings with noise: a loop closes within this many position uncertainties (or
/// `closure_tolerance`, whichever is larger).
const CLOSURE_NOISE: f64 = 4.0;
/// Segments longer than this are measured as Hermite arcs, shorter ones as chords
/// (an arc of length `h` and curvature `κ` exceeds its chord by `κ²h³/24`, below
/// `10⁻⁹` here for the curvatures of the arm's sets).
const ARC_SPACING: f64 = 2e-3;

/// A traced branch: nodes on the set (unwrapped coordinates) and unit tangents.
#[derive(Debug, Default)]
pub(crate) struct Branch {
    pub nodes: Vec<f64>,
    pub tangents: Vec<f64>,
    /// The linearisation at every node (`rows × N` each) when the level set keeps
    /// them ([`LevelSet::node_jacobian`]); empty otherwise.
    pub jacobians: Vec<f64>,
    pub steps: usize,
    /// For a closed loop: the image of the start the loop returns to (unwrapped).
    pub closes_at: Option<Vec<f64>>,
    pub max_residual: f64,
}

/// Result of one corrector run.
pub(crate) struct Corrected {
    first_step: f64,
    /// How far the corrector moved the point in all.
    total_step: f64,
    /// The residual norm at the corrected point.
    pub(crate) residual: f64,
    /// Whether the level set is linearised at the corrected point.
    linearized: bool,
}

/// Scratch buffers for the tracer, reused from set to set by a worker thread (their
/// contents never carry over: every use starts by clearing or overwriting them).
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    r: Vec<f64>,
    delta: Vec<f64>,
    /// Segment chords of the resampler and its cumulative arc length.
    fine: Vec<f64>,
    arc: Vec<f64>,
    /// Node and tangent storage handed to branches.
    pub(crate) spare: Vec<Vec<f64>>,
}

impl Scratch {
    /// Sizes the small buffers for a level set with `rows` residuals and `n` motors.
    pub(crate) fn prepare(&mut self, rows: usize, n: usize) {
        self.r.clear();
        self.r.resize(rows, 0.0);
        self.delta.clear();
        self.delta.resize(n, 0.0);
    }

    /// An empty vector, reusing storage from an earlier set when there is some.
    pub(crate) fn take(&mut self) -> Vec<f64> {
        let mut v = self.spare.pop().unwrap_or_default();
        v.clear();
        v
    }

    /// Returns storage for later sets.
    pub(crate) fn give(&mut self, v: Vec<f64>) {
        self.spare.push(v);
    }
}

/// Readings with noise: the next tangent is oriented by the heading from this many
/// nodes back.
const HEADING_NODES: usize = 3;

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// How the corrector may conclude.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Convergence {
    /// Only a measured residual within the tolerance ends the iteration.
    Measured,
    /// A measured residual within the level set's node tolerance
    /// ([`LevelSet::node_tolerance`]) ends it, and also:
    /// a Newton step shorter than `0.1 √tol` ends it, without a further
    /// evaluation: Newton's quadratic remainder `½ |F''| |Δ|²` is then far below the
    /// tolerance for second derivatives of order one (the arm's are bounded by its
    /// reach). Used between traced nodes, never for the resampled output points.
    NewtonStep,
}

/// Moves `m` back onto the level set. Newton level sets are linearised at every
/// iterate (so on return they are linearised at, or within a negligible Newton step
/// of, the final `m`); chord level sets reuse the current linearisation and
/// re-linearise only when convergence stalls.
pub(crate) fn correct(
    set: &mut dyn LevelSet,
    m: &mut [f64],
    scratch: &mut Scratch,
    max_iterations: usize,
    convergence: Convergence,
) -> Option<Corrected> {
    let newton = set.newton();
    if newton {
        set.linearize(m, &mut scratch.r).ok()?;
    } else {
        set.residual(m, &mut scratch.r);
    }
    let mut first_step = 0.0;
    let mut total_step = 0.0;
    let mut previous = f64::INFINITY;
    for iteration in 0..=max_iterations {
        // (A level set with noise scales its tolerance to its current linearisation.)
        let tolerance = match convergence {
            Convergence::Measured => set.tolerance(),
            Convergence::NewtonStep => set.node_tolerance(),
        };
        let residual = set.residual_norm(&scratch.r);
        if !residual.is_finite() {
            return None;
        }
        if residual <= tolerance {
            if set.final_step() {
                set.correction(&scratch.r, &mut scratch.delta);
                total_step += norm(&scratch.delta);
                for (x, d) in m.iter_mut().zip(&scratch.delta) {
                    *x -= d;
                }
            }
            return Some(Corrected {
                first_step,
                total_step,
                residual,
                linearized: newton,
            });
        }
        if iteration == max_iterations {
            return None;
        }
        if !newton && iteration > 0 && residual > 0.25 * previous {
            set.linearize(m, &mut scratch.r).ok()?;
        }
        previous = residual;
        set.correction(&scratch.r, &mut scratch.delta);
        let step = norm(&scratch.delta);
        if iteration == 0 {
            first_step = step;
        }
        total_step += step;
        for (x, d) in m.iter_mut().zip(&scratch.delta) {
            *x -= d;
        }
        if newton && convergence == Convergence::NewtonStep && step <= set.newton_step_tolerance() {
            return Some(Corrected {
                first_step,
                total_step,
                residual: step * step,
                linearized: true,
            });
        }
        if newton {
            set.linearize(m, &mut scratch.r).ok()?;
        } else {
            set.residual(m, &mut scratch.r);
        }
    }
    None
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// Closest approach of the segment `[a, b]` to `p` (Euclidean): `(parameter, distance)`,
/// the parameter `τ ∈ [0, 1]` of the nearest point `a + τ (b − a)`.
pub(crate) fn closest_on_segment(a: &[f64], b: &[f64], p: &[f64]) -> (f64, f64) {
    let mut len2 = 0.0;
    let mut dot = 0.0;
    for ((x, y), q) in a.iter().zip(b).zip(p) {
        len2 += (y - x) * (y - x);
        dot += (q - x) * (y - x);
    }
    let tau = if len2 > 0.0 {
        (dot / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = a
        .iter()
        .zip(b)
        .zip(p)
        .map(|((x, y), q)| (x + tau * (y - x) - q).powi(2))
        .sum::<f64>()
        .sqrt();
    (tau, d)
}

/// Traces from `start` along `direction` until the curve closes (back at an image of
/// the start), reaches a bound of a bounded coordinate, or fails: then the status and
/// the steps taken before the failure. The level set must be linearised at `start`.
pub(crate) fn trace_branch(
    set: &mut dyn LevelSet,
    start: &[f64],
    direction: &[f64],
    params: &TraceValidParams,
    space: &MotorSpace,
    scratch: &mut Scratch,
) -> Result<Branch, (SetStatus, usize)> {
    let mut branch = Branch {
        nodes: scratch.take(),
        tangents: scratch.take(),
        jacobians: scratch.take(),
        ..Branch::default()
    };
    match follow(set, start, direction, params, space, scratch, &mut branch) {
        Ok(()) => Ok(branch),
        Err(status) => {
            let steps = branch.steps;
            scratch.give(branch.nodes);
            scratch.give(branch.tangents);
            scratch.give(branch.jacobians);
            Err((status, steps))
        }
    }
}

/// The steps of [`trace_branch`], into `branch`.
fn follow(
    set: &mut dyn LevelSet,
    start: &[f64],
    direction: &[f64],
    params: &TraceValidParams,
    space: &MotorSpace,
    scratch: &mut Scratch,
    branch: &mut Branch,
) -> Result<(), SetStatus> {
    let n = start.len();
    let adaptive = params.step_control == StepControl::Adaptive;
    branch.nodes.extend_from_slice(start);
    branch.tangents.extend_from_slice(direction);
    let keep_jacobians = set.node_jacobian().is_some();
    if let Some(jacobian) = set.node_jacobian() {
        branch.jacobians.extend_from_slice(jacobian);
    }
    let mut m = start.to_vec();
    let mut t = direction.to_vec();
    let (mut predicted, mut previous, mut t_new) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    // Change of the unit tangent per unit length (curvature vector), for a second-order
    // predictor m + h t + ½ h² k.
    let mut bend = vec![0.0; n];
    // A level set that keeps its nodes' linearisations (exact readings, secant
    // Jacobians): from the second step on, the predictor extrapolates the cubic
    // Hermite segment through the last two nodes and their tangents (error `O(h⁴)`
    // instead of the second-order predictor's `O(h³)`), and the step grows by up to
    // 4 at a time ([`growth`]); the other level sets keep the second-order predictor
    // and grow by 1.5.
    let mut previous_t = vec![0.0; n];
    let mut cubic = false;
    let mut h = params.step;
    // Readings with noise: corrections below a few position uncertainties are noise
    // (nothing to do), steps shorter than a few are not taken, a loop closes within a
    // few, and the tangent's own noise is allowed on top of `max_turn` (all 0 for
    // exact readings).
    let position_noise = set.position_noise();
    let min_step = MIN_ADAPTIVE_STEP.max(MIN_STEP_NOISE * position_noise);
    let closure_tolerance = params.closure_tolerance.max(CLOSURE_NOISE * position_noise);
    let mut watch = ClosureWatch::new(space, closure_tolerance, n);
    if position_noise > 0.0 {
        h = h.max(min_step);
    }
    let bounded = space.has_bounds();
    let max_step = params.max_step_or(set.automatic_max_step());
    loop {
        if branch.steps >= params.max_steps {
            return Err(SetStatus::NotClosed);
        }
        if params.rows_spent(set.sensor_rows()) {
            return Err(SetStatus::RowBudget);
        }
        let chord = distance(&m, &previous);
        if cubic && chord > 0.0 {
            hermite(
                &previous,
                &m,
                &previous_t,
                &t,
                chord,
                1.0 + h / chord,
                &mut predicted,
            );
        } else {
            for j in 0..n {
                predicted[j] = m[j] + h * t[j] + 0.5 * h * h * bend[j];
            }
        }
        let outcome = correct_step(set, &mut predicted, params, scratch);
        let corrected = match outcome {
            Ok(c) => c,
            Err(status) => {
                if adaptive && h > min_step {
                    halve(set, &m, scratch, &mut h)?;
                    continue;
                }
                return Err(status);
            }
        };
        next_tangent(
            set,
            &branch.nodes,
            &predicted,
            &t,
            position_noise > 0.0,
            &mut t_new,
        );
        let cos_turn: f64 = t.iter().zip(&t_new).map(|(a, b)| a * b).sum();
        let max_turn = params.max_turn + set.tangent_noise();
        let too_sharp = cos_turn < max_turn.cos();
        let (first_step, jumped) = noise_allowance(set, &corrected, h, position_noise);
        if jumped && !(adaptive && h > min_step) {
            return Err(SetStatus::CorrectorFailed);
        }
        if adaptive && h > min_step && (too_sharp || jumped || first_step > 0.1 * h) {
            halve(set, &m, scratch, &mut h)?;
            continue;
        }
        if too_sharp {
            // The null direction jumps however short the step: two directions are
            // (nearly) null, so the set is not a curve the tracer can follow here.
            return Err(SetStatus::Singular);
        }
        branch.max_residual = branch.max_residual.max(corrected.residual);
        std::mem::swap(&mut previous, &mut m);
        m.copy_from_slice(&predicted);
        let travelled = distance(&m, &previous);
        // (With noise the turn between nodes is mostly the tangents' noise.)
        let curving = travelled > 0.0 && position_noise == 0.0;
        for ((b, new), old) in bend.iter_mut().zip(&t_new).zip(&t) {
            *b = if curving {
                (new - old) / travelled
            } else {
                0.0
            };
        }
        previous_t.copy_from_slice(&t);
        cubic = keep_jacobians;
        std::mem::swap(&mut t, &mut t_new);
        branch.steps += 1;
        branch.nodes.extend_from_slice(&m);
        branch.tangents.extend_from_slice(&t);
        if keep_jacobians {
            match set.node_jacobian() {
                Some(jacobian) => branch.jacobians.extend_from_slice(jacobian),
                None => return Err(SetStatus::Singular),
            }
        }
        if !set.covers(&m) {
            return Err(SetStatus::LeftData);
        }
        if adaptive {
            let turn = cos_turn.clamp(-1.0, 1.0).acos();
            let factor = if keep_jacobians {
                growth(first_step / h, turn / max_turn)
            } else if first_step < 0.025 * h && turn < max_turn / 4.0 {
                1.5
            } else {
                1.0
            };
            h = (h * factor).min(max_step);
        }

        // (With noise, a loop closes after `min_steps` steps, adaptive or not: the
        // tangent's noise can turn a first few short steps back towards the start.)
        let may_close = (adaptive && position_noise == 0.0) || branch.steps >= params.min_steps;
        let step = Step {
            previous: &previous,
            m: &m,
            t: &t,
            travelled,
        };
        let ends = (may_close, position_noise > 0.0, bounded.then_some(space));
        if let Some(end) = branch_ends(&mut watch, branch, (start, direction), step, ends) {
            return end;
        }
    }
}

/// The factor the adaptive step grows by after a step whose first correction was
/// `correction` times the step and whose tangent turned by `turn` times the largest
/// turn allowed. A step is taken again shorter when its first correction exceeds a
/// tenth of it or its turn the largest; the step grows while both stay below a
/// quarter of those once grown, the correction growing at most as `h³` (the
/// predictor's error) and the turn as `h`: `×1.5` below `0.025 h` and a quarter of the
/// largest turn (the rule of the other level sets), `×2` below `0.01 h` and an
/// eighth, `×4` below `10⁻³ h` and a sixteenth (the first steps from the small
/// initial `step` towards `max_step`). (Growing up to half the largest turn, about
/// twice the steps where the set bends, left the arm's sets `2·10⁻⁶` rad from
/// those of short steps: the Hermite curve's arc length is off by more.)
fn growth(correction: f64, turn: f64) -> f64 {
    if correction < 1e-3 && turn < 1.0 / 16.0 {
        4.0
    } else if correction < 0.01 && turn < 0.125 {
        2.0
    } else if correction < 0.025 && turn < 0.25 {
        1.5
    } else {
        1.0
    }
}

/// Halves the step `h` and linearises the set again at `m`, where the predictor
/// starts (the chord corrector needs it).
fn halve(
    set: &mut dyn LevelSet,
    m: &[f64],
    scratch: &mut Scratch,
    h: &mut f64,
) -> Result<(), SetStatus> {
    *h /= 2.0;
    set.linearize(m, &mut scratch.r)
        .map_err(|_| SetStatus::Singular)
}

/// The last step of a branch: from `previous` to `m` (`travelled` long), tangent `t`.
struct Step<'a> {
    previous: &'a [f64],
    m: &'a [f64],
    t: &'a [f64],
    travelled: f64,
}

/// Whether the branch ends with `step`: `Ok` when it closes its loop (from the last
/// segment's beginning when the start lies inside it; `closes_at` set) or stops on a
/// motor's bound (`bounds`: the space, when it has bounds); `Err(Retraced)` when a noisy
/// trace comes back to its start heading the other way (it has run back along its own
/// path: no loop); `None` to go on.
fn branch_ends(
    watch: &mut ClosureWatch,
    branch: &mut Branch,
    (start, direction): (&[f64], &[f64]),
    step: Step<'_>,
    (may_close, noisy, bounds): (bool, bool, Option<&MotorSpace>),
) -> Option<Result<(), SetStatus>> {
    let n = start.len();
    if let Some(tau) = watch.closes(start, step.previous, step.m, step.travelled, may_close) {
        if tau < 1.0 && branch.steps > 1 {
            branch.nodes.truncate(branch.nodes.len() - n);
            branch.tangents.truncate(branch.tangents.len() - n);
            let per_node = branch.jacobians.len() / (branch.nodes.len() / n + 1);
            branch.jacobians.truncate(branch.jacobians.len() - per_node);
        }
        let heading: f64 = step.t.iter().zip(direction).map(|(a, b)| a * b).sum();
        if noisy && heading < 0.0 {
            return Some(Err(SetStatus::Retraced));
        }
        branch.closes_at = Some(watch.image.clone());
        return Some(Ok(()));
    }
    match bounds {
        Some(space) if stops_on_bound(space, step.previous, step.m, &mut branch.nodes) => {
            Some(Ok(()))
        }
        _ => None,
    }
}

/// The null vector at `at` (where the level set is linearised) into `t_new`, oriented
/// along the previous tangent `t`; with noisy readings along the heading from the
/// node [`HEADING_NODES`] back to `at` instead (positions are known far better than a
/// noisy tangent, which a poorly determined null direction can turn round).
fn next_tangent(
    set: &dyn LevelSet,
    nodes: &[f64],
    at: &[f64],
    t: &[f64],
    noisy: bool,
    t_new: &mut [f64],
) {
    let n = at.len();
    if !noisy {
        set.null_vector(t, t_new);
        return;
    }
    let back = (nodes.len() / n).saturating_sub(1 + HEADING_NODES);
    let from = &nodes[back * n..(back + 1) * n];
    let mut heading: Vec<f64> = at.iter().zip(from).map(|(a, b)| a - b).collect();
    if norm(&heading) == 0.0 {
        heading.copy_from_slice(t);
    }
    set.null_vector(&heading, t_new);
}

/// The corrector from a predicted point, linearised where it lands (the next null
/// vector is read there): `corrector-failed` when it does not converge, `singular`
/// when the Jacobian there is.
fn correct_step(
    set: &mut dyn LevelSet,
    predicted: &mut [f64],
    params: &TraceValidParams,
    scratch: &mut Scratch,
) -> Result<Corrected, SetStatus> {
    let corrected = correct(
        set,
        predicted,
        scratch,
        params.max_corrector_iterations,
        Convergence::NewtonStep,
    )
    .ok_or(SetStatus::CorrectorFailed)?;
    if corrected.linearized {
        return Ok(corrected);
    }
    match set.linearize(predicted, &mut scratch.r) {
        Ok(()) => Ok(corrected),
        Err(_) => Err(SetStatus::Singular),
    }
}

/// The first correction of a step less what the readings' noise explains (a few
/// position uncertainties, and the tangent's noise times the step: nothing to do),
/// and whether the corrector left the step's neighbourhood (readings with noise only:
/// a Gauss–Newton step through a poor slope). For exact readings, the first
/// correction itself and `false`.
fn noise_allowance(
    set: &dyn LevelSet,
    corrected: &Corrected,
    h: f64,
    position_noise: f64,
) -> (f64, bool) {
    if position_noise == 0.0 {
        return (corrected.first_step, false);
    }
    let allowance = QUIET_NOISE * position_noise + set.tangent_noise() * h;
    let jumped = corrected.total_step > 2.0 * h + allowance;
    ((corrected.first_step - allowance).max(0.0), jumped)
}

/// The closure test of a trace: the segment just travelled passes within the tolerance
/// of the start. Far from the start the test is skipped until the trace has travelled
/// the distance that separated it from the start's tolerance ball.
struct ClosureWatch<'a> {
    space: &'a MotorSpace,
    tolerance: f64,
    /// Largest distance from the start seen so far.
    farthest: f64,
    /// Length still to travel before the next test.
    travel_to_check: f64,
    /// The image of the start nearest the last point tested.
    image: Vec<f64>,
}

impl<'a> ClosureWatch<'a> {
    fn new(space: &'a MotorSpace, tolerance: f64, n: usize) -> Self {
        Self {
            space,
            tolerance,
            farthest: 0.0,
            travel_to_check: 0.0,
            image: vec![0.0; n],
        }
    }

    /// After a step from `previous` to `m` of length `travelled`: the parameter on
    /// that segment of the point nearest the start, when the trace closes there.
    fn closes(
        &mut self,
        start: &[f64],
        previous: &[f64],
        m: &[f64],
        travelled: f64,
        enough_steps: bool,
    ) -> Option<f64> {
        self.travel_to_check -= travelled;
        if self.travel_to_check > 0.0 {
            return None;
        }
        self.space.nearest_image(start, m, &mut self.image);
        let from_start = distance(m, &self.image);
        // (Farther than twice the tolerance before this step: a first long step may
        // leave from within the tolerance of the start, where it has not come back.)
        let may_close = self.farthest > 2.0 * self.tolerance && enough_steps;
        self.farthest = self.farthest.max(from_start);
        self.travel_to_check = (from_start - 2.0 * self.tolerance) / 2.0;
        if may_close && from_start <= self.tolerance + travelled {
            let (tau, d) = closest_on_segment(previous, m, &self.image);
            if d <= self.tolerance {
                return Some(tau);
            }
        }
        None
    }
}

/// When the step from `previous` to `m` leaves the range of a bounded coordinate,
/// moves the last node of `nodes` (that is `m`) to where the step crosses the bound and
/// returns `true`: the branch ends there.
fn stops_on_bound(space: &MotorSpace, previous: &[f64], m: &[f64], nodes: &mut [f64]) -> bool {
    let Some(tau) = space.exit_fraction(previous, m) else {
        return false;
    };
    let last = nodes.len() - m.len();
    space.point_on_exit(previous, m, tau, &mut nodes[last..]);
    true
}

/// Cubic Hermite point on the segment from `a` to `b` with unit tangents `ta`, `tb`
/// scaled by the chord `c`, at parameter `s ∈ [0, 1]`.
pub(crate) fn hermite(
    a: &[f64],
    b: &[f64],
    ta: &[f64],
    tb: &[f64],
    c: f64,
    s: f64,
    out: &mut [f64],
) {
    let s2 = s * s;
    let s3 = s2 * s;
    let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
    let h10 = s3 - 2.0 * s2 + s;
    let h01 = -2.0 * s3 + 3.0 * s2;
    let h11 = s3 - s2;
    for j in 0..a.len() {
        out[j] = h00 * a[j] + h10 * c * ta[j] + h01 * b[j] + h11 * c * tb[j];
    }
}

/// Speed `|H'(s)|` of the Hermite segment.
fn hermite_speed(a: &[f64], b: &[f64], ta: &[f64], tb: &[f64], c: f64, s: f64) -> f64 {
    let s2 = s * s;
    let d00 = 6.0 * s2 - 6.0 * s;
    let d10 = 3.0 * s2 - 4.0 * s + 1.0;
    let d11 = 3.0 * s2 - 2.0 * s;
    let mut sum = 0.0;
    for j in 0..a.len() {
        let v = d00 * (a[j] - b[j]) + c * (d10 * ta[j] + d11 * tb[j]);
        sum += v * v;
    }
    sum.sqrt()
}

/// Five-point Gauss–Legendre nodes and weights on `[0, 1]`.
const GAUSS: [(f64, f64); 5] = [
    (0.046_910_077_030_668, 0.118_463_442_528_094_5),
    (0.230_765_344_947_158_4, 0.239_314_335_249_683_2),
    (0.5, 0.284_444_444_444_444_4),
    (0.769_234_655_052_841_6, 0.239_314_335_249_683_2),
    (0.953_089_922_969_332, 0.118_463_442_528_094_5),
];

/// Arc length of the Hermite segment from parameter 0 to `s`.
fn hermite_arc(a: &[f64], b: &[f64], ta: &[f64], tb: &[f64], c: f64, s: f64) -> f64 {
    s * GAUSS
        .iter()
        .map(|&(x, w)| w * hermite_speed(a, b, ta, tb, c, s * x))
        .sum::<f64>()
}

/// A curve ready for resampling: nodes with tangents, in traversal order, ending at
/// the closing image of the start for a closed loop.
pub(crate) struct Curve {
    pub nodes: Vec<f64>,
    pub tangents: Vec<f64>,
    /// The level set's linearisation at every node (`rows × N` each, the closing image
    /// of a loop its start's) when it keeps them, else empty: the resampled points
    /// start from their interpolation ([`resample`]).
    pub jacobians: Vec<f64>,
    pub closed: bool,
}

/// Points of the polyline a curve is checked on for doubling back ([`doubled_back`]).
const DOUBLING_POINTS: usize = 200;
/// Pairs of points closer than this many of their spacings pair up (see [`doubled_back`]).
const DOUBLING_REACH: f64 = 1.5;
/// ... when their chords are parallel or antiparallel to within this cosine.
const DOUBLING_COSINE: f64 = 0.8;

/// The fraction of a curve that runs over another part of itself (see the module docs
/// of [`super`], "Noisy sensors"): the polyline through its nodes is cut into
/// [`DOUBLING_POINTS`] points equally spaced in arc length `Δ`, and a point doubles
/// when another point at least `DOUBLING_POINTS / 20` points away along the curve
/// (round the loop for a closed curve) lies within [`DOUBLING_REACH`] `Δ` of it (torus
/// distance) with chords parallel or antiparallel (`|cos| ≥` [`DOUBLING_COSINE`]). A
/// simple loop or segment has none (two passes of a smooth curve cross rather than
/// run alongside); a trace that the noisy tangent turned back runs over its own path.
pub(crate) fn doubled_back(space: &MotorSpace, curve: &Curve) -> f64 {
    let n = space.dim();
    let count = curve.nodes.len() / n;
    let node = |i: usize| &curve.nodes[i * n..(i + 1) * n];
    let mut arc = Vec::with_capacity(count);
    arc.push(0.0);
    for i in 1..count {
        arc.push(arc[i - 1] + distance(node(i - 1), node(i)));
    }
    let total = arc.last().copied().unwrap_or(0.0);
    if count < 2 || total <= 0.0 {
        return 0.0;
    }
    let q = DOUBLING_POINTS;
    let spacing = total / q as f64;
    // Points at arc lengths i Δ (unwrapped) and their chords to the next one.
    let mut points = vec![0.0; (q + 1) * n];
    let mut segment = 0;
    for i in 0..=q {
        let s = (i as f64 * spacing).min(total);
        while segment + 2 < count && arc[segment + 1] < s {
            segment += 1;
        }
        let width = arc[segment + 1] - arc[segment];
        let c = if width > 0.0 {
            (s - arc[segment]) / width
        } else {
            0.0
        };
        for (j, p) in points[i * n..(i + 1) * n].iter_mut().enumerate() {
            *p = node(segment)[j] + c * (node(segment + 1)[j] - node(segment)[j]);
        }
    }
    let chord = |i: usize| -> Vec<f64> {
        (0..n)
            .map(|j| points[(i + 1) * n + j] - points[i * n + j])
            .collect()
    };
    let chords: Vec<Vec<f64>> = (0..q).map(chord).collect();
    let window = q / 20;
    let mut doubled = 0;
    for i in 0..q {
        let pi = &points[i * n..(i + 1) * n];
        let pairs = (0..q).any(|k| {
            let apart = i.abs_diff(k);
            let apart = if curve.closed {
                apart.min(q - apart)
            } else {
                apart
            };
            if apart <= window
                || space.distance(pi, &points[k * n..(k + 1) * n]) > DOUBLING_REACH * spacing
            {
                return false;
            }
            let (a, b) = (&chords[i], &chords[k]);
            let cos = a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / (norm(a) * norm(b));
            cos.abs() >= DOUBLING_COSINE
        });
        doubled += usize::from(pairs);
    }
    doubled as f64 / q as f64
}

/// Resamples `curve` to `points` points equally spaced in arc length (a closed loop
/// gets `points` points without repeating the start; an open curve includes both
/// ends), each projected back onto the level set. Between nodes the curve is the cubic
/// Hermite segment through them with their tangents; a segment longer than about
/// `2·10⁻³` has its arc length measured by five-point Gauss–Legendre quadrature of the
/// segment's speed, and a point at a given arc length is found by Newton's method on
/// that integral, so that large adaptive steps give the same points as small fixed ones
/// (shorter segments are taken as straight chords). Returns the points (unwrapped), the
/// curve length and the largest residual.
pub(crate) fn resample(
    set: &mut dyn LevelSet,
    curve: &Curve,
    points: usize,
    max_iterations: usize,
    scratch: &mut Scratch,
) -> Result<(Vec<f64>, f64, f64), SetStatus> {
    let n = set.motor_dim();
    let count = curve.nodes.len() / n;
    let node = |i: usize| &curve.nodes[i * n..(i + 1) * n];
    let tangent = |i: usize| &curve.tangents[i * n..(i + 1) * n];
    // Chord of every segment (0 marks a straight segment) and cumulative arc length.
    let mut chords = std::mem::take(&mut scratch.fine);
    let mut arc = std::mem::take(&mut scratch.arc);
    chords.clear();
    arc.clear();
    arc.push(0.0);
    for i in 0..count.saturating_sub(1) {
        let chord = distance(node(i), node(i + 1));
        let length = if chord > ARC_SPACING {
            hermite_arc(node(i), node(i + 1), tangent(i), tangent(i + 1), chord, 1.0)
        } else {
            chord
        };
        chords.push(if chord > ARC_SPACING { chord } else { 0.0 });
        arc.push(arc[i] + length);
    }
    let length = arc[arc.len() - 1];
    let mut out = Vec::with_capacity(points * n);
    let mut point = vec![0.0; n];
    // The nodes' linearisations, when kept, interpolated linearly to every point.
    let per_node = curve.jacobians.len().checked_div(count).unwrap_or(0);
    let mut jacobian = vec![0.0; per_node];
    let mut max_residual: f64 = 0.0;
    let mut segment = 0;
    let mut status = None;
    for k in 0..points {
        let target = if curve.closed {
            length * k as f64 / points as f64
        } else if points > 1 {
            length * k as f64 / (points - 1) as f64
        } else {
            0.0
        };
        while segment + 2 < arc.len() && arc[segment + 1] < target {
            segment += 1;
        }
        let mut at = 0.0;
        if count < 2 {
            point.copy_from_slice(node(0));
        } else {
            let (a, b) = (node(segment), node(segment + 1));
            let span = arc[segment + 1] - arc[segment];
            let local = (target - arc[segment]).clamp(0.0, span);
            let mut s = if span > 0.0 { local / span } else { 0.0 };
            let chord = chords[segment];
            if chord > 0.0 {
                let (ta, tb) = (tangent(segment), tangent(segment + 1));
                for _ in 0..3 {
                    let speed = hermite_speed(a, b, ta, tb, chord, s);
                    if speed <= 0.0 {
                        break;
                    }
                    s = (s - (hermite_arc(a, b, ta, tb, chord, s) - local) / speed).clamp(0.0, 1.0);
                }
                hermite(a, b, ta, tb, chord, s, &mut point);
            } else {
                for j in 0..n {
                    point[j] = a[j] + s * (b[j] - a[j]);
                }
            }
            at = s;
        }
        let start_jacobian = if per_node > 0 {
            let from = &curve.jacobians[segment * per_node..(segment + 1) * per_node];
            let to = curve
                .jacobians
                .get((segment + 1) * per_node..(segment + 2) * per_node)
                .unwrap_or(from);
            for ((o, x), y) in jacobian.iter_mut().zip(from).zip(to) {
                *o = x + at * (y - x);
            }
            Some(jacobian.as_slice())
        } else {
            None
        };
        match project_point(set, &mut point, max_iterations, scratch, start_jacobian) {
            Ok(residual) => max_residual = max_residual.max(residual),
            Err(failed) => {
                status = Some(failed);
                break;
            }
        }
        out.extend_from_slice(&point);
    }
    scratch.fine = chords;
    scratch.arc = arc;
    match status {
        Some(status) => Err(status),
        None => Ok((out, length, max_residual)),
    }
}

/// Projects a point of the Hermite curve onto the level set for [`resample`]: from the
/// nodes' linearisations interpolated to the point (`jacobian`, when the level set kept
/// them; its error is `O(h²)` for nodes `h` apart, so the secant corrector's first
/// steps contract by far more than from a secant update carried from the last point),
/// else a secant linearisation from the last reading when the level set keeps one
/// (the corrector's landing point moves along the set by the distance to the set
/// times the angle the Jacobian's row space is off, far below the tolerances), the
/// corrector, and on a failure once more from an exact linearisation. Returns the
/// residual.
fn project_point(
    set: &mut dyn LevelSet,
    point: &mut [f64],
    max_iterations: usize,
    scratch: &mut Scratch,
    jacobian: Option<&[f64]>,
) -> Result<f64, SetStatus> {
    let interpolated = point.to_vec();
    if let Some(jacobian) = jacobian {
        set.set_linearization(Linearization::Secant);
        if set.restart_from(jacobian).is_ok() {
            let corrected = correct(set, point, scratch, max_iterations, Convergence::Measured);
            if let Some(corrected) = corrected {
                set.set_linearization(Linearization::Exact);
                return Ok(corrected.residual);
            }
        }
        point.copy_from_slice(&interpolated);
    }
    let secant = set.set_linearization(Linearization::Secant);
    let attempts: &[Linearization] = if secant {
        &[Linearization::Secant, Linearization::Exact]
    } else {
        &[Linearization::Exact]
    };
    for &linearization in attempts {
        set.set_linearization(linearization);
        point.copy_from_slice(&interpolated);
        if !set.newton() && set.linearize(point, &mut scratch.r).is_err() {
            if linearization == Linearization::Exact {
                return Err(SetStatus::Singular);
            }
            continue;
        }
        if let Some(corrected) = correct(set, point, scratch, max_iterations, Convergence::Measured)
        {
            set.set_linearization(Linearization::Exact);
            return Ok(corrected.residual);
        }
    }
    set.set_linearization(Linearization::Exact);
    Err(SetStatus::CorrectorFailed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A loop of radius 1 in the first two of four hinges, `count` nodes from angle
    /// `from` to `to` (unwrapped).
    fn arc(count: usize, from: f64, to: f64) -> Vec<f64> {
        (0..count)
            .flat_map(|i| {
                let a = from + (to - from) * i as f64 / (count - 1) as f64;
                [a.cos(), a.sin(), 0.3, -0.2]
            })
            .collect()
    }

    fn curve(nodes: Vec<f64>, closed: bool) -> Curve {
        let tangents = vec![0.0; nodes.len()];
        Curve {
            nodes,
            tangents,
            jacobians: Vec::new(),
            closed,
        }
    }

    #[test]
    fn a_simple_loop_does_not_double_back_and_a_retraced_one_does() {
        let space = MotorSpace::hinges(4);
        let tau = std::f64::consts::TAU;
        let simple = curve(arc(400, 0.0, tau), true);
        assert_eq!(doubled_back(&space, &simple), 0.0);
        // Out along a third of the loop and back again, then "closed" at the start.
        let mut there_and_back = arc(200, 0.0, tau / 3.0);
        there_and_back.extend(arc(200, tau / 3.0, 0.0));
        let retraced = curve(there_and_back, true);
        assert!(doubled_back(&space, &retraced) > 0.8);
        // Round twice (a loop that missed its closure once) runs alongside itself too.
        let twice = curve(arc(800, 0.0, 2.0 * tau), true);
        assert!(doubled_back(&space, &twice) > 0.8);
        // An open segment, and a loop that nearly touches itself at one place.
        let segment = curve(arc(100, 0.0, 2.0), false);
        assert_eq!(doubled_back(&space, &segment), 0.0);
        // A peanut whose waist brings two parallel stretches 0.2 apart (10 spacings).
        let mut waist: Vec<f64> = arc(400, 0.0, tau);
        for p in waist.chunks_exact_mut(4) {
            let r = 0.1 + p[0] * p[0];
            p[0] *= r;
            p[1] *= r;
        }
        assert_eq!(doubled_back(&space, &curve(waist, true)), 0.0);
    }
}
