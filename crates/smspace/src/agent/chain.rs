//! A kinematic chain of your own (`kind = "chain"`): revolute joints described in TOML,
//! planar or in 3-D, ending in the pinhole retina of the paper's arm (section 3.1,
//! generalised).
//!
//! **Kinematics.** Joints are listed from the base outwards. Joint `j` rotates by its
//! motor `m_j` about its unit `axis_j` (in the frame left by joint `j − 1`), then
//! translates by `link_j` (in the rotated frame). With `R_0 = I`, `p_0 = 0`:
//!
//! ```text
//! R_j = R_{j−1} Rot(axis_j, m_j),   p_j = p_{j−1} + R_j link_j ,
//! ```
//!
//! and the retina sits at `p = p_N` with orientation `R = R_N` (products of rotations,
//! computed with unit quaternions). A joint with `range = [low, high]` is a bounded motor
//! of the [`MotorSpace`]; without one it is a hinge (period `2π`).
//!
//! **Retina.** The retina looks along `+x` of its frame; a light at `q` has forward
//! distance `u = x̂_R·(q − p)` and image coordinates
//! `(a, b) = (−f ŷ_R·(q − p) / u, −f ẑ_R·(q − p) / u)` (`f` the focal length; the image
//! is inverted). Only lights in front (`u > 0`) count. Cells sit on a regular grid of
//! `[−w, w]²` (`cells = [rows, cols]`: columns along the image's `a`, rows along `b`) or
//! on one row of `[−w, w]` at `b = 0` (`cells = K`), and cell `(r, c)` is excited by the
//! planar arm's law with 2-D image coordinates
//!
//! ```text
//! s_{r,c} = Σ_l exp(−(a_c − a_l)² − (b_r − b_l)²) / ‖q_l − p‖ .
//! ```
//!
//! `[agent.retina] tuning`, `tuning_width`, `falloff`, `falloff_length` change the law
//! as on the arm ([`RetinaLaw`]): `s_{r,c} = Σ_l I_l τ(a_c − a_l) τ(b_r − b_l) φ(‖q_l − p‖)`
//! (a row of cells: `τ(b_r − b_l)` with `b_r = 0`, as above).
//!
//! **Planar chains.** A chain whose axes are all along `±z`, whose links lie in the
//! `xy` plane and whose retina is one row is planar: with `σ_j = ±1` the sign of axis
//! `j`, `θ_j = Σ_{i≤j} σ_i m_i`, the pose is the paper's `(x, y, alpha = θ_N)` and the
//! lights are in the plane; with the paper's links this *is* the planar arm (same
//! formulas, same floating-point operations: the sensations and traced sets agree to
//! 1e-12). Otherwise the chain is 3-D: its ground truth is
//! `(x, y, z, qw, qx, qy, qz)` (the unit quaternion of `R`, `qw ≥ 0`) and its lights are
//! in a volume.
//!
//! **Pose Jacobian** (the geometric Jacobian of the last frame, paper appendix A for the
//! plane). With `a_j = R_{j−1} axis_j` the joint's axis in the world and `p_{j−1}` its
//! position, `∂p/∂m_j = a_j × (p − p_{j−1})` and the rotation rows (tangent
//! coordinates of the quaternion block: the rotation vector of `q_0⁻¹ q`, a body-frame
//! angle) are `Rᵀ a_j`. In the plane this is `∂(x, y)/∂m_j = σ_j (−Σ_{k≥j} c_k^y,
//! Σ_{k≥j} c_k^x)` with `c_k = R_k link_k`, and `∂alpha/∂m_j = σ_j`.
//!
//! **Camera.** `[agent.camera]` instead of `[agent.retina]` puts a pinhole camera at
//! the end of the chain ([`super::Camera`]: its sensors are the pixels of an image of
//! the environment's scene); the kinematics and the ground truth are the chain's.
//!
//! **Pupil.** `[agent.retina] aperture = [low, high]` adds the aperture motor of
//! [`super::Pupil`], the last, after the joints.
//!
//! **Probes.** A planar chain shaped as the paper's arm (links `[L_k, 0, 0]` on `+z`
//! hinges, then a retina hinge without a link) has the arm's inverse kinematics, so the
//! probe grid (`probes = "grid"`) places it exactly as the arm; other chains have none
//! (babbled configurations only).
//!
//! **Working space and lights.** The working space is `[agent.workspace]` (a box:
//! `center` and `size` with 2 values in the plane, 3 in 3-D) or, by default, one
//! derived from the chain's reach `L = Σ‖link_j‖` and its home direction `û` (the
//! retina's position with every motor at 0, or at the middle of its range): centre
//! `7L/12 û`, extent `L/2` along the axis closest to `û` and `2L/3` along the others
//! (for the paper's arm this is the paper's rectangle). Random lights surround it: a
//! square of half side `L` minus the working space widened by `L/6`, at heights within
//! `L` of its centre in 3-D.

