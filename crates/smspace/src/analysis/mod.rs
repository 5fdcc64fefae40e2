//! Measuring what the agent learned (paper section 3.3): the topology and dimension of
//! the manifold of kernel sets and its agreement with the observer's ground truth (its
//! independence of the environment is the experiment [`crate::invariance`]).
//!
//! The paper judges its result by eye ("the resultant manifold has the topology of
//! `T × ℝ²`", a circle of orientations times a plane of positions) and states that "the
//! same exploration in different environments thus leads to the construction of the
//! same internal manifold". This module puts numbers on both claims, from the matrix
//! `D_ij = ρ(M^i, M^j)` alone:
//!
//! - [`homology`]: Vietoris–Rips persistence `H0`, `H1` (and `H2`), and Betti numbers
//!   read off by a stated gap rule ([`BettiRule`]); the arm should give `b = [1, 1]`;
//! - [`dimension`]: TwoNN and Levina–Bickel estimates (the arm: 3, the redundant toy: 1);
//! - [`agreement`]: Spearman, trustworthiness and continuity against the poses;
//! - [`affine`]: how well one affine map reads the sensor's positions off a learned
//!   representation (an embedding), the measures of the paper's best known follow-up;
//! - [`circular`]: a circular coordinate for every set from the longest loop (a
//!   cocycle of persistent cohomology, smoothed), scored by its circular correlation
//!   with the pose's angles: "circle × plane" with the circle as a number.
//!
//! [`analyze`] runs the first three and returns an [`AnalysisReport`], whose JSON keys
//! (`betti`, `persistence`, `intrinsic_dimension.twonn`, `intrinsic_dimension.mle`,
//! `agreement.spearman`, `agreement.trustworthiness`, `agreement.continuity`) are a
//! stable contract.
//!
//! Homology of more than [`AnalysisParams::max_points`] points runs on max–min
//! landmarks (a greedy farthest-point subsample starting at row 0); the report says
//! so and gives the covering radius, the largest distance of a point to its nearest
//! landmark: features shorter than about twice that radius are not resolved. `H1` of the
//! paper's arm sets takes about 0.6 s on the default 800 landmarks and 4.5 s on 1500
//! (2 cores); the long-lived classes of a sampled manifold cost time roughly like `M⁴`.

pub mod affine;
pub mod agreement;
pub mod circular;
pub mod compensability;
pub mod dimension;
pub mod homology;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::agent::GroundTruthView;
use crate::metric::DistanceMatrix;
use crate::neighbours::{farthest_first, DenseDistances, NeighboursError};
use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;
pub use agreement::Agreement;
pub use dimension::DimensionEstimate;
pub use homology::{rips_persistence, Bar, BettiRule, Persistence};

/// Errors of the analysis stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// Too few points to analyse.
    #[error("the distance matrix has {points} points; the analysis needs at least {needed}")]
    TooFewPoints {
        /// `M`.
        points: usize,
        /// The least `M` accepted.
        needed: usize,
    },
    /// The poses do not match the distance matrix.
    #[error("poses have shape ({rows}, {columns}), expected ({expected}, {coordinates}) to match the distance matrix")]
    PosesShape {
        /// Rows.
        rows: usize,
        /// Columns.
        columns: usize,
        /// `M`.
        expected: usize,
        /// The pose's coordinates `d` (3 for the planar `(x, y, alpha)`).
        coordinates: usize,
    },
    /// A parameter is out of its domain.
    #[error(transparent)]
    Invalid(#[from] InvalidParameter),
    /// Nearest-neighbour distances given to a dimension estimate are not usable.
    #[error("the nearest-neighbour distances are not usable: {reason}")]
    NotNeighbourDistances {
        /// What is wrong, with the row.
        reason: String,
    },
    /// The data give no estimate.
    #[error("{what} is undefined for these data: {reason}")]
    Degenerate {
        /// The figure.
        what: &'static str,
        /// Why.
        reason: String,
    },
    /// A neighbour computation refused its input.
    #[error(transparent)]
    Neighbours(#[from] NeighboursError),
    /// The compensability analysis refused its input.
    #[error(transparent)]
    Compensability(#[from] compensability::CompensabilityError),
    /// The computation would be too large.
    #[error("{what} is too large to compute: the limit is {limit}")]
    TooLarge {
        /// The computation.
        what: String,
        /// The limit.
        limit: &'static str,
    },
}

impl AnalysisError {
    /// The parameter out of its domain, located by table and key, if this is one.
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            AnalysisError::Invalid(p) => Some(p),
            AnalysisError::Compensability(compensability::CompensabilityError::Invalid(p)) => {
                Some(p)
            }
            _ => None,
        }
    }
}

