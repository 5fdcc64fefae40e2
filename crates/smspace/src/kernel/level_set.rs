//! The two level sets the tracer follows: the observer's pose (`kinematic`) and the
//! agent's own sensor values (`sensory`). Each gives, at a motor configuration `m`, a
//! residual `F(m) − F(m⁰)`, a local linearisation `J = ∂F/∂m` (which
//! [`tangent_space`](super::tangent_space) decomposes for a null-space basis of any
//! dimension), the unit null vector of `J` (the tangent of a 1-D set) and the
//! minimum-norm correction `Δ` with `J Δ = r`.

use nalgebra::{DMatrix, SymmetricEigen};
use ndarray::{ArrayView2, ArrayViewMut2};

use super::gather::Caller;
use super::{
    JacobianMethod, RowPhase, SensorRowPhases, SetNoise, TraceValidParams, DEFAULT_MAX_STEP,
    EXACT_SENSORY_MAX_STEP,
};
use crate::agent::{wrap_angle, Agent, CoordinateKind, Environment, Observer, PoseSpace};

/// `value > floor`, false for NaN (so a NaN pivot counts as singular).
#[inline]
fn exceeds(value: f64, floor: f64) -> bool {
    value > floor
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// How a level set may linearise ([`LevelSet::set_linearization`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Linearization {
    /// Differences of readings at the point (traced nodes: their tangents are the
    /// Hermite curve's).
    Exact,
    /// A secant update from the last reading when it lies within [`SECANT_REACH`] and
    /// the residual did not grow since the last linearisation; exact otherwise
    /// (projections of seeds, resampled points).
    Secant,
}

/// Longest secant step of a [`Linearization::Secant`] linearisation, radians.
const SECANT_REACH: f64 = 1.0;

/// Secant steps shorter than this are not used to update the Jacobian: the difference
/// of two readings that close is mostly rounding.
const SECANT_MIN_STEP: f64 = 1e-8;

/// With `jacobian = "secant"`, a traced node is accepted at this many times the sensor
/// tolerance: a node only carries the Hermite curve, whose points are projected onto
/// the set to the tolerance itself, and a node off the set by `10³` tolerances
/// (`10⁻⁹` of the sensor scale, about `10⁻⁹` rad) moves a projected point by less
/// than that; the last chord iterations of every node are saved.
const NODE_TOLERANCE_FACTOR: f64 = 1e3;

/// The linearisation lost rank: the set is not a 1-D curve there.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Singular;

/// What the tracer needs from a level set `{ m | F(m) = F(m⁰) }`.
pub(crate) trait LevelSet {
    /// Motor dimension `N`.
    fn motor_dim(&self) -> usize;
    /// Number of residual components.
    fn rows(&self) -> usize;
    /// `r = F(m) − F(m⁰)`.
    fn residual(&mut self, m: &[f64], r: &mut [f64]);
    /// Size of a residual, comparable with [`tolerance`](LevelSet::tolerance).
    fn residual_norm(&self, r: &[f64]) -> f64;
    /// A point is on the set when its residual norm is at most this.
    fn tolerance(&self) -> f64;
    /// The residual norm a traced node is accepted at (the nodes only carry the Hermite
    /// curve the resampled points are projected from): [`tolerance`](LevelSet::tolerance)
    /// unless the level set says otherwise.
    fn node_tolerance(&self) -> f64 {
        self.tolerance()
    }
    /// Linearises `F` at `m` and writes the residual at `m` into `r`.
    fn linearize(&mut self, m: &[f64], r: &mut [f64]) -> Result<(), Singular>;
    /// The unit null vector of the current linearisation, oriented so that
    /// `t · reference ≥ 0`.
    fn null_vector(&self, reference: &[f64], t: &mut [f64]);
    /// The minimum-norm `Δ` with `J Δ = r` (so that `m − Δ` cancels `r` to first order).
    fn correction(&self, r: &[f64], delta: &mut [f64]);
    /// The current linearisation `J` (row-major) and its number of rows.
    fn jacobian(&self) -> (&[f64], usize);
    /// Whether the corrector should re-linearise at every iteration (Newton) rather
    /// than reuse the current linearisation (chord method) while it converges.
    fn newton(&self) -> bool;
    /// A Newton step at most this long ends the corrector between traced nodes
    /// ([`Convergence::NewtonStep`](super::curve::Convergence::NewtonStep)). The
    /// default is `0.1 √tolerance`.
    fn newton_step_tolerance(&self) -> f64 {
        0.1 * self.tolerance().sqrt()
    }
    /// Whether the corrector, once the residual is within the tolerance, still moves
    /// the point by the last correction (readings with noise: the corrected point is
    /// the best estimate; exact readings: the point stays). Default `false`.
    fn final_step(&self) -> bool {
        false
    }
    /// The linearisation at the point the level set was last linearised at (`rows × N`,
    /// row-major), when the tracer is to keep it for every node and restart the
    /// resampled points' projections from it ([`restart_from`](LevelSet::restart_from));
    /// `None` (the default) when the level set does not restart so, or its last
    /// linearisation was singular.
    fn node_jacobian(&self) -> Option<&[f64]> {
        None
    }
    /// Takes `jacobian` (`rows × N`, from [`node_jacobian`](LevelSet::node_jacobian)
    /// values) as the current linearisation, the next reading to be read afresh (no
    /// secant update from the last one); `Err` when it is singular or the level set
    /// does not restart so.
    fn restart_from(&mut self, _jacobian: &[f64]) -> Result<(), Singular> {
        Err(Singular)
    }
    /// The largest adaptive step when `max_step = 0` (automatic): the default
    /// [`DEFAULT_MAX_STEP`].
    fn automatic_max_step(&self) -> f64 {
        DEFAULT_MAX_STEP
    }
    /// The uncertainty of a corrected point's position (radians) that the readings'
    /// noise leaves: corrections below a few of it are noise, and a closure needs a
    /// tolerance above it. 0 for exact readings (the default).
    fn position_noise(&self) -> f64 {
        0.0
    }
    /// The uncertainty of the null direction (radians) that the readings' noise
    /// leaves, added to `max_turn`. 0 for exact readings (the default).
    fn tangent_noise(&self) -> f64 {
        0.0
    }
    /// The noise measured for this level set (`None` for exact readings).
    fn noise(&self) -> Option<SetNoise> {
        None
    }
    /// Whether the level set's function is known at `m` (a law learned from data: near
    /// its samples only).
    fn covers(&self, _m: &[f64]) -> bool {
        true
    }
    /// Motor rows of the agent's sensors read so far for this level set (0 for a level
    /// set that reads none, the kinematic one).
    fn sensor_rows(&self) -> u64 {
        0
    }
    /// The rows of [`sensor_rows`](LevelSet::sensor_rows) by phase (`None` for a level
    /// set that reads no sensor).
    fn sensor_row_phases(&self) -> Option<SensorRowPhases> {
        None
    }
    /// The phase of tracing the next readings are counted in.
    fn set_phase(&mut self, _phase: RowPhase) {}
    /// Whether `m`, where a seed of the piece search landed on the set to within
    /// [`tolerance`](LevelSet::tolerance), is on the set indeed: always for exact
    /// readings; for noisy ones a test of the residual the slope cannot remove.
    fn confirms_piece(&mut self, _m: &[f64]) -> bool {
        true
    }
    /// How the next [`linearize`](LevelSet::linearize) calls may linearise: exactly, or
    /// by a secant update from the last reading when the level set keeps one (the
    /// sensory set with `jacobian = "secant"`; the others always linearise exactly).
    /// Setting it also restarts the secant's watch of the residual. Returns whether
    /// the level set makes secant updates at all.
    fn set_linearization(&mut self, _linearization: Linearization) -> bool {
        false
    }
    /// An orthonormal basis of `k` vectors of the null space of the current
    /// linearisation, written row by row into `basis` (`k × N`). The default
    /// orthonormalises the rows of `J` (Gram–Schmidt), then the coordinate axes
    /// against them, keeping the `k` longest remainders in axis order.
    fn null_basis(&self, k: usize, basis: &mut [f64]) {
        let n = self.motor_dim();
        let (jacobian, rows) = self.jacobian();
        let mut frame: Vec<Vec<f64>> = Vec::with_capacity(n);
        for row in jacobian.chunks_exact(n).take(rows) {
            let mut v = row.to_vec();
            if orthonormalise(&mut v, &frame) {
                frame.push(v);
            }
        }
        let fixed = frame.len();
        let mut axes: Vec<(f64, Vec<f64>)> = (0..n)
            .map(|j| {
                let mut e = vec![0.0; n];
                e[j] = 1.0;
                for f in &frame {
                    let c = dot(&e, f);
                    for (x, y) in e.iter_mut().zip(f) {
                        *x -= c * y;
                    }
                }
                (dot(&e, &e), e)
            })
            .collect();
        // Longest remainders first (stable: ties keep axis order).
        axes.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (_, mut e) in axes {
            if frame.len() == fixed + k {
                break;
            }
            if orthonormalise(&mut e, &frame) {
                frame.push(e);
            }
        }
        for (a, v) in frame[fixed..].iter().enumerate().take(k) {
            basis[a * n..(a + 1) * n].copy_from_slice(v);
        }
    }
}

