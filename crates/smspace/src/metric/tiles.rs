//! The distance matrix in tiles, so that its pairs can be spread over threads,
//! processes or machines and computed exactly once.
//!
//! A [`Tile`] is a block `D[rows, cols]` of the symmetric matrix. Inside a tile, the
//! entry of a pair `{i, j}` is always computed as `ρ(M^min(i,j), M^max(i,j))`, the
//! same call [`distance_matrix`](super::distance_matrix) makes, so any tiling gives the
//! matrix bit for bit, for any number of threads; a pair that a tile holds twice (both
//! sets among its rows and among its columns) is computed once and mirrored, and its
//! diagonal is zero.
//!
//! [`TilePlan`] cuts `0..M` into blocks of `size` sets and keeps the tiles of the upper
//! triangle, `(block a, block b)` with `a ≤ b`:
//!
//! ```text
//!            cols →   b0    b1    b2
//!   rows  b0        [T00] [T01] [T02]        every pair {i < j} lies in exactly one
//!    ↓    b1              [T11] [T12]        tile: (block of i, block of j)
//!         b2                    [T22]
//! ```
//!
//! so that every pair is computed exactly once (a split into row blocks computes the
//! pairs across blocks twice, once in each block). [`fill_tile`] and
//! [`distance_tile`] compute one tile from the sets of its rows and of its columns only
//! (what a worker of a cluster receives), for any [`SetMetric`]: the built-in metrics
//! on their SIMD kernels ([`SetMetric::kernel`]), any other one call per pair.
//! [`TileMerge`] assembles tiles into the [`DistanceMatrix`], checking that every pair
//! is covered and that tiles that overlap agree. [`save_tile`] and [`load_tile`] keep a
//! tile in a `.npy` file with a `<stem>.tile.json` record of where it lies.
//!
//! ```
//! use ndarray::{Axis, Slice};
//! use smspace::metric::{distance_matrix, distance_tile, DistanceParams, MetricKind, TileMerge, TilePlan};
//! use smspace::progress::Silent;
//! let sets = ndarray::Array3::from_shape_fn((7, 5, 2), |(i, p, n)| (i * 5 + p * 2 + n) as f64 * 0.1);
//! let params = DistanceParams::new().metric(MetricKind::Hausdorff);
//! let metric = params.check()?.set_metric();
//! let plan = TilePlan::new(7, 3)?;
//! let mut merge = TileMerge::new(7, None)?;
//! for tile in plan.tiles() {
//!     // A worker needs the sets of the tile's rows and columns only.
//!     let rows = sets.slice_axis(Axis(0), Slice::from(tile.rows.clone()));
//!     let cols = sets.slice_axis(Axis(0), Slice::from(tile.cols.clone()));
//!     let values = distance_tile(rows, cols, &tile, metric.as_ref(), &Silent)?;
//!     merge.add(&tile, values.view())?;
//! }
//! let whole = distance_matrix(sets.view(), &params, &Silent)?;
//! assert_eq!(merge.finish()?, whole);
//! # Ok::<(), smspace::metric::MetricError>(())
//! ```

use std::borrow::Cow;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Axis, CowArray, Ix3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::kernel::{self, Driver, Eval, Scratch};
use super::{
    check_metric, closure_for, prepared, Closure, DistanceMatrix, MetricError, MetricKind,
    Periodicity, PreparedPairs, PreparedSets, SetMetric, SetsView,
};
use crate::io::{self, IoError};
use crate::params::InvalidParameter;
use crate::progress::Progress;

/// Rows of a task share a pass over each block of this many columns, so that the
/// block's sets stay in the core's L2 cache while every row of the task uses them.
const TILE_COLUMNS: usize = 32;
/// Rows computed together (one parallel task).
const TILE_ROWS: usize = 32;

/// A block `D[rows, cols]` of the distance matrix (global set indices).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Tile {
    /// The rows `[i0, i1)`.
    pub rows: Range<usize>,
    /// The columns `[j0, j1)`.
    pub cols: Range<usize>,
}

