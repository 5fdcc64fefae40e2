//! Environments: point lights in the plane or in a volume, drawn from a seed or loaded
//! from JSON.
//!
//! A random environment draws `lights` positions in a rectangle (`center ± half_size`)
//! minus an inner rectangle (`center ± exclusion_half_size`), from a ChaCha8 stream
//! seeded with `seed`: the same seed gives the same lights on every machine. The draws
//! are stratified by direction: light `l` of `L` is uniform in the part of the region
//! seen from the centre at angles `[2πl/L, 2π(l+1)/L)`, so that lights surround the
//! centre and a sensor looking any way sees some (a rich environment, paper section
//! 2.3). For an agent that senses lights in a volume ([`LightSpace::Volume`], a 3-D
//! chain), each accepted light then draws its height `z` uniformly from the agent's
//! [`default_light_heights`](super::Agent::default_light_heights), from the same
//! stream: the region is a box minus a vertical column around the working space.
//!
//! The JSON form is `{"lights": [[x, y], ...], "seed": 1}` in the plane and
//! `{"lights": [[x, y, z], ...]}` in a volume: every light has the same number of
//! coordinates, and an environment whose lights do not live where the agent senses
//! them (`[x, y]` for a 3-D chain, `[x, y, z]` for a planar agent) is refused by
//! [`Environment::check_for`].
//!
//! **Intensities and changes of the environment**. Every light has an
//! intensity, a factor on its contribution to every sensor (`1` by default: the JSON
//! form then has no `intensities` key, and every sensation is bit for bit what it was
//! without intensities). The changes an agent can experience without moving are
//! [`Environment::displaced`] (a rigid displacement of the whole scene: a rotation then a
//! translation of every light) and [`Environment::scaled`] (a common scaling of all
//! intensities, a change of luminance); [`Environment::with_intensities`] sets each
//! light's own.
//!
//! **Scenes.** An environment may also hold a [`Scene`] (JSON key `scene`, module
//! [`Scene`]'s docs): textured walls, boxes, spheres and discs, what a camera
//! ([`Stimulus::Scene`]) looks at. An environment with a scene may have no lights
//! (`lights` is then optional in the file).

use std::path::Path;

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::{Agent, AgentError, Scene};
use crate::io::{self, IoError};
use crate::params::InvalidParameter;

/// A rectangle (minus an inner rectangle) where random lights are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightRegion {
    /// Centre of both rectangles.
    pub center: [f64; 2],
    /// Half extents of the outer rectangle.
    pub half_size: [f64; 2],
    /// Half extents of the inner rectangle kept free of lights (`[0, 0]`: none).
    pub exclusion_half_size: [f64; 2],
}

impl LightRegion {
    fn contains_excluded(&self, p: [f64; 2]) -> bool {
        (p[0] - self.center[0]).abs() < self.exclusion_half_size[0]
            && (p[1] - self.center[1]).abs() < self.exclusion_half_size[1]
    }

    /// Checks that every value is finite, the half sizes positive (the exclusion's
    /// non-negative), and that the exclusion leaves room for lights.
    pub fn check(&self) -> Result<(), InvalidParameter> {
        let finite = self
            .center
            .iter()
            .chain(&self.half_size)
            .chain(&self.exclusion_half_size)
            .all(|v| v.is_finite());
        let positive = self.half_size.iter().all(|&h| h > 0.0)
            && self.exclusion_half_size.iter().all(|&h| h >= 0.0);
        let room = self.exclusion_half_size[0] < self.half_size[0]
            || self.exclusion_half_size[1] < self.half_size[1];
        if finite && positive && room {
            Ok(())
        } else {
            Err(InvalidParameter::new(
                "environment",
                "region",
                format!("{self:?}"),
                "a light region needs finite values, positive half sizes, and an exclusion smaller than the region",
            ))
        }
    }
}

/// Most lights [`Environment::random`] draws.
pub const MAX_RANDOM_LIGHTS: usize = 2_000;

/// Most draws spent on one random light before the region is declared too small.
pub const MAX_DRAWS_PER_LIGHT: usize = 10_000_000;

/// Where an environment's lights live (and where an agent senses them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightSpace {
    /// In the plane `z = 0`: lights `[x, y]` (the paper's agents, planar chains).
    Plane,
    /// In a volume: lights `[x, y, z]` (3-D chains).
    Volume,
}

impl LightSpace {
    /// The number of coordinates of a light: 2 or 3.
    pub fn coordinates(self) -> usize {
        match self {
            LightSpace::Plane => 2,
            LightSpace::Volume => 3,
        }
    }
}