/// Removes from `v` its components along the orthonormal `frame` (twice, for
/// accuracy) and normalises it; `false` when almost nothing is left.
fn orthonormalise(v: &mut [f64], frame: &[Vec<f64>]) -> bool {
    let before = dot(v, v).sqrt();
    for _ in 0..2 {
        for f in frame {
            let c = dot(v, f);
            for (x, y) in v.iter_mut().zip(f) {
                *x -= c * y;
            }
        }
    }
    let after = dot(v, v).sqrt();
    if !exceeds(after, 1e-8 * before.max(f64::MIN_POSITIVE)) {
        return false;
    }
    for x in v.iter_mut() {
        *x /= after;
    }
    true
}

/// The kinematic level set: the first `C` tangent coordinates of the observer's pose
/// (the paper's method, appendix A, where `J` is the pose Jacobian). `J` is `C × N`
/// (`C = N − 1` for curves); with `G = J Jᵀ` (Cholesky), the tangent is the projection
/// `t ∝ (I − Jᵀ G⁻¹ J) t_prev`, which keeps the sign continuous, and the correction is
/// `Δ = Jᵀ G⁻¹ r`.
pub(crate) struct Kinematic<'a> {
    observer: &'a dyn Observer,
    space: PoseSpace,
    n: usize,
    c: usize,
    target: Vec<f64>,
    tolerance: f64,
    /// The pose Jacobian, `T × N` (all tangent rows; the first `C` are constrained).
    jacobian: Vec<f64>,
    /// Cholesky factor of `G` for `C ≤ 3`, row-major with stride 3.
    cholesky: [f64; 9],
    /// Cholesky factor of `G` for `C > 3`, `C × C` row-major.
    cholesky_any: Vec<f64>,
    /// Whether the pose is the planar `(x, y, alpha)` (differences without the
    /// general [`PoseSpace::difference`]).
    planar: bool,
    pose: Vec<f64>,
    difference: Vec<f64>,
}

/// The relative precision the kinematic corrector asks of a pose: its residual is
/// accepted below `pose_tolerance` or this fraction of the pose's largest linear
/// coordinate, whichever is larger (for the paper's arm, whose poses are within a few
/// units of the origin, `pose_tolerance` alone).
pub(crate) const POSE_RESOLUTION: f64 = 1e-12;

impl<'a> Kinematic<'a> {
    /// The level set of the pose at `start`, a residual accepted up to `tolerance`, or
    /// up to [`POSE_RESOLUTION`] times the largest linear coordinate of the start's pose
    /// when that is larger (the precision of a pose far from the origin: an arm of
    /// links `10⁶` long cannot meet `10⁻¹¹`).
    pub(crate) fn new(observer: &'a dyn Observer, start: &[f64], tolerance: f64) -> Self {
        let n = start.len();
        let space = observer.pose_space();
        let c = observer.configuration_dim();
        let mut target = vec![0.0; space.dim()];
        observer.pose(start, &mut target);
        let scale = space
            .coordinates()
            .iter()
            .zip(&target)
            .filter(|(coordinate, _)| coordinate.kind == CoordinateKind::Linear)
            .fold(0.0_f64, |largest, (_, v)| largest.max(v.abs()));
        let tolerance = if scale.is_finite() {
            tolerance.max(POSE_RESOLUTION * scale)
        } else {
            tolerance
        };
        Self {
            observer,
            n,
            c,
            jacobian: vec![0.0; space.tangent_dim() * n],
            cholesky: [0.0; 9],
            cholesky_any: vec![0.0; if c > 3 { c * c } else { 0 }],
            planar: space.is_planar(),
            pose: vec![0.0; space.dim()],
            difference: vec![0.0; space.tangent_dim()],
            target,
            space,
            tolerance,
        }
    }

