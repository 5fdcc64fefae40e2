//! The planar arm of paper section 3.1: serial hinge links ending in a pinhole retina.
//!
//! With `L` links and motors `m ∈ ℝ^{L+1}` (one hinge per link plus a last hinge that
//! turns the retina), the cumulative link angles are `θ_k = Σ_{j≤k} m_j` and the
//! retina's pose is
//!
//! ```text
//! x = Σ_k L_k cos θ_k,   y = Σ_k L_k sin θ_k,   alpha = Σ_j m_j .
//! ```
//!
//! The retina is a pinhole camera whose lens sits at `(x, y)` looking along `alpha`.
//! A light at world position `q` has, in the retina's frame, a forward distance
//! `u = (q − p)·(cos α, sin α)` and a lateral offset `v = (q − p)·(−sin α, cos α)`;
//! if `u > 0` it projects through the lens onto the retina at `p_proj = −f v / u`
//! (`f` the focal length; the image is inverted), otherwise it adds nothing. The
//! `K` cells sit regularly on `[−w, w]` (`w` the retina's half width) and cell `i`
//! is excited by (paper eq. for `s_{i,l}`)
//!
//! ```text
//! s_i = Σ_l exp(−(p_cell_i − p_proj_l)²) / ‖(x, y) − q_l‖ .
//! ```
//!
//! ## Other retina laws
//!
//! `[agent.retina]` may change the law (the default is the paper's, bit for bit):
//! `s_i = Σ_l I_l · τ(p_cell_i − p_proj_l) · φ(‖(x, y) − q_l‖)` with the **tuning**
//! curve `τ` of width `w` (`tuning_width`, default 1) and the **falloff** `φ` with
//! distance `d` of length `ℓ` (`falloff_length`, default 1) ([`RetinaLaw`]):
//!
//! ```text
//! tuning = "gaussian" (default)   τ(o) = exp(−(o/w)²)            (the paper's with w = 1)
//! tuning = "cauchy"               τ(o) = 1 / (1 + (o/w)²)
//! tuning = "cosine"               τ(o) = cos²(π o / (4w)) for |o| < 2w, else 0
//! falloff = "inverse" (default)   φ(d) = 1/d                     (the paper's)
//! falloff = "none"                φ(d) = 1
//! falloff = "inverse-square"      φ(d) = 1/d²
//! falloff = "exponential"         φ(d) = exp(−d/ℓ)
//! ```
//!
//! The cosine tuning is a raised cosine: it and its slope vanish at `|o| = 2w`, so the
//! law stays continuously differentiable (the tracer's Newton corrector needs a slope).

use serde::{Deserialize, Serialize};

use super::{
    check_positive, wrap_angle, Agent, AgentError, Environment, LightRegion, Observer, Pose,
    PoseSpace, Workspace,
};
use crate::params::{CheckParams, InvalidParameter};

/// Parameters of the planar arm (`kind = "planar-arm"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmParams {
    /// Length of every link, from the base outwards. Default `[1.0, 1.0, 1.0]` (the paper's).
    pub link_lengths: Vec<f64>,
    /// Number of light-sensitive cells on the retina. Default 6.
    pub retina_cells: usize,
    /// Cells are spaced regularly on `[-retina_half_width, retina_half_width]`. Default 1.0.
    pub retina_half_width: f64,
    /// Distance from the lens to the retina. Default 1.0.
    pub focal_length: f64,
    /// The `[agent.retina]` table: the pupil. Default: none (the paper's arm).
    #[serde(skip_serializing_if = "ArmRetinaParams::is_default")]
    pub retina: ArmRetinaParams,
}

/// The `[agent.retina]` table of the planar arm (the cells are `retina_cells`,
/// `retina_half_width` and `focal_length`, the arm's first keys).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArmRetinaParams {
    /// A pupil: one more motor, the last, bounded in `[low, high]` (`0 < low < high`),
    /// that scales every cell's input ([`super::Pupil`]). Default: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aperture: Option<[f64; 2]>,
    /// The cells' tuning curve. Default `gaussian` (the paper's).
    #[serde(skip_serializing_if = "Tuning::is_default")]
    pub tuning: Tuning,
    /// The tuning curve's width `w` (image units). Default 1 (the paper's).
    #[serde(skip_serializing_if = "is_one")]
    pub tuning_width: f64,
    /// How a light's input falls with its distance. Default `inverse` (the paper's).
    #[serde(skip_serializing_if = "Falloff::is_default")]
    pub falloff: Falloff,
    /// The length `ℓ` of the `exponential` falloff. Default 1.
    #[serde(skip_serializing_if = "is_one")]
    pub falloff_length: f64,
}

