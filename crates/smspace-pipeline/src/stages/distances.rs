//! `distances`: the set metric between every pair of kernel sets (paper section 3.2,
//! step 3), or on the landmark path ([`crate::scale`]) the distances of every
//! set to `L` landmark sets and the exact kNN graph of the babbled sets, never the
//! `M × M` matrix.

use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput};
use crate::manifest::StageId;
use crate::scale::{ChosenPath, ScaleParams};
use smspace::explore::Exploration;
use smspace::io::{self, IoError, Outputs};
use smspace::kernel::TracedSets;
use smspace::metric::landmarks::{landmarks_and_knn_with, LandmarkDistances, LandmarkSelection};
use smspace::metric::{
    distance_matrix_with, BuiltMetric, DistanceMatrix, DistanceParams, Knn, MetricName,
    Periodicity, SetMetric, SetsView, WorkForecast,
};
use smspace::progress::Progress;

/// Where the `distances` stage computes its matrix: in this process
/// ([`LocalDistances`], what [`run`](crate::run) uses) or elsewhere, e.g. on a
/// cluster's workers ([`run_with`](crate::run_with); the Python package's
/// Dask backend). The stage's key does not depend on it, so every backend must return
/// the matrix [`distance_matrix_with`] returns, bit for bit (tiles do:
/// [`smspace::metric::fill_tile`]).
pub trait DistanceBackend: Sync {
    /// The matrix of `stage`'s metric ([`DistancesStage::set_metric`], built from its
    /// `metric`, `period` and `params`) between `sets`, refusing a matrix above
    /// `memory_limit_bytes`, reporting to `progress`.
    fn distances(
        &self,
        stage: &DistancesStage,
        sets: SetsView<'_>,
        memory_limit_bytes: Option<u64>,
        progress: &dyn Progress,
    ) -> crate::Result<DistanceMatrix>;

    /// Where the backend computes, when not in this process (e.g. "the Dask cluster
    /// of the client given"). The landmark path ([`ScaleParams`]) computes in this
    /// process only, and refuses a remote backend rather than ignore it. The default
    /// is `None`: this process.
    fn remote(&self) -> Option<String> {
        None
    }
}

/// Refuses a backend's matrix that is not `m × m` for `m` sets, naming the backend
/// and both shapes, before anything is written.
fn check_backend_shape(
    matrix: &DistanceMatrix,
    m: usize,
    backend: &dyn DistanceBackend,
) -> crate::Result<()> {
    let found = matrix.len();
    if found == m {
        return Ok(());
    }
    Err(smspace::metric::MetricError::Backend {
        backend: backend
            .remote()
            .unwrap_or_else(|| "in this process".to_owned()),
        reason: format!(
            "it returned a {found} × {found} matrix for {m} kernel sets; a backend must return the {m} × {m} matrix of every pair"
        ),
    }
    .into())
}

/// The matrix in this process, on its threads ([`distance_matrix_with`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct LocalDistances;

impl DistanceBackend for LocalDistances {
    fn distances(
        &self,
        stage: &DistancesStage,
        sets: SetsView<'_>,
        memory_limit_bytes: Option<u64>,
        progress: &dyn Progress,
    ) -> crate::Result<DistanceMatrix> {
        let limit = DistanceParams::new().memory_limit_bytes(memory_limit_bytes);
        Ok(distance_matrix_with(
            sets,
            stage.set_metric(),
            &limit,
            progress,
        )?)
    }
}

/// The `distances` stage: the `[metric]` table's metric, period and parameters (its
/// memory limit is the run's, in the [`StageContext`]), and the metric they build
/// (built-in or registered, [`smspace::metric::MetricRegistry`]).
#[derive(Clone, Serialize)]
pub struct DistancesStage {
    /// The set metric's name.
    pub metric: MetricName,
    /// The period of the motor coordinates (resolved: never `"motors"`).
    pub period: Periodicity,
    /// The metric's own parameters (`[metric.params]`; none for the built-in ones).
    #[serde(skip_serializing_if = "toml::Table::is_empty")]
    pub params: toml::Table,
    /// The `[scale]` table: dense or landmark path (keyed only when not the default,
    /// so that the default's key is the one from before the table existed).
    #[serde(skip_serializing_if = "ScaleParams::is_default")]
    pub scale: ScaleParams,
    /// The `[analysis] mle_neighbors`: the kNN graph of the landmark path serves the
    /// dimension estimates (checked `≤ scale.knn`; not keyed, it changes no output).
    #[serde(skip)]
    pub mle_neighbors: usize,
    /// The metric built from the fields above.
    #[serde(skip)]
    set_metric: Arc<dyn SetMetric>,
}