impl Tile {
    /// The tile `D[rows, cols]`.
    pub fn new(rows: Range<usize>, cols: Range<usize>) -> Self {
        Self { rows, cols }
    }

    /// `(rows, columns)` of its values.
    pub fn shape(&self) -> (usize, usize) {
        (self.rows.len(), self.cols.len())
    }

    /// The sets both among its rows and its columns (whose pairs it holds twice).
    pub fn overlap(&self) -> Range<usize> {
        let start = self.rows.start.max(self.cols.start);
        start..self.rows.end.min(self.cols.end).max(start)
    }

    /// Pairs the tile computes: its entries less the diagonal and the mirrored ones.
    pub fn pairs(&self) -> u64 {
        let shared = self.overlap().len() as u64;
        (self.rows.len() as u64) * (self.cols.len() as u64)
            - shared
            - shared * shared.saturating_sub(1) / 2
    }

    /// Pairs computed in row `i` (in `rows`).
    fn row_pairs(&self, i: usize) -> u64 {
        let overlap = self.overlap();
        if overlap.contains(&i) {
            (self.cols.len() - 1 - (i - overlap.start)) as u64
        } else {
            self.cols.len() as u64
        }
    }

    /// Checks that both ranges are non-empty and within `0..sets`.
    pub fn check(&self, sets: usize) -> Result<(), MetricError> {
        for range in [&self.rows, &self.cols] {
            if range.start >= range.end || range.end > sets {
                return Err(MetricError::BadRows {
                    start: range.start,
                    end: range.end,
                    sets,
                });
            }
        }
        Ok(())
    }
}

/// The tiles of the upper triangle for `M` sets in blocks of `size` (module docs):
/// every pair in exactly one tile.
///
/// ```
/// let plan = smspace::metric::TilePlan::new(10, 4)?;
/// let tiles: Vec<_> = plan.tiles().collect();
/// assert_eq!(tiles.len(), 6); // blocks 0..4, 4..8, 8..10
/// assert_eq!(tiles.iter().map(|t| t.pairs()).sum::<u64>(), 10 * 9 / 2);
/// # Ok::<(), smspace::metric::MetricError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TilePlan {
    sets: usize,
    size: usize,
}

impl TilePlan {
    /// The plan for `sets ≥ 2` sets in blocks of `size ≥ 1` sets.
    pub fn new(sets: usize, size: usize) -> Result<Self, MetricError> {
        if sets < 2 {
            return Err(MetricError::TooFewSets { sets });
        }
        if size == 0 {
            return Err(InvalidParameter::new(
                "tiles",
                "size",
                0,
                "a tile holds at least 1 set per side",
            )
            .into());
        }
        Ok(Self { sets, size })
    }

    /// Sets `M`.
    pub fn sets(&self) -> usize {
        self.sets
    }

    /// Sets per block.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The blocks of `0..M`.
    pub fn blocks(&self) -> impl Iterator<Item = Range<usize>> + '_ {
        (0..self.sets)
            .step_by(self.size)
            .map(|start| start..(start + self.size).min(self.sets))
    }

    /// The tiles, row block by row block.
    pub fn tiles(&self) -> impl Iterator<Item = Tile> + '_ {
        self.blocks().enumerate().flat_map(move |(a, rows)| {
            self.blocks()
                .skip(a)
                .map(move |cols| Tile::new(rows.clone(), cols))
        })
    }

    /// Number of tiles.
    pub fn len(&self) -> usize {
        let blocks = self.sets.div_ceil(self.size);
        blocks * (blocks + 1) / 2
    }

    /// Always false: a plan has at least one tile.
    pub fn is_empty(&self) -> bool {
        false
    }
}

/// Where the sets of a tile's rows and columns sit among the sets a [`Measure`] holds:
/// row `i` is set `row_base + i − rows.start`, column `j` is set
/// `col_base + j − cols.start`.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    pub(crate) tile: Tile,
    row_base: usize,
    col_base: usize,
}