impl Default for ArmRetinaParams {
    fn default() -> Self {
        Self {
            aperture: None,
            tuning: Tuning::default(),
            tuning_width: 1.0,
            falloff: Falloff::default(),
            falloff_length: 1.0,
        }
    }
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

/// A retina cell's tuning curve `τ(o)`, `o` the offset of a light's image from the
/// cell's centre (see the arm module's docs, "Other retina laws").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tuning {
    /// `exp(−(o/w)²)`: the paper's with `w = 1`.
    #[default]
    Gaussian,
    /// `1 / (1 + (o/w)²)`: heavy tails, every cell sees every light in front.
    Cauchy,
    /// `cos²(π o / (4w))` for `|o| < 2w`, else 0: a cell blind beyond `2w`.
    Cosine,
}

impl Tuning {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// How a light's input falls with its distance `d` to the lens, `φ(d)` (see the
/// arm module's docs, "Other retina laws").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Falloff {
    /// `1/d`: the paper's.
    #[default]
    Inverse,
    /// `1`: no falloff.
    None,
    /// `1/d²`: a point source's irradiance.
    InverseSquare,
    /// `exp(−d/ℓ)`: a medium that absorbs light.
    Exponential,
}

impl Falloff {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// The law of a retina cell: tuning curve and falloff with their lengths (see the
/// arm module's docs, "Other retina laws"); the default is the paper's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetinaLaw {
    /// The tuning curve.
    pub tuning: Tuning,
    /// Its width `w` (image units, > 0).
    pub tuning_width: f64,
    /// The falloff with distance.
    pub falloff: Falloff,
    /// The exponential falloff's length `ℓ` (world units, > 0).
    pub falloff_length: f64,
}

impl Default for RetinaLaw {
    fn default() -> Self {
        Self::PAPER
    }
}

impl RetinaLaw {
    /// The paper's law: `exp(−o²) / d`.
    pub const PAPER: Self = Self {
        tuning: Tuning::Gaussian,
        tuning_width: 1.0,
        falloff: Falloff::Inverse,
        falloff_length: 1.0,
    };

    /// Checks the lengths, `keys` naming them in errors (`[agent]` keys).
    pub(crate) fn checked(
        (tuning, tuning_width): (Tuning, f64),
        (falloff, falloff_length): (Falloff, f64),
        keys: [&'static str; 2],
    ) -> Result<Self, AgentError> {
        for (key, value) in keys.into_iter().zip([tuning_width, falloff_length]) {
            if !(value.is_finite() && value > 0.0) {
                return Err(InvalidParameter::new(
                    "agent",
                    key,
                    value,
                    "must be a finite length greater than zero (1 is the paper's)",
                )
                .into());
            }
        }
        Ok(Self {
            tuning,
            tuning_width,
            falloff,
            falloff_length,
        })
    }

    /// `τ(o)`. The Gaussian of width 1 is the paper's `exp(−o²)` bit for bit (`o / 1`
    /// is `o`).
    #[inline]
    pub fn tuning(&self, offset: f64) -> f64 {
        let x = offset / self.tuning_width;
        match self.tuning {
            Tuning::Gaussian => (-x * x).exp(),
            Tuning::Cauchy => 1.0 / (1.0 + x * x),
            Tuning::Cosine => {
                if x.abs() < 2.0 {
                    let c = (std::f64::consts::FRAC_PI_4 * x).cos();
                    c * c
                } else {
                    0.0
                }
            }
        }
    }

    /// `I · φ(d)` for a light of intensity `I` at squared distance `d2`. The inverse
    /// falloff is the paper's `I / sqrt(d2)` bit for bit.
    #[inline]
    pub fn falloff(&self, intensity: f64, d2: f64) -> f64 {
        match self.falloff {
            Falloff::Inverse => intensity / d2.sqrt(),
            Falloff::None => intensity,
            Falloff::InverseSquare => intensity / d2,
            Falloff::Exponential => intensity * (-d2.sqrt() / self.falloff_length).exp(),
        }
    }
}

impl ArmRetinaParams {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// The cells' law, checked.
    fn law(&self) -> Result<RetinaLaw, AgentError> {
        RetinaLaw::checked(
            (self.tuning, self.tuning_width),
            (self.falloff, self.falloff_length),
            ["retina.tuning_width", "retina.falloff_length"],
        )
    }
}

impl Default for ArmParams {
    fn default() -> Self {
        Self {
            link_lengths: vec![1.0, 1.0, 1.0],
            retina_cells: 6,
            retina_half_width: 1.0,
            focal_length: 1.0,
            retina: ArmRetinaParams::default(),
        }
    }
}

/// The planar arm with a pinhole retina (paper section 3.1). See the module docs for
/// the equations.
#[derive(Debug, Clone)]
pub struct PlanarArm {
    link_lengths: Vec<f64>,
    cell_positions: Vec<f64>,
    focal_length: f64,
    law: RetinaLaw,
}

/// Most retina cells an arm may have (each is a sensor).
pub const MAX_RETINA_CELLS: usize = 10_000;

/// Most links an arm may have.
pub const MAX_LINKS: usize = 1_000;

/// Checked [`ArmParams`], the only form an arm is built from
/// ([`PlanarArm::from_valid`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ArmValidParams {
    link_lengths: Vec<f64>,
    retina_cells: usize,
    retina_half_width: f64,
    focal_length: f64,
    aperture: Option<[f64; 2]>,
    law: RetinaLaw,
}

