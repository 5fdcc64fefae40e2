//! The stages one by one, on NumPy arrays: `_explore`, `_trace`, `_distances` (and the
//! tiles a cluster's workers compute, `_distance_tile` and `_merge_tiles`, and
//! `_knn`), `_embed`, `_analyze`. The package's `smspace.explore`, … wrap them.
//!
//! Parameters are the JSON of the library's parameter structs (`ExploreParams`,
//! `TraceParams`, `EmbedParams`, `AnalysisParams`); arrays in are float64 views of any
//! layout, arrays out are moved into NumPy. Each computation runs with the GIL released
//! on the engine's threads, on its own copy of its inputs, and stops on Ctrl-C
//! ([`run_interruptible`]).

use std::sync::Arc;

use ndarray::{Array1, Array2, Array3, ArrayView3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::prelude::*;
use smspace::analysis::affine::affine_errors;
use smspace::analysis::{analyze, AnalysisParams};
use smspace::embed::EmbedParams;
use smspace::explore::{explore_with, ExploreParams, Workspace};
use smspace::kernel::{trace_sets, Closure, TraceParams, TraceReport};
use smspace::metric::{
    distance_matrix_with, fill_tile, knn_with, BuiltMetric, DistanceMatrix, DistanceParams,
    KnnParams, SetsView, Tile, TileMerge,
};
use smspace_pipeline::front::{self, MetricRequest};

use crate::agent::Agent;
use crate::host::{run_interruptible, Interrupt};
use crate::progress::PyProgress;
use crate::{from_json, to_py_err, value_error};

/// Raises a `ValueError` naming `argument` at its first non-finite value.
pub(crate) fn check_finite<'a>(
    values: impl Iterator<Item = &'a f64>,
    argument: &str,
) -> PyResult<()> {
    match values.enumerate().find(|(_, v)| !v.is_finite()) {
        Some((index, v)) => Err(value_error(format!(
            "{argument} holds a non-finite value ({v}) at flat index {index}; every entry must be a finite number"
        ))),
        None => Ok(()),
    }
}

/// A computation's progress reporter (shared with the engine's threads) and the stop
/// flags Ctrl-C raises: the reporter's and, with an agent, the agent's.
fn reporter(
    progress: Option<Py<PyAny>>,
    agent: Option<&Agent>,
) -> (Arc<PyProgress>, Vec<Interrupt>) {
    let progress = Arc::new(PyProgress::new(progress));
    let mut interrupts = agent.map(Agent::interrupts).unwrap_or_default();
    interrupts.push(progress.interrupt());
    (progress, interrupts)
}

/// The closures of the sets from their codes (1: closed loop, 0: open polyline).
fn closures(
    codes: Option<PyReadonlyArray1<'_, i64>>,
    sets: usize,
) -> PyResult<Option<Vec<Closure>>> {
    let Some(codes) = codes else {
        return Ok(None);
    };
    let codes = codes.as_array();
    if codes.len() != sets {
        return Err(value_error(format!(
            "closed has {} entries but there are {sets} sets; give one code per set (1: closed loop, 0: open polyline)",
            codes.len()
        )));
    }
    codes
        .iter()
        .map(|&c| {
            Closure::from_code(c).ok_or_else(|| {
                value_error(format!(
                    "closed holds {c}; each code is 1 (closed loop) or 0 (open polyline)"
                ))
            })
        })
        .collect::<PyResult<Vec<_>>>()
        .map(Some)
}

/// What names a metric in a Python call: its name, `period` (`"2pi"`, `"none"`, or one
/// entry per motor: `"2pi,2pi,none"`), its parameters (the JSON of a dict, the
/// `[metric.params]` table) and the trace report of the sets when they come from
/// `trace` (its JSON, read once: the kernels' shape, which a parameter may follow and
/// the metric checks).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct MetricArgs {
    name: String,
    period: String,
    params: Option<String>,
    #[pyo3(from_py_with = trace_report)]
    report: Option<TraceReport>,
}

