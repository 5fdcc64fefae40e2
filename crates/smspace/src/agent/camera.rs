//! A pinhole camera at the end of a chain (`kind = "chain"` with `[agent.camera]`
//! instead of `[agent.retina]`): the sensors are the pixels of the image of a
//! [`Scene`](super::Scene), rendered by ray casting.
//!
//! **Geometry.** The camera sits at the chain's last frame (position `p`, rotation
//! `R`, [`Chain`]'s kinematics) and looks along its `+x`, as the retina does. An image
//! of `W × H` pixels (`width`, `height`) covers the horizontal field of view `fov`
//! (radians) with square pixels of pitch `δ = 2 tan(fov/2) / W` on the image plane at
//! unit distance. Pixel `(r, c)` (row `r` from the top, column `c` from the left) has
//! image coordinates and ray direction
//!
//! ```text
//! a_c = (c + ½ − W/2) δ,   b_r = (r + ½ − H/2) δ,
//! d̂_{r,c} = R (1, −a_c, −b_r)ᵀ / ‖(1, −a_c, −b_r)‖ ,
//! ```
//!
//! (the retina's sign convention: an image coordinate `a` sees the direction with
//! `ŷ·d / x̂·d = −a`; `+y` of the frame is to the left, `+z` up). `height = 1` is a
//! strip of `W` pixels in the frame's `xy` plane. A planar chain (all axes along `±z`)
//! may carry an image of any height: its rows look above and below the chain's plane
//! into the 3-D scene, and the image changes with the camera's pose in the plane
//! `(x, y, α)` only, so its rank is at most 3, as the retina's.
//!
//! **A camera that keeps its world orientation** (`direction = [x, y, z]`, as the
//! camera of Laflaquière & Garcia Ortiz's arm in a room, NeurIPS 2019): the camera
//! sits at the chain's last frame's position `p` but looks along the fixed world
//! direction `f̂ = direction / ‖direction‖` whatever the chain's orientation, its image
//! upright: `R = [f̂, l̂, û]` with `l̂ = (ẑ × f̂) / ‖ẑ × f̂‖` (left) and `û = f̂ × l̂` (up),
//! so `direction` may not be vertical. The image then depends on the position `p`
//! alone, and the sensor's pose (the ground truth) is that position: `(x, y)` for a
//! planar chain, `(x, y, z)` otherwise.
//!
//! **Pixel values.** The ray of pixel `(r, c)` starts at `p` with the footprint
//! `σ(t) = ς_{r,c} t`, `ς_{r,c} = ½ δ (x̂·d̂_{r,c})` (half a pixel's pitch at the
//! forward depth `t x̂·d̂`), and its colour `v_{r,c} ∈ ℝ³` is the scene's filtered,
//! composited colour along it (the scene's module docs: the texture convolved with a
//! Gaussian of standard deviation `σ`, soft coverage at silhouettes). The sensors are
//!
//! ```text
//! s_{(r W + c) C + j} = v_{r,c,j}                       (color = "rgb", C = 3, j ∈ {r, g, b})
//! s_{r W + c}         = 0.2126 v_r + 0.7152 v_g + 0.0722 v_b   (color = "grey", C = 1)
//! ```
//!
//! row-major, channels last: `K = W · H · C ≤` [`MAX_CAMERA_SENSORS`].
//!
//! **Smoothness.** One ray per pixel; the anti-aliasing is the footprint filtering of
//! the smooth texture (a wave of wavelength `λ` is scaled by
//! `exp(−2π² σ² / λ²)`, so detail finer than a pixel fades instead of aliasing) and the
//! soft coverage of silhouettes over two footprints. So the image is a smooth function
//! of the motors wherever every pixel's ray meets the same primitives in the same
//! order; it is continuously differentiable across silhouettes of spheres, boxes seen
//! from outside and rims of discs; continuous with a kink across the edges of a room
//! (a box around the camera); and it jumps across a wall's horizon and where two
//! primitives cut through each other. The tracer's finite differences see a smooth
//! image in a room with separate objects in it.
//!
//! **Ground truth**: the chain's, the pose of the camera's frame (its position alone for
//! a camera with a fixed `direction`).
//!
//! **Determinism.** Every pixel is computed from the motors alone, in a fixed order of
//! operations, with no sum across threads: the image is bit-identical for any number
//! of threads.
//!
//! ```
//! use smspace::agent::{AgentConfig, Environment, Scene};
//! let config: AgentConfig = toml::from_str(r#"
//!     kind = "chain"
//!     joints = [
//!         { axis = [0, 0, 1], link = [0.5, 0, 0] },
//!         { axis = [0, 1, 0], link = [0.5, 0, 0], range = [-1.0, 1.0] },
//!     ]
//!     [camera]
//!     width = 32
//!     height = 24
//!     fov = 1.2
//!     color = "rgb"
//! "#).unwrap();
//! let camera = config.build()?;
//! assert_eq!(camera.sensor_dim(), 32 * 24 * 3);
//! let environment = Environment::from_scene(Scene::textured_room([6.0, 6.0, 4.0], 1));
//! environment.check_for(camera.as_ref())?;
//! let mut image = vec![0.0; camera.sensor_dim()];
//! camera.sense(&environment, &[0.3, 0.1], &mut image);
//! # Ok::<(), smspace::agent::AgentError>(())
//! ```