impl CheckParams for ArmParams {
    type Valid = ArmValidParams;
    type Error = AgentError;

    /// At least one and at most [`MAX_LINKS`] links of positive length, 1 to
    /// [`MAX_RETINA_CELLS`] cells, a positive half width and focal length.
    fn check_params(&self) -> Result<ArmValidParams, AgentError> {
        let invalid =
            |key, value: String, reason| InvalidParameter::new("agent", key, value, reason);
        if self.link_lengths.is_empty() {
            return Err(invalid(
                "link_lengths",
                "[]".into(),
                "the arm needs at least one link",
            )
            .into());
        }
        for &length in &self.link_lengths {
            check_positive("link_lengths", length)?;
        }
        if self.retina_cells == 0 {
            return Err(invalid(
                "retina_cells",
                "0".into(),
                "the retina needs at least one cell",
            )
            .into());
        }
        if self.retina_cells > MAX_RETINA_CELLS {
            return Err(invalid(
                "retina_cells",
                self.retina_cells.to_string(),
                "must be at most 10000 (one sensor per cell; the paper's retina has 6)",
            )
            .into());
        }
        if self.link_lengths.len() > MAX_LINKS {
            return Err(invalid(
                "link_lengths",
                format!("{} links", self.link_lengths.len()),
                "at most 1000 links (one motor per joint; the paper's arm has 3)",
            )
            .into());
        }
        check_positive("retina_half_width", self.retina_half_width)?;
        check_positive("focal_length", self.focal_length)?;
        if let Some(range) = self.retina.aperture {
            super::pupil::check_aperture("retina.aperture", range)?;
        }
        let law = self.retina.law()?;
        Ok(ArmValidParams {
            link_lengths: self.link_lengths.clone(),
            retina_cells: self.retina_cells,
            retina_half_width: self.retina_half_width,
            focal_length: self.focal_length,
            aperture: self.retina.aperture,
            law,
        })
    }
}

impl PlanarArm {
    /// Validates `params` and builds the arm (without its pupil: see
    /// [`PlanarArm::build`]).
    pub fn new(params: &ArmParams) -> Result<Self, AgentError> {
        Ok(Self::from_valid(params.check_params()?))
    }

    /// The agent of `params`: the arm, or the arm with its pupil when
    /// `[agent.retina] aperture` is given ([`super::Pupil`]).
    pub fn build(params: &ArmParams) -> Result<Box<dyn Agent>, AgentError> {
        let valid = params.check_params()?;
        let aperture = valid.aperture;
        let arm = Self::from_valid(valid);
        Ok(match aperture {
            None => Box::new(arm),
            Some(range) => Box::new(super::Pupil::new(arm, range)?),
        })
    }

