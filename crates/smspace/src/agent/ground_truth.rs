//! The observer's ground truth: the external configuration of the agent's sensor, a
//! pose of any dimension, for evaluation only (paper section 2.1: the agent never
//! sees it; the `kinematic` tracer and the analysis of agreement do).
//!
//! A pose is a vector of `d` coordinates, each of a [`CoordinateKind`]:
//!
//! - **linear** (a position, in length units): differences are `a − b`;
//! - **angle** (radians): differences are wrapped into `[−π, π)`;
//! - **quaternion**, in blocks of four consecutive coordinates `(w, x, y, z)`, a unit
//!   quaternion of the sensor's orientation in 3-D (`q` and `−q` are the same
//!   orientation): the difference of two blocks is the rotation vector of
//!   `δ = q_b⁻¹ q_a` (with `δ_w ≥ 0`), `2 atan2(|δ_v|, δ_w) δ_v / |δ_v|`, three tangent
//!   coordinates; their distance is the rotation angle `2 acos |q_a · q_b|`.
//!
//! So a pose space of `d` coordinates has `T` tangent coordinates (`T = d − b` for `b`
//! quaternion blocks), the rows of a pose Jacobian. The planar pose `(x, y, alpha)`
//! of the paper's agents is [`PoseSpace::planar`] and the [`Pose`] type.
//!
//! An agent that has a ground truth returns an [`Observer`] from
//! [`Agent::ground_truth`](super::Agent::ground_truth); the poses of many
//! configurations travel between stages as [`GroundTruth`] (`poses.npy`, `(M, d)`).

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Axis};
use serde::{Deserialize, Serialize};

use super::{wrap_angle, AgentError};
use crate::params::InvalidParameter;

/// How one pose coordinate behaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CoordinateKind {
    /// A position along an axis (length units).
    Linear,
    /// An angle in radians, compared modulo `2π`.
    Angle,
    /// One component of a unit quaternion `(w, x, y, z)`: four consecutive coordinates
    /// of this kind form one orientation.
    Quaternion,
}

/// One pose coordinate: its name (as in figures and `analysis.json`) and kind.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseCoordinate {
    /// The coordinate's name, e.g. `x` or `alpha`.
    pub name: String,
    /// How it behaves.
    pub kind: CoordinateKind,
}

impl PoseCoordinate {
    /// A coordinate of this name and kind.
    pub fn new(name: &str, kind: CoordinateKind) -> Self {
        Self {
            name: name.to_owned(),
            kind,
        }
    }
}

/// One compared part of a pose: a linear or angular coordinate, or a quaternion block
/// (an orientation in 3-D).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PoseComponent {
    /// Its name: the coordinate's, or for a quaternion block its four names joined by
    /// `/` (`qw/qx/qy/qz`).
    pub name: String,
    /// Its kind.
    pub kind: CoordinateKind,
    /// Its first column in a pose.
    pub column: usize,
}

impl PoseComponent {
    /// The distance between the component in poses `a` and `b`: `|a − b|` (linear),
    /// the wrapped `|a − b|` (angle), or the rotation angle `2 acos |q_a · q_b|`
    /// (quaternion, radians in `[0, π]`).
    pub fn distance(&self, a: &[f64], b: &[f64]) -> f64 {
        let c = self.column;
        match self.kind {
            CoordinateKind::Linear => (a[c] - b[c]).abs(),
            CoordinateKind::Angle => wrap_angle(a[c] - b[c]).abs(),
            CoordinateKind::Quaternion => {
                let (qa, qb) = (&a[c..c + 4], &b[c..c + 4]);
                let dot: f64 = qa.iter().zip(qb).map(|(x, y)| x * y).sum();
                let norms = norm(qa) * norm(qb);
                let cos = if norms > 0.0 { dot.abs() / norms } else { 1.0 };
                2.0 * cos.min(1.0).acos()
            }
        }
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// How far from 1 the norm of a pose's quaternion may be: an observer's orientation is
/// a unit quaternion, and a pose whose quaternion is not is refused (never normalised,
/// since a scaled quaternion is the sign of a wrong pose function).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-6;

/// The layout of the observer's poses: a kind and a name per coordinate, quaternion
/// coordinates in blocks of four.
///
/// ```
/// use smspace::agent::{CoordinateKind, PoseCoordinate, PoseSpace};
/// let planar = PoseSpace::planar();
/// assert_eq!((planar.dim(), planar.tangent_dim()), (3, 3));
/// let names = ["x", "y", "z", "qw", "qx", "qy", "qz"];
/// let kinds = [CoordinateKind::Linear; 3].into_iter().chain([CoordinateKind::Quaternion; 4]);
/// let space = PoseSpace::new(names.iter().zip(kinds).map(|(n, k)| PoseCoordinate::new(n, k)).collect())?;
/// assert_eq!((space.dim(), space.tangent_dim()), (7, 6));
/// // A quarter turn about z, with the position unchanged.
/// let h = std::f64::consts::FRAC_1_SQRT_2;
/// let turned = [0.0, 0.0, 0.0, h, 0.0, 0.0, h];
/// let rest = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
/// let rotation = &space.components()[3];
/// assert!((rotation.distance(&turned, &rest) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
/// # Ok::<(), smspace::params::InvalidParameter>(())
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "Vec<PoseCoordinate>", into = "Vec<PoseCoordinate>")]
pub struct PoseSpace {
    coordinates: Vec<PoseCoordinate>,
}