use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::scene::{CompiledScene, Hit};
use super::{
    Agent, AgentError, Chain, Environment, LightRegion, LightSpace, MotorSpace, Observer,
    PoseSpace, Stimulus, Workspace,
};
use crate::params::InvalidParameter;

/// Most sensors (`width × height × channels`) a camera may have.
pub const MAX_CAMERA_SENSORS: usize = 1 << 18;

/// The channels of a camera's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ColorMode {
    /// One value per pixel, the luminance `0.2126 r + 0.7152 g + 0.0722 b`.
    #[default]
    #[serde(alias = "gray")]
    Grey,
    /// Three values per pixel, `r, g, b`.
    Rgb,
}

impl ColorMode {
    /// Values per pixel: 1 or 3.
    pub fn channels(self) -> usize {
        match self {
            ColorMode::Grey => 1,
            ColorMode::Rgb => 3,
        }
    }
}

/// The `[agent.camera]` table of a chain (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraParams {
    /// Pixels per row. Default 32.
    pub width: usize,
    /// Rows of pixels (1: a strip in the frame's `xy` plane). Default 1.
    pub height: usize,
    /// The horizontal field of view, radians, in `(0, π)`. Default `π/2`.
    pub fov: f64,
    /// `grey` (one value per pixel) or `rgb` (three). Default `grey`.
    pub color: ColorMode,
    /// The world direction `[x, y, z]` the camera looks along whatever the chain's
    /// orientation, not vertical (module docs); the sensor's pose is then its position
    /// only. Default: none (the camera turns with the chain's last frame).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub direction: Option<[f64; 3]>,
}

impl Default for CameraParams {
    fn default() -> Self {
        Self {
            width: 32,
            height: 1,
            fov: std::f64::consts::FRAC_PI_2,
            color: ColorMode::Grey,
            direction: None,
        }
    }
}

impl CameraParams {
    /// Checks the image's size and field of view.
    fn check(&self) -> Result<(), AgentError> {
        let sensors = self
            .width
            .checked_mul(self.height)
            .and_then(|p| p.checked_mul(self.color.channels()));
        if !matches!(sensors, Some(k) if (1..=MAX_CAMERA_SENSORS).contains(&k)) {
            return Err(InvalidParameter::new(
                "agent",
                "camera",
                format!(
                    "width = {}, height = {}, color = {:?}",
                    self.width, self.height, self.color
                ),
                format!(
                    "a camera has 1 to {MAX_CAMERA_SENSORS} sensors (width × height × 1 for grey, × 3 for rgb)"
                ),
            )
            .into());
        }
        if !(self.fov.is_finite() && self.fov > 0.0 && self.fov < std::f64::consts::PI) {
            return Err(InvalidParameter::new(
                "agent",
                "camera.fov",
                self.fov,
                "the horizontal field of view is an angle in radians between 0 and π (exclusive)",
            )
            .into());
        }
        if let Some(direction) = self.direction {
            if world_from_camera(direction).is_none() {
                return Err(InvalidParameter::new(
                    "agent",
                    "camera.direction",
                    format!("{direction:?}"),
                    "the direction a camera keeps is a finite, non-zero vector [x, y, z] that is not vertical (its image's up is the world's +z)",
                )
                .into());
            }
        }
        Ok(())
    }
}