/// The trace report of [`MetricArgs`], from its JSON (or `None`).
fn trace_report(value: &Bound<'_, PyAny>) -> PyResult<Option<TraceReport>> {
    let json: Option<String> = value.extract()?;
    json.as_deref()
        .map(|json| from_json(json, "trace report"))
        .transpose()
}

impl MetricArgs {
    /// The metric, from the registry of this process (built-in metrics and those
    /// registered from Python), checked against the kernels of the trace report.
    fn build(&self, memory_limit_bytes: Option<u64>) -> PyResult<BuiltMetric> {
        self.build_for(None, memory_limit_bytes)
    }

    /// [`build`](Self::build), with the period resolved for `agent` when given
    /// ([`front::resolve_period`]: `"motors"` is the agent's own).
    fn build_for(
        &self,
        agent: Option<&dyn smspace::agent::Agent>,
        memory_limit_bytes: Option<u64>,
    ) -> PyResult<BuiltMetric> {
        let mut period = smspace::metric::Periodicity::parse(&self.period)
            .map_err(|e| value_error(format!("period: {e}")))?;
        if let Some(agent) = agent {
            period = front::resolve_period(agent, &period)
                .map_err(|e| value_error(format!("period: {}", crate::message(&e))))?;
        }
        let params = match self.params.as_deref() {
            None => toml::Table::new(),
            Some(json) => {
                let value: serde_json::Value = from_json(json, "metric parameters")?;
                toml::Table::try_from(value).map_err(|e| {
                    value_error(format!(
                        "metric parameters: {e} (give a dict of numbers, strings, booleans and lists)"
                    ))
                })?
            }
        };
        let kernels = self.report.as_ref().map(TraceReport::kernel_shape);
        let request = MetricRequest {
            name: &self.name,
            period,
            params,
            memory_limit_bytes: front::memory_limit(memory_limit_bytes),
            kernels,
        };
        let built = front::metric(&crate::metric::registry(), request).map_err(to_py_err)?;
        if let Some(shape) = kernels {
            built
                .metric
                .check_kernels(shape)
                .map_err(|e| value_error(format!("sets: {}", crate::message(&e))))?;
        }
        Ok(built)
    }

    /// Checks `sets` against the trace report (sets extended along motors must be
    /// recorded as slices for a metric that reads pieces).
    fn check_sets(&self, built: &BuiltMetric, sets: &SetsView<'_>) -> PyResult<()> {
        if let Some(report) = &self.report {
            built
                .metric
                .check_sets(sets, &report.extended_along)
                .map_err(|e| value_error(format!("sets: {}", crate::message(&e))))?;
        }
        Ok(())
    }
}

/// The piece of every point `(M, P)` int64 (`smspace.trace(..., components="all")`):
/// checked against the sets' shape.
fn pieces<'a>(
    pieces: Option<&'a PyReadonlyArray2<'_, i64>>,
    points: ArrayView3<'_, f64>,
    argument: &str,
) -> PyResult<Option<ndarray::ArrayView2<'a, i64>>> {
    let Some(pieces) = pieces else {
        return Ok(None);
    };
    let view = pieces.as_array();
    let (m, p, _) = points.dim();
    if view.dim() != (m, p) {
        return Err(value_error(format!(
            "{argument} has shape {:?} but the sets are ({m}, {p}, N); give the piece of every point, shape (M, P)",
            view.shape()
        )));
    }
    if let Some(bad) = view.iter().find(|&&v| v < 0) {
        return Err(value_error(format!(
            "{argument} holds {bad}; piece indices are 0, 1, ..."
        )));
    }
    Ok(Some(view))
}

