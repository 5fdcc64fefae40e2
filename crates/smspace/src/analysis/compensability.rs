//! Compensability: which sensory changes the agent's own movements can undo, and which
//! of those are spatial (the paper's conclusion, after Philipona, O'Regan &
//! Nadal 2003, "Is there something out there?", and Philipona's thesis, ch. 6).
//!
//! At a base configuration `m` in an environment `E`, with `s = σ_E(m) ∈ ℝ^K`:
//!
//! - `T_M = span ∂s/∂m` (`K × N`, central differences of step `motor_step`): the
//!   sensory changes of small movements;
//! - `T_E = span ∂s/∂e` (`K × p`, central differences of step `environment_step`) over
//!   the parameters `e` of the environment changes the agent experiences
//!   ([`SceneChange`]: rigid displacements of the whole scene, 3 in the plane and 6 in
//!   3-D; a common change of luminance, 1; each light's intensity, one per light);
//! - the compensable changes `T_M ∩ T_E`, of dimension
//!   `d = rank T_M + rank T_E − rank [T_M, T_E]` (their Table 1: the body's
//!   `p + e − b`).
//!
//! **Rank rule.** With `ρ_i = σ_i / σ_1` the singular values relative to the largest,
//! the rank is the number of `ρ_i > rank_floor`; it is *ambiguous* when a kept value is
//! below `rank_floor · gap` or a dropped one above `rank_floor / gap` (no clear gap).
//! The intersection is read from the principal angles between orthonormal bases of
//! `T_M` and `T_E` (scale-free: motor and environment units do not mix): `d` is the
//! number of angles below `angle_tolerance`, ambiguous when an angle lies within a
//! factor `gap` of it. Then `rank [T_M, T_E] = rank T_M + rank T_E − d`. A base point
//! with any ambiguity is reported with its reasons and left out of the histogram,
//! never silently counted.
//!
//! **Compensable motor directions** (Philipona et al., NIPS 2003: the null space of
//! `[J_M, −J_E]` mapped back to motor space): for each shared sensory direction `u`
//! (a principal vector of an angle below the tolerance), the motor direction
//! `v = J_M⁺ u` and the environment direction `e = J_E⁺ u`, so that `J_M v = J_E e`.
//!
//! **Attributes out by commutation** (Philipona's thesis, ch. 6). Displacements of the
//! scene do not all commute (a rotation and a translation give a translation), while a
//! change of luminance commutes with every one. The bracket of two environment
//! generators `a`, `b` (each an exact one-parameter group: a rotation about a world
//! axis through the origin, a translation along one, a scaling of intensities) is
//! measured through the sensations by the commutator of small flows,
//!
//! ```text
//! c_ab = [σ(m, φ_a(ε) φ_b(ε) φ_a(−ε) φ_b(−ε) E) − σ(m, E)] / ε² ≈ J_E [a, b] ,
//! ```
//!
//! `ε = commutation_step` (the error is `O(ε)` relative; pairs that commute exactly,
//! as luminance and displacements do, give round-off only). The brackets are bilinear,
//! so with `Q` a basis of the compensable environment directions, the directions
//! `x = Q z` that commute with every compensable change are the null space of the
//! stacked `K·d × d` matrix of `[Q z, Q_k]` over the basis vectors `Q_k`: its singular
//! values relative to the largest sensory change of a unit compensable change
//! (`σ_1(J_E Q)`) below `commutation_tolerance` (ambiguous within a factor `gap`). They
//! are the non-spatial (attribute) directions, mapped to motors by `J_M⁺ J_E`, and
//! `d_spatial = d − (their number)`.
//!
//! **Summary over base points.** `dimension` is the most frequent `d` over the
//! unambiguous points (`histogram[d]` counts them), `spatial_dimension` likewise, and
//! `non_spatial_motors` the motors whose axis is a non-spatial direction (cosine above
//! `1 − 1e-3`) at no fewer than `agreement` of the unambiguous points that have one.

use nalgebra::{DMatrix, SVD};
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::agent::{check_motor_count, Agent, AgentError, Environment, LightSpace};
use crate::params::{CheckParams, InvalidParameter};