/// The rotation `[f̂, l̂, û]` (columns, row-major) of a camera that looks along the world
/// `direction` with its image upright (module docs); `None` for a direction that is not
/// finite, zero or within `10⁻⁶` of vertical.
fn world_from_camera(direction: [f64; 3]) -> Option<[[f64; 3]; 3]> {
    let norm = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(norm.is_finite() && norm > 0.0) {
        return None;
    }
    let f = direction.map(|v| v / norm);
    // ẑ × f̂ = (−f_y, f_x, 0).
    let across = (f[0] * f[0] + f[1] * f[1]).sqrt();
    if across < 1e-6 {
        return None;
    }
    let l = [-f[1] / across, f[0] / across, 0.0];
    let u = [
        f[1] * l[2] - f[2] * l[1],
        f[2] * l[0] - f[0] * l[2],
        f[0] * l[1] - f[1] * l[0],
    ];
    Some([[f[0], l[0], u[0]], [f[1], l[1], u[1]], [f[2], l[2], u[2]]])
}

/// The position of a chain's last frame, `(x, y)` for a planar chain and `(x, y, z)`
/// otherwise: the pose of a camera that keeps its world orientation (module docs).
#[derive(Debug, Clone)]
struct ChainPosition {
    chain: Chain,
    space: PoseSpace,
    /// The chain's own pose: its coordinates and tangent coordinates.
    full_dim: usize,
    full_tangent_dim: usize,
}

impl ChainPosition {
    fn new(chain: Chain) -> Self {
        let space = if chain.is_planar() {
            PoseSpace::planar_position()
        } else {
            PoseSpace::spatial_position()
        };
        let full = chain.pose_space();
        Self {
            full_dim: full.dim(),
            full_tangent_dim: full.tangent_dim(),
            chain,
            space,
        }
    }
}

/// The chain's pose, of which the position's coordinates come first (and its tangent
/// rows first in the pose Jacobian).
impl Observer for ChainPosition {
    fn pose_space(&self) -> PoseSpace {
        self.space.clone()
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        let mut full = vec![0.0; self.full_dim];
        self.chain.pose(motors, &mut full);
        pose.copy_from_slice(&full[..self.space.dim()]);
    }

    fn configuration_dim(&self) -> usize {
        self.space.dim()
    }

    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let n = motors.len();
        let mut full_jacobian = vec![0.0; self.full_tangent_dim * n];
        let mut full = vec![0.0; self.full_dim];
        self.chain
            .pose_jacobian(motors, &mut full_jacobian, &mut full);
        let d = self.space.dim();
        jacobian.copy_from_slice(&full_jacobian[..d * n]);
        pose.copy_from_slice(&full[..d]);
    }
}

/// A pinhole camera at the end of a [`Chain`] (module docs).
#[derive(Debug, Clone)]
pub struct Camera {
    chain: Chain,
    params: CameraParams,
    /// The unit ray direction of every pixel in the camera's frame, row-major.
    rays: Vec<[f64; 3]>,
    /// Every pixel's footprint standard deviation per unit length `ς`.
    spreads: Vec<f64>,
    /// With `direction`: the camera's fixed rotation in the world, and its pose (the
    /// chain's position).
    fixed: Option<([[f64; 3]; 3], ChainPosition)>,
}

impl Camera {
    /// A camera of `params` at the end of `chain`.
    pub fn new(chain: Chain, params: &CameraParams) -> Result<Self, AgentError> {
        params.check()?;
        let (w, h) = (params.width, params.height);
        let pitch = 2.0 * (0.5 * params.fov).tan() / w as f64;
        let mut rays = Vec::with_capacity(w * h);
        let mut spreads = Vec::with_capacity(w * h);
        for r in 0..h {
            let b = (r as f64 + 0.5 - 0.5 * h as f64) * pitch;
            for c in 0..w {
                let a = (c as f64 + 0.5 - 0.5 * w as f64) * pitch;
                let length = (1.0 + a * a + b * b).sqrt();
                rays.push([1.0 / length, -a / length, -b / length]);
                spreads.push(0.5 * pitch / length);
            }
        }
        let fixed = params
            .direction
            .and_then(world_from_camera)
            .map(|rotation| (rotation, ChainPosition::new(chain.clone())));
        Ok(Self {
            chain,
            params: params.clone(),
            rays,
            spreads,
            fixed,
        })
    }

    /// The camera's parameters.
    pub fn params(&self) -> &CameraParams {
        &self.params
    }

