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
//! - [`agreement`]: Spearman, trustworthiness and continuity against the poses.
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

pub mod agreement;
pub mod dimension;
pub mod homology;

use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use crate::neighbours::{farthest_first, DenseDistances, NeighboursError};
use crate::progress::Progress;
pub use agreement::Agreement;
pub use dimension::DimensionEstimate;
pub use homology::{rips_persistence, Bar, BettiRule, Persistence};

/// Errors of the analysis stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// The distance matrix is not square.
    #[error("the distance matrix has shape ({rows}, {columns}), expected (M, M)")]
    NotSquare {
        /// Rows.
        rows: usize,
        /// Columns.
        columns: usize,
    },
    /// Too few points to analyse.
    #[error("the distance matrix has {points} points; the analysis needs at least {needed}")]
    TooFewPoints {
        /// `M`.
        points: usize,
        /// The least `M` accepted.
        needed: usize,
    },
    /// An entry is not a distance.
    #[error("the distance matrix is not a distance matrix: {reason}")]
    NotDistances {
        /// What is wrong, with the entry.
        reason: String,
    },
    /// The poses do not match the distance matrix.
    #[error("poses have shape ({rows}, {columns}), expected ({expected}, 3) to match the distance matrix")]
    PosesShape {
        /// Rows.
        rows: usize,
        /// Columns.
        columns: usize,
        /// `M`.
        expected: usize,
    },
    /// A parameter is out of its domain.
    #[error("invalid analysis parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter, as in the configuration file.
        name: &'static str,
        /// The value given.
        value: String,
        /// What a valid value looks like.
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
    /// The computation would be too large.
    #[error("{what} is too large to compute: the limit is {limit}")]
    TooLarge {
        /// The computation.
        what: String,
        /// The limit.
        limit: &'static str,
    },
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

fn invalid(name: &'static str, value: impl ToString, reason: &str) -> AnalysisError {
    AnalysisError::InvalidParameter {
        name,
        value: value.to_string(),
        reason: reason.to_owned(),
    }
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
        Ok(AnalysisValidParams { params: p.clone() })
    }
}

/// Checks that `distances` is a distance matrix: square, finite, non-negative, zero on
/// the diagonal and symmetric (to `1e-9` of its largest entry). Returns it with the
/// two triangles averaged, so that every algorithm sees exactly symmetric values.
pub fn check_distances(distances: ArrayView2<'_, f64>) -> Result<Array2<f64>, AnalysisError> {
    let (rows, columns) = distances.dim();
    if rows != columns {
        return Err(AnalysisError::NotSquare { rows, columns });
    }
    let not = |reason: String| AnalysisError::NotDistances { reason };
    let mut largest: f64 = 0.0;
    for ((i, j), &d) in distances.indexed_iter() {
        if !d.is_finite() {
            return Err(not(format!("entry ({i}, {j}) is {d}")));
        }
        if d < 0.0 {
            return Err(not(format!("entry ({i}, {j}) is negative ({d})")));
        }
        largest = largest.max(d);
    }
    let tolerance = 1e-9 * largest.max(f64::MIN_POSITIVE);
    let mut out = distances.to_owned();
    for i in 0..rows {
        if distances[[i, i]] > tolerance {
            return Err(not(format!(
                "diagonal entry ({i}, {i}) is {}, expected 0",
                distances[[i, i]]
            )));
        }
        out[[i, i]] = 0.0;
        for j in i + 1..rows {
            let (a, b) = (distances[[i, j]], distances[[j, i]]);
            if (a - b).abs() > tolerance {
                return Err(not(format!(
                    "it is not symmetric: entry ({i}, {j}) is {a} but ({j}, {i}) is {b}"
                )));
            }
            let mean = 0.5 * (a + b);
            out[[i, j]] = mean;
            out[[j, i]] = mean;
        }
    }
    Ok(out)
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

fn all_sets() -> String {
    "all".to_owned()
}

/// The report of [`analyze`], written by `smspace analyze`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnalysisReport {
    /// Points `M` of the distance matrix.
    pub points: usize,
    /// Betti numbers `[b0, b1, …]` by the gap rule.
    pub betti: Vec<usize>,
    /// Persistence diagrams: `persistence[k]` lists the bars `[birth, death]` of
    /// dimension `k` (`death` is `null` for a bar alive at the threshold).
    pub persistence: Vec<Vec<(f64, Option<f64>)>>,
    /// How the homology was computed.
    pub homology: HomologySummary,
    /// Intrinsic dimension.
    pub intrinsic_dimension: IntrinsicDimension,
    /// Agreement with the poses; `null` when no poses were given.
    pub agreement: Option<Agreement>,
}