/// Errors of the compensability analysis.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CompensabilityError {
    /// A parameter is out of its domain.
    #[error(transparent)]
    Invalid(#[from] InvalidParameter),
    /// The agent, its motors or the environment do not fit.
    #[error(transparent)]
    Agent(#[from] AgentError),
    /// No base point to analyse.
    #[error("no base configuration to analyse: the compensability analysis needs at least one motor row")]
    NoBasePoints,
    /// The sensations are not finite at a base configuration.
    #[error("the sensations are not finite near base configuration {row} ({motors:?}); the compensability analysis needs a finite sensorimotor law")]
    NonFinite {
        /// The base row.
        row: usize,
        /// Its motors.
        motors: Vec<f64>,
    },
}

/// One kind of environment change the agent experiences.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneChange {
    /// A rigid displacement of every light: a rotation about the origin and a
    /// translation (3 parameters in the plane: the angle about `z`, `t_x`, `t_y`; 6 in a
    /// volume: angles about `x`, `y`, `z`, then `t_x`, `t_y`, `t_z`).
    Rigid,
    /// A common scaling `exp(λ)` of every light's intensity (1 parameter).
    Luminance,
    /// Each light's own intensity scaled by `exp(λ_l)` (one parameter per light).
    Intensities,
}

/// Parameters of the compensability analysis (`[analysis.compensability]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CompensabilityParams {
    /// The environment changes. Default `["rigid"]`.
    pub changes: Vec<SceneChange>,
    /// The most base configurations analysed (evenly spaced rows of the babbled ones).
    /// Default 200.
    pub base_points: usize,
    /// Step of the central differences in the motors (radians or the motor's units).
    /// Default 1e-4.
    pub motor_step: f64,
    /// Step of the central differences in the environment parameters. Default 1e-4.
    pub environment_step: f64,
    /// Singular values below this fraction of the largest are noise. Default 1e-6.
    pub rank_floor: f64,
    /// Principal angles (radians) below this are shared directions. Default 1e-4.
    pub angle_tolerance: f64,
    /// Required separation (a factor) of kept and dropped values from each threshold;
    /// closer is ambiguous. Default 10.
    pub gap: f64,
    /// `ε` of the commutator of flows. Default 1e-3.
    pub commutation_step: f64,
    /// Brackets below this fraction of the largest sensory change of a unit
    /// compensable change commute. Default 1e-3.
    pub commutation_tolerance: f64,
    /// Share of the base points (unambiguous, with a non-spatial direction) at which a
    /// motor's axis must be non-spatial for the motor to be called so. Default 0.9.
    pub agreement: f64,
}

impl Default for CompensabilityParams {
    fn default() -> Self {
        Self {
            changes: vec![SceneChange::Rigid],
            base_points: 200,
            motor_step: 1e-4,
            environment_step: 1e-4,
            rank_floor: 1e-6,
            angle_tolerance: 1e-4,
            gap: 10.0,
            commutation_step: 1e-3,
            commutation_tolerance: 1e-3,
            agreement: 0.9,
        }
    }
}

/// Checked [`CompensabilityParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct CompensabilityValidParams(CompensabilityParams);

impl CheckParams for CompensabilityParams {
    type Valid = CompensabilityValidParams;
    type Error = CompensabilityError;

    /// At least one change, each once; at least one base point; positive finite steps
    /// and tolerances below 1; a gap above 1; an agreement in `(0, 1]`.
    fn check_params(&self) -> Result<CompensabilityValidParams, CompensabilityError> {
        let invalid = |key, value: String, reason: &str| {
            Err(InvalidParameter::new("analysis.compensability", key, value, reason).into())
        };
        let mut seen = self.changes.clone();
        seen.sort_by_key(|c| *c as u8);
        seen.dedup();
        if self.changes.is_empty() || seen.len() != self.changes.len() {
            return invalid(
                "changes",
                format!("{:?}", self.changes),
                "one or more distinct changes among \"rigid\", \"luminance\", \"intensities\"",
            );
        }
        if self.base_points == 0 {
            return invalid("base_points", "0".into(), "at least one base point");
        }
        for (key, value) in [
            ("motor_step", self.motor_step),
            ("environment_step", self.environment_step),
            ("commutation_step", self.commutation_step),
        ] {
            if !(value.is_finite() && value > 0.0 && value < 1.0) {
                return invalid(key, value.to_string(), "a finite step in (0, 1)");
            }
        }
        for (key, value) in [
            ("rank_floor", self.rank_floor),
            ("angle_tolerance", self.angle_tolerance),
            ("commutation_tolerance", self.commutation_tolerance),
        ] {
            if !(value.is_finite() && value > 0.0 && value * self.gap.max(1.0) < 1.0) {
                return invalid(
                    key,
                    value.to_string(),
                    "a finite tolerance in (0, 1), below 1 / gap",
                );
            }
        }
        if !(self.gap.is_finite() && self.gap > 1.0) {
            return invalid("gap", self.gap.to_string(), "a finite factor above 1");
        }
        if !(self.agreement > 0.0 && self.agreement <= 1.0) {
            return invalid("agreement", self.agreement.to_string(), "a share in (0, 1]");
        }
        Ok(CompensabilityValidParams(self.clone()))
    }
}