    /// `r = pose − target` in the first `C` tangent coordinates, for the pose in
    /// `self.pose` (straight-line for the planar pose, the arm's case).
    #[inline]
    fn pose_residual(&mut self, r: &mut [f64]) {
        if self.planar {
            let (p, t) = (&self.pose, &self.target);
            let d = [p[0] - t[0], p[1] - t[1], wrap_angle(p[2] - t[2])];
            r[..self.c].copy_from_slice(&d[..self.c]);
        } else {
            self.space
                .difference(&self.pose, &self.target, &mut self.difference);
            r[..self.c].copy_from_slice(&self.difference[..self.c]);
        }
    }

    /// Gram matrix `G = J Jᵀ` and its Cholesky factor, for `C` constraint rows.
    fn factor<const C: usize>(&mut self) -> Result<(), Singular> {
        let n = self.n;
        let mut gram = [[0.0; C]; C];
        for a in 0..C {
            for b in 0..=a {
                let ra = &self.jacobian[a * n..(a + 1) * n];
                let rb = &self.jacobian[b * n..(b + 1) * n];
                gram[a][b] = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
            }
        }
        let trace: f64 = (0..C).map(|a| gram[a][a]).sum();
        let l = &mut self.cholesky;
        for i in 0..C {
            for j in 0..=i {
                let mut s = gram[i][j];
                for k in 0..j {
                    s -= l[i * 3 + k] * l[j * 3 + k];
                }
                if i == j {
                    if !exceeds(s, 1e-14 * trace) {
                        return Err(Singular);
                    }
                    l[i * 3 + i] = s.sqrt();
                } else {
                    l[i * 3 + j] = s / l[j * 3 + j];
                }
            }
        }
        Ok(())
    }

    /// [`factor`](Self::factor) for any number `c` of rows (agents beyond the paper's:
    /// more than three pose coordinates held fixed).
    #[inline(never)]
    fn factor_any(&mut self) -> Result<(), Singular> {
        let (n, c) = (self.n, self.c);
        let mut gram = vec![0.0; c * c];
        for a in 0..c {
            for b in 0..=a {
                let ra = &self.jacobian[a * n..(a + 1) * n];
                let rb = &self.jacobian[b * n..(b + 1) * n];
                gram[a * c + b] = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
            }
        }
        let trace: f64 = (0..c).map(|a| gram[a * c + a]).sum();
        let l = &mut self.cholesky_any;
        for i in 0..c {
            for j in 0..=i {
                let mut s = gram[i * c + j];
                for k in 0..j {
                    s -= l[i * c + k] * l[j * c + k];
                }
                if i == j {
                    if !exceeds(s, 1e-14 * trace) {
                        return Err(Singular);
                    }
                    l[i * c + i] = s.sqrt();
                } else {
                    l[i * c + j] = s / l[j * c + j];
                }
            }
        }
        Ok(())
    }

    /// [`row_space`](Self::row_space) for any number of rows (kept out of line: the
    /// arm's three rows take [`row_space_3`](Self::row_space_3)).
    #[inline(never)]
    fn row_space_any(&self, v: &[f64], apply_first: bool, out: &mut [f64]) {
        let (n, c) = (self.n, self.c);
        let mut y: Vec<f64> = (0..c)
            .map(|a| {
                if apply_first {
                    dot(&self.jacobian[a * n..(a + 1) * n], v)
                } else {
                    v[a]
                }
            })
            .collect();
        let l = &self.cholesky_any;
        for i in 0..c {
            let mut s = y[i];
            for k in 0..i {
                s -= l[i * c + k] * y[k];
            }
            y[i] = s / l[i * c + i];
        }
        for i in (0..c).rev() {
            let mut s = y[i];
            for k in i + 1..c {
                s -= l[k * c + i] * y[k];
            }
            y[i] = s / l[i * c + i];
        }
        for (j, o) in out.iter_mut().enumerate() {
            *o = (0..c).map(|a| self.jacobian[a * n + j] * y[a]).sum();
        }
    }

    #[inline]
    /// `out = Jᵀ G⁻¹ J v` (the projection of `v` onto the row space of `J`) when
    /// `apply_first`, else `out = Jᵀ G⁻¹ v` for `v` of length `C`.
    fn row_space<const C: usize>(&self, v: &[f64], apply_first: bool, out: &mut [f64]) {
        let n = self.n;
        let mut y = [0.0; C];
        for a in 0..C {
            y[a] = if apply_first {
                let row = &self.jacobian[a * n..(a + 1) * n];
                row.iter().zip(v).map(|(j, x)| j * x).sum()
            } else {
                v[a]
            };
        }
        let l = &self.cholesky;
        for i in 0..C {
            let mut s = y[i];
            for k in 0..i {
                s -= l[i * 3 + k] * y[k];
            }
            y[i] = s / l[i * 3 + i];
        }
        for i in (0..C).rev() {
            let mut s = y[i];
            for k in i + 1..C {
                s -= l[k * 3 + i] * y[k];
            }
            y[i] = s / l[i * 3 + i];
        }
        for (j, o) in out.iter_mut().enumerate() {
            *o = (0..C).map(|a| self.jacobian[a * n + j] * y[a]).sum();
        }
    }

    #[inline]
    fn project_row_space(&self, v: &[f64], apply_first: bool, out: &mut [f64]) {
        match self.c {
            1 => self.row_space::<1>(v, apply_first, out),
            2 => self.row_space::<2>(v, apply_first, out),
            3 => self.row_space_3(v, apply_first, out),
            _ => self.row_space_any(v, apply_first, out),
        }
    }

    /// Straight-line [`row_space`](Self::row_space) for three rows (the arm's case).
    #[inline]
    fn row_space_3(&self, v: &[f64], apply_first: bool, out: &mut [f64]) {
        let n = self.n;
        let (r0, rest) = self.jacobian.split_at(n);
        let (r1, r2) = rest.split_at(n);
        let r2 = &r2[..n];
        let (v0, v1, v2) = if apply_first {
            (dot(r0, v), dot(r1, v), dot(r2, v))
        } else {
            (v[0], v[1], v[2])
        };
        let l = &self.cholesky;
        let (l00, l10, l11, l20, l21, l22) = (l[0], l[3], l[4], l[6], l[7], l[8]);
        let y0 = v0 / l00;
        let y1 = (v1 - l10 * y0) / l11;
        let y2 = (v2 - l20 * y0 - l21 * y1) / l22;
        let z2 = y2 / l22;
        let z1 = (y1 - l21 * z2) / l11;
        let z0 = (y0 - l10 * z1 - l20 * z2) / l00;
        for (((o, a), b), c) in out.iter_mut().zip(r0).zip(r1).zip(r2) {
            *o = a * z0 + b * z1 + c * z2;
        }
    }