/// Parameters of [`analyze`] (the `[analysis]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AnalysisParams {
    /// Highest homology dimension, 0 to 2. Default 1.
    pub max_homology_dim: usize,
    /// Rips threshold; `None`: the enclosing radius (no bar is lost). Default `None`.
    pub threshold: Option<f64>,
    /// Homology of more points runs on this many max–min landmarks. Default 800.
    pub max_points: usize,
    /// Betti rule: smallest ratio of a significant bar to the next. Default 3.
    pub gap_ratio: f64,
    /// Betti rule: the noise floor, as a fraction of the threshold. Default 0.1.
    pub noise_fraction: f64,
    /// TwoNN: fraction of the largest neighbour ratios discarded. Default 0.1.
    pub twonn_discard: f64,
    /// Levina–Bickel: neighbours `k`. Default 20.
    pub mle_neighbors: usize,
    /// Trustworthiness and continuity: neighbours `k`, at most `M/2`. Default 10.
    pub neighbors: usize,
    /// Environment invariance (`smspace run`, when the experiment has more than one
    /// environment): how many babbled starts are traced with the `sensory` method in
    /// every environment and compared ([`crate::invariance`]). `0` turns it off. Default 300.
    pub invariance_starts: usize,
    /// The circular coordinate ([`circular`]): max–min landmarks of its complex;
    /// `0` turns it off. Default 300.
    pub circle_landmarks: usize,
    /// The circular coordinate: where its balls' radius lies in the loop's bar,
    /// `(0, 1)`. Default 0.5.
    pub circle_scale: f64,
    /// The compensability analysis (`[analysis.compensability]`,
    /// [`compensability`]): run by `smspace run` on the babbled configurations when
    /// the table is given. Default: not run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compensability: Option<compensability::CompensabilityParams>,
}

impl Default for AnalysisParams {
    fn default() -> Self {
        Self {
            max_homology_dim: 1,
            threshold: None,
            max_points: 800,
            gap_ratio: 3.0,
            noise_fraction: 0.1,
            twonn_discard: 0.1,
            mle_neighbors: 20,
            neighbors: 10,
            invariance_starts: 300,
            circle_landmarks: 300,
            circle_scale: 0.5,
            compensability: None,
        }
    }
}

/// Checked analysis parameters, the only form that runs. Built by
/// [`AnalysisParams::check`].
#[derive(Debug, Clone, PartialEq)]
pub struct AnalysisValidParams {
    params: AnalysisParams,
}

impl AnalysisValidParams {
    /// The parameters.
    pub fn params(&self) -> &AnalysisParams {
        &self.params
    }

    /// The Betti rule.
    pub fn betti_rule(&self) -> BettiRule {
        BettiRule {
            gap_ratio: self.params.gap_ratio,
            noise_fraction: self.params.noise_fraction,
        }
    }
}

fn invalid(key: &'static str, value: impl std::fmt::Display, reason: &str) -> AnalysisError {
    InvalidParameter::new("analysis", key, value, reason).into()
}