impl Layout {
    /// A tile of the full sets `0..M` (set `i` is set `i`).
    pub(crate) fn within(tile: Tile) -> Self {
        Self {
            row_base: tile.rows.start,
            col_base: tile.cols.start,
            tile,
        }
    }

    fn row(&self, i: usize) -> usize {
        self.row_base + i - self.tile.rows.start
    }

    fn col(&self, j: usize) -> usize {
        self.col_base + j - self.tile.cols.start
    }

    /// The global index of held set `s`.
    fn global(&self, s: usize) -> usize {
        if (self.row_base..self.row_base + self.tile.rows.len()).contains(&s) {
            self.tile.rows.start + s - self.row_base
        } else {
            self.tile.cols.start + s - self.col_base
        }
    }
}

/// The first pair whose [`SetMetric::distance`] failed, by its held set indices.
type Failure = Mutex<Option<((usize, usize), MetricError)>>;

/// Sets and the metric that measures them: prepared for a built-in metric's SIMD
/// kernels, or as they are for any [`SetMetric`] (one call per pair).
pub(crate) enum Measure<'a> {
    /// A built-in metric on its kernels.
    Kernel {
        /// The prepared sets.
        prepared: Cow<'a, PreparedSets>,
        /// The metric.
        kind: MetricKind,
    },
    /// Any metric.
    Generic {
        /// The sets `(M, P, N)`.
        sets: CowArray<'a, f64, Ix3>,
        /// The metric.
        metric: &'a dyn SetMetric,
        /// What the metric prepared for these sets ([`SetMetric::prepare`]).
        pairs: Option<Box<dyn PreparedPairs>>,
        /// The first failing pair.
        failure: Failure,
    },
}

impl<'a> Measure<'a> {
    /// The built-in `kind` on `sets` (checked, closures required by `curve`).
    pub(crate) fn kernel(
        sets: SetsView<'a>,
        kind: MetricKind,
        period: &Periodicity,
    ) -> Result<Self, MetricError> {
        let prepared = PreparedSets::new(closure_for(sets, kind)?, period)?;
        check_metric(&prepared, kind)?;
        Ok(Self::Kernel {
            prepared: Cow::Owned(prepared),
            kind,
        })
    }

    /// Sets already prepared for `kind`.
    pub(crate) fn prepared(
        prepared: &'a PreparedSets,
        kind: MetricKind,
    ) -> Result<Self, MetricError> {
        check_metric(prepared, kind)?;
        Ok(Self::Kernel {
            prepared: Cow::Borrowed(prepared),
            kind,
        })
    }

    /// `metric` on `sets`: on its kernel when it has one ([`SetMetric::kernel`]; sets
    /// without closures then take the metric's own), else one call per pair.
    pub(crate) fn new(sets: SetsView<'a>, metric: &'a dyn SetMetric) -> Result<Self, MetricError> {
        let Some(spec) = metric.kernel() else {
            prepared::check_points(sets.points())?;
            return Ok(Self::Generic {
                pairs: metric.prepare(sets.points())?,
                sets: CowArray::from(sets.points()),
                metric,
                failure: Mutex::new(None),
            });
        };
        let every: Vec<Closure>;
        let sets = match sets.closure() {
            None if spec.kind.needs_closure() => {
                every = vec![spec.closure; sets.points().dim().0];
                sets.reborrow().with_closure(&every)
            }
            _ => sets.reborrow(),
        };
        let prepared = PreparedSets::new(closure_for(sets, spec.kind)?, &spec.period)?;
        check_metric(&prepared, spec.kind)?;
        Ok(Self::Kernel {
            prepared: Cow::Owned(prepared),
            kind: spec.kind,
        })
    }

    /// Number of sets held.
    pub(crate) fn len(&self) -> usize {
        match self {
            Self::Kernel { prepared, .. } => prepared.len(),
            Self::Generic { sets, .. } => sets.dim().0,
        }
    }

