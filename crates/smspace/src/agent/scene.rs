//! Scenes: coloured, textured primitives a camera looks at (an environment's `scene`).
//!
//! A [`Scene`] is a list of [`Primitive`]s and a background colour (RGB, what a ray
//! that hits nothing sees). Every primitive has a base colour `c ∈ ℝ³` and a smooth
//! procedural **solid texture**: a sum of plane waves of the 3-D position `p`,
//!
//! ```text
//! colour(p) = c + Σ_i a_i sin(k_i·p + φ_i),     k_i = 2π d̂_i / λ_i ,
//! ```
//!
//! with `d̂_i` the wave's unit direction, `λ_i` its wavelength (length units), `a_i ∈ ℝ³`
//! its amplitude per channel and `φ_i` its phase (radians). A texture is a list of
//! waves (`{"waves": [...]}`) or drawn from a seed (`{"random": {...}}`,
//! [`RandomTexture`]). Because the texture is a function of the position in space, not
//! of a surface's own coordinates, it is continuous across the corners of a box: a
//! room is one continuous image.
//!
//! **Primitives** (JSON, `kind` picks one):
//!
//! | kind | keys | surface |
//! |---|---|---|
//! | `wall` | `point`, `normal` | the infinite plane through `point` orthogonal to `normal`, seen from both sides |
//! | `box` | `center`, `size` | the axis-aligned box `center ± size/2`, seen from outside or, with the camera in it, from inside (a room) |
//! | `sphere` | `center`, `radius` | the sphere, from outside or inside |
//! | `disc` | `center`, `normal`, `radius` | the flat disc, seen from both sides |
//!
//! and every primitive has `color = [r, g, b]` and an optional `texture`. The JSON form
//! of an environment with a scene is
//!
//! ```json
//! {"scene": {"background": [0, 0, 0], "primitives": [
//!     {"kind": "box", "center": [0, 0, 0], "size": [8, 8, 4], "color": [0.5, 0.5, 0.5],
//!      "texture": {"random": {"seed": 3, "waves": 6, "wavelength": [0.5, 2.0], "amplitude": 0.08}}},
//!     {"kind": "sphere", "center": [2, 1, 0], "radius": 0.5, "color": [0.9, 0.2, 0.1],
//!      "texture": {"waves": [{"direction": [1, 0, 0], "wavelength": 0.3, "amplitude": 0.1}]}}
//! ]}}
//! ```
//!
//! **Rendering a ray** (what [`Camera`](super::Camera) does for each pixel). A ray
//! `o + t d̂` (`t > 0`) carries a footprint: the standard deviation `σ(t) = ς t` of a
//! Gaussian spot around the point it reaches, with `ς` the camera's spread per unit
//! length (half a pixel's pitch). The colour at a hit is the texture **filtered** by
//! that isotropic Gaussian, which a plane wave survives with a known gain:
//!
//! ```text
//! colour_σ(p) = c + Σ_i a_i exp(−|k_i|² σ² / 2) sin(k_i·p + φ_i)
//! ```
//!
//! (waves finer than the footprint fade out instead of aliasing). Each primitive the
//! ray meets has a coverage `α ∈ (0, 1]`: `1` for walls, and for a box or a sphere seen
//! from inside; for a box or a sphere seen from outside `α = S(ℓ / 2σ)` with `ℓ` the
//! length of the chord the ray cuts through it (which falls continuously to `0` at the
//! silhouette); for a disc `α = S((R − ρ) / 2σ)` with `ρ` the hit's distance from its
//! centre; `S(x) = x³(6x² − 15x + 10)` on `[0, 1]` (the smoother step, `0` below,
//! `1` above). The hits are composited front to back,
//!
//! ```text
//! value = Σ_j α_j Π_{i<j} (1 − α_i) colour_σ(p_j) + Π_j (1 − α_j) background .
//! ```
//!
//! **What is smooth.** For a fixed scene the value is a smooth function of the ray
//! (its origin and direction) wherever the primitives it meets keep their order, except
//! on these sets, which the anti-aliasing bounds as follows:
//!
//! - the silhouette of a sphere, of a box seen from outside and the rim of a disc: the
//!   coverage rises from `0` with zero first and second derivatives, over a chord (a
//!   radial distance) of two footprints, so the value is continuous and once
//!   continuously differentiable there (its derivative is of the order of the contrast
//!   over two footprints);
//! - a box's edges and corners seen from inside (a room): the texture is continuous
//!   there, the footprint too, so the value is continuous with a kink;
//! - the horizon of a wall (a ray parallel to it) and the curves where two primitives
//!   cut through each other (their order swaps): jumps, of at most the contrast
//!   between the two sides; a wall far away has faded to its base colour (its texture
//!   is filtered by a footprint growing with the distance).
//!
//! A smooth scene for tracing is therefore a room (a box around the camera) with
//! spheres, discs and boxes in it, none touching another.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize};

