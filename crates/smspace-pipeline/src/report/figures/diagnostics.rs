//! Figures that judge the result: the persistence diagram, CCA's `dy–dx` plot and
//! stress, and the environment invariance (paper section 2.3).

use ndarray::ArrayView2;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::super::plot::{
    chart_2d, dashed_line, finite_extent, series_color, stride_sample, Axis2d, Chart2d, Dash,
    Drawn, Figure, Legend, Mark, Print, TickStyle,
};
use super::{Panel, MAX_SCATTER_POINTS};
use crate::report::tables::num;
use smspace::analysis::AnalysisReport;

/// A straight line between two data points, solid or dashed, in pixels.
fn data_line<DB: DrawingBackend>(
    chart: &Chart2d<'_, DB>,
    a: (f64, f64),
    b: (f64, f64),
    style: ShapeStyle,
    dash: Dash,
    print: Print,
) -> Drawn {
    let area = chart.plotting_area();
    let (pa, pb) = (area.map_coordinate(&a), area.map_coordinate(&b));
    let (x0, y0) = area.get_base_pixel();
    let local = |p: (i32, i32)| (p.0 - x0, p.1 - y0);
    let strip = area.strip_coord_spec();
    dashed_line(&strip, &[local(pa), local(pb)], style, dash, print)
}

/// Where the persistence diagram draws a bar that never dies: at the Rips threshold,
/// the scale the filtration stops at and the number the topology table gives (a bar
/// alive there has no death to draw), or a little above the finite deaths when the
/// threshold is not a positive number.
pub(in crate::report) fn infinite_death(analysis: &AnalysisReport, finite_top: f64) -> f64 {
    let threshold = analysis.homology.threshold;
    if threshold.is_finite() && threshold > 0.0 {
        threshold
    } else {
        finite_top.max(1e-9) * 1.06
    }
}

/// Rips persistence diagram with the Betti numbers.
pub(in crate::report) struct PersistenceDiagram<'a> {
    pub(in crate::report) analysis: &'a AnalysisReport,
    pub(in crate::report) distance_unit: &'static str,
    pub(in crate::report) panel: Panel,
}

impl Figure for PersistenceDiagram<'_> {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.15)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let bars = &self.analysis.persistence;
        let finite_top = finite_extent(
            bars.iter()
                .flatten()
                .flat_map(|&(b, d)| [Some(b), d].into_iter().flatten()),
        )
        .map_or(1.0, |(_, hi)| hi);
        let threshold = self.analysis.homology.threshold;
        let infinity = infinite_death(self.analysis, finite_top);
        let end = infinity.max(finite_top).max(1e-9) * 1.1;
        let grey = BLACK.mix(0.6);
        let mut legend = Legend::new();
        let marks: Vec<Mark> = (0..bars.len())
            .map(|dim| match dim {
                0 => Mark::Dot(series_color(0), 2.0),
                1 => Mark::Triangle(series_color(1)),
                _ => Mark::Cross(series_color(dim)),
            })
            .collect();
        for (dim, diagram) in bars.iter().enumerate() {
            let infinite = diagram.iter().filter(|b| b.1.is_none()).count();
            legend.add(
                marks[dim],
                format!("H{dim}: {} bars, {infinite} infinite", diagram.len()),
            );
        }
        legend.add(
            Mark::Line(RGBColor(100, 100, 100), 0.8, Dash::Dashed),
            if threshold.is_finite() && threshold > 0.0 {
                format!(
                    "death = \u{221e}, drawn at the Rips threshold {}",
                    num(threshold)
                )
            } else {
                "death = \u{221e} (alive at the largest scale)".to_owned()
            },
        );
        legend.add(
            Mark::Line(RGBColor(128, 128, 128), 0.6, Dash::Solid),
            "birth = death",
        );
        let (plot, strip) = legend.split(root, print);
        let betti = self
            .analysis
            .betti
            .iter()
            .map(|b| b.to_string())
            .collect::<Vec<_>>()
            .join(", ");
        let title = format!("persistence: Betti numbers [{betti}]");
        let x_title = format!("birth ({})", self.distance_unit);
        let y_title = format!("death ({})", self.distance_unit);
        let mut chart = chart_2d(
            &plot,
            print,
            &title,
            Axis2d::new(0.0..end, &x_title),
            Axis2d::new(0.0..end, &y_title),
        )?;
        data_line(
            &chart,
            (0.0, 0.0),
            (end, end),
            grey.stroke_width(print.stroke(0.6)),
            Dash::Solid,
            print,
        )?;
        data_line(
            &chart,
            (0.0, infinity),
            (end, infinity),
            grey.stroke_width(print.stroke(0.8)),
            Dash::Dashed,
            print,
        )?;
        for (dim, diagram) in bars.iter().enumerate() {
            let color = series_color(dim);
            let points = diagram.iter().map(|&(b, d)| (b, d.unwrap_or(infinity)));
            match dim {
                0 => chart
                    .draw_series(points.map(|p| Circle::new(p, print.i(2.0), color.filled())))?,
                1 => chart.draw_series(
                    points.map(|p| TriangleMarker::new(p, print.i(3.5), color.filled())),
                )?,
                _ => {
                    chart.draw_series(points.map(|p| {
                        Cross::new(p, print.i(3.0), color.stroke_width(print.stroke(1.0)))
                    }))?
                }
            };
        }
        legend.draw(&strip, print)
    }
}