/// Topology, dimension and (with `poses`, `M × 3` `(x, y, alpha)`) agreement of the
/// distance matrix `distances` (`M × M`).
pub fn analyze(
    distances: ArrayView2<'_, f64>,
    poses: Option<ArrayView2<'_, f64>>,
    params: &AnalysisValidParams,
    progress: &dyn Progress,
) -> Result<AnalysisReport, AnalysisError> {
    analyze_on(distances, poses, None, params, progress)
}

/// The sets an intrinsic dimension is estimated on.
#[derive(Debug, Clone, Copy)]
pub struct DimensionSets<'a> {
    /// Rows of the distance matrix.
    pub rows: &'a [usize],
    /// What they are, for the report (e.g. `babbled`).
    pub name: &'a str,
}

/// [`analyze`], with the intrinsic dimension estimated on the sets `dimension_sets`
/// only (e.g. the babbled configurations without the regular probe grid; `None`: all
/// sets). Topology and agreement always use every set.
pub fn analyze_on(
    distances: ArrayView2<'_, f64>,
    poses: Option<ArrayView2<'_, f64>>,
    dimension_sets: Option<DimensionSets<'_>>,
    params: &AnalysisValidParams,
    progress: &dyn Progress,
) -> Result<AnalysisReport, AnalysisError> {
    let p = &params.params;
    let distances = checked_inputs(distances, poses)?;
    let (persistence, subsampling) = homology_of(distances.view(), p, progress)?;
    let intrinsic_dimension = intrinsic_dimension(distances.view(), dimension_sets, p, progress)?;
    let agreement = match poses {
        Some(poses) => Some(agreement::agreement(distances.view(), poses, p.neighbors)?),
        None => None,
    };
    let rule = params.betti_rule();
    Ok(AnalysisReport {
        points: distances.nrows(),
        betti: rule.betti(&persistence),
        persistence: persistence
            .diagrams
            .iter()
            .map(|bars| bars.iter().map(|b| (b.birth, b.death)).collect())
            .collect(),
        homology: HomologySummary {
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
            longest_bars: longest_bars(&persistence),
        },
        intrinsic_dimension,
        agreement,
    })
}

/// The distance matrix, checked and symmetrised ([`check_distances`]), of at least 3
/// points, and poses `(M, 3)` if given. A matrix that is already an exact distance
/// matrix (square, finite, non-negative, exactly symmetric with a zero diagonal, as
/// the pipeline's `D`) is used as it is rather than copied (`pipeline::memory`).
fn checked_inputs<'a>(
    distances: ArrayView2<'a, f64>,
    poses: Option<ArrayView2<'_, f64>>,
) -> Result<ndarray::CowArray<'a, f64, ndarray::Ix2>, AnalysisError> {
    let exact = distances.is_square()
        && distances.indexed_iter().all(|((i, j), &d)| {
            d.is_finite()
                && d >= 0.0
                && (if i == j {
                    d == 0.0
                } else {
                    d == distances[[j, i]]
                })
        });
    let distances = if exact {
        ndarray::CowArray::from(distances)
    } else {
        ndarray::CowArray::from(check_distances(distances)?)
    };
    let n = distances.nrows();
    if n < 3 {
        return Err(AnalysisError::TooFewPoints {
            points: n,
            needed: 3,
        });
    }
    if let Some(poses) = poses {
        if poses.dim() != (n, 3) {
            return Err(AnalysisError::PosesShape {
                rows: poses.nrows(),
                columns: poses.ncols(),
                expected: n,
            });
        }
    }
    Ok(distances)
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
fn longest_bars(persistence: &Persistence) -> Vec<Vec<f64>> {
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
                return Err(AnalysisError::InvalidParameter {
                    name: "dimension_sets",
                    value: bad.to_string(),
                    reason: format!("a row of the {n} x {n} distance matrix"),
                });
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