    /// Whether the triangle inequality holds, and the absolute error of the values.
    pub(crate) fn bounds(&self) -> (bool, f64) {
        match self {
            Self::Kernel { kind, .. } => (kind.is_metric(), kind.tolerance()),
            Self::Generic { metric, .. } => (metric.is_metric(), metric.tolerance()),
        }
    }

    /// Runs `driver` with this measure's evaluator (the kernels under runtime SIMD
    /// dispatch, or the generic calls).
    pub(crate) fn drive<D: Driver>(&self, scratch: &mut Scratch, driver: D) -> D::Output {
        match self {
            Self::Kernel { prepared, kind } => kernel::dispatch(prepared, *kind, scratch, driver),
            Self::Generic {
                sets,
                metric,
                pairs,
                failure,
            } => driver.drive(&mut GenericEval {
                sets: sets.view(),
                metric: *metric,
                pairs: pairs.as_deref(),
                failure,
            }),
        }
    }

    /// The error of the first failing pair (by global indices, the smaller first), if
    /// any; `global` maps held set indices to global ones.
    pub(crate) fn failure(self, global: impl Fn(usize) -> usize) -> Result<(), MetricError> {
        let Self::Generic {
            metric, failure, ..
        } = self
        else {
            return Ok(());
        };
        match failure.into_inner().unwrap_or_else(|e| e.into_inner()) {
            Some(((a, b), reason)) => {
                let (i, j) = (global(a), global(b));
                Err(MetricError::Pair {
                    metric: metric.name().to_owned(),
                    i: i.min(j),
                    j: i.max(j),
                    reason: Box::new(reason),
                })
            }
            None => Ok(()),
        }
    }
}

/// Evaluates a [`SetMetric`] on a pair of held sets; records the first failure (by
/// held indices, which every caller orders like the global ones) and returns NaN for
/// it.
struct GenericEval<'a> {
    sets: ndarray::ArrayView3<'a, f64>,
    metric: &'a dyn SetMetric,
    pairs: Option<&'a dyn PreparedPairs>,
    failure: &'a Failure,
}

impl Eval for GenericEval<'_> {
    fn distance(&mut self, i: usize, j: usize, _limit: f64) -> Option<f64> {
        let value = match self.pairs {
            Some(pairs) => pairs.distance(i, j),
            None => self.metric.distance(
                self.sets.index_axis(Axis(0), i),
                self.sets.index_axis(Axis(0), j),
            ),
        };
        let reason = match value {
            Ok(d) if d.is_finite() && d >= 0.0 => return Some(d),
            Ok(value) => MetricError::NotADistance { value },
            Err(reason) => reason,
        };
        let mut failure = self.failure.lock().unwrap_or_else(|e| e.into_inner());
        if failure.as_ref().is_none_or(|(at, _)| (i, j) < *at) {
            *failure = Some(((i, j), reason));
        }
        Some(f64::NAN)
    }
}

/// Computes rows `[row0, row0 + out.len() / width)` of a tile, column block by column
/// block (cache blocking: each column set is read from memory once per task instead of
/// once per row). Every entry is the same `distance(min, max)` call as without tiling.
struct TileRows<'a> {
    layout: &'a Layout,
    row0: usize,
    out: &'a mut [f64],
}

impl Driver for TileRows<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        let layout = self.layout;
        let (rows, cols) = (&layout.tile.rows, &layout.tile.cols);
        let width = cols.len();
        let count = self.out.len() / width;
        for block in cols.clone().step_by(TILE_COLUMNS) {
            let columns = block..(block + TILE_COLUMNS).min(cols.end);
            for r in 0..count {
                let i = self.row0 + r;
                let row_is_column = cols.contains(&i);
                let out = &mut self.out[r * width..(r + 1) * width];
                for j in columns.clone() {
                    // The diagonal, and the pairs this tile computes at (j, i).
                    if j == i || (j < i && row_is_column && rows.contains(&j)) {
                        continue;
                    }
                    // The first row of the task brings the block's sets from memory:
                    // start loading the one after next while this pair is computed.
                    if r == 0 && j + 2 < columns.end {
                        eval.touch(layout.col(j + 2));
                    }
                    let d = if i < j {
                        eval.distance(layout.row(i), layout.col(j), f64::INFINITY)
                    } else {
                        eval.distance(layout.col(j), layout.row(i), f64::INFINITY)
                    };
                    out[j - cols.start] = d.unwrap_or(f64::INFINITY);
                }
            }
        }
    }
}