/// What an agent senses in its environment ([`Agent::stimulus`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stimulus {
    /// The point lights (every retina).
    Lights,
    /// The scene (a camera).
    Scene,
}

/// The environment `E`: a set of point lights, and optionally a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "EnvironmentFile", into = "EnvironmentFile")]
pub struct Environment {
    /// Positions `[x, y, z]` of the point lights (`z = 0` in the plane).
    pub lights: Vec<[f64; 3]>,
    /// Whether the lights are in the plane (2 coordinates in files) or in a volume.
    pub space: LightSpace,
    /// The seed the lights were drawn from, if they were drawn.
    pub seed: Option<u64>,
    /// Each light's intensity (a factor on its contribution to every sensor); empty:
    /// all `1` (the paper's lights).
    pub intensities: Vec<f64>,
    /// The scene a camera looks at; none by default.
    pub scene: Option<Scene>,
}

/// The JSON form of an [`Environment`]: 2 or 3 coordinates per light.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentFile {
    #[serde(default)]
    lights: Vec<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    seed: Option<u64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    intensities: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    scene: Option<Scene>,
}

impl TryFrom<EnvironmentFile> for Environment {
    type Error = String;
    fn try_from(file: EnvironmentFile) -> Result<Self, String> {
        let width = file.lights.first().map_or(2, Vec::len);
        let space = match width {
            2 => LightSpace::Plane,
            3 => LightSpace::Volume,
            n => {
                return Err(format!(
                    "light 0 has {n} coordinates; a light is [x, y] (in the plane) or [x, y, z] (in a volume)"
                ))
            }
        };
        let mut lights = Vec::with_capacity(file.lights.len());
        for (i, light) in file.lights.iter().enumerate() {
            if light.len() != width {
                return Err(format!(
                    "light {i} has {} coordinates but light 0 has {width}; the lights of one environment are all [x, y] (in the plane) or all [x, y, z] (in a volume)",
                    light.len()
                ));
            }
            lights.push([light[0], light[1], light.get(2).copied().unwrap_or(0.0)]);
        }
        if !file.intensities.is_empty() && file.intensities.len() != lights.len() {
            return Err(format!(
                "{} intensities for {} lights; give one intensity per light (or none: all 1)",
                file.intensities.len(),
                lights.len()
            ));
        }
        Ok(Self {
            lights,
            space,
            seed: file.seed,
            intensities: file.intensities,
            scene: file.scene,
        })
    }
}

impl From<Environment> for EnvironmentFile {
    fn from(env: Environment) -> Self {
        let width = env.space.coordinates();
        Self {
            lights: env.lights.iter().map(|l| l[..width].to_vec()).collect(),
            seed: env.seed,
            intensities: env.intensities,
            scene: env.scene,
        }
    }
}

impl Environment {
    /// An environment with the given lights in the plane.
    pub fn from_lights(lights: Vec<[f64; 2]>) -> Self {
        Self {
            lights: lights.into_iter().map(|[x, y]| [x, y, 0.0]).collect(),
            space: LightSpace::Plane,
            seed: None,
            intensities: Vec::new(),
            scene: None,
        }
    }

    /// An environment of a scene and no lights (what a camera looks at).
    pub fn from_scene(scene: Scene) -> Self {
        Self {
            scene: Some(scene),
            ..Self::from_lights(Vec::new())
        }
    }

    /// An environment with the given lights in a volume.
    pub fn from_lights_3d(lights: Vec<[f64; 3]>) -> Self {
        Self {
            lights,
            space: LightSpace::Volume,
            seed: None,
            intensities: Vec::new(),
            scene: None,
        }
    }

    /// `count` lights drawn in `region`, stratified by direction from its centre (see
    /// the module docs), from a stream seeded with `seed`.
    ///
    /// At most [`MAX_RANDOM_LIGHTS`] lights (light `i` is drawn until it falls in its
    /// sector, so the work grows as `count²`), and at most [`MAX_DRAWS_PER_LIGHT`]
    /// draws per light: a region whose exclusion leaves a sector empty is an error.
    pub fn random(count: usize, seed: u64, region: &LightRegion) -> Result<Self, AgentError> {
        Self::random_in(count, seed, region, None)
    }

    /// `count` lights drawn as [`random`](Self::random) in the plane, each then given a
    /// height `z` drawn uniformly from `heights = [low, high]` (from the same stream):
    /// lights in a volume.
    pub fn random_volume(
        count: usize,
        seed: u64,
        region: &LightRegion,
        heights: [f64; 2],
    ) -> Result<Self, AgentError> {
        if !(heights.iter().all(|h| h.is_finite()) && heights[0] < heights[1]) {
            return Err(InvalidParameter::new(
                "environment",
                "heights",
                format!("{heights:?}"),
                "the heights of lights in a volume are two finite numbers [low, high] with low < high",
            )
            .into());
        }
        Self::random_in(count, seed, region, Some(heights))
    }