/// The sets view, with closures when the metric reads them (`curve` needs them) and
/// the pieces of their points when given (no segment joins two pieces).
fn sets_view<'a>(
    points: ArrayView3<'a, f64>,
    closure: Option<&'a [Closure]>,
    pieces: Option<ndarray::ArrayView2<'a, i64>>,
    metric: &Reader,
) -> PyResult<SetsView<'a>> {
    let view = sets_view_closed(points, closure, metric)?;
    Ok(match pieces {
        Some(p) => view.with_pieces(p),
        None => view,
    })
}

fn sets_view_closed<'a>(
    points: ArrayView3<'a, f64>,
    closure: Option<&'a [Closure]>,
    metric: &Reader,
) -> PyResult<SetsView<'a>> {
    match closure {
        Some(c) => Ok(SetsView::new(points).with_closure(c)),
        None if metric.reads_closure => Err(value_error(format!(
            "metric={:?} needs to know which sets are closed loops: pass the result of smspace.trace, or closed= (1: closed loop, 0: open polyline per set, or 'closed'/'open' for all)",
            metric.name
        ))),
        None => Ok(SetsView::new(points)),
    }
}

/// Sets with their closures and pieces, checked here and copied for a computation on
/// the engine's threads, which views them there.
struct OwnedSets {
    points: Array3<f64>,
    closure: Option<Vec<Closure>>,
    pieces: Option<Array2<i64>>,
    metric: Reader,
}

/// What the sets' checks need of the metric: its name (for messages) and whether it
/// reads the sets' closures (`curve` does).
struct Reader {
    name: String,
    reads_closure: bool,
}

impl Reader {
    fn of(built: &BuiltMetric) -> Self {
        Self {
            name: built.metric.name().to_owned(),
            reads_closure: built.metric.records().closure,
        }
    }
}

impl OwnedSets {
    /// `points` with their `closed` codes and `pieces` (the argument `argument`), as
    /// `metric` reads them.
    fn new(
        points: ArrayView3<'_, f64>,
        closed: Option<PyReadonlyArray1<'_, i64>>,
        pieces: Option<&PyReadonlyArray2<'_, i64>>,
        argument: &str,
        metric: &BuiltMetric,
    ) -> PyResult<Self> {
        let closure = closures(closed, points.dim().0)?;
        let pieces = self::pieces(pieces, points, argument)?.map(|p| p.to_owned());
        let sets = Self {
            points: points.to_owned(),
            closure,
            pieces,
            metric: Reader::of(metric),
        };
        sets.view()?;
        Ok(sets)
    }

    /// The view the metrics take.
    fn view(&self) -> PyResult<SetsView<'_>> {
        sets_view(
            self.points.view(),
            self.closure.as_deref(),
            self.pieces.as_ref().map(|p| p.view()),
            &self.metric,
        )
    }
}

/// `_explore(agent, params_json, workspace, progress)`: the babbled (and probe)
/// configurations, `(motors (M, N), poses (M, d) or None, probes (M, 3) int64)`.
#[pyfunction]
#[pyo3(signature = (agent, params, workspace=None, progress=None))]
#[allow(clippy::type_complexity)]
fn _explore<'py>(
    py: Python<'py>,
    agent: &Agent,
    params: &str,
    workspace: Option<&Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Option<Bound<'py, PyArray2<f64>>>,
    Bound<'py, PyArray2<i64>>,
)> {
    let params: ExploreParams = from_json(params, "exploration parameters")?;
    let law = agent.law.as_ref();
    let workspace = match workspace {
        Some(w) if w.extract::<String>().is_ok_and(|t| t == "default") => {
            params.workspace(law).map_err(to_py_err)?
        }
        w => resolve_workspace(agent, w)?,
    };
    let (progress, interrupts) = reporter(progress, Some(agent));
    let (law, shared) = (agent.law.clone(), progress.clone());
    let found = run_interruptible(py, &interrupts, move || {
        explore_with(law.as_ref(), &params, workspace, shared.as_ref())
    })?
    .map_err(to_py_err)?;
    agent.check_callbacks()?;
    progress.check()?;
    let poses = found
        .ground_truth
        .map(|g| g.poses().to_owned().into_pyarray(py));
    Ok((
        found.motors.into_pyarray(py),
        poses,
        found.probes.into_pyarray(py),
    ))
}