/// CCA's `dy–dx` plot.
pub(in crate::report) struct DyDx<'a> {
    pub(in crate::report) pairs: ArrayView2<'a, f64>,
    pub(in crate::report) distance_unit: &'static str,
    pub(in crate::report) panel: Panel,
}

impl Figure for DyDx<'_> {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.1)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let rows = stride_sample(self.pairs.nrows(), MAX_SCATTER_POINTS);
        let dx = self.pairs.column(0);
        let dy = self.pairs.column(1);
        let hi = finite_extent(rows.iter().flat_map(|&i| [dx[i], dy[i]]))
            .map_or(1.0, |(_, hi)| hi)
            .max(1e-12)
            * 1.05;
        let color = series_color(0);
        let red = series_color(3);
        let mut legend = Legend::new();
        legend.add(
            Mark::Dot(color, 1.5),
            format!("pair of sets ({} of {})", rows.len(), self.pairs.nrows()),
        );
        legend.add(
            Mark::Line(red, 0.8, Dash::Dashed),
            "dy = dx (distance preserved)",
        );
        let (plot, strip) = legend.split(root, print);
        let x_title = format!("dx: learned distance ({})", self.distance_unit);
        let mut chart = chart_2d(
            &plot,
            print,
            "dy-dx plot of the embedding",
            Axis2d::new(0.0..hi, &x_title),
            Axis2d::new(0.0..hi, "dy: embedded distance"),
        )?;
        chart.draw_series(
            rows.iter()
                .map(|&i| Circle::new((dx[i], dy[i]), print.i(0.9), color.mix(0.45).filled())),
        )?;
        // The reference line goes on top, so that dense pairs do not hide it.
        data_line(
            &chart,
            (0.0, 0.0),
            (hi, hi),
            red.stroke_width(print.stroke(0.8)),
            Dash::Dashed,
            print,
        )?;
        legend.draw(&strip, print)
    }
}

/// Set distances and sensor distances in two environments.
pub(in crate::report) struct Invariance {
    /// `(d in environment 1, d in environment 2)` for the drawn pairs of sets.
    pub(in crate::report) set_pairs: Vec<(f64, f64)>,
    /// The same for sensor distances.
    pub(in crate::report) sensor_pairs: Vec<(f64, f64)>,
    pub(in crate::report) mantel: f64,
    pub(in crate::report) sensor_mantel: f64,
    pub(in crate::report) environments: (usize, usize),
    pub(in crate::report) distance_unit: &'static str,
    pub(in crate::report) panel: Panel,
}