    fn random_in(
        count: usize,
        seed: u64,
        region: &LightRegion,
        heights: Option<[f64; 2]>,
    ) -> Result<Self, AgentError> {
        region.check()?;
        if count > MAX_RANDOM_LIGHTS {
            return Err(InvalidParameter::new(
                "environment",
                "lights",
                count,
                format!(
                    "at most {MAX_RANDOM_LIGHTS} random lights (the paper uses 10); \
                     for more, write the lights into an environment file"
                ),
            )
            .into());
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut lights = Vec::with_capacity(count);
        let sector = 2.0 * std::f64::consts::PI / count.max(1) as f64;
        let mut draws = 0;
        while lights.len() < count {
            draws += 1;
            if draws > MAX_DRAWS_PER_LIGHT {
                return Err(InvalidParameter::new(
                    "environment",
                    "region",
                    format!("{region:?}"),
                    format!(
                        "cannot place light {} of {count}: after {MAX_DRAWS_PER_LIGHT} draws none fell in its direction sector outside the exclusion; \
                         make the exclusion smaller or use fewer lights",
                        lights.len()
                    ),
                )
                .into());
            }
            let p = [
                region.center[0] + region.half_size[0] * rng.random_range(-1.0..1.0),
                region.center[1] + region.half_size[1] * rng.random_range(-1.0..1.0),
            ];
            let angle = (p[1] - region.center[1])
                .atan2(p[0] - region.center[0])
                .rem_euclid(2.0 * std::f64::consts::PI);
            let wanted = lights.len() as f64 * sector;
            if !region.contains_excluded(p) && (wanted..wanted + sector).contains(&angle) {
                let z = heights.map_or(0.0, |[low, high]| rng.random_range(low..high));
                lights.push([p[0], p[1], z]);
                draws = 0;
            }
        }
        Ok(Self {
            lights,
            space: match heights {
                None => LightSpace::Plane,
                Some(_) => LightSpace::Volume,
            },
            seed: Some(seed),
            intensities: Vec::new(),
            scene: None,
        })
    }

    /// The intensity of light `l` (`1` when the environment gives none).
    #[inline]
    pub fn intensity(&self, l: usize) -> f64 {
        self.intensities.get(l).copied().unwrap_or(1.0)
    }

    /// The same lights with these intensities (one per light).
    pub fn with_intensities(&self, intensities: Vec<f64>) -> Result<Self, AgentError> {
        if intensities.len() != self.lights.len() || !intensities.iter().all(|v| v.is_finite()) {
            return Err(AgentError::InvalidEnvironment {
                reason: format!(
                    "{} intensities for {} lights; give one finite intensity per light",
                    intensities.len(),
                    self.lights.len()
                ),
            });
        }
        Ok(Self {
            intensities,
            ..self.clone()
        })
    }

    /// The scene displaced rigidly: every light `q` goes to `R q + t`, with `rotation`
    /// the row-major matrix `R` (a rotation) and `translation` `t` (in the plane, use a
    /// rotation about `z` and `t_z = 0`). Intensities are kept.
    pub fn displaced(&self, rotation: &[[f64; 3]; 3], translation: [f64; 3]) -> Self {
        let lights = self
            .lights
            .iter()
            .map(|q| {
                let mut p = translation;
                for (pi, row) in p.iter_mut().zip(rotation) {
                    *pi += row[0] * q[0] + row[1] * q[1] + row[2] * q[2];
                }
                p
            })
            .collect();
        Self {
            lights,
            ..self.clone()
        }
    }

    /// Every light's intensity multiplied by `factor` (a common change of luminance).
    pub fn scaled(&self, factor: f64) -> Self {
        let intensities = (0..self.lights.len())
            .map(|l| factor * self.intensity(l))
            .collect();
        Self {
            intensities,
            ..self.clone()
        }
    }

    /// Reads an environment from its JSON file and checks it.
    pub fn load(path: &Path) -> Result<Self, AgentError> {
        let env: Environment = io::read_json(path, "environment")?;
        env.check().map_err(|e| match e {
            AgentError::InvalidEnvironment { reason } => AgentError::InvalidEnvironment {
                reason: format!("{}: {reason}", path.display()),
            },
            other => other,
        })?;
        Ok(env)
    }

    /// Writes the environment as JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<(), IoError> {
        io::write_json(path, self)
    }