use std::sync::Arc;

use nalgebra::{Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::{
    wrap_angle, Agent, AgentBuilder, AgentError, ArmParams, Camera, CameraParams, Environment,
    Falloff, LightRegion, LightSpace, Motor, MotorSpace, Observer, PlanarArm, PoseSpace, RetinaLaw,
    Tuning, Workspace, MAX_LINKS, MAX_RETINA_CELLS,
};
use crate::params::{CheckParams, InvalidParameter};

/// One joint of a chain: `{ axis = [x, y, z], link = [x, y, z], range = [low, high] }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointParams {
    /// The rotation axis, in the frame left by the previous joint (any length but zero;
    /// the motor turns about it by the right-hand rule).
    pub axis: [f64; 3],
    /// The translation after the rotation, in the rotated frame (length units).
    pub link: [f64; 3],
    /// The joint's limits `[low, high]` in radians: a bounded motor. Default: none (a
    /// hinge, periodic with period `2π`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
}

/// The retina's cells: one row of `K` cells, or a grid of `[rows, cols]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(
    untagged,
    expecting = "a number of cells (one row) or [rows, cols] (a grid)"
)]
pub enum RetinaCells {
    /// One row of cells along the image's first axis.
    Row(usize),
    /// A grid: rows along the image's second axis, columns along its first.
    Grid([usize; 2]),
}

impl RetinaCells {
    /// `(rows, cols)`.
    pub fn shape(self) -> (usize, usize) {
        match self {
            RetinaCells::Row(k) => (1, k),
            RetinaCells::Grid([rows, cols]) => (rows, cols),
        }
    }
}

/// The `[agent.retina]` table of a chain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetinaParams {
    /// The cells: a number (one row; the paper's 6) or `[rows, cols]`. Default 6.
    pub cells: RetinaCells,
    /// Cell centres span `[−half_width, half_width]` on each image axis. Default 1.0.
    pub half_width: f64,
    /// Distance from the lens to the image plane. Default 1.0.
    pub focal_length: f64,
    /// A pupil: one more motor, the last, bounded in `[low, high]` (`0 < low < high`),
    /// that scales every cell's input ([`super::Pupil`]). Default: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aperture: Option<[f64; 2]>,
    /// The cells' tuning curve ([`RetinaLaw`]; on a grid, the product of the curves
    /// along the two image axes). Default `gaussian` (the paper's).
    pub tuning: Tuning,
    /// The tuning curve's width (image units). Default 1 (the paper's).
    pub tuning_width: f64,
    /// How a light's input falls with its distance. Default `inverse` (the paper's).
    pub falloff: Falloff,
    /// The length of the `exponential` falloff. Default 1.
    pub falloff_length: f64,
}

impl Default for RetinaParams {
    fn default() -> Self {
        Self {
            cells: RetinaCells::Row(6),
            half_width: 1.0,
            focal_length: 1.0,
            aperture: None,
            tuning: Tuning::default(),
            tuning_width: 1.0,
            falloff: Falloff::default(),
            falloff_length: 1.0,
        }
    }
}

/// The `[agent.workspace]` table of a chain: a box of retina positions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChainWorkspace {
    /// The centre: `[x, y]` (planar chains) or `[x, y, z]` (3-D chains).
    pub center: Vec<f64>,
    /// The full extents along each axis, as many as `center` (positive).
    pub size: Vec<f64>,
}