    /// The arm of checked parameters.
    pub fn from_valid(params: ArmValidParams) -> Self {
        let k = params.retina_cells;
        let w = params.retina_half_width;
        let cell_positions = if k == 1 {
            vec![0.0]
        } else {
            (0..k)
                .map(|i| -w + 2.0 * w * i as f64 / (k - 1) as f64)
                .collect()
        };
        Self {
            link_lengths: params.link_lengths,
            cell_positions,
            focal_length: params.focal_length,
            law: params.law,
        }
    }

    /// The links' lengths.
    pub fn link_lengths(&self) -> &[f64] {
        &self.link_lengths
    }

    /// Positions of the joints in the plane: the base `(0, 0)`, then the end of every
    /// link (the last is the lens). Used to draw the arm.
    pub fn joint_positions(&self, motors: &[f64]) -> Vec<[f64; 2]> {
        let mut points = vec![[0.0, 0.0]];
        let (mut x, mut y, mut theta) = (0.0, 0.0, 0.0);
        for (length, m) in self.link_lengths.iter().zip(motors) {
            theta += m;
            x += length * theta.cos();
            y += length * theta.sin();
            points.push([x, y]);
        }
        points
    }

    /// The retina's pose `(x, y, alpha)` for motors `m` (see the module docs).
    ///
    /// Angles are summed as they are, except that a motor angle beyond `±2^20` rad is
    /// first reduced to `[0, 2π)` (exactly: `rem_euclid` is exact), so that the sum
    /// and its trigonometry stay finite for any finite motors (e.g. `1e308`, whose sum
    /// would overflow). Ordinary angles are untouched, so their poses do not change
    /// by a bit.
    pub fn planar_pose(&self, motors: &[f64]) -> Pose {
        const LARGE_ANGLE: f64 = 1_048_576.0;
        let reduced = |m: f64| {
            if m.abs() > LARGE_ANGLE {
                m.rem_euclid(std::f64::consts::TAU)
            } else {
                m
            }
        };
        let (mut x, mut y, mut theta) = (0.0, 0.0, 0.0);
        for (length, &m) in self.link_lengths.iter().zip(motors) {
            theta += reduced(m);
            let (s, c) = theta.sin_cos();
            x += length * c;
            y += length * s;
        }
        let hinges = &motors[..motors.len().min(self.link_lengths.len() + 1)];
        let alpha = wrap_angle(hinges.iter().map(|&m| reduced(m)).sum());
        Pose { x, y, alpha }
    }

    /// The 2 × N Jacobian of the lens position, row-major, for manipulability.
    fn position_manipulability(&self, motors: &[f64]) -> f64 {
        let n = self.motor_dim();
        let mut j = vec![0.0; 3 * n];
        self.pose_jacobian(motors, &mut j, &mut [0.0; 3]);
        // det(J_p J_pᵀ) for the 2 position rows.
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        for k in 0..n {
            a += j[k] * j[k];
            b += j[k] * j[n + k];
            c += j[n + k] * j[n + k];
        }
        (a * c - b * b).max(0.0).sqrt()
    }
}

impl Agent for PlanarArm {
    fn motor_dim(&self) -> usize {
        self.link_lengths.len() + 1
    }

    fn sensor_dim(&self) -> usize {
        self.cell_positions.len()
    }

    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        let pose = self.planar_pose(motors);
        sense_planar_retina(
            environment,
            [pose.x, pose.y, pose.alpha],
            self.focal_length,
            &self.cell_positions,
            &self.law,
            sensors,
        );
    }

    fn name(&self) -> &str {
        "planar-arm"
    }

    fn skeleton(&self, motors: &[f64]) -> Vec<[f64; 2]> {
        self.joint_positions(motors)
    }

    fn ground_truth(&self) -> Option<&dyn Observer> {
        Some(self)
    }

    /// Lights go around the paper's working space (centre 1.75 units in front of the
    /// base), in a 6 × 6 square minus a margin of 0.5 around the working space, scaled
    /// with the arm's reach (3 for the paper's arm): the retina sees lights from every
    /// pose of the working space.
    fn default_light_region(&self) -> LightRegion {
        let scale = self.link_lengths.iter().sum::<f64>() / 3.0;
        LightRegion {
            center: [1.75 * scale, 0.0],
            half_size: [3.0 * scale, 3.0 * scale],
            exclusion_half_size: [1.25 * scale, 1.5 * scale],
        }
    }

    fn default_light_count(&self) -> usize {
        10
    }

    /// The paper's working space scaled with the arm's reach (the paper's arm reaches
    /// 3): an arm with links `[0.3, 0.3, 0.3]` explores a rectangle it can reach.
    fn default_workspace(&self) -> Option<Workspace> {
        let scale = self.link_lengths.iter().sum::<f64>() / 3.0;
        Some(Workspace::PAPER.scaled(scale))
    }
}