impl AnalysisParams {
    /// Validates the parameters (those that depend on `M` are checked when run).
    pub fn check(&self) -> Result<AnalysisValidParams, AnalysisError> {
        let p = self;
        if p.max_homology_dim > 2 {
            return Err(invalid(
                "max_homology_dim",
                p.max_homology_dim,
                "must be 0, 1 or 2",
            ));
        }
        if let Some(t) = p.threshold {
            if !(t.is_finite() && t > 0.0) {
                return Err(invalid(
                    "threshold",
                    t,
                    "must be a finite number greater than zero",
                ));
            }
        }
        if p.max_points < 3 {
            return Err(invalid("max_points", p.max_points, "must be at least 3"));
        }
        if !(p.gap_ratio.is_finite() && p.gap_ratio >= 1.0) {
            return Err(invalid(
                "gap_ratio",
                p.gap_ratio,
                "must be a finite number of at least 1",
            ));
        }
        if !(p.noise_fraction.is_finite() && (0.0..=1.0).contains(&p.noise_fraction)) {
            return Err(invalid(
                "noise_fraction",
                p.noise_fraction,
                "must be in [0, 1]",
            ));
        }
        if !(p.twonn_discard.is_finite() && (0.0..0.9).contains(&p.twonn_discard)) {
            return Err(invalid(
                "twonn_discard",
                p.twonn_discard,
                "must be in [0, 0.9)",
            ));
        }
        if p.mle_neighbors < 2 {
            return Err(invalid(
                "mle_neighbors",
                p.mle_neighbors,
                "must be at least 2",
            ));
        }
        if p.neighbors == 0 {
            return Err(invalid("neighbors", p.neighbors, "must be at least 1"));
        }
        if let Some(circle) = self.circle() {
            circle.check()?;
        }
        Ok(AnalysisValidParams { params: p.clone() })
    }
}

impl AnalysisParams {
    /// The circular coordinate's parameters, `None` when it is off
    /// (`circle_landmarks = 0`).
    pub fn circle(&self) -> Option<circular::CircleParams> {
        (self.circle_landmarks > 0).then_some(circular::CircleParams {
            landmarks: self.circle_landmarks,
            scale: self.circle_scale,
        })
    }
}

impl CheckParams for AnalysisParams {
    type Valid = AnalysisValidParams;
    type Error = AnalysisError;
    fn check_params(&self) -> Result<AnalysisValidParams, AnalysisError> {
        self.check()
    }
}

/// Max–min landmarks of the square matrix `distances`, from row 0: the
/// [`farthest_first`] landmark rows, in the order chosen, and their covering radius.
/// A matrix that is not square has no landmarks (and an infinite radius);
/// [`farthest_first`] says why.
pub fn maxmin_landmarks(distances: ArrayView2<'_, f64>, count: usize) -> (Vec<usize>, f64) {
    match DenseDistances::new(distances).and_then(|d| farthest_first(&d, count, 0)) {
        Ok(landmarks) => (landmarks.rows, landmarks.covering_radius),
        Err(_) => (Vec::new(), f64::INFINITY),
    }
}

/// How the homology's points were chosen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Subsampling {
    /// `none` or `max-min`.
    pub method: String,
    /// Points the homology was computed on.
    pub points: usize,
    /// Largest distance of a point to its nearest landmark (0 without subsampling).
    pub covering_radius: f64,
}

/// How the homology was computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HomologySummary {
    /// Highest dimension computed.
    pub max_dim: usize,
    /// The Rips threshold.
    pub threshold: f64,
    /// `enclosing-radius` or `given`.
    pub threshold_rule: String,
    /// Points used.
    pub subsampling: Subsampling,
    /// The Betti rule.
    pub rule: BettiRule,
    /// The five longest bar lengths of every dimension (infinite bars cut at the
    /// threshold), to judge the gap.
    pub longest_bars: Vec<Vec<f64>>,
}