/// Parameters of a chain (`kind = "chain"`); see the module docs for the maths.
///
/// ```
/// use smspace::agent::AgentConfig;
/// let config: AgentConfig = toml::from_str(r#"
///     kind = "chain"
///     joints = [
///         { axis = [0, 0, 1], link = [1.0, 0, 0] },
///         { axis = [0, 1, 0], link = [1.0, 0, 0], range = [-1.5, 1.5] },
///     ]
///     [retina]
///     cells = [2, 3]
/// "#).unwrap();
/// let chain = config.build().unwrap();
/// assert_eq!((chain.motor_dim(), chain.sensor_dim()), (2, 6));
/// // Not planar: the ground truth is a position and a unit quaternion.
/// assert_eq!(chain.ground_truth().unwrap().pose_space().dim(), 7);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChainParams {
    /// The joints from the base outwards (at least one).
    #[serde(default)]
    pub joints: Vec<JointParams>,
    /// The retina at the end of the last link. Default: 6 cells in a row, half width 1,
    /// focal length 1 (the paper's).
    #[serde(default)]
    pub retina: RetinaParams,
    /// The working space. Default: derived from the chain's reach (module docs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub workspace: Option<ChainWorkspace>,
    /// A pinhole camera at the end of the last link instead of the retina
    /// ([`Camera`]). Default: none (the retina).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraParams>,
}

impl ChainParams {
    /// The parameters of an `[agent]` table (`kind` removed). A joint that does not
    /// parse is named by its index (from 0).
    pub fn from_table(table: &toml::Table) -> Result<Self, AgentError> {
        let invalid = |reason: String| AgentError::InvalidTable {
            kind: "chain".into(),
            reason,
        };
        if let Some(toml::Value::Array(joints)) = table.get("joints") {
            for (i, joint) in joints.iter().enumerate() {
                JointParams::deserialize(joint.clone())
                    .map_err(|e| invalid(format!("joint {i}: {}", e.to_string().trim_end())))?;
            }
        }
        toml::Value::Table(table.clone())
            .try_into()
            .map_err(|e: toml::de::Error| invalid(e.to_string().trim_end().to_owned()))
    }
}

/// How the chain moves: in the plane (the paper's formulas) or in 3-D.
#[derive(Debug, Clone, PartialEq)]
enum Kinematics {
    /// All axes along `±z` (`signs[j] = σ_j`), links in the plane, one row of cells.
    Planar {
        signs: Vec<f64>,
        links: Vec<[f64; 2]>,
    },
    /// Anything else.
    Spatial,
}

/// Checked [`ChainParams`], the only form a chain is built from ([`Chain::from_valid`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ChainValidParams {
    axes: Vec<Unit<Vector3<f64>>>,
    links: Vec<Vector3<f64>>,
    motors: Vec<Motor>,
    cells: (usize, usize),
    half_width: f64,
    focal_length: f64,
    law: RetinaLaw,
    kinematics: Kinematics,
    workspace: Option<Workspace>,
}