/// The observer sees the retina's planar pose `(x, y, alpha)`; all three change with
/// the motors.
impl Observer for PlanarArm {
    fn pose_space(&self) -> PoseSpace {
        PoseSpace::planar()
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        pose[..3].copy_from_slice(&self.planar_pose(motors).to_array());
    }

    fn configuration_dim(&self) -> usize {
        3
    }

    /// Analytic Jacobian (paper appendix A): `∂x/∂m_j = −Σ_{k≥j} L_k sin θ_k`,
    /// `∂y/∂m_j = Σ_{k≥j} L_k cos θ_k`, `∂alpha/∂m_j = 1`; the retina hinge moves only
    /// `alpha`.
    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let n = self.motor_dim();
        let links = self.link_lengths.len();
        let (dx, rest) = jacobian.split_at_mut(n);
        let (dy, dalpha) = rest.split_at_mut(n);
        // Forward pass: L_k sin θ_k and L_k cos θ_k; backward pass: suffix sums, so that
        // dx[j] = −Σ_{k≥j} L_k sin θ_k and dy[j] = Σ_{k≥j} L_k cos θ_k.
        let mut theta = 0.0;
        for ((length, m), (jx, jy)) in self
            .link_lengths
            .iter()
            .zip(motors)
            .zip(dx.iter_mut().zip(dy.iter_mut()))
        {
            theta += m;
            let (s, c) = theta.sin_cos();
            *jx = -length * s;
            *jy = length * c;
        }
        let (mut sx, mut sy) = (0.0, 0.0);
        for (jx, jy) in dx[..links].iter_mut().zip(dy[..links].iter_mut()).rev() {
            sx += *jx;
            sy += *jy;
            *jx = sx;
            *jy = sy;
        }
        dx[links] = 0.0;
        dy[links] = 0.0;
        dalpha[..n].fill(1.0);
        pose[..3].copy_from_slice(&[sy, -sx, wrap_angle(theta + motors[links])]);
    }

    /// Puts the lens at `(x, y)` with orientation `alpha`. The redundancy is resolved by
    /// aligning the links after the second with one free angle `θ`, solving the two-link
    /// problem for the rest (elbow `+`), and choosing, among 720 values of `θ`, the one of
    /// greatest manipulability `sqrt(det(J_p J_pᵀ))`, which keeps the arm away from
    /// singular (folded or stretched) postures. Deterministic.
    fn inverse_kinematics(&self, pose: &[f64]) -> Option<Vec<f64>> {
        let pose = Pose::from_slice(pose);
        let links = self.link_lengths.len();
        let n = self.motor_dim();
        let to_motors = |thetas: &[f64]| {
            let mut motors = Vec::with_capacity(n);
            let mut previous = 0.0;
            for &t in thetas {
                motors.push(wrap_angle(t - previous));
                previous = t;
            }
            motors.push(wrap_angle(pose.alpha - previous));
            motors
        };
        if links == 1 {
            let r = pose.x.hypot(pose.y);
            if (r - self.link_lengths[0]).abs() > 1e-12 {
                return None;
            }
            return Some(to_motors(&[pose.y.atan2(pose.x)]));
        }
        let (l1, l2) = (self.link_lengths[0], self.link_lengths[1]);
        let rest: f64 = self.link_lengths[2..].iter().sum();
        let two_link = |wx: f64, wy: f64| -> Option<(f64, f64)> {
            let d2 = wx * wx + wy * wy;
            let c = (d2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
            if !(-1.0..=1.0).contains(&c) {
                return None;
            }
            let q2 = c.acos();
            let t1 = wy.atan2(wx) - (l2 * q2.sin()).atan2(l1 + l2 * q2.cos());
            Some((t1, t1 + q2))
        };
        let candidates = if links == 2 { 1 } else { 720 };
        let mut best: Option<(f64, Vec<f64>)> = None;
        for i in 0..candidates {
            let theta = -std::f64::consts::PI + 2.0 * std::f64::consts::PI * i as f64 / 720.0;
            let (wx, wy) = (pose.x - rest * theta.cos(), pose.y - rest * theta.sin());
            let Some((t1, t2)) = two_link(wx, wy) else {
                continue;
            };
            let mut thetas = vec![t1, t2];
            thetas.extend(std::iter::repeat_n(theta, links - 2));
            let motors = to_motors(&thetas);
            let score = self.position_manipulability(&motors);
            if best.as_ref().is_none_or(|(s, _)| score > *s) {
                best = Some((score, motors));
            }
        }
        best.map(|(_, motors)| motors)
    }
}