/// `"default"` (the agent's), `"none"` or `None` (the whole motor space), or
/// `(cx, cy, depth, width)`.
pub(crate) fn resolve_workspace(
    agent: &Agent,
    spec: Option<&Bound<'_, PyAny>>,
) -> PyResult<Option<Workspace>> {
    let Some(spec) = spec else {
        return Ok(None);
    };
    let spec = if let Ok(text) = spec.extract::<String>() {
        match text.as_str() {
            "default" => front::WorkspaceSpec::Default,
            "none" => front::WorkspaceSpec::None,
            other => {
                return Err(value_error(format!(
                    "workspace '{other}' must be 'default', None, or four numbers (cx, cy, depth, width)"
                )))
            }
        }
    } else {
        let (cx, cy, depth, width): (f64, f64, f64, f64) = spec.extract().map_err(|_| {
            value_error("workspace must be 'default', None, or four numbers (cx, cy, depth, width)")
        })?;
        front::WorkspaceSpec::Box([cx, cy, depth, width])
    };
    spec.resolve(agent.law.as_ref()).map_err(to_py_err)
}

/// `_trace(agent, motors, params_json, env, workspace, progress)`: the kernel sets,
/// `(sets (M, P, N), kept (M,) int64, closed (M,) int64, pieces (M, P) int64,
/// report_json)`; the report carries the summary's warnings as `warnings` (which
/// `smspace.trace` takes out of it: its report is `sets.trace.json`'s).
#[pyfunction]
#[pyo3(signature = (agent, motors, params, env=None, workspace=None, progress=None))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn _trace<'py>(
    py: Python<'py>,
    agent: &Agent,
    motors: PyReadonlyArray2<'py, f64>,
    params: &str,
    env: Option<&Bound<'py, PyAny>>,
    workspace: Option<&Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<i64>>,
    String,
)> {
    let params: TraceParams = from_json(params, "tracing parameters")?;
    let params = params.check().map_err(to_py_err)?;
    let motors = motors.as_array().to_owned();
    check_finite(motors.iter(), "motors")?;
    let sensory = params.method() == smspace::kernel::TraceMethod::Sensory;
    let environment = if sensory || env.is_some() {
        Some(agent.environment(env)?)
    } else {
        None
    };
    let workspace = resolve_workspace(agent, workspace)?;
    let (progress, interrupts) = reporter(progress, Some(agent));
    let (law, shared) = (agent.law.clone(), progress.clone());
    let rows = motors.nrows();
    let traced = run_interruptible(py, &interrupts, move || {
        trace_sets(
            law.as_ref(),
            environment.as_ref(),
            motors.view(),
            workspace.as_ref(),
            &params,
            shared.as_ref(),
        )
    })?
    .map_err(to_py_err);
    agent.check_callbacks()?;
    progress.check()?;
    traced_outputs(py, traced?, rows)
}