impl CompensabilityParams {
    /// Validates the parameters.
    pub fn check(&self) -> Result<CompensabilityValidParams, CompensabilityError> {
        self.check_params()
    }
}

/// What one base configuration gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BasePoint {
    /// Its row among the motor rows given.
    pub row: usize,
    /// `rank T_M`.
    pub motor_rank: usize,
    /// `rank T_E`.
    pub environment_rank: usize,
    /// `rank [T_M, T_E] = rank T_M + rank T_E − d`.
    pub joint_rank: usize,
    /// `d`, the dimension of the compensable changes.
    pub dimension: usize,
    /// How many compensable directions commute with every compensable change.
    pub commuting: usize,
    /// `d` minus the commuting directions.
    pub spatial_dimension: usize,
    /// The non-spatial motor directions (unit vectors, `N` values each).
    pub non_spatial_directions: Vec<Vec<f64>>,
    /// The compensable motor directions (unit vectors `J_M⁺ u`, `N` values each).
    pub compensable_directions: Vec<Vec<f64>>,
    /// Why the rank rule is ambiguous here (empty: it is not).
    pub ambiguous: Vec<String>,
}

/// The analysis over many base points (`analysis.json`: `compensability`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompensabilityReport {
    /// The environment changes analysed.
    pub changes: Vec<SceneChange>,
    /// Their parameters `p`.
    pub environment_parameters: usize,
    /// Base points analysed.
    pub base_points: usize,
    /// The most frequent `d` over the unambiguous points (none if every point is
    /// ambiguous).
    pub dimension: Option<usize>,
    /// `histogram[d]`: unambiguous points of dimension `d`.
    pub histogram: Vec<usize>,
    /// The most frequent spatial dimension (`d` minus the commuting directions).
    pub spatial_dimension: Option<usize>,
    /// `spatial_histogram[d]`: unambiguous points of spatial dimension `d`.
    pub spatial_histogram: Vec<usize>,
    /// Points where a rank, an angle or a bracket had no clear gap.
    pub ambiguous: usize,
    /// The motors found non-spatial (module docs), from 0.
    pub non_spatial_motors: Vec<usize>,
    /// Every base point.
    pub points: Vec<BasePoint>,
}

/// One environment generator: an exact one-parameter group acting on environments.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Generator {
    /// Rotation about a world axis through the origin.
    Rotation(usize),
    /// Translation along a world axis.
    Translation(usize),
    /// Common luminance.
    Luminance,
    /// One light's intensity.
    Intensity(usize),
}

impl Generator {
    /// `φ(t) E`.
    fn apply(self, environment: &Environment, t: f64) -> Environment {
        match self {
            Generator::Rotation(axis) => {
                let (s, c) = t.sin_cos();
                let mut r = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
                let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
                r[i][i] = c;
                r[i][j] = -s;
                r[j][i] = s;
                r[j][j] = c;
                environment.displaced(&r, [0.0; 3])
            }
            Generator::Translation(axis) => {
                let mut shift = [0.0; 3];
                shift[axis] = t;
                let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
                environment.displaced(&identity, shift)
            }
            Generator::Luminance => environment.scaled(t.exp()),
            Generator::Intensity(l) => {
                let mut intensities: Vec<f64> = (0..environment.lights.len())
                    .map(|k| environment.intensity(k))
                    .collect();
                intensities[l] *= t.exp();
                Environment {
                    intensities,
                    ..environment.clone()
                }
            }
        }
    }
}