impl DistancesStage {
    /// The stage of a metric built from its `[metric]` table, on the dense path for
    /// every `M` (see [`DistancesStage::with_scale`]).
    pub fn new(built: &BuiltMetric) -> Self {
        Self {
            metric: built.params.metric.clone(),
            period: built.params.period.clone(),
            params: built.params.params.clone(),
            scale: ScaleParams::default(),
            mle_neighbors: 2,
            set_metric: built.metric.clone(),
        }
    }

    /// The stage with the `[scale]` table (checked by [`ScaleParams::check`]).
    pub fn with_scale(self, scale: ScaleParams, mle_neighbors: usize) -> Self {
        Self {
            scale,
            mle_neighbors,
            ..self
        }
    }

    /// The path taken for `m` sets.
    pub fn path(&self, m: usize) -> ChosenPath {
        self.scale.choose(m)
    }

    /// The metric built from the stage's fields.
    pub fn set_metric(&self) -> &dyn SetMetric {
        self.set_metric.as_ref()
    }
}

impl std::fmt::Debug for DistancesStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DistancesStage")
            .field("metric", &self.metric)
            .field("period", &self.period)
            .field("params", &self.params)
            .field("scale", &self.scale)
            .finish()
    }
}

/// What `distances` reads.
#[derive(Debug, Clone, Copy)]
pub struct DistancesInput<'a> {
    /// The kernel sets and which of them are closed loops.
    pub traced: &'a Keyed<TracedSets>,
    /// Which sets are babbled (the landmark path's kNN graph joins those); not among
    /// the keys: the traced sets' key already holds the exploration's.
    pub exploration: &'a Keyed<Exploration>,
}

impl StageInput for DistancesInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.traced.key]
    }
}

/// The distances between the sets, on either path ([`crate::scale`]).
#[derive(Debug, Clone, PartialEq)]
pub enum SetDistances {
    /// The `M × M` matrix.
    Dense(DistanceMatrix),
    /// Landmarks and the kNN graph.
    Landmarks(Box<LandmarkGraph>),
}

impl SetDistances {
    /// Number of sets `M`.
    pub fn sets(&self) -> usize {
        match self {
            Self::Dense(d) => d.len(),
            Self::Landmarks(g) => g.landmarks.sets(),
        }
    }

    /// The `M × M` matrix, on the dense path.
    pub fn dense(&self) -> Option<&DistanceMatrix> {
        match self {
            Self::Dense(d) => Some(d),
            Self::Landmarks(_) => None,
        }
    }
}

/// The landmark path's distances: landmarks and the kNN graph of the babbled sets.
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkGraph {
    /// The landmarks, their matrix and every set's distances to them.
    pub landmarks: LandmarkDistances,
    /// The sets the kNN graph joins (the babbled ones; all sets without a probe grid),
    /// increasing.
    pub knn_sets: Vec<usize>,
    /// The `k` nearest of each of them among them (indices into `knn_sets`).
    pub knn: Knn,
}

/// What `landmarks.json` records beside the arrays.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
struct LandmarkRecord {
    sets: usize,
    landmarks: usize,
    selection: LandmarkSelection,
    covering_radius: f64,
    /// Nearest landmarks measured per set.
    nearest: usize,
    knn_sets: usize,
    k: usize,
}

const MATRIX_FILE: &str = "D.npy";
const LANDMARK_ROWS_FILE: &str = "landmarks.npy";
const LANDMARK_MATRIX_FILE: &str = "D.landmarks.npy";
const NEAREST_FILE: &str = "landmarks.nearest.npy";
const NEAREST_DISTANCES_FILE: &str = "D.nearest-landmarks.npy";
const LANDMARK_RECORD_FILE: &str = "landmarks.json";
const KNN_SETS_FILE: &str = "knn_sets.npy";
const KNN_INDICES_FILE: &str = "knn_indices.npy";
const KNN_DISTANCES_FILE: &str = "knn_distances.npy";

impl Stage for DistancesStage {
    const ID: StageId = StageId::Distances;
    type Input<'a> = DistancesInput<'a>;
    type Output = SetDistances;