/// The Python outputs of traced sets: `(sets, kept, closed, pieces, report_json)`, the
/// report carrying the summary's warnings as `warnings`; `ValueError` when fewer than
/// two sets of `rows` (two or more) are kept.
#[allow(clippy::type_complexity)]
pub(crate) fn traced_outputs(
    py: Python<'_>,
    traced: smspace::kernel::TracedSets,
    rows: usize,
) -> PyResult<(
    Bound<'_, PyArray3<f64>>,
    Bound<'_, PyArray1<i64>>,
    Bound<'_, PyArray1<i64>>,
    Bound<'_, PyArray2<i64>>,
    String,
)> {
    // What the summary says a user must know (noisy sensors, with their measured noise;
    // sets left out; missed pieces): in the report as `warnings`, which `smspace.trace`
    // raises as warnings, and after the error when too few sets are kept.
    let warnings = traced.report.summary.warnings();
    // Fewer than two kept sets of two or more: an error naming the statuses.
    if let Err(error) = traced.report.summary.require(rows.min(2)) {
        let mut message = error.to_string();
        for warning in &warnings {
            message.push_str(". ");
            message.push_str(warning);
        }
        return Err(value_error(message));
    }
    let mut report =
        serde_json::to_value(&traced.report).map_err(|e| value_error(e.to_string()))?;
    if let Some(fields) = report.as_object_mut() {
        fields.insert("warnings".to_owned(), serde_json::Value::from(warnings));
    }
    let report = report.to_string();
    let kept: Array1<i64> = traced.kept.iter().map(|&k| k as i64).collect();
    let closed: Array1<i64> = traced.closure.iter().map(|c| c.code()).collect();
    Ok((
        traced.sets.into_pyarray(py),
        kept.into_pyarray(py),
        closed.into_pyarray(py),
        traced.pieces.into_pyarray(py),
        report,
    ))
}

/// `_distances(sets, closed, metric, memory_limit_bytes, progress, pieces)`: the
/// `(M, M)` matrix (`metric`: the dict of [`MetricArgs`]).
#[pyfunction]
#[pyo3(signature = (sets, closed, metric, memory_limit_bytes=None, progress=None, pieces=None))]
fn _distances<'py>(
    py: Python<'py>,
    sets: PyReadonlyArray3<'py, f64>,
    closed: Option<PyReadonlyArray1<'py, i64>>,
    metric: MetricArgs,
    memory_limit_bytes: Option<u64>,
    progress: Option<Py<PyAny>>,
    pieces: Option<PyReadonlyArray2<'py, i64>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let points = sets.as_array();
    check_finite(points.iter(), "sets")?;
    let built = metric.build(memory_limit_bytes)?;
    let sets = OwnedSets::new(points, closed, pieces.as_ref(), "pieces", &built)?;
    metric.check_sets(&built, &sets.view()?)?;
    let (progress, interrupts) = reporter(progress, None);
    let shared = progress.clone();
    let d = run_interruptible(py, &interrupts, move || {
        distance_matrix_with(
            sets.view()?,
            built.metric.as_ref(),
            &built.params,
            shared.as_ref(),
        )
        .map_err(to_py_err)
    })?;
    progress.check()?;
    Ok(d?.into_array().into_pyarray(py))
}

/// `_distance_tile(rows, rows_closed, cols, cols_closed, tile, metric, rows_pieces,
/// cols_pieces)`: the block `D[r0:r1, c0:c1]` from the sets of its rows
/// and of its columns only, bit for bit the block of the whole matrix (what a
/// cluster's task computes).
#[pyfunction]
#[pyo3(signature = (rows, rows_closed, cols, cols_closed, tile, metric, rows_pieces=None, cols_pieces=None))]
#[allow(clippy::too_many_arguments)]
fn _distance_tile<'py>(
    py: Python<'py>,
    rows: PyReadonlyArray3<'py, f64>,
    rows_closed: Option<PyReadonlyArray1<'py, i64>>,
    cols: PyReadonlyArray3<'py, f64>,
    cols_closed: Option<PyReadonlyArray1<'py, i64>>,
    tile: Bounds,
    metric: MetricArgs,
    rows_pieces: Option<PyReadonlyArray2<'py, i64>>,
    cols_pieces: Option<PyReadonlyArray2<'py, i64>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let built = metric.build(None)?;
    let rows = OwnedSets::new(
        rows.as_array(),
        rows_closed,
        rows_pieces.as_ref(),
        "rows_pieces",
        &built,
    )?;
    let cols = OwnedSets::new(
        cols.as_array(),
        cols_closed,
        cols_pieces.as_ref(),
        "cols_pieces",
        &built,
    )?;
    let tile = Tile::new(tile.0..tile.1, tile.2..tile.3);
    let out = run_interruptible(py, &[], move || {
        let mut out = Array2::zeros(tile.shape());
        fill_tile(
            rows.view()?,
            cols.view()?,
            &tile,
            built.metric.as_ref(),
            out.view_mut(),
            &smspace::progress::Silent,
        )
        .map_err(to_py_err)?;
        Ok::<_, PyErr>(out)
    })??;
    Ok(out.into_pyarray(py))
}