impl HomologySummary {
    /// The summary of `persistence`, computed with `p` on the points of `subsampling`
    /// and read with `rule`.
    pub fn of(
        persistence: &Persistence,
        p: &AnalysisParams,
        subsampling: Subsampling,
        rule: BettiRule,
    ) -> Self {
        Self {
            max_dim: p.max_homology_dim,
            threshold: persistence.threshold,
            threshold_rule: if p.threshold.is_some() {
                "given"
            } else {
                "enclosing-radius"
            }
            .into(),
            subsampling,
            rule,
            longest_bars: longest_bars(persistence),
        }
    }
}

/// The bars `(birth, death)` of every diagram of `persistence` (`None`: never dies).
pub fn bars(persistence: &Persistence) -> Vec<Vec<(f64, Option<f64>)>> {
    persistence
        .diagrams
        .iter()
        .map(|bars| bars.iter().map(|b| (b.birth, b.death)).collect())
        .collect()
}

/// Intrinsic-dimension estimates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntrinsicDimension {
    /// TwoNN estimate.
    pub twonn: f64,
    /// Levina–Bickel estimate.
    pub mle: f64,
    /// TwoNN details.
    pub twonn_detail: DimensionEstimate,
    /// Levina–Bickel details.
    pub mle_detail: DimensionEstimate,
    /// Fraction discarded by TwoNN.
    pub twonn_discard: f64,
    /// `k` of the Levina–Bickel estimate.
    pub mle_neighbors: usize,
    /// The sets both estimates were computed on: `all` the sets of the matrix, or the
    /// `babbled` ones only (the pipeline leaves out the probe grid, whose regular
    /// spacing biases nearest-neighbour ratios).
    #[serde(default = "all_sets")]
    pub sets: String,
    /// How many sets that is.
    #[serde(default)]
    pub sets_used: usize,
}

/// The `sets_used` of a summary computed on every set.
pub fn all_sets() -> String {
    "all".to_owned()
}

/// The report of [`analyze`], written by `smspace analyze`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnalysisReport {
    /// Points `M` of the distance matrix.
    pub points: usize,
    /// Betti numbers `[b0, b1, …]` by the gap rule.
    pub betti: Vec<usize>,
    /// The dimensions whose Betti number the diagrams do not settle, with the likely
    /// cause and the remedy ([`BettiRule::ambiguities`]); empty when every reading is
    /// clear.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub betti_ambiguities: Vec<String>,
    /// Persistence diagrams: `persistence[k]` lists the bars `[birth, death]` of
    /// dimension `k` (`death` is `null` for a bar alive at the threshold).
    pub persistence: Vec<Vec<(f64, Option<f64>)>>,
    /// How the homology was computed.
    pub homology: HomologySummary,
    /// Intrinsic dimension.
    pub intrinsic_dimension: IntrinsicDimension,
    /// Agreement with the poses; `null` when no poses were given.
    pub agreement: Option<Agreement>,
    /// The circular coordinate of every set ([`circular`]), when asked for and the
    /// manifold has a loop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub circle: Option<circular::CircleCoordinate>,
    /// Why there is no circular coordinate although one was asked for (no loop, a
    /// loop the landmarks do not resolve, no integer class).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub circle_missing: Option<String>,
    /// The affine-fit measures of a representation against the positions
    /// ([`affine`]), when one was given (`smspace analyze --representation`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub affine: Option<affine::AffineErrors>,
    /// The compensability analysis (`compensability.dimension`, its histogram, the
    /// ambiguous base points), when `[analysis.compensability]` asks for it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compensability: Option<compensability::CompensabilityReport>,
    /// The landmark path's samples, when the run took it: which sets the
    /// homology, the dimension and the agreement were computed on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<ScaleSummary>,
}

/// What the landmark path computed each figure on (`analysis.json` `scale`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScaleSummary {
    /// Sets `M`.
    pub sets: usize,
    /// Landmarks `L` and how they were chosen (`max-min` or `random`, seeded).
    pub landmarks: usize,
    /// `max-min` or `random`.
    pub selection: String,
    /// The largest distance of a set to its nearest of the `L` landmarks.
    pub covering_radius: f64,
    /// The homology's points: the first `min(L, max_points)` landmarks in the order
    /// chosen (their covering radius over all sets is `homology.subsampling`'s).
    pub homology_points: usize,
    /// Sets whose kNN lists gave the intrinsic dimension, and the lists' `k`.
    pub dimension_sets: usize,
    /// `k` of the kNN graph.
    pub knn: usize,
    /// The agreement's sample: the `L` landmarks.
    pub agreement_sets: usize,
}