    /// The chain that carries the camera.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// Renders the image at `motors` into `sensors` (module docs).
    fn render(
        &self,
        scene: &CompiledScene,
        motors: &[f64],
        sensors: &mut [f64],
        hits: &mut Vec<Hit>,
    ) {
        let frame = self.chain.frames(motors);
        let r = match &self.fixed {
            Some((rotation, _)) => *rotation,
            None => {
                let rotation = frame.rotation.to_rotation_matrix();
                let m = rotation.matrix();
                [
                    [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                    [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                    [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
                ]
            }
        };
        let origin = [frame.position.x, frame.position.y, frame.position.z];
        let rotate = |d: &[f64; 3]| {
            [
                r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
                r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
                r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
            ]
        };
        match self.params.color {
            ColorMode::Grey => {
                for ((s, ray), &spread) in sensors.iter_mut().zip(&self.rays).zip(&self.spreads) {
                    let v = scene.trace(origin, rotate(ray), spread, hits);
                    *s = 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2];
                }
            }
            ColorMode::Rgb => {
                for ((s, ray), &spread) in sensors
                    .chunks_exact_mut(3)
                    .zip(&self.rays)
                    .zip(&self.spreads)
                {
                    s.copy_from_slice(&scene.trace(origin, rotate(ray), spread, hits));
                }
            }
        }
    }

    /// Renders the frames of the row-major `motors` (`N` per frame) into the
    /// row-major `sensors` (`K` per frame), frames in parallel.
    fn render_frames(&self, scene: &CompiledScene, motors: &[f64], sensors: &mut [f64]) {
        let (n, k) = (self.motor_dim(), self.sensor_dim());
        sensors
            .par_chunks_mut(k)
            .zip(motors.par_chunks(n))
            .for_each_init(Vec::new, |hits, (s, m)| self.render(scene, m, s, hits));
    }
}

/// The environment's scene, compiled; `None` when it has none or a bad one
/// ([`Environment::check_for`] refuses both before any sensing).
fn compiled_scene(environment: &Environment) -> Option<CompiledScene> {
    environment.scene.as_ref()?.compile().ok()
}

impl Agent for Camera {
    fn motor_dim(&self) -> usize {
        self.chain.motor_dim()
    }

    fn sensor_dim(&self) -> usize {
        self.rays.len() * self.params.color.channels()
    }

    /// The image at `motors`; NaN everywhere when the environment has no valid scene
    /// (which [`Environment::check_for`] refuses).
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        match compiled_scene(environment) {
            Some(scene) => self.render(&scene, motors, sensors, &mut Vec::new()),
            None => sensors.fill(f64::NAN),
        }
    }

    fn name(&self) -> &str {
        "chain"
    }

    fn motor_space(&self) -> MotorSpace {
        self.chain.motor_space()
    }

    /// The frames in parallel on the rayon pool (the scene compiled once per call).
    fn sense_batch(
        &self,
        environment: &Environment,
        motors: ArrayView2<'_, f64>,
        mut sensors: ArrayViewMut2<'_, f64>,
    ) {
        let Some(scene) = compiled_scene(environment) else {
            sensors.fill(f64::NAN);
            return;
        };
        let motors = motors.as_standard_layout();
        let Some(motors) = motors.as_slice() else {
            unreachable!("a standard-layout array is contiguous")
        };
        match sensors.as_slice_mut() {
            Some(out) => self.render_frames(&scene, motors, out),
            None => {
                let mut out = Array2::zeros(sensors.dim());
                if let Some(slice) = out.as_slice_mut() {
                    self.render_frames(&scene, motors, slice);
                }
                sensors.assign(&out);
            }
        }
    }

    /// The chain's pose, or its position alone for a camera that keeps its world
    /// orientation.
    fn ground_truth(&self) -> Option<&dyn Observer> {
        match &self.fixed {
            Some((_, position)) => Some(position),
            None => Some(&self.chain),
        }
    }

    fn default_workspace(&self) -> Option<Workspace> {
        self.chain.default_workspace()
    }

    fn skeleton(&self, motors: &[f64]) -> Vec<[f64; 2]> {
        self.chain.skeleton(motors)
    }

    fn default_light_region(&self) -> LightRegion {
        self.chain.default_light_region()
    }

    fn light_space(&self) -> LightSpace {
        self.chain.light_space()
    }

    fn stimulus(&self) -> Stimulus {
        Stimulus::Scene
    }
}