/// A tile's bounds `(r0, r1, c0, c1)`: the rows `r0:r1` and columns `c0:c1`.
type Bounds = (usize, usize, usize, usize);

/// `_merge_tiles(m, tiles)`: the `(M, M)` matrix from `[((r0, r1, c0, c1), values)]`,
/// refusing a pair no tile covers or two tiles that disagree.
#[pyfunction]
fn _merge_tiles<'py>(
    py: Python<'py>,
    m: usize,
    tiles: Vec<(Bounds, PyReadonlyArray2<'py, f64>)>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let mut merge = TileMerge::new(m, None).map_err(to_py_err)?;
    for ((r0, r1, c0, c1), values) in &tiles {
        merge
            .add(&Tile::new(*r0..*r1, *c0..*c1), values.as_array())
            .map_err(to_py_err)?;
    }
    let d: DistanceMatrix = merge.finish().map_err(to_py_err)?;
    Ok(d.into_array().into_pyarray(py))
}

/// `_knn(sets, closed, metric, k, pivots, rows, progress, pieces)`: the `k`
/// nearest sets of the rows `r0:r1`, `(indices (R, k) int64, distances (R, k))`.
#[pyfunction]
#[pyo3(signature = (sets, closed, metric, k, pivots, rows, progress=None, pieces=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn _knn<'py>(
    py: Python<'py>,
    sets: PyReadonlyArray3<'py, f64>,
    closed: Option<PyReadonlyArray1<'py, i64>>,
    metric: MetricArgs,
    k: usize,
    pivots: Option<usize>,
    rows: (usize, usize),
    progress: Option<Py<PyAny>>,
    pieces: Option<PyReadonlyArray2<'py, i64>>,
) -> PyResult<(Bound<'py, PyArray2<i64>>, Bound<'py, PyArray2<f64>>)> {
    let points = sets.as_array();
    check_finite(points.iter(), "sets")?;
    let built = metric.build(None)?;
    let sets = OwnedSets::new(points, closed, pieces.as_ref(), "pieces", &built)?;
    metric.check_sets(&built, &sets.view()?)?;
    let mut params = KnnParams::new().k(k);
    if let Some(p) = pivots {
        params = params.pivots(p);
    }
    let (progress, interrupts) = reporter(progress, None);
    let shared = progress.clone();
    let found = run_interruptible(py, &interrupts, move || {
        knn_with(
            sets.view()?,
            built.metric.as_ref(),
            &built.params,
            &params,
            rows.0..rows.1,
            shared.as_ref(),
        )
        .map_err(to_py_err)
    })?;
    progress.check()?;
    let found = found?;
    let indices = found.indices.mapv(|i| i as i64);
    Ok((indices.into_pyarray(py), found.distances.into_pyarray(py)))
}

/// The validated matrix of `distances` (any layout; copied into C order).
fn matrix(distances: PyReadonlyArray2<'_, f64>) -> PyResult<DistanceMatrix> {
    DistanceMatrix::from_view(distances.as_array())
        .map_err(|e| value_error(format!("D: {}", crate::message(&e))))
}