    /// Straight-line [`factor`](Self::factor) for three rows.
    #[inline]
    fn factor_3(&mut self) -> Result<(), Singular> {
        let n = self.n;
        let (r0, rest) = self.jacobian.split_at(n);
        let (r1, r2) = rest.split_at(n);
        let r2 = &r2[..n];
        let (g00, g10, g11) = (dot(r0, r0), dot(r1, r0), dot(r1, r1));
        let (g20, g21, g22) = (dot(r2, r0), dot(r2, r1), dot(r2, r2));
        let floor = 1e-14 * (g00 + g11 + g22);
        if !exceeds(g00, floor) {
            return Err(Singular);
        }
        let l00 = g00.sqrt();
        let l10 = g10 / l00;
        let l20 = g20 / l00;
        let d1 = g11 - l10 * l10;
        if !exceeds(d1, floor) {
            return Err(Singular);
        }
        let l11 = d1.sqrt();
        let l21 = (g21 - l20 * l10) / l11;
        let d2 = g22 - l20 * l20 - l21 * l21;
        if !exceeds(d2, floor) {
            return Err(Singular);
        }
        let l22 = d2.sqrt();
        self.cholesky = [l00, 0.0, 0.0, l10, l11, 0.0, l20, l21, l22];
        Ok(())
    }
}

impl LevelSet for Kinematic<'_> {
    fn motor_dim(&self) -> usize {
        self.n
    }

    fn rows(&self) -> usize {
        self.c
    }

    fn residual(&mut self, m: &[f64], r: &mut [f64]) {
        self.observer.pose(m, &mut self.pose);
        self.pose_residual(r);
    }

    fn residual_norm(&self, r: &[f64]) -> f64 {
        r.iter().fold(0.0, |acc: f64, v| acc.max(v.abs()))
    }

    fn tolerance(&self) -> f64 {
        self.tolerance
    }

    fn linearize(&mut self, m: &[f64], r: &mut [f64]) -> Result<(), Singular> {
        self.observer
            .pose_jacobian(m, &mut self.jacobian, &mut self.pose);
        self.pose_residual(r);
        match self.c {
            1 => self.factor::<1>(),
            2 => self.factor::<2>(),
            3 => self.factor_3(),
            _ => self.factor_any(),
        }
    }

    fn null_vector(&self, reference: &[f64], t: &mut [f64]) {
        let project = |v: &[f64], t: &mut [f64]| {
            self.project_row_space(v, true, t);
            for (tj, vj) in t.iter_mut().zip(v) {
                *tj = vj - *tj;
            }
            t.iter().map(|x| x * x).sum::<f64>().sqrt()
        };
        let reference_norm = reference.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut norm = project(reference, t);
        if norm < 1e-6 * reference_norm {
            // The reference is (nearly) orthogonal to the null space: project the
            // coordinate axis that keeps most of its length instead.
            let mut best = (0.0, 0);
            let mut e = vec![0.0; self.n];
            for k in 0..self.n {
                e.fill(0.0);
                e[k] = 1.0;
                let len = project(&e, t);
                if len > best.0 {
                    best = (len, k);
                }
            }
            e.fill(0.0);
            e[best.1] = 1.0;
            norm = project(&e, t);
        }
        let sign = if t.iter().zip(reference).map(|(a, b)| a * b).sum::<f64>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        for x in t.iter_mut() {
            *x *= sign / norm;
        }
    }

    fn correction(&self, r: &[f64], delta: &mut [f64]) {
        self.project_row_space(r, false, delta);
    }

    fn jacobian(&self) -> (&[f64], usize) {
        (&self.jacobian[..self.c * self.n], self.c)
    }

    fn newton(&self) -> bool {
        true
    }
}

/// The sensory level set `{ m | σ_E(m) = σ_E(m⁰) }`, from what the agent measures
/// alone: `J = ∂s/∂m` by central differences of sensor readings (`2N` readings, asked
/// for with the residual's in one [`Agent::sense_batch`] call; or the agent's own, when
/// [`Agent::sense_with_jacobian`] gives it, as a learned law does), the
/// eigen-decomposition `Jᵀ J = V Λ Vᵀ` (ascending `λ`), the tangent `t = v₀`, and the
/// correction `Δ = Σ_{e≥d} v_e (v_eᵀ Jᵀ r) / λ_e` (Gauss–Newton on `‖s(m) − s⁰‖²`
/// restricted to the rank `N − d` part, `d` the kernel dimension, 1 for curves). The
/// set has dimension `d` only where `λ_d`, the smallest eigenvalue that should be
/// nonzero, is not negligible: `√(λ_d/λ_max)` below the rank tolerance means the
/// sensors cannot tell some pose change apart (too few lights in view) and the set is
/// reported as singular instead of traced.
///
/// For a law fitted to data (an agent that gives its [`Agent::sensory_rank`]), the
/// values do not lie exactly on an image of rank `N − d`, so `s(m) = s⁰` has isolated
/// solutions only. The level set is then that of the projected law
///
/// ```text
/// g(m) = U₀ᵀ (s(m) − s⁰) = 0,    U₀ = J(m⁰) v_e / √λ_e,  e = d … N − 1,
/// ```
///
/// with `U₀` (`K × (N − d)`, orthonormal) the range of the Jacobian **at the start**,
/// held for the whole set: the true law factors through the sensor's configuration
/// (`s = F(pose(m))`), so along its kernel `s(m) = s⁰` and the range of `J` is the
/// tangent space of the sensory manifold at `s⁰`, the same at every point of the set.
/// `g` maps `N` motors to `N − d` values, so its level set through `m⁰` is a
/// `d`-dimensional manifold of a fixed map, which closes (or ends on a bound) as the
/// true set does; a range re-read at every point, `U(m)`, gives a path that is no level
/// set of any map. The residual is `g` (in sensor units, relative to the same scale)
/// and the Jacobian `U₀ᵀ J(m)`. When `J(m⁰)` itself is singular, the range at the
/// current point is used instead: `‖U(m)ᵀ r‖ = √(Σ_{e≥d} (v_eᵀ Jᵀ r)² / λ_e)`.
///
/// Every reading goes to the agent directly, or through a [`Caller`] of a gathered
/// round when the agent asks for [`crate::agent::Calling::Gathered`].
pub(crate) struct Sensory<'a> {
    sensor: Sensor<'a>,
    n: usize,
    k: usize,
    target: Vec<f64>,
    scale: f64,
    tolerance: f64,
    step: f64,
    rank_tolerance: f64,
    /// The kernel dimension `d`: the null space is spanned by the first `d`
    /// eigenvectors.
    dimension: usize,
    /// Whether the residual is measured in the Jacobian's range (a fitted law).
    projected: bool,
    /// For a fitted law: `U₀` (`K × (N − d)`, row-major), the range of the Jacobian at
    /// the start, held for the set (see the type's docs); `None` otherwise, or when the
    /// Jacobian at the start is singular.
    held: Option<Vec<f64>>,
    /// With `held`: `U₀ᵀ J` (`(N − d) × N`), the Jacobian of the projected law.
    held_jacobian: Vec<f64>,
    /// With `held`: the full readings minus the target (`K`).
    full_residual: Vec<f64>,
    jacobian: Vec<f64>,
    eigenvalues: Vec<f64>,
    eigenvectors: Vec<f64>,
    /// The `2N + 1` motor rows of one linearisation: `m`, then `m ± h e_j` for each `j`
    /// (row-major, `(2N + 1) × N`), sensed in one [`Agent::sense_batch`] call.
    probes: Vec<f64>,
    /// Their sensor readings, `(2N + 1) × K`.
    readings: Vec<f64>,
    /// With `jacobian = "secant"` (and a simulated law): the secant state.
    secant: Option<SecantState>,
}