use super::AgentError;
use crate::params::InvalidParameter;

/// Most primitives a scene may have.
pub const MAX_SCENE_PRIMITIVES: usize = 256;

/// Most waves a primitive's texture may have.
pub const MAX_TEXTURE_WAVES: usize = 64;

/// A scene: primitives and the colour of the background (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// The primitives, in any order.
    pub primitives: Vec<Primitive>,
    /// The colour `[r, g, b]` a ray that hits nothing sees. Default black.
    #[serde(default)]
    pub background: [f64; 3],
}

/// One primitive of a [`Scene`]: its shape, colour and texture (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Primitive {
    /// An infinite plane.
    Wall(Wall),
    /// An axis-aligned box.
    Box(BoxShape),
    /// A sphere.
    Sphere(Sphere),
    /// A flat disc.
    Disc(Disc),
}

/// The kinds of [`Primitive`], as the JSON `kind` names them.
const KINDS: &str = "wall, box, sphere, disc";

impl<'de> Deserialize<'de> for Primitive {
    /// Reads `kind` first, so that an unknown kind is named with its value, then the
    /// kind's keys (unknown keys are errors that name them).
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let mut value = serde_json::Value::deserialize(deserializer)?;
        let Some(object) = value.as_object_mut() else {
            return Err(D::Error::custom(format!(
                "a scene primitive is an object with a kind ({KINDS}), found {value}"
            )));
        };
        let kind = match object.remove("kind") {
            Some(serde_json::Value::String(kind)) => kind,
            Some(other) => {
                return Err(D::Error::custom(format!(
                    "scene primitive kind = {other}; the kinds are {KINDS}"
                )))
            }
            None => {
                return Err(D::Error::custom(format!(
                    "a scene primitive has no kind; give kind = one of {KINDS}"
                )))
            }
        };
        fn read<T: serde::de::DeserializeOwned, E: serde::de::Error>(
            kind: &str,
            value: serde_json::Value,
        ) -> Result<T, E> {
            serde_json::from_value(value)
                .map_err(|e| E::custom(format!("scene primitive of kind = \"{kind}\": {e}")))
        }
        match kind.as_str() {
            "wall" => read(&kind, value).map(Primitive::Wall),
            "box" => read(&kind, value).map(Primitive::Box),
            "sphere" => read(&kind, value).map(Primitive::Sphere),
            "disc" => read(&kind, value).map(Primitive::Disc),
            _ => Err(D::Error::custom(format!(
                "unknown scene primitive kind = \"{kind}\"; the kinds are {KINDS}"
            ))),
        }
    }
}

/// An infinite plane through `point` orthogonal to `normal`, seen from both sides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wall {
    /// A point of the plane (length units).
    pub point: [f64; 3],
    /// Its normal (any length but zero).
    pub normal: [f64; 3],
    /// The base colour `[r, g, b]`.
    pub color: [f64; 3],
    /// The texture. Default: none (a uniform colour).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<Texture>,
}

/// An axis-aligned box `center ± size / 2`, seen from outside or from inside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxShape {
    /// Its centre (length units).
    pub center: [f64; 3],
    /// Its full extents along `x`, `y`, `z` (positive, length units).
    pub size: [f64; 3],
    /// The base colour `[r, g, b]`.
    pub color: [f64; 3],
    /// The texture. Default: none (a uniform colour).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<Texture>,
}

/// A sphere, seen from outside or from inside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sphere {
    /// Its centre (length units).
    pub center: [f64; 3],
    /// Its radius (positive, length units).
    pub radius: f64,
    /// The base colour `[r, g, b]`.
    pub color: [f64; 3],
    /// The texture. Default: none (a uniform colour).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<Texture>,
}

/// A flat disc, seen from both sides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Disc {
    /// Its centre (length units).
    pub center: [f64; 3],
    /// The normal of its plane (any length but zero).
    pub normal: [f64; 3],
    /// Its radius (positive, length units).
    pub radius: f64,
    /// The base colour `[r, g, b]`.
    pub color: [f64; 3],
    /// The texture. Default: none (a uniform colour).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<Texture>,
}

/// A solid texture: plane waves given one by one, or drawn from a seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum Texture {
    /// `{"waves": [{...}, ...]}`: the waves themselves.
    Waves(Vec<Wave>),
    /// `{"random": {...}}`: waves drawn from a seed.
    Random(RandomTexture),
}

/// One plane wave `a sin(2π d̂·p / λ + φ)` of a texture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wave {
    /// The direction `d̂` the wave travels along (any length but zero).
    pub direction: [f64; 3],
    /// Its wavelength `λ` (positive, length units).
    pub wavelength: f64,
    /// Its amplitude: one number (the same on every channel) or `[r, g, b]`.
    pub amplitude: Amplitude,
    /// Its phase `φ` (radians). Default 0.
    #[serde(default)]
    pub phase: f64,
}