fn invalid(key: &'static str, value: String, reason: &str) -> AgentError {
    InvalidParameter::new("agent", key, value, reason).into()
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl CheckParams for ChainParams {
    type Valid = ChainValidParams;
    type Error = AgentError;

    /// 1 to [`MAX_LINKS`] joints, each with a finite non-zero axis, a finite link and
    /// a finite range with `low < high`; links not all zero; 1 to
    /// [`MAX_RETINA_CELLS`] cells; a positive half width and focal length; a working
    /// space of the chain's dimension with positive extents.
    fn check_params(&self) -> Result<ChainValidParams, AgentError> {
        if self.joints.is_empty() {
            return Err(invalid(
                "joints",
                "[]".into(),
                "a chain needs at least one joint, e.g. joints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }]",
            ));
        }
        if self.joints.len() > MAX_LINKS {
            return Err(invalid(
                "joints",
                format!("{} joints", self.joints.len()),
                "at most 1000 joints (one motor per joint)",
            ));
        }
        let (mut axes, mut links, mut motors) = (Vec::new(), Vec::new(), Vec::new());
        for (i, joint) in self.joints.iter().enumerate() {
            let axis = Vector3::from(joint.axis);
            if !finite(&joint.axis) || axis.norm() == 0.0 {
                return Err(invalid(
                    "joints",
                    format!("joint {i}: axis = {:?}", joint.axis),
                    "a joint's axis is three finite numbers, not all zero",
                ));
            }
            if !finite(&joint.link) {
                return Err(invalid(
                    "joints",
                    format!("joint {i}: link = {:?}", joint.link),
                    "a joint's link is three finite numbers (length units)",
                ));
            }
            let motor = match joint.range {
                None => Motor::HINGE,
                Some([low, high]) if low.is_finite() && high.is_finite() && low < high => {
                    Motor::Bounded { low, high }
                }
                Some(range) => return Err(invalid(
                    "joints",
                    format!("joint {i}: range = {range:?}"),
                    "a joint's range is two finite angles [low, high] in radians with low < high",
                )),
            };
            axes.push(Unit::new_normalize(axis));
            links.push(Vector3::from(joint.link));
            motors.push(motor);
        }
        if links.iter().all(|l| l.norm() == 0.0) {
            return Err(invalid(
                "joints",
                "every link = [0, 0, 0]".into(),
                "the retina never moves; give at least one joint a non-zero link",
            ));
        }
        let cells = self.check_retina()?;
        let law = RetinaLaw::checked(
            (self.retina.tuning, self.retina.tuning_width),
            (self.retina.falloff, self.retina.falloff_length),
            ["retina.tuning_width", "retina.falloff_length"],
        )?;
        let kinematics = planar_kinematics(&self.joints, self.retina.cells);
        let workspace = self.check_workspace(&kinematics)?;
        Ok(ChainValidParams {
            axes,
            links,
            motors,
            cells,
            half_width: self.retina.half_width,
            focal_length: self.retina.focal_length,
            law,
            kinematics,
            workspace,
        })
    }
}

impl ChainParams {
    /// The retina's `(rows, cols)`, checked.
    fn check_retina(&self) -> Result<(usize, usize), AgentError> {
        let (rows, cols) = self.retina.cells.shape();
        let total = rows.saturating_mul(cols);
        if total == 0 || total > MAX_RETINA_CELLS {
            return Err(invalid(
                "retina.cells",
                format!("{rows} × {cols}"),
                "the retina needs 1 to 10000 cells (one sensor per cell; the paper's has 6)",
            ));
        }
        for (key, value) in [
            ("retina.half_width", self.retina.half_width),
            ("retina.focal_length", self.retina.focal_length),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(invalid(
                    key,
                    value.to_string(),
                    "must be a finite number greater than zero",
                ));
            }
        }
        if let Some(range) = self.retina.aperture {
            super::pupil::check_aperture("retina.aperture", range)?;
        }
        Ok((rows, cols))
    }

    /// The working space of the file, checked against the chain's dimension.
    fn check_workspace(&self, kinematics: &Kinematics) -> Result<Option<Workspace>, AgentError> {
        let Some(w) = &self.workspace else {
            return Ok(None);
        };
        let dim = match kinematics {
            Kinematics::Planar { .. } => 2,
            Kinematics::Spatial => 3,
        };
        let lengths_ok =
            w.center.len() == w.size.len() && (w.center.len() == dim || w.center.len() == 2);
        if !lengths_ok || !finite(&w.center) || !w.size.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(invalid(
                "workspace",
                format!("center = {:?}, size = {:?}", w.center, w.size),
                if dim == 2 {
                    "a planar chain's working space is center = [x, y] and size = [depth, width], finite, with positive extents"
                } else {
                    "a 3-D chain's working space is center = [x, y, z] and size = [dx, dy, dz] (or 2 values each, any height), finite, with positive extents"
                },
            ));
        }
        let z_range = (w.center.len() == 3)
            .then(|| [w.center[2] - w.size[2] / 2.0, w.center[2] + w.size[2] / 2.0]);
        Ok(Some(Workspace {
            center: [w.center[0], w.center[1]],
            size: [w.size[0], w.size[1]],
            z_range,
        }))
    }
}

