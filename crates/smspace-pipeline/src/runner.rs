//! The cache around the stages: a stage whose key is in the previous manifest with
//! intact outputs is read back instead of computed; every stage is recorded.
//!
//! What reaches the folder, and in which order:
//!
//! 1. Nothing, as long as every stage is reused. A finished run whose configuration
//!    did not change is reused without writing a byte, so it can be reused from a
//!    read-only folder ([`lock::Access::ReadOnly`](super::lock::Access)).
//! 2. Before the first write of a run (a stage to compute, or a changed
//!    configuration), `manifest.json` is rewritten as `running`, keeping the earlier
//!    records: from then on no manifest says `complete` for a folder in flux.
//! 3. Each computed stage's files, `config.resolved.toml` (with the first of them)
//!    and the manifest with the stage's record go through one [`Outputs`]: all written
//!    in full and hashed while written, then renamed in that order, the manifest last.
//!    A run killed between two renames leaves a manifest that does not vouch for the
//!    files renamed before it (their hashes do not match its records), so they are
//!    recomputed, never trusted.
//! 4. At the end, the manifest as `complete` (or `failed`, naming the stage).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::lock::{Access, FolderLock};
use super::manifest::{hash_parts, Manifest, RunStatus, StageRecord};
use super::memory::Peak;
use super::stages::{DistanceBackend, Keyed, Stage, StageContext};
use crate::plan::{PipelineError, Recompute, RunObserver, RunOptions};
use crate::report::StageTiming;
use smspace::io::{IoError, Outputs};

/// The resolved configuration's file in the run folder.
pub(super) const CONFIG_FILE: &str = "config.resolved.toml";
/// The manifest's file in the run folder.
pub(super) const MANIFEST_FILE: &str = "manifest.json";

/// The state of a run: folder, manifests, and the records so far.
pub(super) struct Runner<'a> {
    pub(super) dir: PathBuf,
    pub(super) options: &'a RunOptions,
    pub(super) observer: &'a dyn RunObserver,
    pub(super) previous: Option<Manifest>,
    pub(super) manifest: Manifest,
    pub(super) started: Instant,
    /// The resolved configuration (`config.resolved.toml`).
    pub(super) config_toml: &'a str,
    /// The limit of the distance matrix: the smaller of the run's and the
    /// experiment's `[metric] memory_limit_bytes`.
    pub(super) matrix_limit_bytes: Option<u64>,
    /// Whether this run has begun writing the folder (step 2 of the module docs).
    pub(super) writing: bool,
    /// Whether `config.resolved.toml` is this run's.
    pub(super) config_written: bool,
    /// The run folder's lock, held as long as the runner lives.
    pub(super) lock: FolderLock,
    /// Where the distance stage computes its matrix.
    pub(super) distances: &'a dyn DistanceBackend,
}