impl Figure for Invariance {
    fn size(&self) -> (u32, u32) {
        let (w, h) = self.panel.grid(2, 1);
        (w, (f64::from(h) * 1.1).round() as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let panels = root.split_evenly((1, 2));
        let (a, b) = (self.environments.0 + 1, self.environments.1 + 1);
        let specs = [
            (
                &self.set_pairs,
                self.mantel,
                "learned set distances",
                format!("({})", self.distance_unit),
                series_color(0),
            ),
            (
                &self.sensor_pairs,
                self.sensor_mantel,
                "raw sensor distances",
                "(arb. units)".to_owned(),
                series_color(1),
            ),
        ];
        for (panel, (pairs, mantel, what, unit, color)) in panels.iter().zip(specs) {
            let grey = BLACK.mix(0.6);
            let mut legend = Legend::new();
            legend.add(
                Mark::Dot(color, 1.5),
                format!("pair of rows: Mantel r = {mantel:.4}"),
            );
            legend.add(
                Mark::Line(RGBColor(100, 100, 100), 0.8, Dash::Dashed),
                "same distance in both",
            );
            let (plot, strip) = legend.split(panel, print);
            let (x_range, y_range) = quantile_ranges(pairs);
            let x_title = format!("environment {a} {unit}");
            let y_title = format!("environment {b} {unit}");
            let mut chart = chart_2d(
                &plot,
                print,
                what,
                Axis2d::new(x_range.clone(), &x_title),
                Axis2d::new(y_range.clone(), &y_title),
            )?;
            let diagonal = x_range.end.min(y_range.end);
            data_line(
                &chart,
                (0.0, 0.0),
                (diagonal, diagonal),
                grey.stroke_width(print.stroke(0.8)),
                Dash::Dashed,
                print,
            )?;
            chart.draw_series(
                pairs
                    .iter()
                    .filter(|p| x_range.contains(&p.0) && y_range.contains(&p.1))
                    .map(|&p| Circle::new(p, print.i(0.9), color.mix(0.4).filled())),
            )?;
            legend.draw(&strip, print)?;
        }
        Ok(())
    }
}

/// Axis ranges from 0 to just above the 99.5th percentile of each coordinate, so that
/// a few far pairs do not leave most of the panel empty.
fn quantile_ranges(pairs: &[(f64, f64)]) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let top = |mut v: Vec<f64>| {
        v.retain(|x| x.is_finite());
        v.sort_by(f64::total_cmp);
        let q = v
            .get(((v.len() as f64 - 1.0) * 0.995).round() as usize)
            .copied();
        q.unwrap_or(1.0).max(1e-12) * 1.05
    };
    let x = top(pairs.iter().map(|p| p.0).collect());
    let y = top(pairs.iter().map(|p| p.1).collect());
    (0.0..x, 0.0..y)
}

/// CCA stress per epoch.
pub(in crate::report) struct StressTrace<'a> {
    pub(in crate::report) stress: &'a [f64],
    pub(in crate::report) panel: Panel,
}

impl Figure for StressTrace<'_> {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.0)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let n = self.stress.len();
        let positive: Vec<(f64, f64)> = self
            .stress
            .iter()
            .enumerate()
            .filter(|(_, s)| s.is_finite() && **s > 0.0)
            .map(|(k, &s)| ((k + 1) as f64, s.log10()))
            .collect();
        let (lo, hi) = finite_extent(positive.iter().map(|p| p.1)).unwrap_or((0.0, 1.0));
        // Whole decades around the values, at least one, so that the smallest epochs
        // sit above the axis.
        let (lo, hi) = (lo.floor(), hi.ceil().max(lo.floor() + 1.0));
        let pad = 0.04 * (hi - lo);
        let x_range = 0.5..n as f64 + 0.5;
        let mut chart = chart_2d(
            root,
            print,
            &format!("CCA stress, {n} epochs"),
            Axis2d::new(x_range, "epoch"),
            Axis2d {
                range: lo - pad..hi + pad,
                title: "stress (log scale)",
                ticks: TickStyle::Decades,
            },
        )?;
        let color = series_color(0);
        chart.draw_series(LineSeries::new(
            positive.iter().copied(),
            color.stroke_width(print.stroke(1.0)),
        ))?;
        if n <= 200 {
            chart.draw_series(
                positive
                    .iter()
                    .map(|&p| Circle::new(p, print.i(1.5), color.filled())),
            )?;
        }
        Ok(())
    }
}