/// A wave's amplitude: the same on every channel, or one per channel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(
    untagged,
    expecting = "an amplitude: a number (every channel) or [r, g, b]"
)]
pub enum Amplitude {
    /// The same amplitude on every channel.
    Grey(f64),
    /// One amplitude per channel.
    Rgb([f64; 3]),
}

impl Amplitude {
    /// Per channel.
    pub fn rgb(self) -> [f64; 3] {
        match self {
            Amplitude::Grey(a) => [a; 3],
            Amplitude::Rgb(a) => a,
        }
    }
}

/// Waves drawn from a seed (ChaCha8): directions uniform on the sphere, wavelengths
/// log-uniform in `wavelength = [low, high]`, phases uniform in `[0, 2π)`, and each
/// channel's amplitude uniform in `[−amplitude, amplitude]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomTexture {
    /// The seed of the draws.
    pub seed: u64,
    /// How many waves (1 to [`MAX_TEXTURE_WAVES`]).
    pub waves: usize,
    /// The range of wavelengths `[low, high]`, `0 < low ≤ high` (length units).
    pub wavelength: [f64; 2],
    /// The largest amplitude of a channel (non-negative).
    pub amplitude: f64,
}

fn invalid(value: String, reason: &str) -> AgentError {
    InvalidParameter::new("environment", "scene.primitives", value, reason).into()
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

fn norm(v: [f64; 3]) -> f64 {
    dot(v, v).sqrt()
}

#[inline(always)]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `v / ‖v‖` for a checked, non-zero `v`.
fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = norm(v);
    [v[0] / n, v[1] / n, v[2] / n]
}

/// The RGB colour of hue `h ∈ [0, 1)`, saturation `s` and value `v`.
fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [f64; 3] {
    let sector = (h * 6.0).floor();
    let f = h * 6.0 - sector;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match sector as u32 % 6 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}

impl Primitive {
    /// The kind, as JSON names it.
    pub fn kind(&self) -> &'static str {
        match self {
            Primitive::Wall(_) => "wall",
            Primitive::Box(_) => "box",
            Primitive::Sphere(_) => "sphere",
            Primitive::Disc(_) => "disc",
        }
    }

    fn surface(&self) -> ([f64; 3], Option<&Texture>) {
        match self {
            Primitive::Wall(w) => (w.color, w.texture.as_ref()),
            Primitive::Box(b) => (b.color, b.texture.as_ref()),
            Primitive::Sphere(s) => (s.color, s.texture.as_ref()),
            Primitive::Disc(d) => (d.color, d.texture.as_ref()),
        }
    }

    /// Checks the primitive's values (`index` names it) and compiles it.
    fn compile(&self, index: usize) -> Result<Compiled, AgentError> {
        let name = |key: &str, value: String| {
            format!("primitive {index} ({}): {key} = {value}", self.kind())
        };
        let point = |key: &str, p: [f64; 3]| {
            if finite(&p) {
                Ok(p)
            } else {
                Err(invalid(
                    name(key, format!("{p:?}")),
                    "a position is three finite numbers (length units)",
                ))
            }
        };
        let normal = |key: &str, n: [f64; 3]| {
            if finite(&n) && norm(n) > 0.0 {
                Ok(unit(n))
            } else {
                Err(invalid(
                    name(key, format!("{n:?}")),
                    "a normal is three finite numbers, not all zero",
                ))
            }
        };
        let radius = |r: f64| {
            if r.is_finite() && r > 0.0 {
                Ok(r)
            } else {
                Err(invalid(
                    name("radius", r.to_string()),
                    "a radius is a finite number greater than zero (length units)",
                ))
            }
        };
        let shape = match self {
            Primitive::Wall(w) => Shape::Plane {
                point: point("point", w.point)?,
                normal: normal("normal", w.normal)?,
            },
            Primitive::Box(b) => {
                let center = point("center", b.center)?;
                if !b.size.iter().all(|s| s.is_finite() && *s > 0.0) {
                    return Err(invalid(
                        name("size", format!("{:?}", b.size)),
                        "a box's size is three finite extents greater than zero (length units)",
                    ));
                }
                let half = b.size.map(|s| 0.5 * s);
                Shape::Box {
                    low: [
                        center[0] - half[0],
                        center[1] - half[1],
                        center[2] - half[2],
                    ],
                    high: [
                        center[0] + half[0],
                        center[1] + half[1],
                        center[2] + half[2],
                    ],
                }
            }
            Primitive::Sphere(s) => Shape::Sphere {
                center: point("center", s.center)?,
                radius: radius(s.radius)?,
            },
            Primitive::Disc(d) => Shape::Disc {
                center: point("center", d.center)?,
                normal: normal("normal", d.normal)?,
                radius: radius(d.radius)?,
            },
        };
        let (color, texture) = self.surface();
        if !finite(&color) {
            return Err(invalid(
                name("color", format!("{color:?}")),
                "a colour is three finite numbers [r, g, b]",
            ));
        }
        let waves = match texture {
            None => Vec::new(),
            Some(texture) => texture.compile(|value| name("texture", value))?,
        };
        Ok(Compiled {
            shape,
            color,
            waves,
        })
    }
}

