//! Environments: point lights in the plane, drawn from a seed or loaded from JSON.
//!
//! A random environment draws `lights` positions in a rectangle (`center ± half_size`)
//! minus an inner rectangle (`center ± exclusion_half_size`), from a ChaCha8 stream
//! seeded with `seed`: the same seed gives the same lights on every machine. The draws
//! are stratified by direction: light `l` of `L` is uniform in the part of the region
//! seen from the centre at angles `[2πl/L, 2π(l+1)/L)`, so that lights surround the
//! centre and a sensor looking any way sees some (a rich environment, paper section
//! 2.3). The JSON form is `{"lights": [[x, y], ...], "seed": 1}`.

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{Agent, AgentError};
use crate::error::InvalidParameter;
use crate::io::{self, IoError};

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

/// The environment `E`: a set of point lights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// Positions `[x, y]` of the point lights.
    pub lights: Vec<[f64; 2]>,
    /// The seed the lights were drawn from, if they were drawn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

impl Environment {
    /// An environment with the given lights.
    pub fn from_lights(lights: Vec<[f64; 2]>) -> Self {
        Self { lights, seed: None }
    }

    /// `count` lights drawn in `region`, stratified by direction from its centre (see
    /// the module docs), from a stream seeded with `seed`.
    ///
    /// At most [`MAX_RANDOM_LIGHTS`] lights (light `i` is drawn until it falls in its
    /// sector, so the work grows as `count²`), and at most [`MAX_DRAWS_PER_LIGHT`]
    /// draws per light: a region whose exclusion leaves a sector empty is an error.
    pub fn random(count: usize, seed: u64, region: &LightRegion) -> Result<Self, AgentError> {
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
                region.center[0] + region.half_size[0] * rng.gen_range(-1.0..1.0),
                region.center[1] + region.half_size[1] * rng.gen_range(-1.0..1.0),
            ];
            let angle = (p[1] - region.center[1])
                .atan2(p[0] - region.center[0])
                .rem_euclid(2.0 * std::f64::consts::PI);
            let wanted = lights.len() as f64 * sector;
            if !region.contains_excluded(p) && (wanted..wanted + sector).contains(&angle) {
                lights.push(p);
                draws = 0;
            }
        }
        Ok(Self {
            lights,
            seed: Some(seed),
        })
    }

    /// Reads an environment from its JSON file and checks it.
    pub fn load(path: &Path) -> Result<Self, crate::Error> {
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

    /// Checks that there is a light and that every light position is finite.
    pub fn check(&self) -> Result<(), AgentError> {
        if self.lights.is_empty() {
            return Err(AgentError::InvalidEnvironment {
                reason: "no lights: an environment without lights gives constant sensors; give at least one light".into(),
            });
        }
        if let Some((i, l)) = self
            .lights
            .iter()
            .enumerate()
            .find(|(_, l)| !(l[0].is_finite() && l[1].is_finite()))
        {
            return Err(AgentError::InvalidEnvironment {
                reason: format!("light {i} is at {l:?}; positions must be finite numbers"),
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
}

impl Default for EnvironmentConfig {
    fn default() -> Self {
        Self {
            lights: None,
            seed: 1,
            region: None,
        }
    }
}

impl EnvironmentConfig {
    /// Draws the environment for `agent`.
    pub fn build(&self, agent: &dyn Agent) -> Result<Environment, AgentError> {
        let region = self.region.unwrap_or_else(|| agent.default_light_region());
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
        Environment::random(count, self.seed, &region)
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