/// Fills `out` (`layout.tile.shape()`, C order: checked by the caller) with the tile,
/// in parallel on rayon's current pool; pairs it holds twice are mirrored and its
/// diagonal is zero. `progress` sees one stage, "distances", counted in pairs. Errors
/// with the first failing pair of a generic metric.
pub(crate) fn fill(
    measure: Measure<'_>,
    layout: &Layout,
    mut out: ArrayViewMut2<'_, f64>,
    progress: &dyn Progress,
) -> Result<(), MetricError> {
    let tile = &layout.tile;
    let width = tile.cols.len();
    progress.start("distances", tile.pairs());
    let buffer = out
        .as_slice_mut()
        .expect("standard layout was checked by the caller");
    buffer
        .par_chunks_mut(width * TILE_ROWS)
        .enumerate()
        .for_each_init(Scratch::default, |scratch, (t, block)| {
            let row0 = tile.rows.start + t * TILE_ROWS;
            let count = block.len() / width;
            for i in row0..row0 + count {
                if tile.cols.contains(&i) {
                    block[(i - row0) * width + i - tile.cols.start] = 0.0;
                }
            }
            let driver = TileRows {
                layout,
                row0,
                out: block,
            };
            measure.drive(scratch, driver);
            progress.advance((row0..row0 + count).map(|i| tile.row_pairs(i)).sum());
        });
    let (r0, c0) = (tile.rows.start, tile.cols.start);
    let overlap = tile.overlap();
    for i in overlap.clone() {
        for j in overlap.start..i {
            out[[i - r0, j - c0]] = out[[j - r0, i - c0]];
        }
    }
    progress.finish();
    measure.failure(|s| layout.global(s))
}

/// Checks that `out` can hold `tile`.
pub(crate) fn check_buffer(out: &ArrayViewMut2<'_, f64>, tile: &Tile) -> Result<(), MetricError> {
    if out.dim() != tile.shape() || !out.is_standard_layout() {
        return Err(MetricError::BadBuffer {
            found: out.dim(),
            expected: tile.shape(),
        });
    }
    Ok(())
}

/// The values of `tile` `(rows, cols)`, from the sets of its rows and of its columns
/// only (see [`fill_tile`]).
pub fn distance_tile<'a>(
    rows: impl Into<SetsView<'a>>,
    cols: impl Into<SetsView<'a>>,
    tile: &Tile,
    metric: &dyn SetMetric,
    progress: &dyn Progress,
) -> Result<Array2<f64>, MetricError> {
    let mut out = Array2::zeros(tile.shape());
    fill_tile(rows, cols, tile, metric, out.view_mut(), progress)?;
    Ok(out)
}

/// Fills `out` (`tile.shape()`, C order) with `D[tile.rows, tile.cols]` under `metric`,
/// in parallel, from `rows` (the sets `tile.rows`, `(rows.len(), P, N)`, with their
/// closures for the `curve` metric) and `cols` (the sets `tile.cols`). A worker of a
/// cluster needs nothing else: the tile is bit for bit the same block of
/// [`distance_matrix`](super::distance_matrix) (module docs). For a tile on the
/// diagonal (`rows == cols`) the two views hold the same sets and only `rows` is read.
pub fn fill_tile<'a>(
    rows: impl Into<SetsView<'a>>,
    cols: impl Into<SetsView<'a>>,
    tile: &Tile,
    metric: &dyn SetMetric,
    mut out: ArrayViewMut2<'_, f64>,
    progress: &dyn Progress,
) -> Result<(), MetricError> {
    fill_tile_values(rows, cols, tile, metric, out.view_mut(), progress)?;
    super::check_finite_distances(out.view(), tile.rows.start, tile.cols.start)
}