    fn compute(
        &self,
        input: &DistancesInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<SetDistances> {
        let traced = &input.traced.value;
        let sets = SetsView::new(traced.sets.view())
            .with_closure(&traced.closure)
            .with_pieces(traced.pieces.view());
        // The metric says whether it measures these kernels (the curve metric reads
        // polylines, and spatial sets slice by slice).
        let metric = self.set_metric();
        metric
            .check_kernels(traced.report.kernel_shape())
            .map_err(smspace::metric::MetricError::Invalid)?;
        metric.check_sets(&sets, &traced.report.extended_along)?;
        match self.path(traced.kept.len()) {
            ChosenPath::Dense => {
                let matrix = context.distances.distances(
                    self,
                    sets,
                    context.memory_limit_bytes,
                    context.progress,
                )?;
                check_backend_shape(&matrix, traced.kept.len(), context.distances)?;
                Ok(SetDistances::Dense(matrix))
            }
            ChosenPath::Landmarks => {
                if let Some(remote) = context.distances.remote() {
                    let refused = smspace::params::InvalidParameter::new(
                        "scale",
                        "path",
                        super::label(&self.scale.path),
                        format!(
                            "the landmark path for {} sets computes in this process, not on {remote}; set scale.path = \"dense\" to compute the {0} × {0} matrix there, or run without it",
                            traced.kept.len()
                        ),
                    );
                    return Err(smspace::metric::MetricError::Invalid(refused).into());
                }
                Ok(SetDistances::Landmarks(Box::new(
                    self.landmark_graph(input, sets, context)?,
                )))
            }
        }
    }

    fn save(
        &self,
        _: &DistancesInput<'_>,
        d: &SetDistances,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        match d {
            SetDistances::Dense(d) => d.write_into(outputs, &dir.join(MATRIX_FILE))?,
            SetDistances::Landmarks(g) => save_graph(g, outputs, dir)?,
        }
        Ok(())
    }

    fn load(&self, input: &DistancesInput<'_>, dir: &Path) -> crate::Result<SetDistances> {
        let m = input.traced.kept.len();
        if self.path(m) == ChosenPath::Landmarks {
            return Ok(SetDistances::Landmarks(Box::new(load_graph(dir, m)?)));
        }
        let path = dir.join(MATRIX_FILE);
        let d = DistanceMatrix::load(&path).map_err(smspace::metric::MetricError::from)?;
        if d.len() != m {
            return Err(IoError::Shape {
                path,
                found: smspace::io::shape_string(d.shape()),
                expected: format!("({m}, {m}), one row per set of sets.npy"),
            }
            .into());
        }
        Ok(SetDistances::Dense(d))
    }

    /// For kernels of dimension `k ≥ 2` (surfaces sampled by `P` points) under a metric
    /// other than `curve` (which reads spatial sets as polylines): the point metric
    /// between two of them compares every point with every point, almost without
    /// the early exits that make loops fast, about `M (M − 1) P²` point distances in
    /// all; said with the time it takes at `SURFACE_POINT_DISTANCES_PER_CORE_SECOND`
    /// when it exceeds about a minute on one core.
    ///
    /// On the landmark path: the path, its sizes and its pairs.
    fn forecast(&self, input: &DistancesInput<'_>) -> Option<String> {
        let traced = &input.traced.value;
        let (m, p, _) = traced.sets.dim();
        let landmarks = match self.path(m) {
            ChosenPath::Dense => None,
            ChosenPath::Landmarks => {
                let l = self.scale.landmarks.min(m);
                let pairs = match self.scale.selection {
                    LandmarkSelection::MaxMin => format!(
                        "{} set pairs to choose them",
                        (l * m).saturating_sub(l * (l + 1) / 2)
                    ),
                    LandmarkSelection::Random => format!(
                        "{} pairs among them and about {} from the sets to their {} nearest",
                        l * l.saturating_sub(1) / 2,
                        m * self.scale.nearest.min(l),
                        self.scale.nearest.min(l)
                    ),
                };
                Some(format!(
                    "landmark path (scale.path = {}, {m} sets, above = {}): {l} {} landmarks, {pairs}, and the {} nearest of every babbled set (found through the landmarks); no {m} × {m} matrix",
                    super::label(&self.scale.path),
                    self.scale.above,
                    self.scale.selection,
                    self.scale.knn
                ))
            }
        };
        let work = self
            .set_metric()
            .forecast(traced.report.kernel_shape(), m, p)
            .and_then(|work| long_work(traced.report.kernel_shape().dimension, m, work));
        match (landmarks, work) {
            (Some(a), Some(b)) => Some(format!("{a}; {b}")),
            (a, b) => a.or(b),
        }
    }

    fn summary(&self, d: &SetDistances) -> String {
        match d {
            SetDistances::Dense(d) => format!(
                "{0} × {0} matrix ({1}, period {2})",
                d.len(),
                self.metric,
                self.period
            ),
            SetDistances::Landmarks(g) => format!(
                "{} sets to their {} nearest of {} {} landmarks (covering radius {:.4}) and the {} nearest of {} babbled sets ({}, period {})",
                g.landmarks.sets(),
                g.landmarks.measured(),
                g.landmarks.len(),
                g.landmarks.selection,
                g.landmarks.covering_radius,
                g.knn.k(),
                g.knn_sets.len(),
                self.metric,
                self.period
            ),
        }
    }
}

impl DistancesStage {
    /// The landmark path: landmarks of every set, then the kNN graph of the babbled
    /// sets, both with the stage's metric in this process.
    fn landmark_graph(
        &self,
        input: &DistancesInput<'_>,
        sets: SetsView<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<LandmarkGraph> {
        let traced = &input.traced.value;
        let params = self.scale.check(self.mle_neighbors)?;
        let probes = &input.exploration.value.probes;
        let knn_sets: Vec<usize> = (0..traced.kept.len())
            .filter(|&i| smspace::explore::is_babbled(probes.row(traced.kept[i])))
            .collect();
        let (landmarks, knn) = landmarks_and_knn_with(
            sets,
            self.set_metric(),
            &params,
            &knn_sets,
            self.scale.knn,
            context.memory_limit_bytes,
            context.progress,
        )?;
        Ok(LandmarkGraph {
            landmarks,
            knn_sets,
            knn,
        })
    }
}

/// Stages the landmark path's files.
fn save_graph(g: &LandmarkGraph, outputs: &mut Outputs, dir: &Path) -> Result<(), IoError> {
    let l = &g.landmarks;
    let rows = ndarray::Array1::from_iter(l.rows.iter().map(|&r| r as i64));
    outputs.npy(&dir.join(LANDMARK_ROWS_FILE), &rows)?;
    outputs.npy(&dir.join(LANDMARK_MATRIX_FILE), &l.landmarks.view())?;
    outputs.npy(&dir.join(NEAREST_FILE), &l.nearest.mapv(|a| a as i64))?;
    outputs.npy(&dir.join(NEAREST_DISTANCES_FILE), &l.nearest_distances)?;
    let knn_sets = ndarray::Array1::from_iter(g.knn_sets.iter().map(|&r| r as i64));
    outputs.npy(&dir.join(KNN_SETS_FILE), &knn_sets)?;
    outputs.npy(
        &dir.join(KNN_INDICES_FILE),
        &g.knn.indices.mapv(|j| j as i64),
    )?;
    outputs.npy(&dir.join(KNN_DISTANCES_FILE), &g.knn.distances)?;
    let record = LandmarkRecord {
        sets: l.sets(),
        landmarks: l.len(),
        selection: l.selection,
        covering_radius: l.covering_radius,
        nearest: l.measured(),
        knn_sets: g.knn_sets.len(),
        k: g.knn.k(),
    };
    outputs.json(&dir.join(LANDMARK_RECORD_FILE), &record)
}

/// Reads back [`save_graph`]'s files for `m` sets, checking their shapes.
fn load_graph(dir: &Path, m: usize) -> crate::Result<LandmarkGraph> {
    let record: LandmarkRecord = io::read_json(&dir.join(LANDMARK_RECORD_FILE), "landmark record")?;
    let shape_error = |file: &str, found: &[usize], expected: String| IoError::Shape {
        path: dir.join(file),
        found: io::shape_string(found),
        expected,
    };
    let index = |file: &str, len: usize, bound: usize| -> crate::Result<Vec<usize>> {
        let path = dir.join(file);
        let values = io::read_i64(&path)?;
        if values.ndim() != 1
            || values.len() != len
            || values.iter().any(|&v| v < 0 || v as usize >= bound)
        {
            return Err(shape_error(
                file,
                values.shape(),
                format!("({len},) set rows below {bound}, as landmarks.json says"),
            )
            .into());
        }
        Ok(values.iter().map(|&v| v as usize).collect())
    };
    if record.sets != m {
        return Err(shape_error(
            LANDMARK_RECORD_FILE,
            &[record.sets],
            format!("{m} sets, one per set of sets.npy"),
        )
        .into());
    }
    let rows = index(LANDMARK_ROWS_FILE, record.landmarks, m)?;
    let knn_sets = index(KNN_SETS_FILE, record.knn_sets, m)?;
    let landmarks = DistanceMatrix::load(&dir.join(LANDMARK_MATRIX_FILE))
        .map_err(smspace::metric::MetricError::from)?;
    let nearest_distances = io::read_matrix(
        &dir.join(NEAREST_DISTANCES_FILE),
        Some(record.nearest),
        "(M, q)",
    )?;
    let nearest = io::read_i64(&dir.join(NEAREST_FILE))?;
    let nearest = match nearest.into_dimensionality::<ndarray::Ix2>() {
        Ok(nearest)
            if nearest.dim() == (m, record.nearest)
                && nearest
                    .iter()
                    .all(|&a| a >= 0 && (a as usize) < record.landmarks) =>
        {
            nearest.mapv(|a| a as usize)
        }
        Ok(nearest) => {
            return Err(shape_error(
                NEAREST_FILE,
                nearest.shape(),
                format!(
                    "({m}, {}) landmark positions below {}",
                    record.nearest, record.landmarks
                ),
            )
            .into())
        }
        Err(_) => {
            return Err(shape_error(NEAREST_FILE, &[], format!("({m}, {})", record.nearest)).into())
        }
    };
    let indices = io::read_i64(&dir.join(KNN_INDICES_FILE))?;
    let indices = match indices.into_dimensionality::<ndarray::Ix2>() {
        Ok(indices) if indices.ncols() == record.k => indices,
        Ok(indices) => {
            return Err(shape_error(
                KNN_INDICES_FILE,
                indices.shape(),
                format!("(sets, {})", record.k),
            )
            .into())
        }
        Err(_) => {
            return Err(shape_error(KNN_INDICES_FILE, &[], format!("(sets, {})", record.k)).into())
        }
    };
    let distances = io::read_matrix(&dir.join(KNN_DISTANCES_FILE), Some(record.k), "(M, k)")?;
    if landmarks.len() != record.landmarks
        || nearest_distances.nrows() != m
        || indices.nrows() != record.knn_sets
        || distances.nrows() != record.knn_sets
        || indices
            .iter()
            .any(|&j| j < 0 || j as usize >= record.knn_sets)
    {
        return Err(shape_error(
            NEAREST_DISTANCES_FILE,
            nearest_distances.shape(),
            "the shapes landmarks.json records".into(),
        )
        .into());
    }
    Ok(LandmarkGraph {
        landmarks: LandmarkDistances {
            rows,
            selection: record.selection,
            covering_radius: record.covering_radius,
            landmarks,
            nearest,
            nearest_distances,
        },
        knn: Knn {
            rows: 0..record.knn_sets,
            indices: indices.mapv(|j| j as usize),
            distances,
        },
        knn_sets,
    })
}

/// The forecast of a long matrix of `m` sets of kernels of dimension `k`: said when the
/// metric's forecast ([`SetMetric::forecast`]) exceeds about a minute on one core.
fn long_work(k: usize, m: usize, work: WorkForecast) -> Option<String> {
    if work.core_seconds < 60.0 {
        return None;
    }
    let cores = rayon::current_num_threads().max(1) as f64;
    Some(format!(
        "the kernels are {k}-D surfaces: {} for {m} sets, roughly {:.0} min on {cores} threads (about {:.0} core-minutes); lower exploration.n or kernel.points to shorten it",
        work.what,
        work.core_seconds / cores / 60.0,
        work.core_seconds / 60.0
    ))
}

#[cfg(test)]
mod tests {
    use super::long_work;
    use smspace::metric::{
        Hausdorff, KernelShape, MetricKind, Periodicity, SetMetric, Surface, SurfaceParams,
    };
    use smspace::sets::Closure;

    fn note(metric: &dyn SetMetric, k: usize, m: usize, p: usize) -> Option<String> {
        metric
            .forecast(KernelShape::of_dimension(k), m, p)
            .and_then(|work| long_work(k, m, work))
    }

    #[test]
    fn surfaces_are_forecast_and_curves_are_not() {
        let point: Box<dyn SetMetric> = Box::new(Hausdorff {
            period: Periodicity::default(),
        });
        let curve = MetricKind::Curve.with_period(Periodicity::default(), Closure::Closed);
        let surface = Surface::new(SurfaceParams::default(), Periodicity::default()).unwrap();
        assert_eq!(note(point.as_ref(), 1, 100_000, 100), None);
        assert_eq!(note(point.as_ref(), 2, 10, 20), None);
        assert_eq!(note(curve.as_ref(), 2, 3500, 200), None);
        let disks = note(&surface, 2, 1288, 600).unwrap();
        assert!(disks.contains("tangent disks"), "{disks}");
        let note = note(point.as_ref(), 2, 3500, 200).unwrap();
        assert!(
            note.contains("2-D surfaces") && note.contains("3500 sets"),
            "{note}"
        );
        assert!(note.contains("kernel.points"), "{note}");
    }
}