    /// Checks that there is a light or a scene, that every light position is finite,
    /// and the scene's values ([`Scene::check`]).
    pub fn check(&self) -> Result<(), AgentError> {
        if let Some(scene) = &self.scene {
            scene.check()?;
        }
        if self.lights.is_empty() && self.scene.is_none() {
            return Err(AgentError::InvalidEnvironment {
                reason: "no lights: an environment without lights gives constant sensors; give at least one light".into(),
            });
        }
        if let Some((i, l)) = self
            .lights
            .iter()
            .enumerate()
            .find(|(_, l)| !l.iter().all(|v| v.is_finite()))
        {
            let l = &l[..self.space.coordinates()];
            return Err(AgentError::InvalidEnvironment {
                reason: format!("light {i} is at {l:?}; positions must be finite numbers"),
            });
        }
        if let Some((i, v)) = self
            .intensities
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
        {
            return Err(AgentError::InvalidEnvironment {
                reason: format!(
                    "light {i} has intensity {v}; intensities must be finite and non-negative"
                ),
            });
        }
        Ok(())
    }

    /// Checks the environment ([`Environment::check`]: at least one light, finite
    /// values) and that the lights live where `agent` senses them
    /// ([`Agent::light_space`]): `[x, y]` for a planar agent, `[x, y, z]` for one in 3-D.
    ///
    /// An agent that senses a scene ([`Stimulus::Scene`], a camera) needs one, and must
    /// see something of it: its sensors at the home pose (every motor at 0, or at the
    /// middle of its range) must not all be equal.
    pub fn check_for(&self, agent: &dyn Agent) -> Result<(), AgentError> {
        self.check()?;
        if agent.stimulus() == Stimulus::Scene {
            return self.check_scene_for(agent);
        }
        let wanted = agent.light_space();
        if self.space == wanted {
            return Ok(());
        }
        let reason = match wanted {
            LightSpace::Volume => format!(
                "the {} agent senses lights in a volume but the environment's lights have 2 coordinates [x, y]; write every light as [x, y, z] (z = 0 for lights in the plane)",
                agent.name()
            ),
            LightSpace::Plane => format!(
                "the {} agent senses lights in the plane z = 0 but the environment's lights have 3 coordinates [x, y, z]; write every light as [x, y]",
                agent.name()
            ),
        };
        Err(AgentError::InvalidEnvironment { reason })
    }
}

impl Environment {
    /// The checks of [`check_for`](Self::check_for) for an agent that senses a scene.
    fn check_scene_for(&self, agent: &dyn Agent) -> Result<(), AgentError> {
        if self.scene.is_none() {
            return Err(AgentError::InvalidEnvironment {
                reason: format!(
                    "the {} agent has a camera, which looks at a scene, but the environment has none; give the environment a \"scene\" (textured walls, boxes, spheres and discs)",
                    agent.name()
                ),
            });
        }
        let home = agent.motor_space().home();
        let mut sensors = vec![0.0; agent.sensor_dim()];
        agent.sense(self, &home, &mut sensors);
        let first = sensors.first().copied().unwrap_or(0.0);
        if sensors.iter().all(|&v| v == first) {
            return Err(AgentError::InvalidEnvironment {
                reason: format!(
                    "the {} agent's camera sees nothing at its home pose (motors {home:?}): all {} sensors read {first}; place primitives in its view (or a textured room around it)",
                    agent.name(),
                    sensors.len()
                ),
            });
        }
        Ok(())
    }
}

/// How to make the environment: the `[environment]` table of an experiment file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvironmentConfig {
    /// Number of random lights (default: the agent's, 5 for the toys and 10 for the arm).
    pub lights: Option<usize>,
    /// Seed of the random lights. Default 1.
    pub seed: u64,
    /// Where the lights are drawn (default: the agent's region, around its working space).
    pub region: Option<LightRegion>,
    /// For an agent with a camera: the extents `[x, y, z]` of the textured room around
    /// the origin it looks at ([`Scene::textured_room`], its texture seeded by `seed`).
    /// Default: the agent's light region's outer rectangle, widened to be centred on
    /// the origin (`2 (|c_x| + h_x)` by `2 (|c_y| + h_y)`), as tall as it is narrow.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub room: Option<[f64; 3]>,
    /// For an agent with a camera: how many objects (cubes and spheres of random
    /// colours, seeded by `seed`) stand on the room's floor
    /// ([`Scene::furnished_room`]). Default 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub objects: usize,
}

fn is_zero(value: &usize) -> bool {
    *value == 0
}