/// [`Kinematics::Planar`] when every axis is along `±z`, every link in the `xy` plane
/// and the retina one row; else [`Kinematics::Spatial`].
fn planar_kinematics(joints: &[JointParams], cells: RetinaCells) -> Kinematics {
    let planar = matches!(cells, RetinaCells::Row(_))
        && joints
            .iter()
            .all(|j| j.axis[0] == 0.0 && j.axis[1] == 0.0 && j.link[2] == 0.0);
    if !planar {
        return Kinematics::Spatial;
    }
    Kinematics::Planar {
        signs: joints.iter().map(|j| j.axis[2].signum()).collect(),
        links: joints.iter().map(|j| [j.link[0], j.link[1]]).collect(),
    }
}

/// Regularly spaced cell centres on `[−w, w]` (the centre alone for one cell), as the
/// planar arm places them.
fn cell_positions(count: usize, w: f64) -> Vec<f64> {
    if count == 1 {
        return vec![0.0];
    }
    (0..count)
        .map(|i| -w + 2.0 * w * i as f64 / (count - 1) as f64)
        .collect()
}

/// A kinematic chain with a pinhole retina (`kind = "chain"`); see the module docs.
#[derive(Debug, Clone)]
pub struct Chain {
    axes: Vec<Unit<Vector3<f64>>>,
    links: Vec<Vector3<f64>>,
    motors: MotorSpace,
    kinematics: Kinematics,
    /// Cell centres along the image's first axis (columns).
    columns: Vec<f64>,
    /// Cell centres along the image's second axis (rows; `[0]` for one row).
    rows: Vec<f64>,
    focal_length: f64,
    law: RetinaLaw,
    workspace: Workspace,
    reach: f64,
    /// The planar arm this chain is, when it is one (links `[L_k, 0, 0]` with `L_k > 0`
    /// on counter-clockwise `z` hinges, then a retina hinge without a link): its inverse
    /// kinematics places the probe grid.
    arm: Option<PlanarArm>,
}

/// The frame of the retina (or camera) in the world.
pub(super) struct Frames {
    /// The orientation `R`.
    pub(super) rotation: UnitQuaternion<f64>,
    /// The position `p`.
    pub(super) position: Vector3<f64>,
}

impl Chain {
    /// Validates `params` and builds the chain.
    pub fn new(params: &ChainParams) -> Result<Self, AgentError> {
        Ok(Self::from_valid(params.check_params()?))
    }

    /// The chain of checked parameters.
    pub fn from_valid(params: ChainValidParams) -> Self {
        let (rows, cols) = params.cells;
        let motors = MotorSpace::new(params.motors).expect("checked ranges");
        let reach = params.links.iter().map(|l| l.norm()).sum();
        let mut chain = Self {
            axes: params.axes,
            links: params.links,
            motors,
            kinematics: params.kinematics,
            columns: cell_positions(cols, params.half_width),
            rows: if rows == 1 {
                vec![0.0]
            } else {
                cell_positions(rows, params.half_width)
            },
            focal_length: params.focal_length,
            law: params.law,
            workspace: Workspace::PAPER,
            reach,
            arm: None,
        };
        chain.arm = chain.as_planar_arm();
        chain.workspace = params.workspace.unwrap_or_else(|| chain.reach_workspace());
        chain
    }

    /// The planar arm of the same body, when the chain is shaped as one (links
    /// `[L_k, 0, 0]`, `L_k > 0`, on `+z` hinges, then a retina hinge without a link).
    fn as_planar_arm(&self) -> Option<PlanarArm> {
        let Kinematics::Planar { signs, links } = &self.kinematics else {
            return None;
        };
        let (last, arm_links) = links.split_last()?;
        let shaped = signs.iter().all(|&s| s == 1.0)
            && *last == [0.0, 0.0]
            && !arm_links.is_empty()
            && arm_links.iter().all(|l| l[0] > 0.0 && l[1] == 0.0);
        let params = ArmParams {
            link_lengths: arm_links.iter().map(|l| l[0]).collect(),
            retina_cells: self.columns.len(),
            ..ArmParams::default()
        };
        shaped.then(|| PlanarArm::new(&params).ok()).flatten()
    }

    /// Whether the chain is planar (ground truth `(x, y, alpha)`, lights in the plane).
    pub fn is_planar(&self) -> bool {
        matches!(self.kinematics, Kinematics::Planar { .. })
    }