impl AnalysisReport {
    /// Writes the report as JSON to `path` (atomically). `smspace analyze --out` and
    /// the pipeline's analyze stage write through here.
    pub fn save(&self, path: &std::path::Path) -> Result<(), crate::io::IoError> {
        let mut outputs = crate::io::Outputs::new();
        self.write_into(&mut outputs, path)?;
        outputs.commit().map(drop)
    }

    /// Stages the report for `path` into `outputs`, to be renamed into place with the
    /// other files of a command or stage (the bytes [`save`](Self::save) writes).
    pub fn write_into(
        &self,
        outputs: &mut crate::io::Outputs,
        path: &std::path::Path,
    ) -> Result<(), crate::io::IoError> {
        outputs.json(path, self)?;
        if let Some(circle) = &self.circle {
            let values = ndarray::ArrayView1::from(&circle.values[..]);
            outputs.npy(&circle_path(path), &values)?;
        }
        Ok(())
    }

    /// Reads a report written by [`save`](AnalysisReport::save), with its circular
    /// coordinates when it has them.
    pub fn load(path: &std::path::Path) -> Result<Self, crate::io::IoError> {
        let mut report: Self = crate::io::read_json(path, "analysis report")?;
        if let Some(circle) = &mut report.circle {
            let file = circle_path(path);
            if file.is_file() {
                circle.values = crate::io::read_f64(&file)?.iter().copied().collect();
            }
        }
        Ok(report)
    }
}

/// The circular coordinates beside the report at `path`: `circle.npy` (`M`, radians).
pub fn circle_path(path: &std::path::Path) -> std::path::PathBuf {
    path.with_file_name("circle.npy")
}

/// Topology, dimension and (with `poses`, any strides, their layout read off the column
/// count by [`PoseSpace::from_columns`](crate::agent::PoseSpace::from_columns): `M × 3`
/// `(x, y, alpha)`, `M × 2` `(x, y)` or `M × 7` the 3-D pose) agreement of the distance
/// matrix `distances` (`M × M`, `M ≥ 3`). [`analyze_on`] takes poses of any layout.
///
/// ```
/// use smspace::analysis::{analyze, AnalysisParams};
/// use smspace::metric::DistanceMatrix;
/// use smspace::progress::Silent;
/// // 60 points on a circle of radius 1, unevenly spaced, at chord distances: one
/// // component, one loop, dimension about 1.
/// let angle = |i: usize| (i as f64 + 0.4 * (7.0 * i as f64).sin()) * std::f64::consts::TAU / 60.0;
/// let d = ndarray::Array2::from_shape_fn((60, 60), |(i, j)| 2.0 * ((angle(i) - angle(j)) / 2.0).sin().abs());
/// let d = DistanceMatrix::new(d)?;
/// let params = AnalysisParams { mle_neighbors: 5, ..AnalysisParams::default() }.check()?;
/// let report = analyze(&d, None, &params, &Silent)?;
/// assert_eq!(report.betti, vec![1, 1]);
/// assert!((0.5..2.0).contains(&report.intrinsic_dimension.mle));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn analyze(
    distances: &DistanceMatrix,
    poses: Option<ArrayView2<'_, f64>>,
    params: &AnalysisValidParams,
    progress: &dyn Progress,
) -> Result<AnalysisReport, AnalysisError> {
    let space = poses
        .as_ref()
        .and_then(|p| crate::agent::PoseSpace::from_columns(p.ncols()))
        .unwrap_or_else(crate::agent::PoseSpace::planar);
    let truth = match poses {
        Some(poses) => Some(GroundTruthView::new(&space, poses.reborrow()).map_err(|_| {
            AnalysisError::PosesShape {
                rows: poses.nrows(),
                columns: poses.ncols(),
                expected: distances.len(),
                coordinates: space.dim(),
            }
        })?),
        None => None,
    };
    analyze_on(distances, truth, None, params, progress)
}

