//! `_run`: a whole experiment file into a run folder (`smspace run`), optionally with
//! the distance stage computed by a Python callable (the Dask backend,
//! `smspace.run(..., client=client)`) through [`smspace_pipeline::run_with`].

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use numpy::{IntoPyArray, PyReadonlyArray2};
use pyo3::prelude::*;
use smspace::metric::{DistanceMatrix, MetricError, SetsView};
use smspace::progress::Progress;
use smspace_pipeline::config::load_experiment;
use smspace_pipeline::front::{
    default_run_dir, memory_limit, own_folder_line, stage_line, waiting_line, StageEvent,
};
use smspace_pipeline::manifest::StageRecord;
use smspace_pipeline::stages::DistancesStage;
use smspace_pipeline::{
    self, BusyFolder, DistanceBackend, Recompute, RunObserver, RunOptions, StageId,
};

use crate::host::run_interruptible;
use crate::progress::PyProgress;
use crate::to_py_err;

/// The run's events: progress, and one line per stage to `log(line)`.
struct Observer {
    progress: PyProgress,
    log: Option<Py<PyAny>>,
    error: Mutex<Option<PyErr>>,
}

impl Observer {
    fn say(&self, line: String) {
        let Some(log) = &self.log else {
            return;
        };
        if let Err(e) = crate::host::attach(|py| log.call1(py, (line,))) {
            if let Ok(mut first) = self.error.lock() {
                first.get_or_insert(e);
            }
        }
    }
}

impl RunObserver for Observer {
    fn progress(&self) -> &dyn Progress {
        &self.progress
    }

    fn stage_finished(&self, stage: StageId, record: &StageRecord, summary: &str) {
        self.say(stage_line(stage, StageEvent::Finished { record, summary }));
    }

    fn stage_note(&self, stage: StageId, note: &str) {
        self.say(stage_line(stage, StageEvent::Note(note)));
    }

    fn stage_skipped(&self, stage: StageId, why: &str) {
        self.say(stage_line(stage, StageEvent::Skipped(why)));
    }

    fn waiting_for_folder(&self, lock: &std::path::Path) {
        self.say(waiting_line(lock));
    }
}

/// The distance stage computed by
/// `callable(sets, closed, metric, period, pieces, params) -> (M, M)` (`pieces`: the
/// piece of every point, `(M, P)` int64, or `None`; `params`: the JSON of the
/// `[metric.params]` table, or `None` when it is empty).
struct PythonDistances {
    callable: Py<PyAny>,
    error: Mutex<Option<PyErr>>,
}

impl DistanceBackend for PythonDistances {
    fn distances(
        &self,
        stage: &DistancesStage,
        sets: SetsView<'_>,
        _memory_limit_bytes: Option<u64>,
        _progress: &dyn Progress,
    ) -> smspace_pipeline::Result<DistanceMatrix> {
        // "2pi", "none" or "[2pi, none, …]", which `Periodicity::parse` reads back.
        let period = stage.period.to_string();
        let params = if stage.params.is_empty() {
            None
        } else {
            Some(
                serde_json::to_string(&stage.params).map_err(|e| MetricError::Backend {
                    backend: self.remote().unwrap_or_default(),
                    reason: format!("the [metric.params] table does not convert to JSON: {e}"),
                })?,
            )
        };
        let answer = crate::host::attach(|py| -> PyResult<DistanceMatrix> {
            let points = sets.points().to_owned().into_pyarray(py);
            let closed = sets.closure().map(|c| {
                c.iter()
                    .map(|c| c.code())
                    .collect::<Vec<i64>>()
                    .into_pyarray(py)
            });
            let pieces = sets.pieces().map(|p| p.to_owned().into_pyarray(py));
            let d = self.callable.call1(
                py,
                (
                    points,
                    closed,
                    stage.metric.as_str(),
                    period.as_str(),
                    pieces,
                    params,
                ),
            )?;
            let d: PyReadonlyArray2<'_, f64> = d.bind(py).extract()?;
            DistanceMatrix::from_view(d.as_array()).map_err(to_py_err)
        });
        answer.map_err(|e| {
            let text = crate::host::attach(|py| e.value(py).to_string());
            if let Ok(mut first) = self.error.lock() {
                first.get_or_insert(e);
            }
            MetricError::Backend {
                backend: self.remote().unwrap_or_default(),
                reason: text,
            }
            .into()
        })
    }

    fn remote(&self) -> Option<String> {
        Some("the Dask cluster of the client given".to_owned())
    }
}

/// `_run(path, out, overrides, force, max_memory, distances, log, progress)`: runs the
/// experiment; returns `(run folder, analysis report JSON)`.
#[pyfunction]
#[pyo3(signature = (path, out=None, overrides=Vec::new(), force=false, max_memory=None, distances=None, log=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn _run(
    py: Python<'_>,
    path: PathBuf,
    out: Option<PathBuf>,
    overrides: Vec<String>,
    force: bool,
    max_memory: Option<u64>,
    distances: Option<Py<PyAny>>,
    log: Option<Py<PyAny>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(PathBuf, String)> {
    let loaded = load_experiment(&path, &overrides).map_err(to_py_err)?;
    let metrics = crate::metric::registry();
    let plan = smspace_pipeline::check_with(&loaded, &metrics).map_err(to_py_err)?;
    let observer = Arc::new(Observer {
        progress: PyProgress::new(progress),
        log,
        error: Mutex::new(None),
    });
    let out_dir = out.unwrap_or_else(|| {
        let dir = default_run_dir(&loaded.name, &overrides);
        if !overrides.is_empty() {
            observer.say(own_folder_line(&dir, &loaded.name, "overrides", "out="));
        }
        dir
    });
    let options = RunOptions {
        out_dir,
        recompute: if force {
            Recompute::All
        } else {
            Recompute::Changed
        },
        memory_limit_bytes: memory_limit(max_memory),
        busy: BusyFolder::Refuse,
    };
    let backend = Arc::new(distances.map(|callable| PythonDistances {
        callable,
        error: Mutex::new(None),
    }));
    let interrupts = [observer.progress.interrupt()];
    // A run interrupted just before still holds its folder until its threads end.
    crate::host::wait_for_abandoned(py, ABANDONED_WAIT)?;
    let (shared, shared_backend) = (observer.clone(), backend.clone());
    let summary = run_interruptible(py, &interrupts, move || match shared_backend.as_ref() {
        Some(b) => smspace_pipeline::run_with(&plan, &options, shared.as_ref(), b),
        None => smspace_pipeline::run(&plan, &options, shared.as_ref()),
    })?;
    if let Some(e) =
        Option::as_ref(&backend).and_then(|b| b.error.lock().ok().and_then(|mut e| e.take()))
    {
        return Err(e);
    }
    if let Some(e) = observer.error.lock().ok().and_then(|mut e| e.take()) {
        return Err(e);
    }
    observer.progress.check()?;
    let summary = summary.map_err(to_py_err)?;
    let report =
        serde_json::to_string(&summary.analysis).map_err(|e| crate::value_error(e.to_string()))?;
    Ok((summary.dir, report))
}

/// How long a run waits for the computations abandoned after Ctrl-C to end (and
/// release a run folder) before it takes its folder's lock.
const ABANDONED_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Adds `_run` to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_run, m)?)?;
    Ok(())
}