    /// The chain's reach `Σ‖link_j‖`.
    pub fn reach(&self) -> f64 {
        self.reach
    }

    /// The default working space (module docs): a box at `7/12` of the reach along the
    /// home direction.
    fn reach_workspace(&self) -> Workspace {
        let home = self.motors.home();
        let p = self.frames(&home).position;
        let r = self.reach;
        let u = if p.norm() > 1e-9 * r {
            p / p.norm()
        } else {
            Vector3::x()
        };
        let along = u.iamax();
        let distance = r * 7.0 / 12.0;
        let size = |axis: usize| {
            if axis == along {
                r / 2.0
            } else {
                2.0 * r / 3.0
            }
        };
        let center = u * distance;
        Workspace {
            center: [center.x, center.y],
            size: [size(0), size(1)],
            z_range: (!self.is_planar())
                .then(|| [center.z - size(2) / 2.0, center.z + size(2) / 2.0]),
        }
    }

    /// The retina's frame for motors `m` (unit quaternion and position).
    pub(super) fn frames(&self, motors: &[f64]) -> Frames {
        let mut rotation = UnitQuaternion::identity();
        let mut position = Vector3::zeros();
        for ((axis, link), &m) in self.axes.iter().zip(&self.links).zip(motors) {
            rotation *= UnitQuaternion::from_axis_angle(axis, m);
            position += rotation * link;
        }
        Frames { rotation, position }
    }

    /// The planar pose `(x, y, alpha)` with the arm's floating-point operations.
    fn planar_pose(&self, signs: &[f64], links: &[[f64; 2]], motors: &[f64]) -> [f64; 3] {
        let (mut x, mut y, mut theta) = (0.0, 0.0, 0.0);
        for ((sign, link), m) in signs.iter().zip(links).zip(motors) {
            theta += sign * m;
            let (s, c) = theta.sin_cos();
            x += link[0] * c - link[1] * s;
            y += link[0] * s + link[1] * c;
        }
        [x, y, wrap_angle(theta)]
    }

    /// Joint positions from the base to the retina (the base, then the end of every
    /// link), in the world.
    pub fn joint_positions(&self, motors: &[f64]) -> Vec<[f64; 3]> {
        let mut rotation = UnitQuaternion::identity();
        let mut position = Vector3::zeros();
        let mut points = vec![[0.0; 3]];
        for ((axis, link), &m) in self.axes.iter().zip(&self.links).zip(motors) {
            rotation *= UnitQuaternion::from_axis_angle(axis, m);
            position += rotation * link;
            points.push([position.x, position.y, position.z]);
        }
        points
    }

    fn sense_planar(&self, environment: &Environment, pose: [f64; 3], sensors: &mut [f64]) {
        super::arm::sense_planar_retina(
            environment,
            pose,
            self.focal_length,
            &self.columns,
            &self.law,
            sensors,
        );
    }

    fn sense_spatial(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        let frames = self.frames(motors);
        let r = frames.rotation.to_rotation_matrix();
        let (ex, ey, ez) = (
            r.matrix().column(0).into_owned(),
            r.matrix().column(1).into_owned(),
            r.matrix().column(2).into_owned(),
        );
        sensors.fill(0.0);
        let cols = self.columns.len();
        for (l, light) in environment.lights.iter().enumerate() {
            let d = Vector3::from(*light) - frames.position;
            let forward = ex.dot(&d);
            if forward <= 0.0 {
                continue;
            }
            let a = -self.focal_length * ey.dot(&d) / forward;
            let b = -self.focal_length * ez.dot(&d) / forward;
            let falloff = self.law.falloff(environment.intensity(l), d.norm_squared());
            for (row, &cell_b) in sensors.chunks_exact_mut(cols).zip(&self.rows) {
                let vertical = self.law.tuning(cell_b - b) * falloff;
                for (s, &cell_a) in row.iter_mut().zip(&self.columns) {
                    *s += self.law.tuning(cell_a - a) * vertical;
                }
            }
        }
    }

