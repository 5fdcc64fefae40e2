//! The toy agents' figures (paper section 2): the raw sensory manifolds of Fig. 1,
//! and the kernel lines and the learned manifold of Fig. 2.

use ndarray::{ArrayView2, ArrayView3, Axis};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::super::plot::{
    chart_2d, color_bar, padded, series_color, stride_sample, with_color_bar, Axis2d, ColorScale,
    Dash, Drawn, Figure, Legend, Mark,
};
use super::super::SensoryManifold;
use super::{motor_range, periods, wrap_curve, Panel, MAX_SCATTER_POINTS};
use smspace::agent::MotorSpace;

/// Fig. 1: the sensory manifolds of several environments.
pub(in crate::report) struct SensoryManifolds<'a> {
    pub(in crate::report) manifolds: &'a [SensoryManifold],
    pub(in crate::report) motor_unit: &'static str,
    pub(in crate::report) panel: Panel,
}

impl SensoryManifolds<'_> {
    /// The two plotted coordinates of row `t` of `m`: `(s1, s2)`, or `(m1, s1)` for a
    /// single sensor.
    fn point(m: &SensoryManifold, t: usize) -> (f64, f64) {
        if m.sensors.ncols() >= 2 {
            (m.sensors[[t, 0]], m.sensors[[t, 1]])
        } else {
            (m.motors[[t, 0]], m.sensors[[t, 0]])
        }
    }

    /// The legend: one line per environment and the mark of the sweep's start.
    fn legend(&self) -> Legend {
        let mut legend = Legend::new();
        for (i, m) in self.manifolds.iter().enumerate() {
            legend.add(
                Mark::Line(series_color(i), 1.2, Dash::Solid),
                m.label.clone(),
            );
        }
        if let Some(m) = self.manifolds.first() {
            if m.motors.nrows() > 0 {
                // Two decimals, the precision of the figure (not the tick format's).
                let start = format!("{:.2}", m.motors[[0, 0]]).replace('-', "\u{2212}");
                legend.add(
                    Mark::Dot(RGBColor(60, 60, 60), 2.2),
                    format!("start of the sweep, m1 = {start} {}", self.motor_unit),
                );
            }
        }
        legend
    }
}

impl Figure for SensoryManifolds<'_> {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.15)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let points: Vec<Vec<(f64, f64)>> = self
            .manifolds
            .iter()
            .map(|m| (0..m.sensors.nrows()).map(|t| Self::point(m, t)).collect())
            .collect();
        let two = self.manifolds.iter().all(|m| m.sensors.ncols() >= 2);
        let (x_title, y_title) = if two {
            (
                "s1: sensor 1 (arbitrary units)".to_owned(),
                "s2: sensor 2 (arbitrary units)".to_owned(),
            )
        } else {
            (
                format!("m1 ({})", self.motor_unit),
                "s1: sensor 1 (arbitrary units)".to_owned(),
            )
        };
        let legend = self.legend();
        let (plot, strip) = legend.split(root, print);
        let x = Axis2d::new(padded(points.iter().flatten().map(|p| p.0)), &x_title);
        let y = Axis2d::new(padded(points.iter().flatten().map(|p| p.1)), &y_title);
        let mut chart = chart_2d(&plot, print, "Fig. 1: sensory manifolds", x, y)?;
        for (i, pts) in points.iter().enumerate() {
            chart.draw_series(LineSeries::new(
                pts.iter().copied(),
                series_color(i).stroke_width(print.stroke(1.2)),
            ))?;
        }
        // The start dots after every curve, outlined, so that no curve hides one.
        for (i, pts) in points.iter().enumerate() {
            if let Some(&start) = pts.first() {
                chart.draw_series([
                    Circle::new(start, print.i(2.8), WHITE.filled()),
                    Circle::new(start, print.i(2.2), series_color(i).filled()),
                ])?;
            }
        }
        legend.draw(&strip, print)
    }
}

/// Fig. 2 (right): kernel sets in the motor plane, coloured by the pose `x`.
pub(in crate::report) struct KernelLines<'a> {
    pub(in crate::report) sets: ArrayView3<'a, f64>,
    /// The explored configuration `m^i` of each sampled set, `(m1, m2)`.
    pub(in crate::report) starts: Vec<(f64, f64)>,
    pub(in crate::report) sample: Vec<usize>,
    pub(in crate::report) set_x: Vec<f64>,
    pub(in crate::report) space: MotorSpace,
    pub(in crate::report) motor_unit: &'static str,
    pub(in crate::report) total: usize,
    pub(in crate::report) panel: Panel,
}