/// [`fill_tile`] without the check of its values.
fn fill_tile_values<'a>(
    rows: impl Into<SetsView<'a>>,
    cols: impl Into<SetsView<'a>>,
    tile: &Tile,
    metric: &dyn SetMetric,
    out: ArrayViewMut2<'_, f64>,
    progress: &dyn Progress,
) -> Result<(), MetricError> {
    let (rows, cols): (SetsView<'a>, SetsView<'a>) = (rows.into(), cols.into());
    let (rows, cols) = (rows.reborrow(), cols.reborrow());
    let held = |sets: &SetsView<'_>, range: &Range<usize>| {
        let found = sets.points().dim().0;
        if found == range.len() {
            Ok(())
        } else {
            Err(MetricError::TileSets {
                found,
                start: range.start,
                end: range.end,
            })
        }
    };
    for range in [&tile.rows, &tile.cols] {
        if range.is_empty() {
            return Err(MetricError::BadRows {
                start: range.start,
                end: range.end,
                sets: range.end,
            });
        }
    }
    held(&rows, &tile.rows)?;
    held(&cols, &tile.cols)?;
    check_buffer(&out, tile)?;
    if tile.rows == tile.cols {
        let layout = Layout {
            tile: tile.clone(),
            row_base: 0,
            col_base: 0,
        };
        return fill(Measure::new(rows, metric)?, &layout, out, progress);
    }
    // Rows then columns, in one array (a set in both is held twice, with the same
    // values, so its pairs do not depend on which copy is read).
    let stacked_points =
        ndarray::concatenate(Axis(0), &[rows.points(), cols.points()]).map_err(|_| {
            MetricError::DimensionMismatch {
                a: rows.points().dim().2,
                b: cols.points().dim().2,
            }
        })?;
    let stacked_closure: Option<Vec<Closure>> = match (rows.closure(), cols.closure()) {
        (Some(a), Some(b)) => Some([a, b].concat()),
        _ => None,
    };
    // The pieces of the points (kernels of several pieces): a side without them is one
    // piece per set.
    let stacked_pieces = match (rows.pieces(), cols.pieces()) {
        (None, None) => None,
        (a, b) => {
            let one = |sets: &SetsView<'_>| {
                let (m, p, _) = sets.points().dim();
                ndarray::Array2::<i64>::zeros((m, p))
            };
            let a = a.map_or_else(|| one(&rows), |a| a.to_owned());
            let b = b.map_or_else(|| one(&cols), |b| b.to_owned());
            Some(
                ndarray::concatenate(Axis(0), &[a.view(), b.view()]).map_err(|_| {
                    MetricError::DimensionMismatch {
                        a: a.ncols(),
                        b: b.ncols(),
                    }
                })?,
            )
        }
    };
    let stacked = match &stacked_closure {
        Some(c) => SetsView::new(stacked_points.view()).with_closure(c),
        None => SetsView::new(stacked_points.view()),
    };
    let stacked = match &stacked_pieces {
        Some(p) => stacked.with_pieces(p.view()),
        None => stacked,
    };
    let layout = Layout {
        tile: tile.clone(),
        row_base: 0,
        col_base: tile.rows.len(),
    };
    fill(Measure::new(stacked, metric)?, &layout, out, progress)
}

/// Assembles tiles into the full [`DistanceMatrix`] of `M` sets: each tile's values
/// go to both triangles; pairs held by several tiles must agree exactly; every pair
/// must be covered.
#[derive(Debug, Clone)]
pub struct TileMerge {
    values: Array2<f64>,
}

