//! `smspace distances`: the metric between kernel sets (paper section 3.2, step 3).
//!
//! Reads kernel sets `(M, P, N)` and writes either the distance matrix `(M, M)` (or a
//! block of its rows) or, with `--knn K`, the `K` nearest sets of every set.

use std::ops::Range;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::ValueEnum;
use smspace::metric::{self, Closure, DistanceParams, KnnParams, Period, SetsView};

use super::common::{sibling, MetricArg};

use crate::ui;

/// Arguments of `smspace distances`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Kernel sets: a float64 .npy array of shape (M, P, N), motor angles in radians.
    #[arg(long, value_name = "FILE")]
    sets: PathBuf,
    /// Output: the distance matrix, float64 (M, M) (or (i1 - i0, M) with --rows). With
    /// --knn this file is not written: knn_indices.npy and knn_distances.npy go into
    /// the folder that holds it.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Distance between two sets. `curve` reads every set as a polyline: closed or open
    /// as recorded by `smspace trace` in SETS.closed.npy next to the sets, or as --curve
    /// says.
    #[arg(long, value_enum, default_value_t = MetricArg::Hausdorff)]
    metric: MetricArg,
    /// For --metric curve: join every set's points into a closed loop or an open
    /// polyline, instead of reading SETS.closed.npy (1 closed, 0 open per set).
    #[arg(long, value_enum, value_name = "closed|open")]
    curve: Option<CurveArg>,
    /// Period of every motor coordinate: 2pi (hinge joints, the paper's metric) or none
    /// (plain Euclidean).
    #[arg(long, value_enum, default_value_t = PeriodArg::TwoPi)]
    period: PeriodArg,
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
    #[arg(long, value_name = "I0:I1", value_parser = parse_rows)]
    rows: Option<Range<usize>>,
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum PeriodArg {
    /// wrap coordinate differences into [-π, π]
    #[value(name = "2pi")]
    TwoPi,
    /// no wrapping
    None,
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

/// The closures of the sets for `--metric curve`: `--curve`, else `SETS.closed.npy`
/// next to the sets; `None` for the point metrics.
fn closure(args: &Args, sets: usize) -> anyhow::Result<Option<Vec<Closure>>> {
    if args.metric != MetricArg::Curve {
        anyhow::ensure!(
            args.curve.is_none(),
            "--curve only applies to --metric curve (the point metrics do not join the points)"
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
    let record = sibling(&args.sets, "closed.npy");
    if !record.exists() {
        anyhow::bail!(
            "--metric curve needs to know which sets are closed loops: {} is missing (smspace trace writes it next to the sets); for sets from elsewhere give --curve closed or --curve open",
            record.display()
        );
    }
    Ok(Some(smspace::kernel::read_closure(&record, sets)?))
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let sets = smspace::io::read_cube(&args.sets, "(M, P, N)")?;
    let (m, p, n) = sets.dim();
    let kind = args.metric.kind();
    let closure = closure(&args, m)?;
    let view = match &closure {
        Some(c) => SetsView::new(sets.view()).with_closure(c),
        None => SetsView::new(sets.view()),
    };
    let params = DistanceParams::new()
        .metric(kind)
        .period(match args.period {
            PeriodArg::TwoPi => Period::TwoPi,
            PeriodArg::None => Period::None,
        })
        .memory_limit_bytes(args.max_memory.or_else(super::common::memory_available));
    let rows = args.rows.clone().unwrap_or(0..m);
    let context = || {
        format!(
            "cannot compute distances between the sets of {}",
            args.sets.display()
        )
    };
    let bar = ui::Bar::new();
    let started = Instant::now();
    match args.knn {
        None => {
            let block =
                metric::distance_rows(view, &params, rows.clone(), &bar).with_context(context)?;
            smspace::io::write_npy(&args.out, &block)?;
            eprintln!(
                "wrote {} ({} x {}, rows {}:{} of {m} sets of {p} points in {n}-D, {}) in {:.2} s",
                args.out.display(),
                block.nrows(),
                block.ncols(),
                rows.start,
                rows.end,
                params.metric.name(),
                started.elapsed().as_secs_f64(),
            );
        }
        Some(k) => {
            let knn_params = KnnParams::new().k(k).pivots(args.pivots);
            let found = metric::knn(view, &params, &knn_params, rows.clone(), &bar)
                .with_context(context)?;
            let folder = smspace::io::folder_of(&args.out);
            let indices_path = folder.join("knn_indices.npy");
            let distances_path = folder.join("knn_distances.npy");
            let indices = found.indices.mapv(|j| j as i64);
            let mut outputs = smspace::io::Outputs::new();
            outputs.npy(&indices_path, &indices)?;
            outputs.npy(&distances_path, &found.distances)?;
            outputs.commit()?;
            eprintln!(
                "wrote {} and {} ({} x {k}, rows {}:{} of {m} sets, {}) in {:.2} s",
                indices_path.display(),
                distances_path.display(),
                rows.len(),
                rows.start,
                rows.end,
                params.metric.name(),
                started.elapsed().as_secs_f64(),
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_parse_and_reject_garbage() {
        assert_eq!(parse_rows("3:10").unwrap(), 3..10);
        assert!(parse_rows("3-10").unwrap_err().contains("expected I0:I1"));
        assert!(parse_rows("a:10").unwrap_err().contains("not a row index"));
    }
}