impl Texture {
    /// Checks and compiles the waves (`name` locates an error).
    fn compile(&self, name: impl Fn(String) -> String) -> Result<Vec<CompiledWave>, AgentError> {
        let waves = match self {
            Texture::Waves(waves) => waves.clone(),
            Texture::Random(random) => random
                .draw()
                .map_err(|reason| invalid(name(format!("{random:?}")), &reason))?,
        };
        if waves.len() > MAX_TEXTURE_WAVES {
            return Err(invalid(
                name(format!("{} waves", waves.len())),
                "a texture has at most 64 waves",
            ));
        }
        waves
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let amplitude = w.amplitude.rgb();
                let ok = finite(&w.direction)
                    && norm(w.direction) > 0.0
                    && w.wavelength.is_finite()
                    && w.wavelength > 0.0
                    && finite(&amplitude)
                    && w.phase.is_finite();
                if !ok {
                    return Err(invalid(
                        name(format!("wave {i} {w:?}")),
                        "a wave has a finite direction, not all zero, a finite wavelength greater than zero, and finite amplitude and phase",
                    ));
                }
                let k = 2.0 * std::f64::consts::PI / w.wavelength;
                let d = unit(w.direction);
                Ok(CompiledWave {
                    k: d.map(|v| k * v),
                    half_k2: 0.5 * k * k,
                    phase: w.phase,
                    amplitude,
                })
            })
            .collect()
    }
}