impl TryFrom<Vec<PoseCoordinate>> for PoseSpace {
    type Error = InvalidParameter;
    fn try_from(coordinates: Vec<PoseCoordinate>) -> Result<Self, InvalidParameter> {
        Self::new(coordinates)
    }
}

impl From<PoseSpace> for Vec<PoseCoordinate> {
    fn from(space: PoseSpace) -> Self {
        space.coordinates
    }
}

impl PoseSpace {
    /// The space of these coordinates: at least one, names non-empty and distinct,
    /// quaternion coordinates in consecutive blocks of four.
    pub fn new(coordinates: Vec<PoseCoordinate>) -> Result<Self, InvalidParameter> {
        let fail = |value: String, reason: &str| {
            Err(InvalidParameter::new(
                "agent",
                "ground_truth",
                value,
                reason,
            ))
        };
        if coordinates.is_empty() {
            return fail("[]".into(), "a pose needs at least one coordinate");
        }
        for (i, c) in coordinates.iter().enumerate() {
            if c.name.trim().is_empty() || coordinates[..i].iter().any(|o| o.name == c.name) {
                return fail(
                    format!("coordinate {i} named {:?}", c.name),
                    "every pose coordinate needs a name of its own",
                );
            }
        }
        let mut i = 0;
        while i < coordinates.len() {
            let run = coordinates[i..]
                .iter()
                .take_while(|c| c.kind == coordinates[i].kind)
                .count();
            if coordinates[i].kind == CoordinateKind::Quaternion && run % 4 != 0 {
                return fail(
                    format!(
                        "{run} quaternion coordinates from {:?}",
                        coordinates[i].name
                    ),
                    "quaternion coordinates come in blocks of four (w, x, y, z)",
                );
            }
            i += run;
        }
        Ok(Self { coordinates })
    }

    /// The paper's planar pose `(x, y, alpha)`: the sensor's position in the plane
    /// and the orientation of its optical axis.
    pub fn planar() -> Self {
        Self {
            coordinates: vec![
                PoseCoordinate::new("x", CoordinateKind::Linear),
                PoseCoordinate::new("y", CoordinateKind::Linear),
                PoseCoordinate::new("alpha", CoordinateKind::Angle),
            ],
        }
    }

    /// The 3-D pose `(x, y, z, qw, qx, qy, qz)`: the sensor's position in space and
    /// its orientation as a unit quaternion (one quaternion block).
    pub fn spatial() -> Self {
        let kinds = [CoordinateKind::Linear; 3]
            .into_iter()
            .chain([CoordinateKind::Quaternion; 4]);
        Self {
            coordinates: ["x", "y", "z", "qw", "qx", "qy", "qz"]
                .iter()
                .zip(kinds)
                .map(|(name, kind)| PoseCoordinate::new(name, kind))
                .collect(),
        }
    }

    /// The position in the plane `(x, y)` alone: the pose of a sensor whose orientation
    /// is fixed (a camera that keeps its world direction).
    pub fn planar_position() -> Self {
        Self {
            coordinates: ["x", "y"]
                .iter()
                .map(|name| PoseCoordinate::new(name, CoordinateKind::Linear))
                .collect(),
        }
    }