/// What the secant Jacobian keeps (see [`Sensory`]).
struct SecantState {
    linearization: Linearization,
    /// The last reading: its motor row and residual `s(m) − s⁰` (`K`).
    last_m: Vec<f64>,
    last_r: Vec<f64>,
    has_last: bool,
    /// The residual norm at the last linearisation (the watch of
    /// [`Linearization::Secant`]; infinite after a restart).
    linearized_norm: f64,
    /// The last exact linearisation: its motor row, residual, Jacobian and
    /// eigen-decomposition, restored when the tracer linearises there again.
    node_m: Vec<f64>,
    node_r: Vec<f64>,
    node_jacobian: Vec<f64>,
    node_eigenvalues: Vec<f64>,
    node_eigenvectors: Vec<f64>,
    node_singular: bool,
    has_node: bool,
}

impl<'a> Sensory<'a> {
    /// The level set through `start` for kernels of dimension `dimension` (at least 1),
    /// with the sensory tolerances of `params`.
    /// Readings go through `caller` when given.
    pub(crate) fn new(
        agent: &'a dyn Agent,
        environment: &'a Environment,
        caller: Option<&'a Caller<'a>>,
        start: &[f64],
        params: &TraceValidParams,
        dimension: usize,
    ) -> Self {
        let mut sensor = Sensor::new(agent, environment, caller);
        let mut target = vec![0.0; agent.sensor_dim()];
        sensor.sense(start, &mut target);
        Self::with_target(sensor, target, start, params, dimension)
    }

    /// [`new`](Self::new) with the start's reading `target` already taken through
    /// `sensor` (which counts it).
    pub(crate) fn with_target(
        sensor: Sensor<'a>,
        target: Vec<f64>,
        start: &[f64],
        params: &TraceValidParams,
        dimension: usize,
    ) -> Self {
        let agent = sensor.agent;
        let (n, k) = (agent.motor_dim(), agent.sensor_dim());
        let scale = target.iter().fold(0.0, |a: f64, v| a.max(v.abs()));
        let mut set = Self {
            sensor,
            n,
            k,
            target,
            scale: if scale > 0.0 { scale } else { 1.0 },
            tolerance: params.sensor_tolerance,
            step: params.finite_difference_step,
            rank_tolerance: params.rank_tolerance,
            dimension,
            projected: agent.sensory_rank().is_some(),
            held: None,
            held_jacobian: Vec::new(),
            full_residual: vec![0.0; k],
            jacobian: vec![0.0; k * n],
            eigenvalues: vec![0.0; n],
            eigenvectors: vec![0.0; n * n],
            probes: vec![0.0; (2 * n + 1) * n],
            readings: vec![0.0; (2 * n + 1) * k],
            secant: None,
        };
        if set.projected && dimension < n {
            set.hold_range(start);
        }
        if params.jacobian == JacobianMethod::Secant && !set.projected {
            // The start's reading is the first one the secant keeps.
            let last_r = vec![0.0; k];
            set.secant = Some(SecantState {
                linearization: Linearization::Exact,
                last_m: start.to_vec(),
                last_r,
                has_last: true,
                linearized_norm: f64::INFINITY,
                node_m: vec![0.0; n],
                node_r: vec![0.0; k],
                node_jacobian: vec![0.0; k * n],
                node_eigenvalues: vec![0.0; n],
                node_eigenvectors: vec![0.0; n * n],
                node_singular: false,
                has_node: false,
            });
        }
        set
    }

    /// Secant mode: the residual at `m` into `r`, from the last reading when it was at
    /// `m` (no row), else read (one row) and used for a Broyden update of the Jacobian,
    /// `J ← J + (Δr − J Δm) Δmᵀ / |Δm|²` with `Δm`, `Δr` the steps from the last
    /// reading (when `SECANT_MIN_STEP ≤ |Δm| ≤ SECANT_REACH`), after which the
    /// eigen-decomposition is redone. Returns whether the Jacobian was updated.
    fn secant_residual(&mut self, m: &[f64], r: &mut [f64]) -> bool {
        let state = self.secant.as_mut().expect("secant mode");
        if state.has_last && state.last_m == m {
            r.copy_from_slice(&state.last_r);
            return false;
        }
        self.sensor.sense(m, r);
        for (ri, t) in r.iter_mut().zip(&self.target) {
            *ri -= t;
        }
        let state = self.secant.as_mut().expect("secant mode");
        let (n, k) = (self.n, self.k);
        let mut updated = false;
        if state.has_last {
            let dm: Vec<f64> = m.iter().zip(&state.last_m).map(|(a, b)| a - b).collect();
            let dm2 = dot(&dm, &dm);
            if dm2.sqrt() >= SECANT_MIN_STEP && dm2.sqrt() <= SECANT_REACH {
                for i in 0..k {
                    let row = &mut self.jacobian[i * n..(i + 1) * n];
                    let error = (r[i] - state.last_r[i]) - dot(row, &dm);
                    for (jij, d) in row.iter_mut().zip(&dm) {
                        *jij += error * d / dm2;
                    }
                }
                updated = true;
            }
        }
        state.last_m.copy_from_slice(m);
        state.last_r.copy_from_slice(r);
        state.has_last = true;
        if updated {
            // The decomposition follows the update; a loss of rank shows at the next
            // linearisation.
            let _ = self.decompose();
        }
        updated
    }

