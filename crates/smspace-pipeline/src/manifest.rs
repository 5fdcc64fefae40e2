//! The run's manifest (`manifest.json`) and the content hashes behind the cache.
//!
//! Every stage has a *key*: the BLAKE3 hash of the smspace version, the stage's name,
//! its parameters (as JSON) and the keys of the stages it reads. A stage is reused
//! when the previous manifest of the folder holds the same key and every output file
//! it recorded still has the recorded BLAKE3 content hash; otherwise it runs again.
//! Changing a parameter therefore recomputes that stage and everything downstream of
//! it, and editing or deleting an output recomputes the stage that wrote it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use smspace::io::IoError;

/// The version written into manifests and stage keys.
pub const SMSPACE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// Hex BLAKE3 hash of `parts`, each prefixed by its length so that no two different
/// lists hash alike.
pub fn hash_parts(parts: &[&[u8]]) -> String {
    let mut hasher = blake3::Hasher::new();
    for part in parts {
        hasher.update(&(part.len() as u64).to_le_bytes());
        hasher.update(part);
    }
    hasher.finalize().to_hex().to_string()
}

/// Hex BLAKE3 hash of a file's content.
pub fn hash_file(path: &Path) -> Result<String, IoError> {
    let read = |reason| IoError::Read {
        path: path.to_owned(),
        reason,
    };
    let file = smspace::io::open_regular(path)?;
    let mut hasher = blake3::Hasher::new();
    hasher.update_reader(file).map_err(read)?;
    Ok(hasher.finalize().to_hex().to_string())
}

/// One stage of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    /// The stage (`explore`, `trace`, `distances`, `embed`, `analyze`, `invariance`,
    /// `report`).
    pub stage: String,
    /// The stage's key (see the module docs).
    pub key: String,
    /// Whether this run reused the outputs instead of computing them.
    pub cached: bool,
    /// Seconds this run spent on the stage (checking and loading, when cached).
    pub seconds: f64,
    /// Seconds the stage took when it was last computed.
    pub compute_seconds: f64,
    /// Output files, relative to the run folder, with their BLAKE3 content hashes.
    pub outputs: BTreeMap<String, String>,
}

/// How the run ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "state")]
pub enum RunStatus {
    /// Stages are still running (or the process was interrupted).
    Running,
    /// Every stage finished.
    Complete,
    /// A stage failed; the stages before it are recorded and their outputs intact.
    Failed {
        /// The stage that failed.
        stage: String,
        /// Why.
        reason: String,
    },
}

/// The seeds of every random choice of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Seeds {
    /// Motor babbling.
    pub exploration: u64,
    /// The random lights of each environment, the main one first.
    pub environments: Vec<u64>,
    /// Samples drawn in the figures.
    pub report: u64,
}

/// `manifest.json`: what ran, with which version and parameters, and how long it took.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// smspace's version.
    pub smspace_version: String,
    /// The experiment's name.
    pub experiment: String,
    /// The experiment file.
    pub config_file: PathBuf,
    /// BLAKE3 hash of the resolved configuration (`config.resolved.toml`).
    pub config_hash: String,
    /// The `--set` overrides applied.
    pub overrides: Vec<String>,
    /// The seeds.
    pub seeds: Seeds,
    /// Worker threads of the run (results do not depend on it).
    pub threads: usize,
    /// The stages, in order.
    pub stages: Vec<StageRecord>,
    /// Seconds of the whole run.
    pub total_seconds: f64,
    /// How the run ended.
    pub status: RunStatus,
}

impl Manifest {
    /// The previous manifest of a folder, if there is a readable one.
    pub fn previous(dir: &Path) -> Option<Manifest> {
        let text =
            smspace::io::read_text_bounded(&dir.join("manifest.json"), smspace::io::MAX_TEXT_BYTES)
                .ok()?;
        serde_json::from_str(&text).ok()
    }

    /// The record of `stage` whose key is `key` and whose outputs are all still there
    /// with their recorded content (see the module docs).
    pub fn reusable(&self, dir: &Path, stage: &str, key: &str) -> Option<&StageRecord> {
        let record = self
            .stages
            .iter()
            .find(|r| r.stage == stage && r.key == key)?;
        let intact = record
            .outputs
            .iter()
            .all(|(file, hash)| hash_file(&dir.join(file)).is_ok_and(|found| &found == hash));
        intact.then_some(record)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hashes_separate_parts_and_follow_content() {
        assert_ne!(hash_parts(&[b"ab", b"c"]), hash_parts(&[b"a", b"bc"]));
        assert_eq!(hash_parts(&[b"x"]), hash_parts(&[b"x"]));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        std::fs::write(&path, b"hello").unwrap();
        let h = hash_file(&path).unwrap();
        assert_eq!(h, blake3::hash(b"hello").to_hex().to_string());
        std::fs::write(&path, b"hellO").unwrap();
        assert_ne!(hash_file(&path).unwrap(), h);
        assert!(hash_file(&dir.path().join("missing")).is_err());
    }
}

/// The stages, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StageId {
    /// Motor babbling and the probe grid.
    Explore,
    /// Kernel sets.
    Trace,
    /// Distance matrix between sets.
    Distances,
    /// Embedding.
    Embed,
    /// Topology, dimension, agreement.
    Analyze,
    /// Environment invariance (only with several environments).
    Invariance,
    /// Figures and report.
    Report,
}

impl StageId {
    /// Every stage, in order.
    pub const ALL: [StageId; 7] = [
        StageId::Explore,
        StageId::Trace,
        StageId::Distances,
        StageId::Embed,
        StageId::Analyze,
        StageId::Invariance,
        StageId::Report,
    ];

    /// The stage's name.
    pub fn name(self) -> &'static str {
        match self {
            StageId::Explore => "explore",
            StageId::Trace => "trace",
            StageId::Distances => "distances",
            StageId::Embed => "embed",
            StageId::Analyze => "analyze",
            StageId::Invariance => "invariance",
            StageId::Report => "report",
        }
    }
}