    /// The position in space `(x, y, z)` alone (a sensor whose orientation is fixed).
    pub fn spatial_position() -> Self {
        Self {
            coordinates: ["x", "y", "z"]
                .iter()
                .map(|name| PoseCoordinate::new(name, CoordinateKind::Linear))
                .collect(),
        }
    }

    /// The layout of poses files read off their column count: 2 the planar position
    /// `(x, y)`, 3 the planar pose `(x, y, alpha)`, 7 the 3-D pose; `None` otherwise.
    ///
    /// ```
    /// use smspace::agent::PoseSpace;
    /// assert_eq!(PoseSpace::from_columns(3), Some(PoseSpace::planar()));
    /// assert_eq!(PoseSpace::from_columns(2), Some(PoseSpace::planar_position()));
    /// assert_eq!(PoseSpace::from_columns(4), None);
    /// ```
    pub fn from_columns(columns: usize) -> Option<Self> {
        match columns {
            2 => Some(Self::planar_position()),
            3 => Some(Self::planar()),
            7 => Some(Self::spatial()),
            _ => None,
        }
    }

    /// Whether this is the planar pose `(x, y, alpha)`.
    pub fn is_planar(&self) -> bool {
        *self == Self::planar()
    }

    /// The number of coordinates `d` (columns of `poses.npy`).
    pub fn dim(&self) -> usize {
        self.coordinates.len()
    }

    /// The number of tangent coordinates `T` (rows of a pose Jacobian): one per
    /// linear or angle coordinate, three per quaternion block.
    pub fn tangent_dim(&self) -> usize {
        self.components()
            .iter()
            .map(|c| match c.kind {
                CoordinateKind::Quaternion => 3,
                _ => 1,
            })
            .sum()
    }

    /// The first quaternion block of `pose` whose norm is not 1 (within
    /// [`QUATERNION_NORM_TOLERANCE`]) or not finite: its first column and its norm.
    pub fn non_unit_quaternion(&self, pose: &[f64]) -> Option<(usize, f64)> {
        self.components()
            .into_iter()
            .filter(|c| c.kind == CoordinateKind::Quaternion)
            .map(|c| {
                let q = &pose[c.column..c.column + 4];
                (c.column, q.iter().map(|v| v * v).sum::<f64>().sqrt())
            })
            .find(|&(_, norm)| !norm.is_finite() || (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE)
    }

    /// Every coordinate, in order.
    pub fn coordinates(&self) -> &[PoseCoordinate] {
        &self.coordinates
    }

    /// The columns of the linear coordinates (the position), in order.
    ///
    /// ```
    /// use smspace::agent::PoseSpace;
    /// assert_eq!(PoseSpace::planar().linear_columns(), [0, 1]);
    /// assert_eq!(PoseSpace::spatial().linear_columns(), [0, 1, 2]);
    /// ```
    pub fn linear_columns(&self) -> Vec<usize> {
        self.coordinates
            .iter()
            .enumerate()
            .filter(|(_, c)| c.kind == CoordinateKind::Linear)
            .map(|(i, _)| i)
            .collect()
    }

    /// The compared parts of a pose: one per linear or angle coordinate, one per
    /// quaternion block.
    pub fn components(&self) -> Vec<PoseComponent> {
        let mut out = Vec::new();
        let mut c = 0;
        while c < self.coordinates.len() {
            let coordinate = &self.coordinates[c];
            if coordinate.kind == CoordinateKind::Quaternion {
                let names: Vec<&str> = self.coordinates[c..c + 4]
                    .iter()
                    .map(|q| q.name.as_str())
                    .collect();
                out.push(PoseComponent {
                    name: names.join("/"),
                    kind: CoordinateKind::Quaternion,
                    column: c,
                });
                c += 4;
            } else {
                out.push(PoseComponent {
                    name: coordinate.name.clone(),
                    kind: coordinate.kind,
                    column: c,
                });
                c += 1;
            }
        }
        out
    }

    /// Writes `a − b` in tangent coordinates into `out` (length
    /// [`tangent_dim`](Self::tangent_dim)): linear differences, wrapped angle
    /// differences, and the rotation vector from `b` to `a` of each quaternion block
    /// (see the module docs).
    pub fn difference(&self, a: &[f64], b: &[f64], out: &mut [f64]) {
        let mut t = 0;
        let mut c = 0;
        while c < self.coordinates.len() {
            match self.coordinates[c].kind {
                CoordinateKind::Linear => {
                    out[t] = a[c] - b[c];
                    (c, t) = (c + 1, t + 1);
                }
                CoordinateKind::Angle => {
                    out[t] = wrap_angle(a[c] - b[c]);
                    (c, t) = (c + 1, t + 1);
                }
                CoordinateKind::Quaternion => {
                    rotation_vector(&a[c..c + 4], &b[c..c + 4], &mut out[t..t + 3]);
                    (c, t) = (c + 4, t + 3);
                }
            }
        }
    }
}

/// The rotation vector of `q_b⁻¹ q_a` (unit quaternions `(w, x, y, z)`, normalised
/// here), with the sign chosen so that the rotation angle is at most `π`.
fn rotation_vector(qa: &[f64], qb: &[f64], out: &mut [f64]) {
    let (na, nb) = (norm(qa), norm(qb));
    let (aw, ax, ay, az) = (qa[0] / na, qa[1] / na, qa[2] / na, qa[3] / na);
    // conj(q_b) = (w, −x, −y, −z).
    let (bw, bx, by, bz) = (qb[0] / nb, -qb[1] / nb, -qb[2] / nb, -qb[3] / nb);
    let mut w = bw * aw - bx * ax - by * ay - bz * az;
    let mut v = [
        bw * ax + bx * aw + by * az - bz * ay,
        bw * ay - bx * az + by * aw + bz * ax,
        bw * az + bx * ay - by * ax + bz * aw,
    ];
    if w < 0.0 {
        w = -w;
        v = v.map(|x| -x);
    }
    let s = norm(&v);
    // 2 atan2(s, w) / s → 2 / w as s → 0.
    let scale = if s > 1e-300 {
        2.0 * s.atan2(w) / s
    } else {
        2.0 / w.max(1e-300)
    };
    for (o, x) in out.iter_mut().zip(v) {
        *o = scale * x;
    }
}

/// The observer's view of an agent: the sensor's pose for any motor configuration,
/// for evaluation only. An agent returns one from
/// [`Agent::ground_truth`](super::Agent::ground_truth), or none.
///
/// Required: [`pose_space`](Observer::pose_space) and [`pose`](Observer::pose). The
/// Jacobian defaults to central differences; the inverse kinematics (for the probe
/// grid) defaults to none.
pub trait Observer: Send + Sync {
    /// The layout of the poses.
    fn pose_space(&self) -> PoseSpace;