    /// The planar pose Jacobian, with the arm's suffix sums.
    fn planar_jacobian(
        &self,
        signs: &[f64],
        links: &[[f64; 2]],
        motors: &[f64],
        jacobian: &mut [f64],
        pose: &mut [f64],
    ) {
        let n = signs.len();
        let (dx, rest) = jacobian.split_at_mut(n);
        let (dy, dalpha) = rest.split_at_mut(n);
        // Forward: the links in the world, c_k = R(θ_k) link_k; backward: suffix sums.
        let mut theta = 0.0;
        for (((sign, link), m), (jx, jy)) in signs
            .iter()
            .zip(links)
            .zip(motors)
            .zip(dx.iter_mut().zip(dy.iter_mut()))
        {
            theta += sign * m;
            let (s, c) = theta.sin_cos();
            *jx = -(link[0] * s + link[1] * c);
            *jy = link[0] * c - link[1] * s;
        }
        let (mut sx, mut sy) = (0.0, 0.0);
        for ((jx, jy), sign) in dx.iter_mut().zip(dy.iter_mut()).zip(signs).rev() {
            sx += *jx;
            sy += *jy;
            *jx = sign * sx;
            *jy = sign * sy;
        }
        dalpha[..n].copy_from_slice(signs);
        pose[..3].copy_from_slice(&[sy, -sx, wrap_angle(theta)]);
    }

    /// The 3-D pose Jacobian (geometric Jacobian of the retina's frame: world
    /// position rows, body rotation rows).
    fn spatial_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let n = self.axes.len();
        let mut rotation = UnitQuaternion::identity();
        let mut position = Vector3::zeros();
        let mut joints = Vec::with_capacity(n);
        for ((axis, link), &m) in self.axes.iter().zip(&self.links).zip(motors) {
            let world_axis = rotation * axis.into_inner();
            joints.push((world_axis, position));
            rotation *= UnitQuaternion::from_axis_angle(axis, m);
            position += rotation * link;
        }
        let inverse = rotation.inverse();
        for (j, (axis, origin)) in joints.iter().enumerate() {
            let linear = axis.cross(&(position - origin));
            let angular = inverse * axis;
            for (row, v) in linear.iter().chain(angular.iter()).enumerate() {
                jacobian[row * n + j] = *v;
            }
        }
        write_spatial_pose(&rotation, &position, pose);
    }
}

/// `(x, y, z, qw, qx, qy, qz)` with `qw ≥ 0`.
fn write_spatial_pose(rotation: &UnitQuaternion<f64>, position: &Vector3<f64>, pose: &mut [f64]) {
    let q = rotation.quaternion();
    let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
    pose[..7].copy_from_slice(&[
        position.x,
        position.y,
        position.z,
        sign * q.w,
        sign * q.i,
        sign * q.j,
        sign * q.k,
    ]);
}

impl Agent for Chain {
    fn motor_dim(&self) -> usize {
        self.axes.len()
    }

    fn sensor_dim(&self) -> usize {
        self.columns.len() * self.rows.len()
    }

    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        match &self.kinematics {
            Kinematics::Planar { signs, links } => {
                let pose = self.planar_pose(signs, links, motors);
                self.sense_planar(environment, pose, sensors);
            }
            Kinematics::Spatial => self.sense_spatial(environment, motors, sensors),
        }
    }

    fn name(&self) -> &str {
        "chain"
    }

    fn motor_space(&self) -> MotorSpace {
        self.motors.clone()
    }

    fn ground_truth(&self) -> Option<&dyn Observer> {
        Some(self)
    }

    fn default_workspace(&self) -> Option<Workspace> {
        Some(self.workspace)
    }

    /// The joints seen from above: the `(x, y)` of every joint position (an orthographic
    /// projection onto the `xy` plane for a 3-D chain).
    fn skeleton(&self, motors: &[f64]) -> Vec<[f64; 2]> {
        self.joint_positions(motors)
            .into_iter()
            .map(|[x, y, _]| [x, y])
            .collect()
    }

    /// A square of half side `L` around the working space, minus the working space
    /// widened by `L/6` (the planar arm's region for the paper's body).
    fn default_light_region(&self) -> LightRegion {
        let (w, r) = (self.workspace, self.reach);
        let exclusion = w.size.map(|s| s / 2.0 + r / 6.0);
        LightRegion {
            center: w.center,
            half_size: exclusion.map(|e| r.max(e + r / 3.0)),
            exclusion_half_size: exclusion,
        }
    }

    fn default_light_count(&self) -> usize {
        10
    }

    fn light_space(&self) -> LightSpace {
        if self.is_planar() {
            LightSpace::Plane
        } else {
            LightSpace::Volume
        }
    }

    /// Within the reach `L` of the working space's middle height.
    fn default_light_heights(&self) -> [f64; 2] {
        let middle = self
            .workspace
            .z_range
            .map_or(0.0, |[low, high]| 0.5 * (low + high));
        [middle - self.reach, middle + self.reach]
    }
}