/// `_embed(D, params_json, progress)`: `(Y (M, d), report_json)`.
#[pyfunction]
#[pyo3(signature = (distances, params, progress=None))]
fn _embed<'py>(
    py: Python<'py>,
    distances: PyReadonlyArray2<'py, f64>,
    params: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, String)> {
    let params: EmbedParams = from_json(params, "embedding parameters")?;
    let method = params.build().map_err(to_py_err)?;
    let d = matrix(distances)?;
    let (progress, interrupts) = reporter(progress, None);
    let shared = progress.clone();
    let embedded = run_interruptible(py, &interrupts, move || method.fit(&d, shared.as_ref()))?
        .map_err(to_py_err);
    progress.check()?;
    let embedded = embedded?;
    let report = serde_json::to_string(&embedded.report).map_err(|e| value_error(e.to_string()))?;
    Ok((embedded.coordinates.into_pyarray(py), report))
}

/// `_analyze(D, poses, params_json, progress)`: the report's JSON (Betti numbers,
/// persistence, intrinsic dimension, agreement with the planar poses `(M, 3)`, the
/// circular coordinate with its `values`).
#[pyfunction]
#[pyo3(signature = (distances, poses, params, progress=None, representation=None))]
fn _analyze<'py>(
    py: Python<'py>,
    distances: PyReadonlyArray2<'py, f64>,
    poses: Option<PyReadonlyArray2<'py, f64>>,
    params: &str,
    progress: Option<Py<PyAny>>,
    representation: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<String> {
    let params: AnalysisParams = from_json(params, "analysis parameters")?;
    let params = params.check().map_err(to_py_err)?;
    let d = matrix(distances)?;
    let poses = poses.as_ref().map(|p| p.as_array().to_owned());
    if let Some(p) = &poses {
        check_finite(p.iter(), "poses")?;
        if p.nrows() != d.len() {
            return Err(value_error(format!(
                "poses has {} rows but D has {} points; the poses must be those of the same sets",
                p.nrows(),
                d.len()
            )));
        }
    }
    let representation = representation.map(|h| h.as_array().to_owned());
    if let Some(h) = &representation {
        if poses.is_none() {
            return Err(value_error(
                "representation needs poses: the measures fit the poses' positions (x, y)",
            ));
        }
        if h.nrows() != d.len() {
            return Err(value_error(format!(
                "representation has {} rows but D has {} points; it must be that of the same sets",
                h.nrows(),
                d.len()
            )));
        }
    }
    let (progress, interrupts) = reporter(progress, None);
    let shared = progress.clone();
    let report = run_interruptible(py, &interrupts, move || {
        let mut report = analyze(
            &d,
            poses.as_ref().map(|p| p.view()),
            &params,
            shared.as_ref(),
        )?;
        if let (Some(h), Some(p)) = (&representation, &poses) {
            let positions = p.slice_axis(ndarray::Axis(1), ndarray::Slice::from(0..2));
            report.affine = Some(affine_errors(h.view(), positions)?);
        }
        Ok::<_, smspace::analysis::AnalysisError>(report)
    })?
    .map_err(to_py_err);
    progress.check()?;
    let report = report?;
    let mut value = serde_json::to_value(&report).map_err(|e| value_error(e.to_string()))?;
    // The circular coordinates, which `analysis.json` leaves to `circle.npy`.
    if let (Some(circle), Some(object)) = (&report.circle, value.get_mut("circle")) {
        object["values"] = serde_json::json!(circle.values);
    }
    serde_json::to_string(&value).map_err(|e| value_error(e.to_string()))
}

/// The defaults of every stage's parameters, as the library defines them (the same
/// that `smspace run` and the `smspace` commands fill in), as JSON: the set metric and
/// period of `[metric]`, the `[exploration]`, `[kernel]` and `[embedding]` tables and
/// the nearest-set search. `smspace`'s functions take their default arguments from it
/// (`_core._DEFAULTS`), so no door restates a default.
fn defaults() -> PyResult<String> {
    let metric = DistanceParams::default();
    let embedding = EmbedParams::default();
    let value = serde_json::json!({
        "metric": metric.metric.as_str(),
        "period": metric.period.to_string(),
        "exploration": ExploreParams::default(),
        "kernel": TraceParams::default(),
        "embedding": {
            "method": embedding.method,
            "params": embedding.params,
        },
        "knn": KnnParams::default(),
    });
    serde_json::to_string(&value).map_err(|e| value_error(e.to_string()))
}