    /// Writes the pose for motors `m` (length `N`) into `pose` (length `d`).
    fn pose(&self, motors: &[f64], pose: &mut [f64]);

    /// Writes the poses of many motor rows: `motors` is `(M, N)`, `poses` `(M, d)`. The
    /// default calls [`pose`](Observer::pose) row by row; an observer that is costly to
    /// call (a simulator in another language) overrides it to answer all rows at once.
    fn pose_batch(&self, motors: ArrayView2<'_, f64>, mut poses: ArrayViewMut2<'_, f64>) {
        let mut m = vec![0.0; motors.ncols()];
        let mut pose = vec![0.0; poses.ncols()];
        for (row, mut out) in motors.outer_iter().zip(poses.outer_iter_mut()) {
            m.iter_mut().zip(row.iter()).for_each(|(a, &b)| *a = b);
            self.pose(&m, &mut pose);
            out.iter_mut().zip(&pose).for_each(|(a, &b)| *a = b);
        }
    }

    /// How many leading tangent coordinates of the pose the motors can change (1 for
    /// the toys, whose pose is `(x, 0, 0)`; 3 for the arm). The `kinematic` tracer
    /// holds these fixed. The default is every tangent coordinate.
    fn configuration_dim(&self) -> usize {
        self.pose_space().tangent_dim()
    }

    /// Writes the pose Jacobian `∂pose/∂m` in tangent coordinates (`T × N`,
    /// row-major) into `jacobian` and the pose into `pose`. The default uses central
    /// differences of [`pose`](Observer::pose) with step `1e-6`, each difference taken
    /// with [`PoseSpace::difference`] (so angles are wrapped).
    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let space = self.pose_space();
        let (n, d, t) = (motors.len(), space.dim(), space.tangent_dim());
        let h = 1e-6;
        let mut m = motors.to_vec();
        let (mut plus, mut minus, mut diff) = (vec![0.0; d], vec![0.0; d], vec![0.0; t]);
        for j in 0..n {
            m[j] = motors[j] + h;
            self.pose(&m, &mut plus);
            m[j] = motors[j] - h;
            self.pose(&m, &mut minus);
            m[j] = motors[j];
            space.difference(&plus, &minus, &mut diff);
            for (row, v) in diff.iter().enumerate() {
                jacobian[row * n + j] = v / (2.0 * h);
            }
        }
        self.pose(motors, pose);
    }