/// The sets an intrinsic dimension is estimated on.
#[derive(Debug, Clone, Copy)]
pub struct DimensionSets<'a> {
    /// Rows of the distance matrix.
    pub rows: &'a [usize],
    /// What they are, for the report (e.g. `babbled`).
    pub name: &'a str,
}

/// [`analyze`] against the observer's poses of any layout (`truth`, `M × d`; `None`:
/// no ground truth, no agreement), with the intrinsic dimension estimated on the sets
/// `dimension_sets` only (e.g. the babbled configurations without the regular probe
/// grid; `None`: all sets). Topology and agreement always use every set.
pub fn analyze_on(
    distances: &DistanceMatrix,
    poses: Option<GroundTruthView<'_>>,
    dimension_sets: Option<DimensionSets<'_>>,
    params: &AnalysisValidParams,
    progress: &dyn Progress,
) -> Result<AnalysisReport, AnalysisError> {
    let p = &params.params;
    check_inputs(distances, poses)?;
    let distances = distances.view();
    let (persistence, subsampling) = homology_of(distances, p, progress)?;
    let intrinsic_dimension = intrinsic_dimension(distances, dimension_sets, p, progress)?;
    let agreement = match poses {
        Some(truth) => Some(agreement::agreement_of(distances, truth, p.neighbors)?),
        None => None,
    };
    let (circle, circle_missing) = circle_of(distances, poses, p, progress)?;
    let rule = params.betti_rule();
    Ok(AnalysisReport {
        points: distances.nrows(),
        betti: rule.betti(&persistence),
        betti_ambiguities: rule.ambiguities(&persistence),
        persistence: bars(&persistence),
        homology: HomologySummary::of(&persistence, p, subsampling, rule),
        intrinsic_dimension,
        agreement,
        circle,
        circle_missing,
        affine: None,
        compensability: None,
        scale: None,
    })
}

/// The circular coordinate ([`circular`]) when asked for (`circle_landmarks > 0`,
/// `max_homology_dim ≥ 1`), or why there is none: no loop, a loop the landmarks do not
/// resolve, no integer class, a complex too tangled (the rest of the analysis stands;
/// only a parameter out of its domain is an error).
pub fn circle_of(
    distances: ArrayView2<'_, f64>,
    poses: Option<GroundTruthView<'_>>,
    p: &AnalysisParams,
    progress: &dyn Progress,
) -> Result<(Option<circular::CircleCoordinate>, Option<String>), AnalysisError> {
    let Some(circle) = p.circle().filter(|_| p.max_homology_dim >= 1) else {
        return Ok((None, None));
    };
    let circle = circular::CircleParams {
        landmarks: circle.landmarks.min(distances.nrows()),
        ..circle
    };
    if circle.landmarks < 3 {
        return Ok((None, Some("fewer than 3 sets".to_owned())));
    }
    progress.start("circular coordinate", 1);
    let found = match circular::circle_coordinate(distances, poses, &circle) {
        Ok(Some(found)) => (Some(found), None),
        Ok(None) => (
            None,
            Some("the landmarks have no loop (no H1 bar)".to_owned()),
        ),
        // A bad parameter is the user's to fix; anything else the data do (no integer
        // class, a complex too tangled) leaves the rest of the analysis standing.
        Err(e @ AnalysisError::Invalid(_)) => return Err(e),
        Err(e) => (None, Some(e.to_string())),
    };
    progress.advance(1);
    progress.finish();
    Ok(found)
}