/// The generators of `changes` for an environment whose lights live in `space`.
fn generators(changes: &[SceneChange], environment: &Environment) -> Vec<Generator> {
    let mut out = Vec::new();
    for change in changes {
        match (change, environment.space) {
            (SceneChange::Rigid, LightSpace::Plane) => out.extend([
                Generator::Rotation(2),
                Generator::Translation(0),
                Generator::Translation(1),
            ]),
            (SceneChange::Rigid, LightSpace::Volume) => {
                out.extend((0..3).map(Generator::Rotation));
                out.extend((0..3).map(Generator::Translation));
            }
            (SceneChange::Luminance, _) => out.push(Generator::Luminance),
            (SceneChange::Intensities, _) => {
                out.extend((0..environment.lights.len()).map(Generator::Intensity))
            }
        }
    }
    out
}

/// A rank (or count) with the reason it is ambiguous, if it is.
struct Ranked {
    rank: usize,
    ambiguous: Option<String>,
}

/// The rank rule (module docs) on singular values sorted in decreasing order.
fn rank_of(what: &str, singular: &[f64], floor: f64, gap: f64) -> Ranked {
    let largest = singular.first().copied().unwrap_or(0.0);
    if largest <= 0.0 {
        return Ranked {
            rank: 0,
            ambiguous: None,
        };
    }
    let relative: Vec<f64> = singular.iter().map(|s| s / largest).collect();
    let rank = relative.iter().filter(|&&r| r > floor).count();
    let kept_low = rank > 0 && relative[rank - 1] < floor * gap;
    let dropped_high = rank < relative.len() && relative[rank] > floor / gap;
    let ambiguous = (kept_low || dropped_high).then(|| {
        format!(
            "{what}: relative singular values {:.1e} (kept) and {:.1e} (dropped) around the floor {floor:.0e} without a gap of {gap}",
            if rank > 0 { relative[rank - 1] } else { f64::NAN },
            relative.get(rank).copied().unwrap_or(0.0),
        )
    });
    Ranked { rank, ambiguous }
}

/// Singular values (decreasing) and the `r` leading left singular vectors.
fn leading(matrix: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let svd = SVD::new(matrix.clone(), true, false);
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let u = svd.u.expect("asked for U");
    let values = order.iter().map(|&i| svd.singular_values[i]).collect();
    let columns: Vec<_> = order.iter().map(|&i| u.column(i).into_owned()).collect();
    (values, DMatrix::from_columns(&columns))
}

/// The pseudo-inverse of `matrix` (`K × n`) restricted to its `rank` leading singular
/// directions, applied to `u` (`K`): the least-norm `x` with `matrix x = u` on that
/// range.
fn pseudo_solve(matrix: &DMatrix<f64>, rank: usize, u: &nalgebra::DVector<f64>) -> Vec<f64> {
    let svd = SVD::new(matrix.clone(), true, true);
    let (uu, vt) = (svd.u.expect("U"), svd.v_t.expect("Vᵀ"));
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let mut x = nalgebra::DVector::zeros(matrix.ncols());
    for &i in order.iter().take(rank) {
        let coefficient = uu.column(i).dot(u) / svd.singular_values[i];
        x += vt.row(i).transpose() * coefficient;
    }
    x.iter().copied().collect()
}

fn unit(v: Vec<f64>) -> Vec<f64> {
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > 0.0 {
        v.into_iter().map(|x| x / norm).collect()
    } else {
        v
    }
}

/// One base configuration's analysis.
struct Base<'a> {
    agent: &'a dyn Agent,
    environment: &'a Environment,
    generators: &'a [Generator],
    params: &'a CompensabilityParams,
    motors: Vec<f64>,
    row: usize,
}