    /// Secant mode: linearises at `m` (see [`Linearization`]): the node's own
    /// linearisation when `m` is the last exact one's point; a secant update when
    /// allowed, `m` is a new point within reach of the last reading, the residual is
    /// smaller than at the last linearisation and the rank holds; else one-sided
    /// differences `(s(m + h e_j) − s(m)) / h` (`N` rows, the reading at `m` reused
    /// when it is the last one).
    fn secant_linearize(&mut self, m: &[f64], r: &mut [f64]) -> Result<(), Singular> {
        let state = self.secant.as_mut().expect("secant mode");
        if state.has_node && state.node_m == m {
            r.copy_from_slice(&state.node_r);
            self.jacobian.copy_from_slice(&state.node_jacobian);
            self.eigenvalues.copy_from_slice(&state.node_eigenvalues);
            self.eigenvectors.copy_from_slice(&state.node_eigenvectors);
            let singular = state.node_singular;
            state.last_m.copy_from_slice(m);
            state.last_r.copy_from_slice(r);
            state.has_last = true;
            return if singular { Err(Singular) } else { Ok(()) };
        }
        // A secant step needs a new reading: at the last reading's own point (a stalled
        // corrector asking again), linearise exactly.
        let near = state.has_last
            && state.last_m != m
            && state
                .last_m
                .iter()
                .zip(m)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt()
                <= SECANT_REACH;
        if state.linearization == Linearization::Secant && near {
            let previous = state.linearized_norm;
            self.secant_residual(m, r);
            let norm = self.residual_norm(r);
            if norm < previous && self.decompose().is_ok() {
                self.secant.as_mut().expect("secant mode").linearized_norm = norm;
                return Ok(());
            }
        }
        self.forward_jacobian(m, r);
        let result = self.decompose();
        let norm = self.residual_norm(r);
        let state = self.secant.as_mut().expect("secant mode");
        state.linearized_norm = norm;
        state.node_m.copy_from_slice(m);
        state.node_r.copy_from_slice(r);
        state.node_jacobian.copy_from_slice(&self.jacobian);
        state.node_eigenvalues.copy_from_slice(&self.eigenvalues);
        state.node_eigenvectors.copy_from_slice(&self.eigenvectors);
        state.node_singular = result.is_err();
        state.has_node = true;
        result
    }

    /// The residual at `m` (reused when it is the last reading) and `J` by one-sided
    /// differences, the `N` shifted rows in one batch.
    fn forward_jacobian(&mut self, m: &[f64], r: &mut [f64]) {
        self.secant_residual(m, r);
        let (n, k, h) = (self.n, self.k, self.step);
        let probes = &mut self.probes[..n * n];
        for (j, probe) in probes.chunks_exact_mut(n).enumerate() {
            probe.copy_from_slice(m);
            probe[j] = m[j] + h;
        }
        let probes = ArrayView2::from_shape((n, n), &self.probes[..n * n]).expect("N × N probes");
        let readings =
            ArrayViewMut2::from_shape((n, k), &mut self.readings[..n * k]).expect("N × K readings");
        self.sensor.sense_batch(probes, readings);
        for j in 0..n {
            let shifted = &self.readings[j * k..(j + 1) * k];
            for i in 0..k {
                self.jacobian[i * n + j] = (shifted[i] - self.target[i] - r[i]) / h;
            }
        }
    }

    /// `U₀`: the range of the Jacobian at `start` (see the type's docs), unless it is
    /// singular there.
    fn hold_range(&mut self, start: &[f64]) {
        let mut r = vec![0.0; self.k];
        self.read_full(start, &mut r);
        if self.decompose().is_err() {
            return;
        }
        let (n, k, d) = (self.n, self.k, self.dimension);
        let columns = n - d;
        let mut basis = vec![0.0; k * columns];
        for (c, e) in (d..n).enumerate() {
            let v = &self.eigenvectors[e * n..(e + 1) * n];
            let norm = self.eigenvalues[e].sqrt();
            for i in 0..k {
                let jv: f64 = (0..n).map(|j| self.jacobian[i * n + j] * v[j]).sum();
                basis[i * columns + c] = jv / norm;
            }
        }
        self.held_jacobian = vec![0.0; columns * n];
        self.held = Some(basis);
    }

    /// The residual `s(m) − s⁰` into `r` (`K`) and the full Jacobian `J(m)`.
    fn read_full(&mut self, m: &[f64], r: &mut [f64]) {
        let k = self.k;
        if self
            .sensor
            .sense_with_jacobian(m, &mut self.readings[..k], &mut self.jacobian)
        {
            for ((ri, s), t) in r.iter_mut().zip(&self.readings[..k]).zip(&self.target) {
                *ri = s - t;
            }
        } else {
            self.difference_jacobian(m, r);
        }
    }

    /// The Jacobian the level set is read with and its rows: `U₀ᵀ J` with a held
    /// range, else `J`.
    fn active(&self) -> (&[f64], usize) {
        match &self.held {
            Some(_) => (&self.held_jacobian, self.n - self.dimension),
            None => (&self.jacobian, self.k),
        }
    }

    /// `out = U₀ᵀ x` for `x` of `K` values (`basis` is `K × columns`).
    fn project(basis: &[f64], columns: usize, x: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for (i, xi) in x.iter().enumerate() {
            for (c, o) in out.iter_mut().enumerate() {
                *o += basis[i * columns + c] * xi;
            }
        }
    }

    /// The residual and `J` by central differences: one batch of the `2N + 1`
    /// readings (the residual's and the differences'), so that an agent simulated
    /// elsewhere is called once per linearisation.
    fn difference_jacobian(&mut self, m: &[f64], r: &mut [f64]) {
        let (n, k, h) = (self.n, self.k, self.step);
        for (row, probe) in self.probes.chunks_exact_mut(n).enumerate() {
            probe.copy_from_slice(m);
            if row > 0 {
                let j = (row - 1) / 2;
                probe[j] = if row % 2 == 1 { m[j] + h } else { m[j] - h };
            }
        }
        let rows = 2 * n + 1;
        let probes = ArrayView2::from_shape((rows, n), &self.probes).expect("(2N + 1) × N probes");
        let readings = ArrayViewMut2::from_shape((rows, k), &mut self.readings)
            .expect("(2N + 1) × K readings");
        self.sensor.sense_batch(probes, readings);
        for ((ri, s), t) in r.iter_mut().zip(&self.readings[..k]).zip(&self.target) {
            *ri = s - t;
        }
        for j in 0..n {
            let plus = &self.readings[(2 * j + 1) * k..(2 * j + 2) * k];
            let minus = &self.readings[(2 * j + 2) * k..(2 * j + 3) * k];
            for i in 0..k {
                self.jacobian[i * n + j] = (plus[i] - minus[i]) / (2.0 * h);
            }
        }
    }