    /// One motor configuration that puts the sensor at `pose` (length `d`), if the
    /// agent can reach it (used for the probe grid). The default knows no inverse
    /// kinematics.
    fn inverse_kinematics(&self, _pose: &[f64]) -> Option<Vec<f64>> {
        None
    }
}

/// The observer's planar pose `(x, y, alpha)`: position in the plane (length units
/// of the agent) and orientation `alpha` (radians). The poses of
/// [`PoseSpace::planar`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position along the world's x axis.
    pub x: f64,
    /// Position along the world's y axis.
    pub y: f64,
    /// Orientation of the sensor's optical axis, radians from the x axis.
    pub alpha: f64,
}

impl Pose {
    /// The pose as `[x, y, alpha]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.alpha]
    }

    /// `self − other` as `[Δx, Δy, Δalpha]`, with `Δalpha` wrapped into `[-π, π)`.
    pub fn difference(self, other: Pose) -> [f64; 3] {
        [
            self.x - other.x,
            self.y - other.y,
            wrap_angle(self.alpha - other.alpha),
        ]
    }

    /// The pose from `[x, y, alpha]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Self {
            x: a[0],
            y: a[1],
            alpha: a[2],
        }
    }

    /// The pose from the first three values of `values`.
    pub fn from_slice(values: &[f64]) -> Self {
        Self::from_array([values[0], values[1], values[2]])
    }
}

/// How the poses of planar figures were obtained ([`GroundTruth::planar_view`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlanarView {
    /// The agent's own planar pose `(x, y, alpha)`.
    #[default]
    Planar,
    /// A 3-D pose seen from above: `(x, y)` and the heading of the optical axis
    /// projected on the xy plane.
    TopView,
}

/// The observer's poses of `M` configurations, `(M, d)`, with their layout: what
/// `poses.npy` holds. Checked once where it is made: `d` columns for a space of `d`
/// coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    space: PoseSpace,
    poses: Array2<f64>,
}

/// A borrowed [`GroundTruth`] (for example the rows of the kept sets).
#[derive(Debug, Clone, Copy)]
pub struct GroundTruthView<'a> {
    space: &'a PoseSpace,
    poses: ArrayView2<'a, f64>,
}

impl GroundTruth {
    /// The poses `(M, d)` of a space of `d` coordinates; every quaternion block must
    /// be a unit quaternion ([`QUATERNION_NORM_TOLERANCE`]).
    pub fn new(space: PoseSpace, poses: Array2<f64>) -> Result<Self, AgentError> {
        if poses.ncols() != space.dim() {
            return Err(AgentError::PoseColumns {
                found: poses.ncols(),
                expected: space.dim(),
            });
        }
        let quaternions = space
            .coordinates()
            .iter()
            .any(|c| c.kind == CoordinateKind::Quaternion);
        for (row, pose) in poses.outer_iter().enumerate().filter(|_| quaternions) {
            let pose: Vec<f64> = pose.to_vec();
            if let Some((column, norm)) = space.non_unit_quaternion(&pose) {
                return Err(AgentError::NonUnitQuaternion { row, column, norm });
            }
        }
        Ok(Self { space, poses })
    }

    /// The poses of the motor rows `(M, N)` as the observer sees them (refused when a
    /// quaternion is not a unit one, as by [`GroundTruth::new`]).
    pub fn observe(
        observer: &dyn Observer,
        motors: ArrayView2<'_, f64>,
    ) -> Result<Self, AgentError> {
        let space = observer.pose_space();
        let mut poses = Array2::zeros((motors.nrows(), space.dim()));
        observer.pose_batch(motors, poses.view_mut());
        Self::new(space, poses)
    }

    /// The layout.
    pub fn space(&self) -> &PoseSpace {
        &self.space
    }

    /// The poses `(M, d)`.
    pub fn poses(&self) -> &Array2<f64> {
        &self.poses
    }

