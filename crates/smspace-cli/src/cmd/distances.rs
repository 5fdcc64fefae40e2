//! `smspace distances`: the metric between kernel sets (paper section 3.2, step 3).
//!
//! Reads kernel sets `(M, P, N)` and writes the distance matrix `(M, M)`, a block of its
//! rows, a tile (`--tile`), or with `--knn K` the `K` nearest sets of every set; or
//! assembles tiles into the matrix (`--merge`). Every file goes through the library's
//! writer of its kind: `DistanceMatrix::save` (as the pipeline's distances stage),
//! `metric::save_tile`, `Knn::save`.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::ValueEnum;
use ndarray::{Array3, Axis, Slice};
use smspace::kernel::TraceReport;
use smspace::metric::{
    self, BuiltMetric, Closure, DistanceParams, KnnParams, MetricRegistry, Periodicity,
    PreparedSets, SetMetric, SetsView, Tile, TileMerge, TileRecord,
};

use super::common::{parse_param, sibling};
use smspace_pipeline::front::{self, MetricRequest};

use crate::ui;

/// Arguments of `smspace distances`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Kernel sets: a float64 .npy array of shape (M, P, N), motor angles in radians.
    #[arg(long, value_name = "FILE", required_unless_present = "merge")]
    sets: Option<PathBuf>,
    /// Output: the distance matrix, float64 (M, M) (or (i1 - i0, M) with --rows, a tile
    /// with --tile; both with their record OUT_STEM.tile.json). With --knn this file is
    /// not written: knn_indices.npy and knn_distances.npy go into the folder that holds
    /// it.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Distance between two sets: a registered metric (curve, the default, which reads
    /// every set as a polyline, closed or open as recorded by `smspace trace` in
    /// SETS.closed.npy next to the sets, or as --curve says; hausdorff, the paper's,
    /// between the sampled points; mean-hausdorff; surface, for kernels of dimension
    /// k >= 2). An unknown name lists them.
    #[arg(long, value_name = "NAME", default_value = metric::DEFAULT_METRIC.name())]
    metric: String,
    /// A parameter of the metric, as in an experiment's [metric.params] table, the value
    /// in TOML (e.g. --param dimension=3 --param radius_scale=0.5); repeat for more.
    /// Parameters the metric does not have are errors that name them. The surface
    /// metric's dimension defaults to the traced one (SETS.trace.json beside the sets).
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = parse_param)]
    params: Vec<(String, toml::Value)>,
    /// For a metric that reads polylines (curve): join every set's points into a closed
    /// loop or an open polyline, instead of reading SETS.closed.npy (1 closed, 0 open
    /// per set).
    #[arg(long, value_enum, value_name = "closed|open")]
    curve: Option<CurveArg>,
    /// Period of every motor coordinate: 2pi (hinge joints, the paper's metric), none
    /// (plain Euclidean), or one entry per motor separated by commas, each 2pi, none or
    /// a period in radians (e.g. 2pi,2pi,none for two hinges and a bounded motor).
    #[arg(long, value_name = "2pi|none|LIST", default_value_t = Periodicity::default(), value_parser = parse_period)]
    period: Periodicity,
    /// Instead of the matrix, the K nearest sets of every set (self excluded, nearest
    /// first, ties by index): knn_indices.npy (M, K) int64 and knn_distances.npy (M, K)
    /// float64, next to --out. Memory O(M·K).
    #[arg(long, value_name = "K")]
    knn: Option<usize>,
    /// Pivot sets for pruning the --knn search with the triangle inequality.
    #[arg(long, value_name = "COUNT", default_value_t = smspace::metric::KnnParams::default().pivots)]
    pivots: usize,
    /// Compute only rows i0 (included) to i1 (excluded), e.g. 0:1000, so that the matrix
    /// (or the --knn lists) can be split over processes. Blocks stack exactly into the
    /// whole.
    #[arg(long, value_name = "I0:I1", value_parser = parse_rows, conflicts_with = "tile")]
    rows: Option<Range<usize>>,
    /// Compute only the tile of rows I0:I1 and columns J0:J1 (e.g. 0:500,500:1000), so
    /// that the pairs can be spread over processes each computed once: the tiles of
    /// the blocks (a, b) with a <= b cover every pair; --merge assembles them.
    #[arg(long, value_name = "I0:I1,J0:J1", value_parser = parse_tile, conflicts_with = "knn")]
    tile: Option<Tile>,
    /// Assemble the matrix from tiles (and row blocks) written by --tile or --rows
    /// (each with its .tile.json record): every pair must be covered, and tiles that
    /// overlap must agree. Reads no sets.
    #[arg(long, value_name = "TILE.npy", num_args = 1.., conflicts_with_all = ["sets", "knn", "rows", "tile"])]
    merge: Vec<PathBuf>,
    /// Refuse to start when the output needs more than this many bytes (default: the
    /// memory available, MemAvailable in /proc/meminfo).
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
}