/// The retina's pose: `(x, y, alpha)` for a planar chain, `(x, y, z, qw, qx, qy, qz)`
/// otherwise.
impl Observer for Chain {
    fn pose_space(&self) -> PoseSpace {
        match self.kinematics {
            Kinematics::Planar { .. } => PoseSpace::planar(),
            Kinematics::Spatial => PoseSpace::spatial(),
        }
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        match &self.kinematics {
            Kinematics::Planar { signs, links } => {
                pose[..3].copy_from_slice(&self.planar_pose(signs, links, motors));
            }
            Kinematics::Spatial => {
                let frames = self.frames(motors);
                write_spatial_pose(&frames.rotation, &frames.position, pose);
            }
        }
    }

    /// 3 in the plane, 6 in 3-D: every tangent coordinate of the pose.
    fn configuration_dim(&self) -> usize {
        if self.is_planar() {
            3
        } else {
            6
        }
    }

    /// For a planar chain shaped as the paper's arm, the arm's inverse kinematics
    /// (the same motors), if they respect the joints' ranges; none otherwise.
    fn inverse_kinematics(&self, pose: &[f64]) -> Option<Vec<f64>> {
        let motors = self.arm.as_ref()?.inverse_kinematics(pose)?;
        let within = self
            .motors
            .motors()
            .iter()
            .zip(&motors)
            .all(|(m, &v)| match *m {
                Motor::Bounded { low, high } => (low..=high).contains(&v),
                Motor::Periodic { .. } => true,
            });
        within.then_some(motors)
    }

    /// The geometric Jacobian (module docs).
    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        match &self.kinematics {
            Kinematics::Planar { signs, links } => {
                self.planar_jacobian(signs, links, motors, jacobian, pose)
            }
            Kinematics::Spatial => self.spatial_jacobian(motors, jacobian, pose),
        }
    }
}

/// The registry's builder of `kind = "chain"` (joints named by index in errors).
pub(super) fn builder() -> AgentBuilder {
    Arc::new(|table: &toml::Table, _: &()| {
        let params = ChainParams::from_table(table)?;
        if let Some(camera) = &params.camera {
            return camera_builder(table, &params, camera);
        }
        let chain = Chain::new(&params)?;
        let agent: Box<dyn Agent> = match params.retina.aperture {
            None => Box::new(chain),
            Some(range) => Box::new(super::Pupil::new(chain, range)?),
        };
        let resolved = match toml::Value::try_from(&params) {
            Ok(toml::Value::Table(t)) => t,
            _ => table.clone(),
        };
        Ok((agent, resolved))
    })
}

/// A chain with `[agent.camera]`: no `[agent.retina]`, and the resolved table without
/// one.
fn camera_builder(
    table: &toml::Table,
    params: &ChainParams,
    camera: &CameraParams,
) -> Result<(Box<dyn Agent>, toml::Table), AgentError> {
    if table.contains_key("retina") {
        return Err(invalid(
            "camera",
            format!("{camera:?}"),
            "a chain ends in a retina ([agent.retina]) or a camera ([agent.camera]), not both; remove one table",
        ));
    }
    let agent = Box::new(Camera::new(Chain::new(params)?, camera)?);
    let mut resolved = match toml::Value::try_from(params) {
        Ok(toml::Value::Table(t)) => t,
        _ => table.clone(),
    };
    resolved.remove("retina");
    Ok((agent, resolved))
}