    /// The poses as `(M, 3)` `(x, y, alpha)` when the layout is
    /// [`PoseSpace::planar`], `None` otherwise (what the figures of planar poses
    /// draw).
    pub fn planar(&self) -> Option<ArrayView2<'_, f64>> {
        self.space.is_planar().then(|| self.poses.view())
    }

    /// The poses drawn in the plane, `(M, 3)` `(x, y, alpha)`, with how they were
    /// obtained: the planar pose itself, or a 3-D pose ([`PoseSpace::spatial`]) seen
    /// from above ([`PlanarView::TopView`]). `None` for other layouts.
    ///
    /// Seen from above, `alpha` is the heading of the optical axis (`+x` of the sensor's
    /// frame) projected on the xy plane: with `d = R(q)·e_x`,
    /// `d = (1 − 2(q_y² + q_z²), 2(q_x q_y + q_w q_z), 2(q_x q_z − q_w q_y))` and
    /// `alpha = atan2(d_y, d_x)` (undefined, and then whatever `atan2` gives, when the
    /// axis is vertical).
    ///
    /// ```
    /// use ndarray::array;
    /// use smspace::agent::{GroundTruth, PlanarView, PoseSpace};
    /// // At (1, 2, 3), turned by 90° about z: the axis points along +y.
    /// let h = std::f64::consts::FRAC_1_SQRT_2;
    /// let truth = GroundTruth::new(PoseSpace::spatial(), array![[1.0, 2.0, 3.0, h, 0.0, 0.0, h]])?;
    /// let (poses, view) = truth.planar_view().unwrap();
    /// assert_eq!(view, PlanarView::TopView);
    /// assert!((poses[[0, 2]] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    /// assert_eq!((poses[[0, 0]], poses[[0, 1]]), (1.0, 2.0));
    /// # Ok::<(), smspace::agent::AgentError>(())
    /// ```
    pub fn planar_view(&self) -> Option<(Array2<f64>, PlanarView)> {
        if self.space.is_planar() {
            return Some((self.poses.clone(), PlanarView::Planar));
        }
        if self.space != PoseSpace::spatial() {
            return None;
        }
        let mut out = Array2::zeros((self.poses.nrows(), 3));
        for (pose, mut row) in self.poses.outer_iter().zip(out.outer_iter_mut()) {
            let (w, x, y, z) = (pose[3], pose[4], pose[5], pose[6]);
            let dx = 1.0 - 2.0 * (y * y + z * z);
            let dy = 2.0 * (x * y + w * z);
            row[0] = pose[0];
            row[1] = pose[1];
            row[2] = dy.atan2(dx);
        }
        Some((out, PlanarView::TopView))
    }

    /// The poses of the given rows, in that order.
    pub fn select(&self, rows: &[usize]) -> GroundTruth {
        Self {
            space: self.space.clone(),
            poses: self.poses.select(Axis(0), rows),
        }
    }

    /// A borrowed view.
    pub fn view(&self) -> GroundTruthView<'_> {
        GroundTruthView {
            space: &self.space,
            poses: self.poses.view(),
        }
    }
}

impl<'a> GroundTruthView<'a> {
    /// A view of poses `(M, d)` of a space of `d` coordinates.
    pub fn new(space: &'a PoseSpace, poses: ArrayView2<'a, f64>) -> Result<Self, AgentError> {
        if poses.ncols() != space.dim() {
            return Err(AgentError::PoseColumns {
                found: poses.ncols(),
                expected: space.dim(),
            });
        }
        Ok(Self { space, poses })
    }