/// Adds the stage functions to the module.
/// `_invariance(agent, motors, params_json, envs, metric, workspace, progress)`: the
/// starts `motors` traced with the sensory method (the `[kernel]` parameters of
/// `params_json`) in every environment of `envs` (each as `env` of `_trace`) and
/// compared under `metric` (the dict of [`MetricArgs`], its period resolved for the
/// agent): `(report JSON, common rows, one (C, C) matrix and one (C, K) sensor array
/// per environment)`, what `smspace invariance` writes.
#[pyfunction]
#[pyo3(signature = (agent, motors, params, envs, metric, workspace=None, progress=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn _invariance<'py>(
    py: Python<'py>,
    agent: &Agent,
    motors: PyReadonlyArray2<'py, f64>,
    params: &str,
    envs: Vec<Bound<'py, PyAny>>,
    metric: MetricArgs,
    workspace: Option<&Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    String,
    Bound<'py, PyArray1<i64>>,
    Vec<Bound<'py, PyArray2<f64>>>,
    Vec<Bound<'py, PyArray2<f64>>>,
)> {
    let params: TraceParams = from_json(params, "tracing parameters")?;
    let params = TraceParams {
        method: smspace::kernel::TraceMethod::Sensory,
        ..params
    }
    .check()
    .map_err(to_py_err)?;
    if agent.calls.is_some() {
        return Err(value_error(
            "a PythonAgent senses its own world, so there are no environments to compare; invariance needs an agent built by smspace (a preset or a TOML file) whose lights it places",
        ));
    }
    let motors = motors.as_array().to_owned();
    check_finite(motors.iter(), "motors")?;
    let environments = envs
        .iter()
        .map(|env| agent.environment(Some(env)))
        .collect::<PyResult<Vec<_>>>()?;
    let built = metric.build_for(Some(agent.law.as_ref()), None)?;
    let workspace = resolve_workspace(agent, workspace)?;
    let (progress, interrupts) = reporter(progress, Some(agent));
    let (law, shared) = (agent.law.clone(), progress.clone());
    let measured = run_interruptible(py, &interrupts, move || {
        smspace::invariance::invariance_measured(
            law.as_ref(),
            motors.view(),
            &environments,
            workspace.as_ref(),
            &params,
            built.metric.as_ref(),
            shared.as_ref(),
        )
    })?
    .map_err(to_py_err);
    agent.check_callbacks()?;
    progress.check()?;
    let measured = measured?;
    let report = serde_json::to_string(&measured.report).map_err(|e| value_error(e.to_string()))?;
    let rows: Vec<i64> = measured.common_rows.iter().map(|&r| r as i64).collect();
    Ok((
        report,
        rows.into_pyarray(py),
        measured
            .set_distances
            .into_iter()
            .map(|d| d.into_pyarray(py))
            .collect(),
        measured
            .sensors
            .into_iter()
            .map(|s| s.into_pyarray(py))
            .collect(),
    ))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("_DEFAULTS", defaults()?)?;
    m.add_function(wrap_pyfunction!(_explore, m)?)?;
    m.add_function(wrap_pyfunction!(_trace, m)?)?;
    m.add_function(wrap_pyfunction!(_distances, m)?)?;
    m.add_function(wrap_pyfunction!(_distance_tile, m)?)?;
    m.add_function(wrap_pyfunction!(_merge_tiles, m)?)?;
    m.add_function(wrap_pyfunction!(_knn, m)?)?;
    m.add_function(wrap_pyfunction!(_embed, m)?)?;
    m.add_function(wrap_pyfunction!(_analyze, m)?)?;
    m.add_function(wrap_pyfunction!(_invariance, m)?)?;
    m.add(
        "CallbackError",
        m.py().get_type::<crate::agent::CallbackError>(),
    )?;
    Ok(())
}
