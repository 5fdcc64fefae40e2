//! The cache around the stages: a stage whose key is in the previous manifest with
//! intact outputs is read back instead of computed; every stage is recorded.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use super::manifest::{hash_file, Manifest, RunStatus, StageRecord};
use super::stages::{Keyed, Stage, StageContext};
use super::{PipelineError, Recompute, RunObserver, RunOptions};
use crate::io::{self, IoError};
use crate::report::StageTiming;

/// The state of a run: folder, manifests, and the records so far.
pub(super) struct Runner<'a> {
    pub(super) dir: PathBuf,
    pub(super) options: &'a RunOptions,
    pub(super) observer: &'a dyn RunObserver,
    pub(super) previous: Option<Manifest>,
    pub(super) manifest: Manifest,
    pub(super) started: Instant,
    /// The run folder's lock, held as long as the runner lives.
    pub(super) _lock: super::lock::FolderLock,
}

impl Runner<'_> {
    /// Writes `manifest.json` (atomically), with the time so far.
    ///
    /// Until the run is complete, the records of the previous manifest for stages not
    /// reached yet are kept too (they stay valid: a record is only reused when its key
    /// and its outputs' hashes match), so that an interrupted or failing run loses no
    /// earlier record.
    pub(super) fn write_manifest(&mut self) -> Result<(), IoError> {
        self.manifest.total_seconds = self.started.elapsed().as_secs_f64();
        let pending: Vec<&StageRecord> = match (&self.manifest.status, &self.previous) {
            (RunStatus::Complete, _) | (_, None) => Vec::new(),
            (_, Some(previous)) => previous
                .stages
                .iter()
                .filter(|old| !self.manifest.stages.iter().any(|r| r.stage == old.stage))
                .collect(),
        };
        if pending.is_empty() {
            return io::write_json(&self.dir.join("manifest.json"), &self.manifest);
        }
        let mut written = self.manifest.clone();
        written.stages.extend(pending.into_iter().cloned());
        io::write_json(&self.dir.join("manifest.json"), &written)
    }

    /// The stages recorded so far, with their times.
    fn stage_times(&self) -> Vec<StageTiming> {
        self.manifest
            .stages
            .iter()
            .map(|r| StageTiming {
                stage: r.stage.clone(),
                seconds: r.compute_seconds,
                cached: r.cached,
            })
            .collect()
    }

    /// Runs one stage: reuses it when the previous manifest has its key and intact
    /// outputs that read back, computes and saves it otherwise; records it either way.
    pub(super) fn run<S: Stage>(
        &mut self,
        stage: &S,
        input: &S::Input<'_>,
    ) -> Result<Keyed<S::Output>, PipelineError> {
        let name = S::ID.name();
        let key = stage.key(input);
        self.observer.stage_started(S::ID);
        let start = Instant::now();
        let reusable = match (self.options.recompute, &self.previous) {
            (Recompute::Changed, Some(previous)) => {
                previous.reusable(&self.dir, name, &key).cloned()
            }
            _ => None,
        };
        // Outputs that no longer read (an older format, say) are recomputed like
        // changed ones.
        let loaded =
            reusable.and_then(|old| stage.load(input, &self.dir).ok().map(|value| (value, old)));
        let result = match loaded {
            Some((value, old)) => Ok((
                value,
                StageRecord {
                    seconds: start.elapsed().as_secs_f64(),
                    cached: true,
                    ..old
                },
            )),
            None => self.compute(stage, input, &key, start),
        };
        match result {
            Ok((value, record)) => {
                self.observer
                    .stage_finished(S::ID, &record, &stage.summary(&value));
                self.manifest.stages.retain(|r| r.stage != name);
                self.manifest.stages.push(record);
                self.write_manifest()?;
                Ok(Keyed { value, key })
            }
            Err(reason) => {
                self.manifest.status = RunStatus::Failed {
                    stage: name.to_owned(),
                    reason: reason.to_string(),
                };
                // The failure itself is what the caller must see; a manifest that
                // cannot be written does not hide it.
                let _ = self.write_manifest();
                Err(PipelineError::Stage {
                    stage: name,
                    dir: self.dir.clone(),
                    reason: Box::new(reason),
                })
            }
        }
    }

    /// Computes and saves a stage; its record hashes every file it wrote.
    fn compute<S: Stage>(
        &self,
        stage: &S,
        input: &S::Input<'_>,
        key: &str,
        start: Instant,
    ) -> crate::Result<(S::Output, StageRecord)> {
        let stage_times = self.stage_times();
        let context = StageContext {
            progress: self.observer.progress(),
            memory_limit_bytes: self.options.memory_limit_bytes,
            dir: &self.dir,
            stage_times: &stage_times,
        };
        let value = stage.compute(input, &context)?;
        let files = stage.save(input, &value, &self.dir)?;
        let seconds = start.elapsed().as_secs_f64();
        let mut outputs = BTreeMap::new();
        for file in files {
            let hash = hash_file(&self.dir.join(&file))?;
            outputs.insert(file, hash);
        }
        Ok((
            value,
            StageRecord {
                stage: S::ID.name().to_owned(),
                key: key.to_owned(),
                cached: false,
                seconds,
                compute_seconds: seconds,
                outputs,
            },
        ))
    }
}