/// The planar pinhole retina's law (paper section 3.1): for a retina at `pose =
/// (x, y, alpha)` looking along `alpha`, cell `c` (at `cells[c]` on the image line, focal
/// length `focal_length`) senses `Σ_lights exp(−(cell − projection)²) / distance` over
/// the lights in front (`forward > 0`), with `projection = −focal_length · lateral /
/// forward`, each light's term times its intensity (`1` by default, bit for bit the
/// paper's law); `law` changes the tuning curve and the falloff ([`RetinaLaw`]).
/// Shared by the arm and planar chains, so that both sense bit for bit alike.
pub(crate) fn sense_planar_retina(
    environment: &Environment,
    pose: [f64; 3],
    focal_length: f64,
    cells: &[f64],
    law: &RetinaLaw,
    sensors: &mut [f64],
) {
    let (sin_a, cos_a) = pose[2].sin_cos();
    sensors.fill(0.0);
    for (l, light) in environment.lights.iter().enumerate() {
        let dx = light[0] - pose[0];
        let dy = light[1] - pose[1];
        let forward = cos_a * dx + sin_a * dy;
        if forward <= 0.0 {
            continue;
        }
        let lateral = -sin_a * dx + cos_a * dy;
        let projection = -focal_length * lateral / forward;
        let falloff = law.falloff(environment.intensity(l), dx * dx + dy * dy);
        for (s, &cell) in sensors.iter_mut().zip(cells) {
            *s += law.tuning(cell - projection) * falloff;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn arm() -> PlanarArm {
        PlanarArm::new(&ArmParams::default()).unwrap()
    }

    #[test]
    fn huge_motor_angles_give_finite_sensors_and_poses() {
        let arm = arm();
        let env = Environment::from_lights(vec![[1.5, 0.3], [2.0, -1.0], [-1.0, 2.0]]);
        for motors in [
            [1e308, 1e308, 1e308, 1e308],
            [-1e308, 3e307, f64::MAX, -f64::MAX],
            [1e20, 0.5, -2e9, 1e6 + 0.5],
        ] {
            let mut sensors = [0.0; 6];
            arm.sense(&env, &motors, &mut sensors);
            let pose = arm.planar_pose(&motors);
            assert!(
                sensors.iter().all(|s| s.is_finite())
                    && [pose.x, pose.y, pose.alpha].iter().all(|v| v.is_finite()),
                "{motors:?}: {sensors:?}, {pose:?}"
            );
            // The same as the angles reduced exactly to [0, 2π).
            let reduced = motors.map(|m| m.rem_euclid(std::f64::consts::TAU));
            let mut expected = [0.0; 6];
            arm.sense(&env, &reduced, &mut expected);
            for (a, b) in sensors.iter().zip(expected) {
                assert_abs_diff_eq!(*a, b, epsilon = 1e-9);
            }
        }
        // Ordinary angles are used as they are.
        let motors = [0.3, -1.2, 2.5, 7.0];
        let mut theta = 0.0;
        let mut x = 0.0;
        for (length, m) in [1.0, 1.0, 1.0].iter().zip(motors) {
            theta += m;
            x += length * f64::cos(theta);
        }
        assert_eq!(arm.planar_pose(&motors).x, x);
    }

    #[test]
    fn the_default_working_space_scales_with_the_reach() {
        assert_eq!(arm().default_workspace(), Some(Workspace::PAPER));
        // An arm of reach 0.9 cannot put its retina in the paper's rectangle
        // (x from 1 to 2.5): its own working space is the paper's scaled by 0.3, and
        // babbling fills it.
        let small = PlanarArm::new(&ArmParams {
            link_lengths: vec![0.3, 0.3, 0.3],
            ..ArmParams::default()
        })
        .unwrap();
        let workspace = small.default_workspace().unwrap();
        assert_abs_diff_eq!(workspace.center[0], 0.525, epsilon = 1e-12);
        assert_abs_diff_eq!(workspace.size[1], 0.6, epsilon = 1e-12);
        let params = crate::explore::ExploreParams {
            n: 50,
            ..Default::default()
        };
        let found = crate::explore::explore(&small, &params).unwrap();
        assert_eq!(found.motors.nrows(), 50);
        let paper = crate::explore::explore_in(&small, &params, Some(Workspace::PAPER));
        assert!(paper.is_err(), "the paper's rectangle is out of reach");
    }

    #[test]
    fn stretched_arm_pose() {
        let p = arm().planar_pose(&[0.0, 0.0, 0.0, 0.0]);
        assert_abs_diff_eq!(p.x, 3.0);
        assert_abs_diff_eq!(p.y, 0.0);
        let p = arm().planar_pose(&[FRAC_PI_2, -FRAC_PI_2, 0.0, 0.5]);
        assert_abs_diff_eq!(p.x, 2.0, epsilon = 1e-12);
        assert_abs_diff_eq!(p.y, 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(p.alpha, 0.5, epsilon = 1e-12);
    }

    #[test]
    fn light_straight_ahead_excites_the_middle_cells_and_lights_behind_nothing() {
        let a = arm();
        let m = [0.0; 4]; // lens at (3, 0) looking along +x
        let ahead = Environment::from_lights(vec![[5.0, 0.0]]);
        let mut s = vec![0.0; 6];
        a.sense(&ahead, &m, &mut s);
        // Projection at 0: cells at ±0.2 get exp(-0.04)/2.
        assert_abs_diff_eq!(s[2], (-0.04f64).exp() / 2.0, epsilon = 1e-12);
        assert_abs_diff_eq!(s[2], s[3], epsilon = 1e-12);
        assert!(s[0] < s[2]);
        let behind = Environment::from_lights(vec![[1.0, 0.5]]);
        a.sense(&behind, &m, &mut s);
        assert!(s.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn image_is_inverted() {
        let a = arm();
        let m = [0.0; 4];
        // A light to the left (+y) projects on the negative side of the retina.
        let env = Environment::from_lights(vec![[4.0, 0.5]]);
        let mut s = vec![0.0; 6];
        a.sense(&env, &m, &mut s);
        assert!(s[0] + s[1] > s[4] + s[5]);
    }

    #[test]
    fn inverse_kinematics_reaches_the_pose() {
        let a = arm();
        for &(x, y, alpha) in &[(1.1, -0.9, 0.0), (2.4, 0.9, 2.0), (1.75, 0.0, -PI + 0.1)] {
            let m = a.inverse_kinematics(&[x, y, alpha]).expect("reachable");
            let p = a.planar_pose(&m);
            assert_abs_diff_eq!(p.x, x, epsilon = 1e-10);
            assert_abs_diff_eq!(p.y, y, epsilon = 1e-10);
            assert_abs_diff_eq!(wrap_angle(p.alpha - alpha), 0.0, epsilon = 1e-10);
        }
        assert!(a.inverse_kinematics(&[3.5, 0.0, 0.0]).is_none());
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        let bad = ArmParams {
            link_lengths: vec![1.0, -1.0],
            ..ArmParams::default()
        };
        let err = PlanarArm::new(&bad).unwrap_err();
        assert!(err.to_string().contains("link_lengths = -1"), "{err}");
        let located = err.invalid_parameter().unwrap();
        assert_eq!((located.table, located.key), ("agent", "link_lengths"));
        let bad = ArmParams {
            focal_length: f64::NAN,
            ..ArmParams::default()
        };
        assert!(PlanarArm::new(&bad).is_err());
    }
}