impl Base<'_> {
    fn sense(&self, environment: &Environment, motors: &[f64]) -> Vec<f64> {
        let mut s = vec![0.0; self.agent.sensor_dim()];
        self.agent.sense(environment, motors, &mut s);
        s
    }

    /// `J_M` (`K × N`) by central differences.
    fn motor_jacobian(&self) -> DMatrix<f64> {
        let (k, n, h) = (
            self.agent.sensor_dim(),
            self.motors.len(),
            self.params.motor_step,
        );
        let mut j = DMatrix::zeros(k, n);
        let mut m = self.motors.clone();
        for c in 0..n {
            m[c] = self.motors[c] + h;
            let plus = self.sense(self.environment, &m);
            m[c] = self.motors[c] - h;
            let minus = self.sense(self.environment, &m);
            m[c] = self.motors[c];
            for r in 0..k {
                j[(r, c)] = (plus[r] - minus[r]) / (2.0 * h);
            }
        }
        j
    }

    /// `J_E` (`K × p`) by central differences.
    fn environment_jacobian(&self) -> DMatrix<f64> {
        let (k, h) = (self.agent.sensor_dim(), self.params.environment_step);
        let mut j = DMatrix::zeros(k, self.generators.len());
        for (c, g) in self.generators.iter().enumerate() {
            let plus = self.sense(&g.apply(self.environment, h), &self.motors);
            let minus = self.sense(&g.apply(self.environment, -h), &self.motors);
            for r in 0..k {
                j[(r, c)] = (plus[r] - minus[r]) / (2.0 * h);
            }
        }
        j
    }

    /// `c_ab` for every pair of generators: `brackets[a][b]` (`K` values).
    fn brackets(&self) -> Vec<Vec<Vec<f64>>> {
        let (p, k, eps) = (
            self.generators.len(),
            self.agent.sensor_dim(),
            self.params.commutation_step,
        );
        let base = self.sense(self.environment, &self.motors);
        let mut c = vec![vec![vec![0.0; k]; p]; p];
        for a in 0..p {
            for b in a + 1..p {
                let (ga, gb) = (self.generators[a], self.generators[b]);
                let e = gb.apply(self.environment, -eps);
                let e = ga.apply(&e, -eps);
                let e = gb.apply(&e, eps);
                let e = ga.apply(&e, eps);
                let s = self.sense(&e, &self.motors);
                for r in 0..k {
                    let v = (s[r] - base[r]) / (eps * eps);
                    c[a][b][r] = v;
                    c[b][a][r] = -v;
                }
            }
        }
        c
    }

    fn analyse(&self) -> Result<BasePoint, CompensabilityError> {
        let p = &self.params;
        let jm = self.motor_jacobian();
        let je = self.environment_jacobian();
        if !(jm.iter().chain(je.iter()).all(|v| v.is_finite())) {
            return Err(CompensabilityError::NonFinite {
                row: self.row,
                motors: self.motors.clone(),
            });
        }
        let mut ambiguous = Vec::new();
        let (sm, um) = leading(&jm);
        let (se, ue) = leading(&je);
        let motor = rank_of("rank T_M", &sm, p.rank_floor, p.gap);
        let environment = rank_of("rank T_E", &se, p.rank_floor, p.gap);
        ambiguous.extend(motor.ambiguous);
        ambiguous.extend(environment.ambiguous);
        let um = um.columns(0, motor.rank).into_owned();
        let ue = ue.columns(0, environment.rank).into_owned();
        // Principal angles between T_M and T_E: cosines are the singular values of
        // U_Mᵀ U_E; the shared directions are U_M a_i for angles below the tolerance.
        let (shared, angles_ambiguous) = if motor.rank == 0 || environment.rank == 0 {
            (Vec::new(), None)
        } else {
            self.shared_directions(&um, &ue)
        };
        ambiguous.extend(angles_ambiguous);
        let d = shared.len();
        let compensable_directions: Vec<Vec<f64>> = shared
            .iter()
            .map(|u| unit(pseudo_solve(&jm, motor.rank, u)))
            .collect();
        let environment_directions: Vec<Vec<f64>> = shared
            .iter()
            .map(|u| pseudo_solve(&je, environment.rank, u))
            .collect();
        let (non_spatial_directions, commutation_ambiguous) =
            self.commuting(&jm, motor.rank, &je, &environment_directions);
        ambiguous.extend(commutation_ambiguous);
        let commuting = non_spatial_directions.len();
        Ok(BasePoint {
            row: self.row,
            motor_rank: motor.rank,
            environment_rank: environment.rank,
            joint_rank: motor.rank + environment.rank - d,
            dimension: d,
            commuting,
            spatial_dimension: d - commuting,
            non_spatial_directions,
            compensable_directions,
            ambiguous,
        })
    }

    /// The shared unit sensory directions (principal angles below the tolerance) and
    /// the reason the count is ambiguous, if it is.
    fn shared_directions(
        &self,
        um: &DMatrix<f64>,
        ue: &DMatrix<f64>,
    ) -> (Vec<nalgebra::DVector<f64>>, Option<String>) {
        let p = &self.params;
        let svd = SVD::new(um.transpose() * ue, true, false);
        let u = svd.u.expect("asked for U");
        let mut shared = Vec::new();
        let mut ambiguous = None;
        for (i, &cosine) in svd.singular_values.iter().enumerate() {
            let angle = cosine.clamp(-1.0, 1.0).acos();
            if angle < p.angle_tolerance {
                shared.push(um * u.column(i));
            }
            if angle > p.angle_tolerance / p.gap && angle < p.angle_tolerance * p.gap {
                ambiguous = Some(format!(
                    "a principal angle between T_M and T_E of {angle:.1e} rad, within a factor {} of the tolerance {:.0e}",
                    p.gap, p.angle_tolerance
                ));
            }
        }
        (shared, ambiguous)
    }

    /// The compensable directions that commute with every compensable change, as unit
    /// motor directions, and the reason the count is ambiguous, if it is.
    fn commuting(
        &self,
        jm: &DMatrix<f64>,
        motor_rank: usize,
        je: &DMatrix<f64>,
        environment_directions: &[Vec<f64>],
    ) -> (Vec<Vec<f64>>, Option<String>) {
        let d = environment_directions.len();
        if d == 0 {
            return (Vec::new(), None);
        }
        let (k, g) = (self.agent.sensor_dim(), self.generators.len());
        let basis = DMatrix::from_columns(
            &environment_directions
                .iter()
                .map(|e| nalgebra::DVector::from_column_slice(e))
                .collect::<Vec<_>>(),
        );
        let q = SVD::new(basis, true, false).u.expect("asked for U");
        let q = q.columns(0, d).into_owned();
        let c = self.brackets();
        // Block k: column i of C_k is Σ_b c_ib Q_bk; the block is C_k Q (K × d).
        let mut stacked = DMatrix::zeros(k * d, d);
        for block in 0..d {
            let mut ck = DMatrix::zeros(k, g);
            for i in 0..g {
                for b in 0..g {
                    for r in 0..k {
                        ck[(r, i)] += c[i][b][r] * q[(b, block)];
                    }
                }
            }
            let product = ck * &q;
            stacked.view_mut((block * k, 0), (k, d)).copy_from(&product);
        }
        let scale = SVD::new(je * &q, false, false)
            .singular_values
            .max()
            .max(f64::MIN_POSITIVE);
        let svd = SVD::new(stacked, false, true);
        let vt = svd.v_t.expect("asked for Vᵀ");
        let (tolerance, gap) = (self.params.commutation_tolerance, self.params.gap);
        let mut directions = Vec::new();
        let mut ambiguous = None;
        for (i, &sigma) in svd.singular_values.iter().enumerate() {
            let relative = sigma / scale;
            if relative < tolerance {
                let z = vt.row(i).transpose();
                let u = je * (&q * z);
                directions.push(unit(pseudo_solve(jm, motor_rank, &u)));
            }
            if relative > tolerance / gap && relative < tolerance * gap {
                ambiguous = Some(format!(
                    "a bracket of relative size {relative:.1e}, within a factor {gap} of the commutation tolerance {tolerance:.0e}"
                ));
            }
        }
        (directions, ambiguous)
    }
}