impl Runner<'_> {
    /// The manifest as it is written now: the records so far and, until the run is
    /// complete, the previous manifest's records of stages not reached yet (they stay
    /// valid: a record is only reused when its key and its outputs' hashes match), so
    /// that an interrupted or failing run loses no earlier record.
    fn manifest_to_write(&mut self) -> Manifest {
        self.manifest.total_seconds = self.started.elapsed().as_secs_f64();
        let mut written = self.manifest.clone();
        if let (false, Some(previous)) = (
            matches!(self.manifest.status, RunStatus::Complete),
            &self.previous,
        ) {
            let pending: Vec<StageRecord> = previous
                .stages
                .iter()
                .filter(|old| !written.stages.iter().any(|r| r.stage == old.stage))
                .cloned()
                .collect();
            written.stages.extend(pending);
        }
        written
    }

    /// Step 2 of the module docs, once per run; `what` says why the run must write
    /// (for the error of a read-only folder).
    fn begin_writing(&mut self, what: &str) -> Result<(), PipelineError> {
        if self.writing {
            return Ok(());
        }
        let dir = self.dir.clone();
        let read_only = |reason: Option<std::io::Error>| PipelineError::ReadOnly {
            dir,
            what: what.to_owned(),
            reason,
        };
        if self.lock.access() == Access::ReadOnly {
            return Err(read_only(None));
        }
        let mut running = self.manifest_to_write();
        running.status = RunStatus::Running;
        match smspace::io::write_json(&self.dir.join(MANIFEST_FILE), &running) {
            Ok(()) => {}
            Err(IoError::Write { reason, .. }) if super::lock::is_read_only(&reason) => {
                return Err(read_only(Some(reason)))
            }
            Err(other) => return Err(other.into()),
        }
        self.writing = true;
        Ok(())
    }

    /// Step 3 of the module docs: stages the configuration (the first time) and the
    /// manifest after `outputs`, then renames them all.
    fn commit(&mut self, mut outputs: Outputs) -> Result<(), IoError> {
        if !self.config_written {
            outputs.bytes(&self.dir.join(CONFIG_FILE), self.config_toml.as_bytes())?;
        }
        let manifest = self.manifest_to_write();
        outputs.json(&self.dir.join(MANIFEST_FILE), &manifest)?;
        outputs.commit()?;
        self.config_written = true;
        Ok(())
    }

    /// Whether the folder already holds exactly this run: a complete manifest of the
    /// same configuration (with the same `config.resolved.toml`) and the same records.
    fn up_to_date(&self) -> bool {
        let Some(previous) = &self.previous else {
            return false;
        };
        let same_records = previous.stages.len() == self.manifest.stages.len()
            && previous
                .stages
                .iter()
                .zip(&self.manifest.stages)
                .all(|(old, new)| {
                    old.stage == new.stage && old.key == new.key && old.outputs == new.outputs
                });
        let config_on_disk = smspace::io::read_text_bounded(
            &self.dir.join(CONFIG_FILE),
            smspace::io::MAX_TEXT_BYTES,
        )
        .is_ok_and(|text| hash_parts(&[text.as_bytes()]) == self.manifest.config_hash);
        !self.writing
            && previous.status == RunStatus::Complete
            && previous.config_hash == self.manifest.config_hash
            && same_records
            && config_on_disk
    }

    /// Ends the run: records it `complete`, writing nothing when the folder already
    /// holds exactly this run.
    pub(super) fn finish(&mut self) -> Result<(), PipelineError> {
        self.manifest.status = RunStatus::Complete;
        if self.up_to_date() {
            self.manifest.total_seconds = self.started.elapsed().as_secs_f64();
            return Ok(());
        }
        self.begin_writing("its manifest or configuration changed")?;
        self.commit(Outputs::new())?;
        Ok(())
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
        peak: Peak,
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
        if let Some((value, old)) = loaded {
            let record = StageRecord {
                seconds: start.elapsed().as_secs_f64(),
                cached: true,
                ..old
            };
            self.record(record.clone());
            self.observer
                .stage_finished(S::ID, &record, &stage.summary(&value));
            return Ok(Keyed { value, key });
        }
        if let Some(available) = self.options.memory_limit_bytes.filter(|&a| peak.bytes > a) {
            return Err(PipelineError::OutOfMemory {
                what: peak.what,
                needed: peak.bytes,
                available,
                fix: peak.fix,
            });
        }
        self.begin_writing(&format!("stage `{name}` must be computed"))?;
        self.observer.stage_note(
            S::ID,
            &format!(
                "memory: about {} at the peak ({}; {})",
                smspace::metric::human_bytes(peak.bytes),
                peak.what,
                peak.fix
            ),
        );
        if let Some(note) = stage.forecast(input) {
            self.observer.stage_note(S::ID, &note);
        }
        match self
            .compute(stage, input, &key, start)
            .and_then(|(value, record, outputs)| {
                self.commit_stage(record.clone(), outputs)?;
                Ok((value, record))
            }) {
            Ok((value, record)) => {
                self.observer
                    .stage_finished(S::ID, &record, &stage.summary(&value));
                Ok(Keyed { value, key })
            }
            Err(reason) => {
                self.manifest.status = RunStatus::Failed {
                    stage: name.to_owned(),
                    reason: reason.to_string(),
                };
                // The failure itself is what the caller must see; a manifest that
                // cannot be written does not hide it.
                let _ = self.commit(Outputs::new());
                Err(PipelineError::Stage {
                    stage: name,
                    dir: self.dir.clone(),
                    reason: Box::new(reason),
                })
            }
        }
    }

    /// Puts `record` in the manifest, in place of an earlier one of the same stage.
    fn record(&mut self, record: StageRecord) {
        self.manifest.stages.retain(|r| r.stage != record.stage);
        self.manifest.stages.push(record);
    }

    /// Commits a computed stage's files with its record; on failure, the record is
    /// dropped again (its files were not all written).
    fn commit_stage(&mut self, record: StageRecord, outputs: Outputs) -> Result<(), IoError> {
        let before = self.manifest.stages.clone();
        self.record(record);
        self.commit(outputs)
            .inspect_err(|_| self.manifest.stages = before)
    }

    /// Computes a stage and stages its files; its record holds each file's hash,
    /// taken while it was written.
    fn compute<S: Stage>(
        &self,
        stage: &S,
        input: &S::Input<'_>,
        key: &str,
        start: Instant,
    ) -> crate::Result<(S::Output, StageRecord, Outputs)> {
        let stage_times = self.stage_times();
        let context = StageContext {
            progress: self.observer.progress(),
            memory_limit_bytes: self.matrix_limit_bytes,
            dir: &self.dir,
            stage_times: &stage_times,
            distances: self.distances,
        };
        let value = stage.compute(input, &context)?;
        let mut outputs = Outputs::new();
        stage.save(input, &value, &mut outputs, &self.dir)?;
        let seconds = start.elapsed().as_secs_f64();
        let outputs_record = outputs
            .staged()
            .map(|(path, hash)| (relative(&self.dir, path), hash.to_owned()))
            .collect();
        Ok((
            value,
            StageRecord {
                stage: S::ID.name().to_owned(),
                key: key.to_owned(),
                cached: false,
                seconds,
                compute_seconds: seconds,
                outputs: outputs_record,
            },
            outputs,
        ))
    }
}

/// `path` relative to the run folder, with `/` between its parts (as the manifest
/// records it on every system).
fn relative(dir: &Path, path: &Path) -> String {
    let inside = path.strip_prefix(dir).unwrap_or(path);
    inside
        .components()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}