/// `--curve`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum CurveArg {
    /// every set is a closed loop (the last point joined to the first)
    Closed,
    /// every set is an open polyline
    Open,
}

/// `--period`.
fn parse_period(text: &str) -> Result<Periodicity, String> {
    match Periodicity::parse(text) {
        Ok(Periodicity::FromMotors) => Err(
            "\"motors\" needs an agent; give 2pi, none or one entry per motor (e.g. 2pi,2pi,none)"
                .to_owned(),
        ),
        Ok(period) => Ok(period),
        Err(err) => Err(err.to_string()),
    }
}

fn parse_tile(text: &str) -> Result<Tile, String> {
    let (rows, cols) = text
        .split_once(',')
        .ok_or_else(|| format!("expected I0:I1,J0:J1, e.g. 0:500,500:1000, got {text:?}"))?;
    Ok(Tile::new(parse_rows(rows)?, parse_rows(cols)?))
}

fn parse_rows(text: &str) -> Result<Range<usize>, String> {
    let (start, end) = text
        .split_once(':')
        .ok_or_else(|| format!("expected I0:I1, e.g. 0:1000, got {text:?}"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<usize>()
            .map_err(|e| format!("{s:?} in {text:?} is not a row index: {e}"))
    };
    Ok(parse(start)?..parse(end)?)
}

/// The closures of the sets for a metric that reads them (`--curve`, else
/// `SETS.closed.npy` next to the sets); `None` for the others.
fn closure(
    args: &Args,
    path: &Path,
    metric: &dyn SetMetric,
    sets: usize,
) -> anyhow::Result<Option<Vec<Closure>>> {
    if !metric.records().closure {
        anyhow::ensure!(
            args.curve.is_none(),
            "--curve only applies to a metric that reads polylines (curve); the {} metric does not join the points",
            metric.name()
        );
        return Ok(None);
    }
    if let Some(curve) = args.curve {
        let closure = match curve {
            CurveArg::Closed => Closure::Closed,
            CurveArg::Open => Closure::Open,
        };
        return Ok(Some(vec![closure; sets]));
    }
    let record = sibling(path, "closed.npy");
    if !record.exists() {
        anyhow::bail!(
            "--metric {} needs to know which sets are closed loops: {} is missing (smspace trace writes it next to the sets); for sets from elsewhere give --curve closed or --curve open",
            metric.name(),
            record.display()
        );
    }
    Ok(Some(smspace::kernel::read_closure(&record, sets)?))
}

/// The trace report `SETS.trace.json` beside the sets, when there.
fn trace_report(path: &Path) -> anyhow::Result<Option<(PathBuf, TraceReport)>> {
    let record = sibling(path, "trace.json");
    if !record.exists() {
        return Ok(None);
    }
    let report: TraceReport = smspace::io::read_json(&record, "trace report")?;
    Ok(Some((record, report)))
}

/// The metric `--metric` names, with its `--param`s, built for the kernels the trace
/// report describes (when there), and checked against them.
fn build_metric(
    args: &Args,
    path: &Path,
    report: Option<&(PathBuf, TraceReport)>,
) -> anyhow::Result<BuiltMetric> {
    let shape = report.map(|(_, r)| r.kernel_shape());
    let request = MetricRequest {
        name: &args.metric,
        period: args.period.clone(),
        params: args.params.iter().cloned().collect(),
        memory_limit_bytes: front::memory_limit(args.max_memory),
        kernels: shape,
    };
    let built =
        front::metric(&MetricRegistry::builtin(), request).context("--metric and --param")?;
    if let (Some(shape), Some((record, _))) = (shape, report) {
        built
            .metric
            .check_kernels(shape)
            .with_context(|| format!("{} (from {})", path.display(), record.display()))?;
    }
    Ok(built)
}

/// The kernel sets, their closures and pieces, and the metric.
struct Input {
    path: PathBuf,
    sets: Array3<f64>,
    closure: Option<Vec<Closure>>,
    /// For a metric that reads pieces: the piece of every point
    /// (`SETS.components.npy`, when there).
    pieces: Option<ndarray::Array2<i64>>,
    params: DistanceParams,
    metric: std::sync::Arc<dyn SetMetric>,
}

impl Input {
    fn read(args: &Args, path: &Path) -> anyhow::Result<Self> {
        let sets = smspace::io::read_cube(path, "(M, P, N)")?;
        let report = trace_report(path)?;
        let built = build_metric(args, path, report.as_ref())?;
        let metric = built.metric;
        let closure = closure(args, path, metric.as_ref(), sets.dim().0)?;
        // The pieces of kernels traced with components = "all": no segment of the curve
        // metric joins two of them.
        let record = sibling(path, "components.npy");
        let pieces = if metric.records().pieces && record.exists() {
            let (m, p, _) = sets.dim();
            Some(smspace::kernel::read_pieces(&record, m, p)?)
        } else {
            None
        };
        let input = Self {
            path: path.to_owned(),
            sets,
            closure,
            pieces,
            params: built.params,
            metric,
        };
        if let Some((record, report)) = &report {
            let m = input.sets.dim().0;
            input
                .metric
                .check_sets(&input.view(0..m), &report.extended_along)
                .with_context(|| format!("{} (from {})", path.display(), record.display()))?;
        }
        Ok(input)
    }

    /// The sets `range` (all of them for `0..M`), with their closures.
    fn view(&self, range: Range<usize>) -> SetsView<'_> {
        let points = self.sets.slice_axis(Axis(0), Slice::from(range.clone()));
        let view = match &self.closure {
            Some(c) => SetsView::new(points).with_closure(&c[range.clone()]),
            None => SetsView::new(points),
        };
        match &self.pieces {
            Some(pieces) => view.with_pieces(pieces.slice_axis(Axis(0), Slice::from(range))),
            None => view,
        }
    }

    fn context(&self) -> String {
        format!(
            "cannot compute distances between the sets of {}",
            self.path.display()
        )
    }

    /// What is measured, for the closing line: `M sets of P points in N-D, metric`.
    fn describe(&self) -> String {
        let (m, p, n) = self.sets.dim();
        format!("{m} sets of {p} points in {n}-D, {}", self.params.metric)
    }
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let folder = smspace::io::folder_of(&args.out);
    let (knn_indices, knn_distances) = (
        folder.join("knn_indices.npy"),
        folder.join("knn_distances.npy"),
    );
    let mut inputs: Vec<(&str, Option<&Path>)> = vec![("--sets", args.sets.as_deref())];
    inputs.extend(args.merge.iter().map(|p| ("--merge", Some(p.as_path()))));
    super::common::spare_inputs(
        &[
            &args.out,
            &sibling(&args.out, "tile.json"),
            &knn_indices,
            &knn_distances,
        ],
        &inputs,
    )?;
    if !args.merge.is_empty() {
        return merge(&args, started);
    }
    let path = args.sets.clone().context("give --sets, or --merge")?;
    let input = Input::read(&args, &path)?;
    let m = input.sets.dim().0;
    let bar = ui::Bar::new();
    let line = if let Some(k) = args.knn {
        let rows = args.rows.clone().unwrap_or(0..m);
        let knn_params = KnnParams::new().k(k).pivots(args.pivots);
        let found = metric::knn_with(
            input.view(0..m),
            input.metric.as_ref(),
            &input.params,
            &knn_params,
            rows.clone(),
            &bar,
        )
        .with_context(|| input.context())?;
        let folder = smspace::io::folder_of(&args.out);
        let written = found.save(
            &folder.join("knn_indices.npy"),
            &folder.join("knn_distances.npy"),
        )?;
        format!(
            "wrote {} ({} x {k}, rows {}:{} of {})",
            names(&written),
            rows.len(),
            rows.start,
            rows.end,
            input.describe()
        )
    } else if let Some(tile) = args
        .rows
        .clone()
        .map(|r| Tile::new(r, 0..m))
        .or(args.tile.clone())
    {
        write_tile(&args, &input, &tile, &bar)?
    } else {
        let d = metric::distance_matrix_with(
            input.view(0..m),
            input.metric.as_ref(),
            &input.params,
            &bar,
        )
        .with_context(|| input.context())?;
        d.save(&args.out)?;
        format!(
            "wrote {} ({m} x {m}, {})",
            args.out.display(),
            input.describe()
        )
    };
    eprintln!("{line} in {:.2} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// `--rows` or `--tile`: the tile from the sets of its rows and columns, and its record.
fn write_tile(args: &Args, input: &Input, tile: &Tile, bar: &ui::Bar) -> anyhow::Result<String> {
    let (m, p, n) = input.sets.dim();
    tile.check(m).with_context(|| input.context())?;
    let (rows, cols) = tile.shape();
    let needed = (rows as u64) * (cols as u64) * 8
        + PreparedSets::estimate_bytes_with_curves(rows + cols, p, n);
    super::common::check_memory(
        &format!("tile ({rows} x {cols}) and its sets"),
        needed,
        input.params.memory_limit_bytes,
        "compute smaller tiles",
    )?;
    let values = metric::distance_tile(
        input.view(tile.rows.clone()),
        input.view(tile.cols.clone()),
        tile,
        input.metric.as_ref(),
        bar,
    )
    .with_context(|| input.context())?;
    let record = TileRecord {
        sets: m,
        rows: [tile.rows.start, tile.rows.end],
        cols: [tile.cols.start, tile.cols.end],
        metric: input.params.metric.to_string(),
    };
    let written = metric::save_tile(&args.out, &record, values.view())?;
    Ok(format!(
        "wrote {} ({rows} x {cols}, rows {}:{} and columns {}:{} of {})",
        names(&written),
        tile.rows.start,
        tile.rows.end,
        tile.cols.start,
        tile.cols.end,
        input.describe()
    ))
}

/// `--merge`: the matrix from tiles.
fn merge(args: &Args, started: Instant) -> anyhow::Result<()> {
    let mut merged: Option<(TileRecord, TileMerge)> = None;
    for path in &args.merge {
        let (record, values) = metric::load_tile(path)?;
        if merged.is_none() {
            let limit = front::memory_limit(args.max_memory);
            let merge = TileMerge::new(record.sets, limit)
                .with_context(|| format!("cannot merge the tiles of {}", path.display()))?;
            merged = Some((record.clone(), merge));
        }
        let (first, merge) = merged.as_mut().expect("set above");
        anyhow::ensure!(
            (record.sets, &record.metric) == (first.sets, &first.metric),
            "{} is a tile of {} sets under the {} metric, but {} is one of {} sets under the {} metric; merge the tiles of one matrix",
            path.display(),
            record.sets,
            record.metric,
            args.merge[0].display(),
            first.sets,
            first.metric
        );
        merge
            .add(&record.tile(), values.view())
            .with_context(|| format!("cannot merge {}", path.display()))?;
    }
    let (record, merge) = merged.context("give the tiles to merge")?;
    let d = merge.finish().context("cannot assemble the matrix")?;
    d.save(&args.out)?;
    eprintln!(
        "wrote {} ({1} x {1}, {2}, from {3} tiles) in {4:.2} s",
        args.out.display(),
        record.sets,
        record.metric,
        args.merge.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The paths written, joined by "and".
fn names(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" and ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_parse_and_reject_garbage() {
        assert_eq!(parse_rows("3:10").unwrap(), 3..10);
        assert!(parse_rows("3-10").unwrap_err().contains("expected I0:I1"));
        assert!(parse_rows("a:10").unwrap_err().contains("not a row index"));
        assert_eq!(parse_tile("0:5,5:9").unwrap(), Tile::new(0..5, 5..9));
        assert!(parse_tile("0:5")
            .unwrap_err()
            .contains("expected I0:I1,J0:J1"));
    }
}