impl TileMerge {
    /// An empty `M × M` matrix (every pair still to come); refused when it would not
    /// fit in `memory_limit_bytes` (or in the address space).
    pub fn new(sets: usize, memory_limit_bytes: Option<u64>) -> Result<Self, MetricError> {
        let needed = (sets as u64).saturating_mul(sets as u64).saturating_mul(8);
        let available = memory_limit_bytes.unwrap_or(isize::MAX as u64);
        if needed > available {
            return Err(MetricError::OutOfMemory {
                sets,
                needed,
                available,
            });
        }
        let mut values = Array2::from_elem((sets, sets), f64::NAN);
        values.diag_mut().fill(0.0);
        Ok(Self { values })
    }

    /// Adds the values `(rows, cols)` of `tile`.
    pub fn add(&mut self, tile: &Tile, values: ArrayView2<'_, f64>) -> Result<(), MetricError> {
        let sets = self.values.nrows();
        tile.check(sets)?;
        if values.dim() != tile.shape() {
            return Err(MetricError::BadBuffer {
                found: values.dim(),
                expected: tile.shape(),
            });
        }
        for ((r, c), &d) in values.indexed_iter() {
            let (i, j) = (tile.rows.start + r, tile.cols.start + c);
            if i == j {
                continue;
            }
            if !(d.is_finite() && d >= 0.0) {
                return Err(MetricError::TileValue { i, j, value: d });
            }
            let before = self.values[[i, j]];
            if !before.is_nan() && before != d {
                return Err(MetricError::TileConflict {
                    i: i.min(j),
                    j: i.max(j),
                    before,
                    after: d,
                });
            }
            self.values[[i, j]] = d;
            self.values[[j, i]] = d;
        }
        Ok(())
    }

    /// The matrix, once every pair is covered.
    pub fn finish(self) -> Result<DistanceMatrix, MetricError> {
        if let Some(((i, j), _)) = self.values.indexed_iter().find(|(_, d)| d.is_nan()) {
            return Err(MetricError::TileMissing {
                i: i.min(j),
                j: i.max(j),
            });
        }
        Ok(DistanceMatrix::from_symmetric(self.values))
    }
}

/// Where a tile file lies in its matrix: `<stem>.tile.json` next to the tile's `.npy`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TileRecord {
    /// Sets `M` of the whole matrix.
    pub sets: usize,
    /// Rows `[i0, i1)`.
    pub rows: [usize; 2],
    /// Columns `[j0, j1)`.
    pub cols: [usize; 2],
    /// The metric's name.
    pub metric: String,
}

impl TileRecord {
    /// The tile it describes.
    pub fn tile(&self) -> Tile {
        Tile::new(self.rows[0]..self.rows[1], self.cols[0]..self.cols[1])
    }
}

/// Writes a tile's values to `path` and its [`TileRecord`] to `<stem>.tile.json`,
/// together (all or none); returns both paths. `smspace distances --tile` and `--rows`
/// write through here.
pub fn save_tile(
    path: &Path,
    record: &TileRecord,
    values: ArrayView2<'_, f64>,
) -> Result<Vec<PathBuf>, IoError> {
    let mut outputs = io::Outputs::new();
    outputs.npy(path, &values)?;
    outputs.json(&io::sibling(path, "tile.json"), record)?;
    outputs.commit()
}

/// Reads a tile written by [`save_tile`]: its record and its values (checked to have
/// the record's shape).
pub fn load_tile(path: &Path) -> Result<(TileRecord, Array2<f64>), IoError> {
    let record_path = io::sibling(path, "tile.json");
    let record: TileRecord = io::read_json(&record_path, "tile record")?;
    let tile = record.tile();
    let values = io::read_matrix(path, None, "(rows, cols)")?;
    if values.dim() != tile.shape() || tile.check(record.sets).is_err() {
        return Err(IoError::Shape {
            path: path.to_owned(),
            found: io::shape_string(values.shape()),
            expected: format!(
                "{:?} for rows {}:{} and columns {}:{} of {} sets (as {} says)",
                tile.shape(),
                tile.rows.start,
                tile.rows.end,
                tile.cols.start,
                tile.cols.end,
                record.sets,
                record_path.display()
            ),
        });
    }
    Ok((record, values))
}