/// The compensability analysis of `agent` in `environment` at the motor rows `motors`
/// (`(M, N)`; at most `base_points` of them, evenly spaced, are analysed).
pub fn compensability(
    agent: &dyn Agent,
    environment: &Environment,
    motors: ArrayView2<'_, f64>,
    params: &CompensabilityValidParams,
) -> Result<CompensabilityReport, CompensabilityError> {
    let p = &params.0;
    check_motor_count(agent, motors.ncols())?;
    environment.check()?;
    environment.check_for(agent)?;
    if motors.nrows() == 0 {
        return Err(CompensabilityError::NoBasePoints);
    }
    let generators = generators(&p.changes, environment);
    let count = p.base_points.min(motors.nrows());
    let rows: Vec<usize> = (0..count).map(|i| i * motors.nrows() / count).collect();
    use rayon::prelude::*;
    let points = rows
        .par_iter()
        .map(|&row| {
            Base {
                agent,
                environment,
                generators: &generators,
                params: p,
                motors: motors.row(row).to_vec(),
                row,
            }
            .analyse()
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(summarise(points, p, generators.len(), agent.motor_dim()))
}

/// The most frequent index of a histogram (the smallest on ties), none if empty.
fn mode(histogram: &[usize]) -> Option<usize> {
    let best = histogram.iter().copied().max().filter(|&c| c > 0)?;
    histogram.iter().position(|&c| c == best)
}

fn summarise(
    points: Vec<BasePoint>,
    params: &CompensabilityParams,
    environment_parameters: usize,
    n: usize,
) -> CompensabilityReport {
    let clear: Vec<&BasePoint> = points.iter().filter(|b| b.ambiguous.is_empty()).collect();
    let histogram_of = |value: fn(&BasePoint) -> usize| {
        let top = clear.iter().map(|b| value(b)).max().map_or(0, |m| m + 1);
        let mut h = vec![0; top];
        for b in &clear {
            h[value(b)] += 1;
        }
        h
    };
    let histogram = histogram_of(|b| b.dimension);
    let spatial_histogram = histogram_of(|b| b.spatial_dimension);
    let with_attributes: Vec<&&BasePoint> = clear.iter().filter(|b| b.commuting > 0).collect();
    let non_spatial_motors = (0..n)
        .filter(|&j| {
            let aligned = with_attributes
                .iter()
                .filter(|b| {
                    b.non_spatial_directions
                        .iter()
                        .any(|v| v[j].abs() > 1.0 - 1e-3)
                })
                .count();
            !with_attributes.is_empty()
                && aligned as f64 >= params.agreement * with_attributes.len() as f64
        })
        .collect();
    CompensabilityReport {
        changes: params.changes.clone(),
        environment_parameters,
        base_points: points.len(),
        dimension: mode(&histogram),
        histogram,
        spatial_dimension: mode(&spatial_histogram),
        spatial_histogram,
        ambiguous: points.len() - clear.len(),
        non_spatial_motors,
        points,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rank_rule_needs_a_gap() {
        let clear = rank_of("x", &[2.0, 1.0, 1e-9], 1e-6, 10.0);
        assert_eq!((clear.rank, clear.ambiguous.is_none()), (2, true));
        let low = rank_of("x", &[1.0, 5e-6, 1e-12], 1e-6, 10.0);
        assert_eq!(low.rank, 2);
        assert!(low.ambiguous.unwrap().contains("without a gap"));
        let high = rank_of("x", &[1.0, 5e-7], 1e-6, 10.0);
        assert_eq!(high.rank, 1);
        assert!(high.ambiguous.is_some());
        assert_eq!(rank_of("x", &[0.0, 0.0], 1e-6, 10.0).rank, 0);
    }

    #[test]
    fn generators_are_exact_groups() {
        let env = Environment::from_lights(vec![[1.0, 2.0], [-0.5, 3.0]]);
        for g in generators(&[SceneChange::Rigid, SceneChange::Luminance], &env) {
            let back = g.apply(&g.apply(&env, 0.3), -0.3);
            for (a, b) in back.lights.iter().zip(&env.lights) {
                for (x, y) in a.iter().zip(b) {
                    assert!((x - y).abs() < 1e-12, "{g:?}");
                }
            }
            assert!((back.intensity(0) - 1.0).abs() < 1e-12);
        }
        let volume = Environment::from_lights_3d(vec![[1.0, 2.0, 3.0]]);
        assert_eq!(generators(&[SceneChange::Rigid], &volume).len(), 6);
        assert_eq!(
            generators(&[SceneChange::Intensities], &env),
            vec![Generator::Intensity(0), Generator::Intensity(1)]
        );
    }

    #[test]
    fn bad_parameters_are_named() {
        let bad = CompensabilityParams {
            changes: vec![SceneChange::Rigid, SceneChange::Rigid],
            ..Default::default()
        };
        let err = bad.check().unwrap_err().to_string();
        assert!(err.contains("changes"), "{err}");
        let bad = CompensabilityParams {
            gap: 1.0,
            ..Default::default()
        };
        assert!(bad.check().unwrap_err().to_string().contains("gap"));
        let bad = CompensabilityParams {
            rank_floor: 0.5,
            ..Default::default()
        };
        assert!(bad.check().unwrap_err().to_string().contains("rank_floor"));
    }
}