impl Figure for KernelLines<'_> {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.15)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let mut legend = Legend::new();
        legend.add(
            Mark::Line(RGBColor(90, 90, 90), 1.2, Dash::Solid),
            "kernel set M^i, coloured by its pose x",
        );
        legend.add(Mark::Dot(BLACK, 1.6), "explored configuration m^i");
        let (body, strip) = legend.split(root, print);
        let (plot, bar) = with_color_bar(&body, print);
        let scale = ColorScale::linear(self.sample.iter().map(|&i| self.set_x[i]));
        let coords = |a: usize| {
            self.sample
                .iter()
                .flat_map(move |&i| self.sets.index_axis(Axis(0), i).column(a).to_vec())
        };
        let x_title = format!("m1 ({})", self.motor_unit);
        let y_title = format!("m2 ({})", self.motor_unit);
        let title = format!(
            "Fig. 2: {} of {} kernel sets",
            self.sample.len(),
            self.total
        );
        let mut chart = chart_2d(
            &plot,
            print,
            &title,
            Axis2d::new(motor_range(self.space.motor(0), coords(0)), &x_title),
            Axis2d::new(motor_range(self.space.motor(1), coords(1)), &y_title),
        )?;
        let periods = periods(&self.space, [0, 1]);
        let closed = !self.space.has_bounds();
        for &i in &self.sample {
            let color = scale.color(self.set_x[i]);
            let set = self.sets.index_axis(Axis(0), i);
            let pts: Vec<[f64; 2]> = set.rows().into_iter().map(|r| [r[0], r[1]]).collect();
            for piece in wrap_curve(&pts, periods, closed).pieces {
                chart.draw_series(LineSeries::new(
                    piece.into_iter().map(|p| (p[0], p[1])),
                    color.stroke_width(print.stroke(1.2)),
                ))?;
            }
        }
        chart.draw_series(
            self.starts
                .iter()
                .map(|&p| Circle::new(p, print.i(1.6), BLACK.filled())),
        )?;
        color_bar(&bar, print, scale, "pose x (m)")?;
        legend.draw(&strip, print)
    }
}

/// Fig. 2 (left): the learned manifold against `x`.
pub(in crate::report) struct LearnedManifold<'a> {
    pub(in crate::report) embedding: ArrayView2<'a, f64>,
    pub(in crate::report) set_x: Vec<f64>,
    pub(in crate::report) panel: Panel,
}

impl Figure for LearnedManifold<'_> {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.0)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let e = &self.embedding;
        let rows = stride_sample(e.nrows(), MAX_SCATTER_POINTS);
        if e.ncols() == 1 {
            let title = format!("Fig. 2: learned 1-D manifold, {} sets", e.nrows());
            let mut chart = chart_2d(
                root,
                print,
                &title,
                Axis2d::new(padded(rows.iter().map(|&i| self.set_x[i])), "pose x (m)"),
                Axis2d::new(padded(rows.iter().map(|&i| e[[i, 0]])), "embedding q1"),
            )?;
            let color = series_color(0);
            chart.draw_series(rows.iter().map(|&i| {
                Circle::new(
                    (self.set_x[i], e[[i, 0]]),
                    print.i(1.5),
                    color.mix(0.7).filled(),
                )
            }))?;
            return Ok(());
        }
        let (plot, bar) = with_color_bar(root, print);
        let scale = ColorScale::linear(rows.iter().map(|&i| self.set_x[i]));
        let title = format!("Fig. 2: learned manifold, {} sets", e.nrows());
        let mut chart = chart_2d(
            &plot,
            print,
            &title,
            Axis2d::new(padded(rows.iter().map(|&i| e[[i, 0]])), "embedding q1"),
            Axis2d::new(padded(rows.iter().map(|&i| e[[i, 1]])), "embedding q2"),
        )?;
        chart.draw_series(rows.iter().map(|&i| {
            Circle::new(
                (e[[i, 0]], e[[i, 1]]),
                print.i(1.5),
                scale.color(self.set_x[i]).filled(),
            )
        }))?;
        color_bar(&bar, print, scale, "pose x (m)")
    }
}