    /// The eigen-decomposition of `JᵀJ` (ascending), singular when the smallest
    /// eigenvalue that should be nonzero is negligible.
    fn decompose(&mut self) -> Result<(), Singular> {
        let (n, dimension, rank_tolerance) = (self.n, self.dimension, self.rank_tolerance);
        let (jacobian, k) = match &self.held {
            Some(_) => (&self.held_jacobian, self.n - self.dimension),
            None => (&self.jacobian, self.k),
        };
        let decomposition = Decomposition {
            eigenvalues: &mut self.eigenvalues,
            eigenvectors: &mut self.eigenvectors,
        };
        decomposition.of(jacobian, k, n, dimension, rank_tolerance)
    }
}

/// The null vector `v₀` (the eigenvector of `JᵀJ` with the smallest eigenvalue) into
/// `t`, oriented along `reference` (`t · reference ≥ 0`).
pub(crate) fn oriented_null_vector(v0: &[f64], reference: &[f64], t: &mut [f64]) {
    let dot: f64 = v0.iter().zip(reference).map(|(a, b)| a * b).sum();
    let sign = if dot < 0.0 { -1.0 } else { 1.0 };
    for (tj, v) in t.iter_mut().zip(v0) {
        *tj = sign * v;
    }
}

/// An eigen-decomposition of `JᵀJ` (ascending, eigenvectors row by row), read: the
/// first `dimension` eigenvectors span the null space, the others the row space.
pub(crate) struct Decomposed<'b> {
    pub(crate) eigenvalues: &'b [f64],
    pub(crate) eigenvectors: &'b [f64],
    pub(crate) dimension: usize,
}

impl Decomposed<'_> {
    /// The minimum-norm step `δ = J⁺ r = Σ_{e ≥ dimension} v_e (v_eᵀ Jᵀ r) / λ_e` into
    /// `delta` (`N` values), `J` of `k` rows (row-major).
    pub(crate) fn minimum_norm_step(
        &self,
        jacobian: &[f64],
        k: usize,
        r: &[f64],
        delta: &mut [f64],
    ) {
        let n = delta.len();
        let mut g = vec![0.0; n];
        for (j, gj) in g.iter_mut().enumerate() {
            *gj = (0..k).map(|i| jacobian[i * n + j] * r[i]).sum();
        }
        delta.fill(0.0);
        for e in self.dimension..n {
            let v = &self.eigenvectors[e * n..(e + 1) * n];
            let coefficient =
                v.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>() / self.eigenvalues[e];
            for (d, vj) in delta.iter_mut().zip(v) {
                *d += coefficient * vj;
            }
        }
    }
}

/// The eigen-decomposition of `JᵀJ` a sensory level set keeps: eigenvalues increasing,
/// eigenvectors row by row (`N × N`).
pub(crate) struct Decomposition<'b> {
    pub(crate) eigenvalues: &'b mut [f64],
    pub(crate) eigenvectors: &'b mut [f64],
}

impl Decomposition<'_> {
    /// Decomposes `JᵀJ` for `J` of `k` rows and `n` columns (row-major); fails when
    /// `σ_{n−dimension}/σ_max` is at most `rank_tolerance` (or not a number).
    pub(crate) fn of(
        self,
        jacobian: &[f64],
        k: usize,
        n: usize,
        dimension: usize,
        rank_tolerance: f64,
    ) -> Result<(), Singular> {
        let mut gram = DMatrix::<f64>::zeros(n, n);
        for a in 0..n {
            for b in 0..=a {
                let s: f64 = (0..k)
                    .map(|i| jacobian[i * n + a] * jacobian[i * n + b])
                    .sum();
                gram[(a, b)] = s;
                gram[(b, a)] = s;
            }
        }
        let eigen = SymmetricEigen::new(gram);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        for (dst, &src) in order.iter().enumerate() {
            self.eigenvalues[dst] = eigen.eigenvalues[src];
            for row in 0..n {
                self.eigenvectors[dst * n + row] = eigen.eigenvectors[(row, src)];
            }
        }
        let largest = self.eigenvalues[n - 1];
        let smallest_nonzero = if n > dimension {
            self.eigenvalues[dimension]
        } else {
            largest
        };
        let ratio = if largest > 0.0 {
            (smallest_nonzero.max(0.0) / largest).sqrt()
        } else {
            0.0
        };
        if !exceeds(ratio, rank_tolerance) {
            return Err(Singular);
        }
        Ok(())
    }
}

/// The agent's sensors as one level set calls them: directly, or through the
/// [`Caller`] of a gathered round, counting the motor rows sensed either way (the
/// rows a simulator or a robot answers for the set: what a set costs its user).
pub(crate) struct Sensor<'a> {
    pub(crate) agent: &'a dyn Agent,
    environment: &'a Environment,
    caller: Option<&'a Caller<'a>>,
    /// Motor rows sensed so far.
    pub(crate) rows: u64,
    /// The phase the next rows are counted in, and the rows of each phase.
    pub(crate) phase: RowPhase,
    pub(crate) phases: SensorRowPhases,
}

impl<'a> Sensor<'a> {
    /// The sensors of `agent` in `environment`, read through `caller` when given; no
    /// row counted yet, in the start phase.
    pub(crate) fn new(
        agent: &'a dyn Agent,
        environment: &'a Environment,
        caller: Option<&'a Caller<'a>>,
    ) -> Self {
        Self {
            agent,
            environment,
            caller,
            rows: 0,
            phase: RowPhase::Start,
            phases: SensorRowPhases::default(),
        }
    }

    /// The readings of the motor rows `(B, N)` into `sensors` `(B, K)`: one call (a
    /// Jacobian's rows).
    pub(crate) fn sense_batch(
        &mut self,
        motors: ArrayView2<'_, f64>,
        mut sensors: ArrayViewMut2<'_, f64>,
    ) {
        // A non-finite motor row is the tracer's own failure: it never reaches the
        // agent (a user's callable), and its readings are not numbers, which fail the set.
        if motors.iter().any(|v| !v.is_finite()) {
            sensors.fill(f64::NAN);
            return;
        }
        self.rows += motors.nrows() as u64;
        self.phases.add(self.phase, true, motors.nrows() as u64);
        match self.caller {
            Some(caller) => caller.sense_batch(motors, sensors),
            None => self.agent.sense_batch(self.environment, motors, sensors),
        }
    }