/// At least 3 points, and poses `(M, d)` if given.
fn check_inputs(
    distances: &DistanceMatrix,
    poses: Option<GroundTruthView<'_>>,
) -> Result<(), AnalysisError> {
    let n = distances.len();
    if n < 3 {
        return Err(AnalysisError::TooFewPoints {
            points: n,
            needed: 3,
        });
    }
    if let Some(truth) = poses {
        let d = truth.space().dim();
        if truth.poses().dim() != (n, d) {
            return Err(AnalysisError::PosesShape {
                rows: truth.poses().nrows(),
                columns: truth.poses().ncols(),
                expected: n,
                coordinates: d,
            });
        }
    }
    Ok(())
}

/// Rips persistence of all points, or of `max_points` max–min landmarks from row 0
/// when there are more.
fn homology_of(
    distances: ArrayView2<'_, f64>,
    p: &AnalysisParams,
    progress: &dyn Progress,
) -> Result<(Persistence, Subsampling), AnalysisError> {
    let n = distances.nrows();
    if n <= p.max_points {
        let persistence = rips_persistence(distances, p.max_homology_dim, p.threshold, progress)?;
        let all = Subsampling {
            method: "none".into(),
            points: n,
            covering_radius: 0.0,
        };
        return Ok((persistence, all));
    }
    let landmarks = farthest_first(&DenseDistances::new(distances)?, p.max_points, 0)?;
    let rows = &landmarks.rows;
    let sub = distances
        .select(ndarray::Axis(0), rows)
        .select(ndarray::Axis(1), rows);
    let persistence = rips_persistence(sub.view(), p.max_homology_dim, p.threshold, progress)?;
    let max_min = Subsampling {
        method: "max-min".into(),
        points: rows.len(),
        covering_radius: landmarks.covering_radius,
    };
    Ok((persistence, max_min))
}

/// The five longest bar lengths of every dimension, longest first (infinite bars cut
/// at the threshold).
pub(crate) fn longest_bars(persistence: &Persistence) -> Vec<Vec<f64>> {
    persistence
        .diagrams
        .iter()
        .map(|bars| {
            let mut l: Vec<f64> = bars
                .iter()
                .map(|b| b.length(persistence.threshold))
                .collect();
            l.sort_by(|a, b| b.total_cmp(a));
            l.truncate(5);
            l
        })
        .collect()
}

/// TwoNN and Levina–Bickel on the sets `dimension_sets` (all sets when `None`, or when
/// they are all the sets or too few for `mle_neighbors`).
fn intrinsic_dimension(
    distances: ArrayView2<'_, f64>,
    dimension_sets: Option<DimensionSets<'_>>,
    p: &AnalysisParams,
    progress: &dyn Progress,
) -> Result<IntrinsicDimension, AnalysisError> {
    let n = distances.nrows();
    progress.start("dimension", 2);
    let subset = dimension_sets.filter(|s| s.rows.len() > p.mle_neighbors && s.rows.len() < n);
    let sub;
    let (on, sets) = match subset {
        Some(s) => {
            if let Some(&bad) = s.rows.iter().find(|&&r| r >= n) {
                return Err(InvalidParameter::new(
                    "analysis",
                    "dimension_sets",
                    bad,
                    format!("a row of the {n} x {n} distance matrix"),
                )
                .into());
            }
            sub = distances
                .select(ndarray::Axis(0), s.rows)
                .select(ndarray::Axis(1), s.rows);
            (sub.view(), s.name.to_owned())
        }
        None => (distances.view(), all_sets()),
    };
    let twonn = dimension::twonn(on, p.twonn_discard)?;
    progress.advance(1);
    let mle = dimension::mle(on, p.mle_neighbors)?;
    progress.advance(1);
    progress.finish();
    Ok(IntrinsicDimension {
        twonn: twonn.dimension,
        mle: mle.dimension,
        twonn_detail: twonn,
        mle_detail: mle,
        sets,
        sets_used: on.nrows(),
        twonn_discard: p.twonn_discard,
        mle_neighbors: p.mle_neighbors,
    })
}