impl RandomTexture {
    /// The waves of the seed (module docs), or why the parameters are out of range.
    pub fn draw(&self) -> Result<Vec<Wave>, String> {
        let [low, high] = self.wavelength;
        if self.waves == 0 || self.waves > MAX_TEXTURE_WAVES {
            return Err(format!(
                "a random texture has 1 to {MAX_TEXTURE_WAVES} waves, not {}",
                self.waves
            ));
        }
        if !(low.is_finite() && high.is_finite() && 0.0 < low && low <= high) {
            return Err(format!(
                "a random texture's wavelength = {:?} is a range [low, high] with 0 < low ≤ high (length units)",
                self.wavelength
            ));
        }
        if !(self.amplitude.is_finite() && self.amplitude >= 0.0) {
            return Err(format!(
                "a random texture's amplitude = {} is finite and non-negative",
                self.amplitude
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let ratio = (high / low).ln();
        let waves = (0..self.waves)
            .map(|_| {
                // Uniform on the sphere: z uniform in [−1, 1], the azimuth uniform.
                let z: f64 = rng.random_range(-1.0..1.0);
                let azimuth = rng.random_range(0.0..2.0 * std::f64::consts::PI);
                let r = (1.0 - z * z).max(0.0).sqrt();
                let wavelength = low * (ratio * rng.random_range(0.0..=1.0)).exp();
                let phase = rng.random_range(0.0..2.0 * std::f64::consts::PI);
                let a = self.amplitude;
                let amplitude = [(); 3].map(|_| {
                    if a > 0.0 {
                        rng.random_range(-a..=a)
                    } else {
                        0.0
                    }
                });
                Wave {
                    direction: [r * azimuth.cos(), r * azimuth.sin(), z],
                    wavelength,
                    amplitude: Amplitude::Rgb(amplitude),
                    phase,
                }
            })
            .collect();
        Ok(waves)
    }
}

impl Scene {
    /// A room: the box `±size/2` around the origin seen from inside, mid-grey with a
    /// random solid texture of 6 waves (seeded by `seed`) of wavelengths between an
    /// eighth and a half of the room's smallest extent and amplitudes up to 0.08 per
    /// channel (colours stay within `0.5 ± 0.48`), on a black background. Its image is
    /// continuous everywhere inside (module docs). Check it with [`Scene::check`].
    pub fn textured_room(size: [f64; 3], seed: u64) -> Scene {
        let smallest = size.iter().copied().fold(f64::INFINITY, f64::min);
        Scene {
            primitives: vec![Primitive::Box(BoxShape {
                center: [0.0; 3],
                size,
                color: [0.5; 3],
                texture: Some(Texture::Random(RandomTexture {
                    seed,
                    waves: 6,
                    wavelength: [smallest / 8.0, smallest / 2.0],
                    amplitude: 0.08,
                })),
            })],
            background: [0.0; 3],
        }
    }

    /// [`textured_room`](Self::textured_room) with `objects` on its floor, in the manner
    /// of Laflaquière & Garcia Ortiz's room (NeurIPS 2019: 16 objects on a jittered
    /// 4 × 4 grid of a 7 × 7 room), all drawn from `seed` (ChaCha8):
    ///
    /// - the sites: a `g × g` grid, `g = ⌈√objects⌉`, spanning `±0.356` of the room's
    ///   `x` and `y` extents (`±2.49` in a room of 7), spaced `δ_x` and `δ_y` apart,
    ///   of which `objects` are taken in a random order, each moved by up to
    ///   `±0.18 δ` along each axis (`±0.3` for 16 objects in 7);
    /// - the shapes: a cube of side `a = 0.51 min(δ_x, δ_y)` (0.85 for 16 objects in 7;
    ///   a single object: `0.121 min(x, y)`) or a sphere of diameter `a`, either with
    ///   probability ½, standing on the floor `z = −size_z/2`;
    /// - the colours: one of 12 hues, saturation and value 0.9, with a random texture
    ///   of 4 waves of wavelengths between `a/4` and `2a`, amplitude up to 0.05.
    ///
    /// Neighbours stay at least `0.13 δ` apart and every object touches the floor only
    /// along its base, so the image is smooth but for silhouettes ([`Scene`]'s docs).
    /// At most [`MAX_SCENE_PRIMITIVES`] − 1 objects: more are refused, naming the
    /// key `objects`.
    pub fn furnished_room(size: [f64; 3], objects: usize, seed: u64) -> Result<Scene, AgentError> {
        if objects >= MAX_SCENE_PRIMITIVES {
            return Err(InvalidParameter::new(
                "environment",
                "objects",
                objects,
                format!("a room holds at most {} objects (a scene has at most {MAX_SCENE_PRIMITIVES} primitives, the room one of them)", MAX_SCENE_PRIMITIVES - 1),
            )
            .into());
        }
        let mut scene = Scene::textured_room(size, seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x006f_626a_6563_7473);
        let side = (objects as f64).sqrt().ceil() as usize;
        let reach = [0.356 * size[0], 0.356 * size[1]];
        let spacing = reach.map(|r| 2.0 * r / side.saturating_sub(1).max(1) as f64);
        let (a, jitter) = if side < 2 {
            (
                0.121 * size[0].min(size[1]),
                [0.043 * size[0], 0.043 * size[1]],
            )
        } else {
            (0.51 * spacing[0].min(spacing[1]), spacing.map(|d| 0.18 * d))
        };
        let site = |i: usize, axis: usize| {
            if side < 2 {
                0.0
            } else {
                -reach[axis] + spacing[axis] * i as f64
            }
        };
        let mut sites: Vec<usize> = (0..side * side).collect();
        for i in (1..sites.len()).rev() {
            let j = rng.random_range(0..=i);
            sites.swap(i, j);
        }
        let floor = -0.5 * size[2];
        for (k, &cell) in sites.iter().take(objects).enumerate() {
            let x = site(cell % side, 0) + rng.random_range(-jitter[0]..=jitter[0]);
            let y = site(cell / side, 1) + rng.random_range(-jitter[1]..=jitter[1]);
            let hue = rng.random_range(0..12) as f64 / 12.0;
            let color = hsv_to_rgb(hue, 0.9, 0.9);
            let texture = Some(Texture::Random(RandomTexture {
                seed: seed.wrapping_add(1 + k as u64),
                waves: 4,
                wavelength: [a / 4.0, 2.0 * a],
                amplitude: 0.05,
            }));
            let primitive = if rng.random_bool(0.5) {
                Primitive::Box(BoxShape {
                    center: [x, y, floor + 0.5 * a],
                    size: [a; 3],
                    color,
                    texture,
                })
            } else {
                Primitive::Sphere(Sphere {
                    center: [x, y, floor + 0.5 * a],
                    radius: 0.5 * a,
                    color,
                    texture,
                })
            };
            scene.primitives.push(primitive);
        }
        Ok(scene)
    }

    /// Checks every value: at most [`MAX_SCENE_PRIMITIVES`] primitives, finite
    /// positions and colours, positive radii and sizes, non-zero normals, and textures
    /// of finite waves. The error names the primitive (by index), the key and the
    /// value.
    pub fn check(&self) -> Result<(), AgentError> {
        self.compile().map(|_| ())
    }

    /// The checked scene, ready to render.
    pub(super) fn compile(&self) -> Result<CompiledScene, AgentError> {
        if self.primitives.len() > MAX_SCENE_PRIMITIVES {
            return Err(InvalidParameter::new(
                "environment",
                "scene.primitives",
                format!("{} primitives", self.primitives.len()),
                "a scene has at most 256 primitives",
            )
            .into());
        }
        if !finite(&self.background) {
            return Err(InvalidParameter::new(
                "environment",
                "scene.background",
                format!("{:?}", self.background),
                "a colour is three finite numbers [r, g, b]",
            )
            .into());
        }
        let primitives = self
            .primitives
            .iter()
            .enumerate()
            .map(|(i, p)| p.compile(i))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(CompiledScene {
            primitives,
            background: self.background,
        })
    }
}

/// A checked scene in the form a ray is traced through.
#[derive(Debug, Clone)]
pub(super) struct CompiledScene {
    primitives: Vec<Compiled>,
    background: [f64; 3],
}

#[derive(Debug, Clone)]
struct Compiled {
    shape: Shape,
    color: [f64; 3],
    waves: Vec<CompiledWave>,
}

#[derive(Debug, Clone, Copy)]
struct CompiledWave {
    /// The wave vector `k = 2π d̂ / λ`.
    k: [f64; 3],
    /// `|k|² / 2`.
    half_k2: f64,
    phase: f64,
    amplitude: [f64; 3],
}

#[derive(Debug, Clone, Copy)]
enum Shape {
    Plane {
        point: [f64; 3],
        normal: [f64; 3],
    },
    Box {
        low: [f64; 3],
        high: [f64; 3],
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    Disc {
        center: [f64; 3],
        normal: [f64; 3],
        radius: f64,
    },
}

/// Hits closer than this (length units) are the ray's own origin, not a surface.
const MIN_DISTANCE: f64 = 1e-9;

/// The filtered texture gain below which a wave is not evaluated (`exp(−40)`, far
/// below a double's resolution of a colour of order 1).
const NEGLIGIBLE_EXPONENT: f64 = 40.0;

/// A ray's hit of one primitive: distance, coverage, primitive.
#[derive(Debug, Clone, Copy)]
pub(super) struct Hit {
    distance: f64,
    coverage: f64,
    primitive: usize,
}

/// The smoother step `x³(6x² − 15x + 10)` on `[0, 1]`, `0` below, `1` above.
#[inline]
fn smoother_step(x: f64) -> f64 {
    if x <= 0.0 {
        0.0
    } else if x >= 1.0 {
        1.0
    } else {
        x * x * x * (x * (6.0 * x - 15.0) + 10.0)
    }
}

impl Shape {
    /// The ray `origin + t direction` (unit `direction`) against the shape:
    /// `(t, α)` of the visible hit, or none. `spread` is the footprint's standard
    /// deviation per unit length.
    #[inline]
    fn hit(&self, origin: [f64; 3], direction: [f64; 3], spread: f64) -> Option<(f64, f64)> {
        match *self {
            Shape::Plane { point, normal } => {
                let facing = dot(normal, direction);
                if facing == 0.0 {
                    return None;
                }
                let t = dot(normal, sub(point, origin)) / facing;
                (t > MIN_DISTANCE && t.is_finite()).then_some((t, 1.0))
            }
            Shape::Box { low, high } => {
                let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
                for axis in 0..3 {
                    let d = direction[axis];
                    if d == 0.0 {
                        if origin[axis] < low[axis] || origin[axis] > high[axis] {
                            return None;
                        }
                        continue;
                    }
                    let inverse = 1.0 / d;
                    let a = (low[axis] - origin[axis]) * inverse;
                    let b = (high[axis] - origin[axis]) * inverse;
                    let (a, b) = if a < b { (a, b) } else { (b, a) };
                    near = near.max(a);
                    far = far.min(b);
                }
                if far < near || far <= MIN_DISTANCE {
                    return None;
                }
                if near > MIN_DISTANCE {
                    // From outside: coverage by the chord.
                    let coverage = smoother_step((far - near) / (2.0 * spread * near));
                    (coverage > 0.0).then_some((near, coverage))
                } else {
                    Some((far, 1.0))
                }
            }
            Shape::Sphere { center, radius } => {
                let to_center = sub(center, origin);
                let along = dot(to_center, direction);
                let distance2 = dot(to_center, to_center);
                let miss2 = distance2 - along * along;
                let half_chord2 = radius * radius - miss2;
                if half_chord2 <= 0.0 {
                    return None;
                }
                let half_chord = half_chord2.sqrt();
                if distance2 < radius * radius {
                    // From inside.
                    return Some((along + half_chord, 1.0));
                }
                let t = along - half_chord;
                if t <= MIN_DISTANCE {
                    return None;
                }
                let coverage = smoother_step(2.0 * half_chord / (2.0 * spread * t));
                (coverage > 0.0).then_some((t, coverage))
            }
            Shape::Disc {
                center,
                normal,
                radius,
            } => {
                let facing = dot(normal, direction);
                if facing == 0.0 {
                    return None;
                }
                let t = dot(normal, sub(center, origin)) / facing;
                if !(t > MIN_DISTANCE && t.is_finite()) {
                    return None;
                }
                let p = [
                    origin[0] + t * direction[0] - center[0],
                    origin[1] + t * direction[1] - center[1],
                    origin[2] + t * direction[2] - center[2],
                ];
                let rho = norm(p);
                if rho >= radius {
                    return None;
                }
                let coverage = smoother_step((radius - rho) / (2.0 * spread * t));
                (coverage > 0.0).then_some((t, coverage))
            }
        }
    }
}

/// `sin x`, to a few units in the last place for `|x| < 2²⁰ π/2` (fdlibm's reduction
/// by `π/2` in two parts and its kernels on `[−π/4, π/4]`; `f64::sin` beyond), in
/// plain arithmetic: the same value on every thread and machine, several times faster
/// than the C library's (textures call it once per wave and pixel).
#[inline]
#[allow(
    clippy::excessive_precision,
    reason = "fdlibm's constants, written as published"
)]
fn sine(x: f64) -> f64 {
    const TWO_OVER_PI: f64 = std::f64::consts::FRAC_2_PI;
    // π/2 = PIO2_1 + PIO2_1T, PIO2_1 with 33 significant bits (n · PIO2_1 exact).
    const PIO2_1: f64 = 1.570_796_326_734_125_614_17;
    const PIO2_1T: f64 = 6.077_100_506_506_192_249_32e-11;
    const S: [f64; 6] = [
        -1.666_666_666_666_663_243_48e-1,
        8.333_333_333_322_489_461_24e-3,
        -1.984_126_982_985_794_931_34e-4,
        2.755_731_370_707_006_767_89e-6,
        -2.505_076_025_340_686_341_95e-8,
        1.589_690_995_211_550_102_21e-10,
    ];
    const C: [f64; 6] = [
        4.166_666_666_666_660_190_37e-2,
        -1.388_888_888_887_410_957_49e-3,
        2.480_158_728_947_672_941_78e-5,
        -2.755_731_435_139_066_330_35e-7,
        2.087_572_321_298_174_827_90e-9,
        -1.135_964_755_778_819_482_65e-11,
    ];
    if x.is_nan() || x.abs() >= 1.0e6 {
        return x.sin();
    }
    // Rounding to the nearest integer by adding and subtracting 1.5 · 2⁵² (no call
    // to the library's `round`), exact for these magnitudes.
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let n = (x * TWO_OVER_PI + ROUND) - ROUND;
    let r = (x - n * PIO2_1) - n * PIO2_1T;
    let z = r * r;
    let quadrant = (n as i64) & 3;
    // Both kernels, then a selection: quadrants change from pixel to pixel, and a
    // branch on them would be mispredicted.
    let sin_poly = S[0] + z * (S[1] + z * (S[2] + z * (S[3] + z * (S[4] + z * S[5]))));
    let cos_poly = C[0] + z * (C[1] + z * (C[2] + z * (C[3] + z * (C[4] + z * C[5]))));
    let s = r + r * z * sin_poly;
    let c = 1.0 - 0.5 * z + z * z * cos_poly;
    let value = if quadrant & 1 == 0 { s } else { c };
    let sign = if quadrant & 2 == 0 { 1.0 } else { -1.0 };
    sign * value
}

impl Compiled {
    /// The texture at `p` filtered by a Gaussian of standard deviation `sigma`.
    #[inline]
    fn colour(&self, p: [f64; 3], sigma: f64) -> [f64; 3] {
        let mut c = self.color;
        let sigma2 = sigma * sigma;
        for w in &self.waves {
            let exponent = w.half_k2 * sigma2;
            if exponent > NEGLIGIBLE_EXPONENT {
                continue;
            }
            let v = (-exponent).exp() * sine(dot(w.k, p) + w.phase);
            c[0] += w.amplitude[0] * v;
            c[1] += w.amplitude[1] * v;
            c[2] += w.amplitude[2] * v;
        }
        c
    }
}

impl CompiledScene {
    /// The colour the ray `origin + t direction` (unit `direction`, footprint `σ(t) =
    /// spread · t`) sees: its hits composited front to back over the background
    /// (module docs). `hits` is scratch space, reused from ray to ray.
    pub(super) fn trace(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        spread: f64,
        hits: &mut Vec<Hit>,
    ) -> [f64; 3] {
        hits.clear();
        for (i, primitive) in self.primitives.iter().enumerate() {
            if let Some((distance, coverage)) = primitive.shape.hit(origin, direction, spread) {
                hits.push(Hit {
                    distance,
                    coverage,
                    primitive: i,
                });
            }
        }
        // Insertion sort by distance, then index: few hits, and a fixed order on ties.
        for i in 1..hits.len() {
            let mut j = i;
            while j > 0
                && (hits[j].distance, hits[j].primitive)
                    < (hits[j - 1].distance, hits[j - 1].primitive)
            {
                hits.swap(j, j - 1);
                j -= 1;
            }
        }
        let mut value = [0.0; 3];
        let mut transmitted = 1.0;
        for hit in hits.iter() {
            let t = hit.distance;
            let p = [
                origin[0] + t * direction[0],
                origin[1] + t * direction[1],
                origin[2] + t * direction[2],
            ];
            let c = self.primitives[hit.primitive].colour(p, spread * t);
            let weight = transmitted * hit.coverage;
            for (v, c) in value.iter_mut().zip(c) {
                *v += weight * c;
            }
            transmitted *= 1.0 - hit.coverage;
            if transmitted == 0.0 {
                return value;
            }
        }
        for (v, b) in value.iter_mut().zip(self.background) {
            *v += transmitted * b;
        }
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    fn parse(json: &str) -> Result<Scene, serde_json::Error> {
        serde_json::from_str(json)
    }

    #[test]
    fn json_names_unknown_kinds_and_keys() {
        let err = parse(r#"{"primitives": [{"kind": "cone", "color": [1, 1, 1]}]}"#)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("kind = \"cone\"") && err.contains("sphere"),
            "{err}"
        );
        let err = parse(r#"{"primitives": [{"kind": "sphere", "center": [0,0,0], "radius": 1, "color": [1,1,1], "radiu": 2}]}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("radiu"), "{err}");
        let scene = Scene::textured_room([4.0, 4.0, 2.0], 3);
        let round: Scene = parse(&serde_json::to_string(&scene).unwrap()).unwrap();
        assert_eq!(round, scene);
    }

    #[test]
    fn bad_values_name_primitive_key_and_value() {
        let scene = |p: &str| parse(&format!(r#"{{"primitives": [{p}]}}"#)).unwrap();
        let err = scene(r#"{"kind": "sphere", "center": [0,0,0], "radius": -1, "color": [1,1,1]}"#)
            .check()
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("radius = -1") && err.contains("primitive 0 (sphere)"),
            "{err}"
        );
        let err =
            scene(r#"{"kind": "wall", "point": [0,0,0], "normal": [0,0,0], "color": [1,1,1]}"#)
                .check()
                .unwrap_err()
                .to_string();
        assert!(err.contains("normal = [0.0, 0.0, 0.0]"), "{err}");
        let err =
            scene(r#"{"kind": "box", "center": [0,0,0], "size": [1,-2,1], "color": [1,1,1]}"#)
                .check()
                .unwrap_err()
                .to_string();
        assert!(err.contains("size = [1.0, -2.0, 1.0]"), "{err}");
        let mut room = Scene::textured_room([4.0, 4.0, 2.0], 3);
        room.check().unwrap();
        room.primitives[0] = Primitive::Box(BoxShape {
            center: [0.0; 3],
            size: [1.0; 3],
            color: [0.5; 3],
            texture: Some(Texture::Random(RandomTexture {
                seed: 1,
                waves: 0,
                wavelength: [1.0, 2.0],
                amplitude: 0.1,
            })),
        });
        let err = room.check().unwrap_err().to_string();
        assert!(err.contains("1 to 64 waves"), "{err}");
    }

    #[test]
    fn sine_matches_the_library_sine() {
        let mut worst: f64 = 0.0;
        for i in -200_000..=200_000 {
            let x = i as f64 * 1.0e-3 + 1.0e-7 * (i % 7) as f64;
            worst = worst.max((sine(x) - x.sin()).abs());
        }
        assert!(worst < 1e-15, "{worst}");
        for x in [0.0, -0.0, 1e-300, 1e7, -3e8, f64::NAN, f64::INFINITY] {
            let (a, b) = (sine(x), x.sin());
            assert!(a == b || (a.is_nan() && b.is_nan()), "{x}: {a} vs {b}");
        }
    }

    #[test]
    fn sphere_coverage_fades_to_zero_at_the_silhouette() {
        let scene = Scene {
            primitives: vec![Primitive::Sphere(Sphere {
                center: [5.0, 0.0, 0.0],
                radius: 1.0,
                color: [1.0; 3],
                texture: None,
            })],
            background: [0.0; 3],
        }
        .compile()
        .unwrap();
        let mut hits = Vec::new();
        let value = |y: f64, hits: &mut Vec<Hit>| {
            let d = unit([5.0, y, 0.0]);
            scene.trace([0.0; 3], d, 0.05, hits)[0]
        };
        assert_abs_diff_eq!(value(0.0, &mut hits), 1.0);
        assert_abs_diff_eq!(value(1.1, &mut hits), 0.0);
        // Monotone across the silhouette, continuous.
        let mut last = 1.0;
        for i in 0..500 {
            let y = 0.95 + 0.0002 * i as f64;
            let v = value(y, &mut hits);
            assert!(
                v <= last + 1e-12 && (last - v) < 0.05,
                "{y}: {v} after {last}"
            );
            last = v;
        }
    }
}