    /// The layout.
    pub fn space(&self) -> &'a PoseSpace {
        self.space
    }

    /// The poses `(M, d)`.
    pub fn poses(&self) -> ArrayView2<'a, f64> {
        self.poses
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use rand::{RngExt, SeedableRng};
    use std::f64::consts::PI;

    fn space_3d() -> PoseSpace {
        let space = PoseSpace::spatial();
        assert_eq!(PoseSpace::new(space.coordinates().to_vec()).unwrap(), space);
        space
    }

    fn random_unit_quaternion(rng: &mut impl RngExt) -> [f64; 4] {
        let q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let n = norm(&q);
        q.map(|v| v / n)
    }

    #[test]
    fn the_planar_difference_is_the_pose_difference() {
        let a = Pose {
            x: 1.0,
            y: -2.0,
            alpha: 3.0,
        };
        let b = Pose {
            x: 0.5,
            y: 1.0,
            alpha: -3.0,
        };
        let mut out = [0.0; 3];
        PoseSpace::planar().difference(&a.to_array(), &b.to_array(), &mut out);
        assert_eq!(out, a.difference(b));
        assert!(PoseSpace::planar().is_planar());
        assert!(!space_3d().is_planar());
    }

    #[test]
    fn quaternion_blocks_compare_by_rotation_angle() {
        let space = space_3d();
        let rotation = &space.components()[3];
        assert_eq!(rotation.name, "qw/qx/qy/qz");
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..200 {
            let (qa, qb) = (
                random_unit_quaternion(&mut rng),
                random_unit_quaternion(&mut rng),
            );
            let a: Vec<f64> = [0.0, 0.0, 0.0].into_iter().chain(qa).collect();
            let b: Vec<f64> = [0.0, 0.0, 0.0].into_iter().chain(qb).collect();
            let angle = rotation.distance(&a, &b);
            assert!((0.0..=PI + 1e-12).contains(&angle));
            // −q is the same orientation.
            let minus: Vec<f64> = [0.0, 0.0, 0.0].into_iter().chain(qb.map(|v| -v)).collect();
            assert_abs_diff_eq!(rotation.distance(&a, &minus), angle, epsilon = 1e-9);
            // The tangent difference is a rotation vector of that length.
            let mut t = [0.0; 6];
            space.difference(&a, &b, &mut t);
            assert_abs_diff_eq!(norm(&t[3..]), angle, epsilon = 1e-9);
        }
        let bad = vec![
            PoseCoordinate::new("x", CoordinateKind::Linear),
            PoseCoordinate::new("q", CoordinateKind::Quaternion),
        ];
        let err = PoseSpace::new(bad).unwrap_err();
        assert!(err.reason.contains("blocks of four"), "{err}");
        let twice = vec![
            PoseCoordinate::new("x", CoordinateKind::Linear),
            PoseCoordinate::new("x", CoordinateKind::Angle),
        ];
        assert!(PoseSpace::new(twice).is_err());
    }

    #[test]
    fn the_default_jacobian_differentiates_the_tangent_coordinates() {
        /// A sensor turned about z by m1 and about x by m2, moved along x by m3.
        struct Turntable;
        impl Observer for Turntable {
            fn pose_space(&self) -> PoseSpace {
                space_3d()
            }
            fn pose(&self, m: &[f64], pose: &mut [f64]) {
                let (s1, c1) = (m[0] / 2.0).sin_cos();
                let (s2, c2) = (m[1] / 2.0).sin_cos();
                // q = q_z(m1) q_x(m2)
                let q = [c1 * c2, c1 * s2, s1 * s2, s1 * c2];
                pose[..3].copy_from_slice(&[m[2], 0.0, 0.0]);
                pose[3..].copy_from_slice(&q);
            }
        }
        let observer = Turntable;
        let m = [0.4, -0.3, 0.2];
        let mut jacobian = vec![0.0; 6 * 3];
        let mut pose = vec![0.0; 7];
        observer.pose_jacobian(&m, &mut jacobian, &mut pose);
        assert_eq!(observer.configuration_dim(), 6);
        // ∂x/∂m3 = 1; the rotation rows of m1 are the body-frame z axis
        // q_x(m2)⁻¹ ẑ = (0, sin m2, cos m2), those of m2 the x axis.
        assert_abs_diff_eq!(jacobian[2], 1.0, epsilon = 1e-8);
        let column = |j: usize| [jacobian[9 + j], jacobian[12 + j], jacobian[15 + j]];
        let expected = [0.0, (-0.3f64).sin(), (-0.3f64).cos()];
        for (a, b) in column(0).iter().zip(expected) {
            assert_abs_diff_eq!(*a, b, epsilon = 1e-7);
        }
        for (a, b) in column(1).iter().zip([1.0, 0.0, 0.0]) {
            assert_abs_diff_eq!(*a, b, epsilon = 1e-7);
        }
        let truth =
            GroundTruth::observe(&observer, ndarray::array![[0.0, 0.0, 1.0]].view()).unwrap();
        assert_eq!(truth.poses().dim(), (1, 7));
        assert!(truth.planar().is_none());
        assert!(GroundTruth::new(space_3d(), Array2::zeros((2, 3))).is_err());
    }
}