impl Default for EnvironmentConfig {
    fn default() -> Self {
        Self {
            lights: None,
            seed: 1,
            region: None,
            room: None,
            objects: 0,
        }
    }
}

impl EnvironmentConfig {
    /// Draws the environment for `agent`.
    pub fn build(&self, agent: &dyn Agent) -> Result<Environment, AgentError> {
        let region = self.region.unwrap_or_else(|| agent.default_light_region());
        if agent.stimulus() == Stimulus::Scene {
            return self.room_for(agent, &region);
        }
        if self.objects > 0 {
            return Err(InvalidParameter::new(
                "environment",
                "objects",
                self.objects,
                format!(
                    "objects stand in a camera's room, and the {} agent senses lights: leave objects out",
                    agent.name()
                ),
            )
            .into());
        }
        if let Some(room) = self.room {
            return Err(InvalidParameter::new(
                "environment",
                "room",
                format!("{room:?}"),
                format!(
                    "a room is what a camera looks at, and the {} agent senses lights: leave room out",
                    agent.name()
                ),
            )
            .into());
        }
        let count = self.lights.unwrap_or_else(|| agent.default_light_count());
        if count == 0 {
            return Err(InvalidParameter::new(
                "environment",
                "lights",
                0,
                "an environment without lights gives constant sensors; use at least one light",
            )
            .into());
        }
        match agent.light_space() {
            LightSpace::Plane => Environment::random(count, self.seed, &region),
            LightSpace::Volume => {
                Environment::random_volume(count, self.seed, &region, agent.default_light_heights())
            }
        }
    }
}

impl EnvironmentConfig {
    /// The textured room of an agent with a camera (see [`room`](Self::room)).
    fn room_for(&self, agent: &dyn Agent, region: &LightRegion) -> Result<Environment, AgentError> {
        let room = self.room.unwrap_or_else(|| {
            let x = 2.0 * (region.center[0].abs() + region.half_size[0]);
            let y = 2.0 * (region.center[1].abs() + region.half_size[1]);
            [x, y, x.min(y)]
        });
        if !room.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(InvalidParameter::new(
                "environment",
                "room",
                format!("{room:?}"),
                "give the room's three extents [x, y, z], finite and positive",
            )
            .into());
        }
        let environment = Environment {
            seed: Some(self.seed),
            ..Environment::from_scene(Scene::furnished_room(room, self.objects, self.seed)?)
        };
        environment.check_for(agent)?;
        Ok(environment)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region() -> LightRegion {
        LightRegion {
            center: [1.75, 0.0],
            half_size: [3.0, 3.0],
            exclusion_half_size: [1.25, 1.5],
        }
    }

    #[test]
    fn random_lights_are_seeded_and_respect_the_region() {
        let a = Environment::random(50, 7, &region()).unwrap();
        let b = Environment::random(50, 7, &region()).unwrap();
        let c = Environment::random(50, 8, &region()).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
        for l in &a.lights {
            assert!((l[0] - 1.75).abs() <= 3.0 && l[1].abs() <= 3.0);
            assert!(!((l[0] - 1.75).abs() < 1.25 && l[1].abs() < 1.5));
        }
    }

    #[test]
    fn json_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("env.json");
        let env = Environment::random(3, 1, &region()).unwrap();
        env.save(&path).unwrap();
        assert_eq!(Environment::load(&path).unwrap(), env);
        std::fs::write(&path, r#"{"lights": [[1.0, 2.0]], "colour": 3}"#).unwrap();
        let err = Environment::load(&path).unwrap_err().to_string();
        assert!(err.contains("colour") && err.contains("env.json"), "{err}");
    }

    #[test]
    fn light_counts_and_regions_are_bounded() {
        let err = Environment::random(MAX_RANDOM_LIGHTS + 1, 1, &region()).unwrap_err();
        assert!(err.to_string().contains("lights = 2001"), "{err}");
        // An exclusion that leaves the sectors along the x axis empty.
        let thin = LightRegion {
            center: [0.0, 0.0],
            half_size: [3.0, 3.0],
            exclusion_half_size: [4.0, 0.5],
        };
        let err = Environment::random(1000, 1, &thin).unwrap_err();
        assert!(err.to_string().contains("cannot place light 0"), "{err}");
        let err = Environment::from_lights(Vec::new()).check().unwrap_err();
        assert!(err.to_string().contains("no lights"), "{err}");
    }

    #[test]
    fn impossible_region_is_rejected() {
        let mut r = region();
        r.exclusion_half_size = [4.0, 4.0];
        assert!(Environment::random(3, 1, &r).is_err());
    }
}