    /// The readings at one motor row: directly, or as a one-row request of the caller.
    fn sense(&mut self, motors: &[f64], sensors: &mut [f64]) {
        if motors.iter().any(|v| !v.is_finite()) {
            sensors.fill(f64::NAN);
            return;
        }
        self.rows += 1;
        self.phases.add(self.phase, false, 1);
        match self.caller {
            Some(caller) => {
                let (n, k) = (motors.len(), sensors.len());
                let motors = ArrayView2::from_shape((1, n), motors).expect("one row of N motors");
                let sensors = ArrayViewMut2::from_shape((1, k), sensors).expect("one row of K");
                caller.sense_batch(motors, sensors);
            }
            None => self.agent.sense(self.environment, motors, sensors),
        }
    }

    /// The agent's own values and Jacobian at one row, when it gives them (one row).
    fn sense_with_jacobian(
        &mut self,
        motors: &[f64],
        sensors: &mut [f64],
        jacobian: &mut [f64],
    ) -> bool {
        if motors.iter().any(|v| !v.is_finite()) {
            return false;
        }
        let given = self
            .agent
            .sense_with_jacobian(self.environment, motors, sensors, jacobian);
        self.rows += u64::from(given);
        self.phases.add(self.phase, true, u64::from(given));
        given
    }
}

impl LevelSet for Sensory<'_> {
    fn motor_dim(&self) -> usize {
        self.n
    }

    fn rows(&self) -> usize {
        self.active().1
    }

    fn residual(&mut self, m: &[f64], r: &mut [f64]) {
        if self.secant.is_some() {
            self.secant_residual(m, r);
            return;
        }
        let Some(basis) = &self.held else {
            self.sensor.sense(m, r);
            for (ri, t) in r.iter_mut().zip(&self.target) {
                *ri -= t;
            }
            return;
        };
        let full = &mut self.full_residual;
        self.sensor.sense(m, full);
        for (ri, t) in full.iter_mut().zip(&self.target) {
            *ri -= t;
        }
        Self::project(basis, self.n - self.dimension, full, r);
    }

    fn residual_norm(&self, r: &[f64]) -> f64 {
        if !self.projected || self.held.is_some() {
            return r.iter().fold(0.0, |acc: f64, v| acc.max(v.abs())) / self.scale;
        }
        let n = self.n;
        let g: Vec<f64> = (0..n)
            .map(|j| (0..self.k).map(|i| self.jacobian[i * n + j] * r[i]).sum())
            .collect();
        let mut squares = 0.0;
        for e in self.dimension..n {
            let v = &self.eigenvectors[e * n..(e + 1) * n];
            let lambda = self.eigenvalues[e];
            if lambda > 0.0 {
                squares += dot(v, &g).powi(2) / lambda;
            }
        }
        squares.sqrt() / self.scale
    }

    fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// With secant Jacobians (exact readings): the last exact linearisation, when the
    /// set was last linearised there and it was not singular.
    fn node_jacobian(&self) -> Option<&[f64]> {
        let state = self.secant.as_ref()?;
        (state.has_node && !state.node_singular && state.last_m == state.node_m)
            .then_some(state.node_jacobian.as_slice())
    }

    /// With secant Jacobians (exact readings): `jacobian` replaces the current one, the
    /// secant's watch restarts, and the last reading is forgotten (the next one is no
    /// secant step).
    fn restart_from(&mut self, jacobian: &[f64]) -> Result<(), Singular> {
        let Some(state) = self.secant.as_mut() else {
            return Err(Singular);
        };
        if jacobian.len() != self.jacobian.len() {
            return Err(Singular);
        }
        state.has_last = false;
        state.linearized_norm = f64::INFINITY;
        self.jacobian.copy_from_slice(jacobian);
        self.decompose()
    }

    /// [`EXACT_SENSORY_MAX_STEP`] with secant Jacobians (exact readings), else the
    /// default.
    fn automatic_max_step(&self) -> f64 {
        match self.secant {
            Some(_) => EXACT_SENSORY_MAX_STEP,
            None => DEFAULT_MAX_STEP,
        }
    }

    fn node_tolerance(&self) -> f64 {
        match self.secant {
            Some(_) => NODE_TOLERANCE_FACTOR * self.tolerance,
            None => self.tolerance,
        }
    }

    fn linearize(&mut self, m: &[f64], r: &mut [f64]) -> Result<(), Singular> {
        if self.secant.is_some() {
            return self.secant_linearize(m, r);
        }
        let Some(basis) = self.held.take() else {
            self.read_full(m, r);
            return self.decompose();
        };
        let mut full = std::mem::take(&mut self.full_residual);
        self.read_full(m, &mut full);
        let (n, columns) = (self.n, self.n - self.dimension);
        Self::project(&basis, columns, &full, r);
        for j in 0..n {
            for c in 0..columns {
                self.held_jacobian[c * n + j] = (0..self.k)
                    .map(|i| basis[i * columns + c] * self.jacobian[i * n + j])
                    .sum();
            }
        }
        self.full_residual = full;
        self.held = Some(basis);
        self.decompose()
    }

    fn null_vector(&self, reference: &[f64], t: &mut [f64]) {
        oriented_null_vector(&self.eigenvectors[..self.n], reference, t);
    }

    fn correction(&self, r: &[f64], delta: &mut [f64]) {
        let (jacobian, k) = self.active();
        let range = Decomposed {
            eigenvalues: &self.eigenvalues,
            eigenvectors: &self.eigenvectors,
            dimension: self.dimension,
        };
        range.minimum_norm_step(jacobian, k, r, delta);
    }

    fn jacobian(&self) -> (&[f64], usize) {
        self.active()
    }

    fn null_basis(&self, k: usize, basis: &mut [f64]) {
        // The eigenvectors of JᵀJ with the smallest eigenvalues.
        let n = self.n;
        basis[..k * n].copy_from_slice(&self.eigenvectors[..k * n]);
    }

    fn newton(&self) -> bool {
        false
    }

    fn covers(&self, m: &[f64]) -> bool {
        self.sensor.agent.covers(m)
    }

    fn sensor_rows(&self) -> u64 {
        self.sensor.rows
    }

    fn sensor_row_phases(&self) -> Option<SensorRowPhases> {
        Some(self.sensor.phases)
    }

    fn set_phase(&mut self, phase: RowPhase) {
        self.sensor.phase = phase;
    }

    fn set_linearization(&mut self, linearization: Linearization) -> bool {
        let Some(state) = &mut self.secant else {
            return false;
        };
        state.linearization = linearization;
        state.linearized_norm = f64::INFINITY;
        true
    }
}
