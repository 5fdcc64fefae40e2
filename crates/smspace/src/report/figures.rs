//! The report's figures, each a [`Figure`] drawn on PNG and SVG alike.
//!
//! What each one shows, and the paper figure it mirrors:
//!
//! | file | paper | content |
//! |---|---|---|
//! | `fig1-sensory-manifolds` | Fig. 1 (2.2) | `s = σ_E(m)` along a motor sweep, one curve per environment |
//! | `fig2-kernel-lines` | Fig. 2 (2.3) | kernel sets `M^i` in the motor plane `(m1, m2)`, coloured by the pose `x` |
//! | `fig2-learned-manifold` | Fig. 2 (2.3) | the 1-D embedding against `x` (or the first two coordinates) |
//! | `fig5a-configurations` | Fig. 5a (3.3) | explored arm configurations, working space and lights |
//! | `fig5b-kernel-sets-3d` | Fig. 5b (3.3) | kernel sets in motor space, two 3-D projections |
//! | `fig5d-embedding-probes` | Fig. 5d (3.3) | the embedding (grey) with the probe surfaces, one per orientation |
//! | `embedding-pose` | — | the embedding coloured by each pose coordinate |
//! | `persistence-diagram` | — | Rips persistence of the set metric, Betti numbers |
//! | `dydx` | — | CCA's `dy–dx` plot (embedded against learned distances) |
//! | `invariance` | 2.3 | set and sensor distances in two environments |
//! | `cca-stress` | — | CCA stress per epoch |

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::ops::Range;

use ndarray::{Array2, ArrayView2, ArrayView3, Axis};
use plotters::coord::ranged3d::Cartesian3d;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::plot::{
    chart_2d, color_bar, equal_aspect, finite_extent, legend, padded, series_color, stride_sample,
    tick_font, tick_label, title_font, with_color_bar, Chart2d, ColorScale, Drawn, Figure,
    PlotError, GREY,
};
use super::SensoryManifold;
use crate::agent::{Environment, Motor, MotorSpace};
use crate::analysis::AnalysisReport;
use crate::explore::Workspace;

/// Most points a scatter draws (evenly spaced rows beyond that), so that SVG files stay
/// small and drawing stays fast.
pub(super) const MAX_SCATTER_POINTS: usize = 20_000;

/// The names of the pose coordinates, with units.
pub(super) const POSE_LABELS: [&str; 3] = ["x (m)", "y (m)", "alpha (rad)"];

// ---------------------------------------------------------------------------------
// Fig. 1

/// Fig. 1: the sensory manifolds of several environments.
pub(super) struct SensoryManifolds<'a> {
    pub(super) manifolds: &'a [SensoryManifold],
    pub(super) agent: &'a str,
    pub(super) motor_unit: &'static str,
    pub(super) size: (u32, u32),
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
}

impl Figure for SensoryManifolds<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let points: Vec<Vec<(f64, f64)>> = self
            .manifolds
            .iter()
            .map(|m| (0..m.sensors.nrows()).map(|t| Self::point(m, t)).collect())
            .collect();
        let x = padded(points.iter().flatten().map(|p| p.0));
        let y = padded(points.iter().flatten().map(|p| p.1));
        let two = self.manifolds.iter().all(|m| m.sensors.ncols() >= 2);
        let more = self.manifolds.iter().any(|m| m.sensors.ncols() > 2);
        let (x_desc, y_desc) = if two {
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
        let title = format!(
            "Fig. 1: sensory manifolds of {} in {} environment{}{}",
            self.agent,
            self.manifolds.len(),
            if self.manifolds.len() == 1 { "" } else { "s" },
            if more { " (first two sensors)" } else { "" }
        );
        let mut chart = chart_2d(root, &title, x, y, &x_desc, &y_desc)?;
        for (i, (m, pts)) in self.manifolds.iter().zip(&points).enumerate() {
            let color = series_color(i);
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?
                .label(m.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            if let Some(&start) = pts.first() {
                chart.draw_series(std::iter::once(Circle::new(start, 4, color.filled())))?;
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }
}

// ---------------------------------------------------------------------------------
// Fig. 2

/// Splits a polyline where a periodic coordinate wraps (a jump over π), so that no
/// segment crosses the whole plot; closes it when `close` and the ends are near.
pub(super) fn wrap_segments<const K: usize>(
    points: &[[f64; K]],
    periodic: bool,
    close: bool,
) -> Vec<Vec<[f64; K]>> {
    let jumps =
        |a: &[f64; K], b: &[f64; K]| periodic && a.iter().zip(b).any(|(x, y)| (x - y).abs() > PI);
    let mut out: Vec<Vec<[f64; K]>> = Vec::new();
    let mut current: Vec<[f64; K]> = Vec::new();
    for p in points {
        if let Some(last) = current.last() {
            if jumps(last, p) {
                out.push(std::mem::take(&mut current));
            }
        }
        current.push(*p);
    }
    if close && points.len() > 2 {
        let (first, last) = (points[0], points[points.len() - 1]);
        let step = points
            .windows(2)
            .map(|w| dist(&w[0], &w[1]))
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max);
        if !jumps(&last, &first) && dist(&last, &first) <= 3.0 * step.max(1e-12) {
            current.push(first);
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

fn dist<const K: usize>(a: &[f64; K], b: &[f64; K]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// The axis range of a motor coordinate: its period's range when periodic, the values'
/// when bounded.
fn motor_range(motor: Motor, values: impl IntoIterator<Item = f64>) -> Range<f64> {
    match motor {
        Motor::Periodic { .. } => {
            let (low, high) = motor.range();
            low..high
        }
        Motor::Bounded { .. } => padded(values),
    }
}

/// Fig. 2 (right): kernel sets in the motor plane, coloured by the pose `x`.
pub(super) struct KernelLines<'a> {
    pub(super) sets: ArrayView3<'a, f64>,
    /// The explored configuration `m^i` of each sampled set, `(m1, m2)`.
    pub(super) starts: Vec<(f64, f64)>,
    pub(super) sample: Vec<usize>,
    pub(super) set_x: Vec<f64>,
    pub(super) space: MotorSpace,
    pub(super) motor_unit: &'static str,
    pub(super) total: usize,
    pub(super) size: (u32, u32),
}

impl Figure for KernelLines<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let (plot, bar) = with_color_bar(root);
        let scale = ColorScale::linear(self.sample.iter().map(|&i| self.set_x[i]));
        let coords = |a: usize| {
            self.sample
                .iter()
                .flat_map(move |&i| self.sets.index_axis(Axis(0), i).column(a).to_vec())
        };
        let x = motor_range(self.space.motor(0), coords(0));
        let y = motor_range(self.space.motor(1), coords(1));
        let title = format!(
            "Fig. 2: {} of {} kernel sets in motor space",
            self.sample.len(),
            self.total
        );
        let mut chart = chart_2d(
            &plot,
            &title,
            x,
            y,
            &format!("m1 ({})", self.motor_unit),
            &format!("m2 ({})", self.motor_unit),
        )?;
        let periodic = !self.space.is_bounded();
        for (k, &i) in self.sample.iter().enumerate() {
            let color = scale.color(self.set_x[i]);
            let set = self.sets.index_axis(Axis(0), i);
            let pts: Vec<[f64; 2]> = set.rows().into_iter().map(|r| [r[0], r[1]]).collect();
            for seg in wrap_segments(&pts, periodic, periodic) {
                let series = chart.draw_series(LineSeries::new(
                    seg.into_iter().map(|p| (p[0], p[1])),
                    color.stroke_width(2),
                ))?;
                if k == 0 {
                    series.label("kernel set M^i").legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                    });
                }
            }
        }
        let starts = self
            .starts
            .iter()
            .map(|&p| Circle::new(p, 3, BLACK.filled()));
        chart
            .draw_series(starts)?
            .label("explored m^i")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        color_bar(&bar, scale, "pose x (m)")
    }
}

/// Fig. 2 (left): the learned manifold against `x`.
pub(super) struct LearnedManifold<'a> {
    pub(super) embedding: ArrayView2<'a, f64>,
    pub(super) set_x: Vec<f64>,
    pub(super) size: (u32, u32),
}

impl Figure for LearnedManifold<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let rows = stride_sample(self.embedding.nrows(), MAX_SCATTER_POINTS);
        if self.embedding.ncols() == 1 {
            let x = padded(rows.iter().map(|&i| self.set_x[i]));
            let y = padded(rows.iter().map(|&i| self.embedding[[i, 0]]));
            let title = format!(
                "Fig. 2: learned 1-D manifold of {} sets against x",
                self.embedding.nrows()
            );
            let mut chart = chart_2d(root, &title, x, y, "pose x (m)", "embedding q1")?;
            let color = series_color(0);
            chart
                .draw_series(rows.iter().map(|&i| {
                    Circle::new(
                        (self.set_x[i], self.embedding[[i, 0]]),
                        3,
                        color.mix(0.7).filled(),
                    )
                }))?
                .label("set M^i")
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
            return legend(&mut chart, SeriesLabelPosition::UpperLeft);
        }
        let (plot, bar) = with_color_bar(root);
        let scale = ColorScale::linear(rows.iter().map(|&i| self.set_x[i]));
        let x = padded(rows.iter().map(|&i| self.embedding[[i, 0]]));
        let y = padded(rows.iter().map(|&i| self.embedding[[i, 1]]));
        let title = format!(
            "Fig. 2: learned manifold of {} sets, coloured by x",
            self.embedding.nrows()
        );
        let mut chart = chart_2d(&plot, &title, x, y, "embedding q1", "embedding q2")?;
        chart.draw_series(rows.iter().map(|&i| {
            Circle::new(
                (self.embedding[[i, 0]], self.embedding[[i, 1]]),
                3,
                scale.color(self.set_x[i]).filled(),
            )
        }))?;
        color_bar(&bar, scale, "pose x (m)")
    }
}

// ---------------------------------------------------------------------------------
// Fig. 5a

/// Fig. 5a: a sample of explored configurations of the arm.
pub(super) struct Configurations {
    /// Joint positions of each drawn configuration, base first.
    pub(super) skeletons: Vec<Vec<[f64; 2]>>,
    /// Sensor orientation of each.
    pub(super) alphas: Vec<f64>,
    pub(super) workspace: Option<Workspace>,
    pub(super) environment: Option<Environment>,
    pub(super) agent: String,
    pub(super) explored: usize,
    pub(super) size: (u32, u32),
}

impl Figure for Configurations {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let reach = self.reach();
        let tick = 0.3 * reach.max(1e-3);
        let (x, y) = self.ranges(tick);
        let title = format!(
            "Fig. 5a: {} of {} explored configurations of the {}",
            self.skeletons.len(),
            self.explored,
            self.agent
        );
        let mut chart = chart_2d(root, &title, x, y, "x (m)", "y (m)")?;
        if let Some(w) = self.workspace {
            draw_workspace(&mut chart, w)?;
        }
        self.draw_arms(&mut chart)?;
        self.draw_sensor_ticks(&mut chart, tick)?;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(-0.04 * reach, -0.04 * reach), (0.04 * reach, 0.04 * reach)],
                BLACK.filled(),
            )))?
            .label("base")
            .legend(|(x, y)| Rectangle::new([(x + 5, y - 4), (x + 13, y + 4)], BLACK.filled()));
        if let Some(env) = &self.environment {
            draw_lights(&mut chart, env)?;
        }
        legend(&mut chart, SeriesLabelPosition::LowerLeft)
    }
}

impl Configurations {
    /// The longest link of any drawn arm: the scale of the sensor ticks and the base.
    fn reach(&self) -> f64 {
        self.skeletons
            .iter()
            .flat_map(|s| s.windows(2).map(|w| dist(&w[0], &w[1])))
            .fold(0.0, f64::max)
    }

    /// The axis ranges, with equal aspect: every joint, the end of every sensor tick
    /// (of length `tick`), the working space and the lights, padded.
    fn ranges(&self, tick: f64) -> (Range<f64>, Range<f64>) {
        let mut xs: Vec<f64> = Vec::new();
        let mut ys: Vec<f64> = Vec::new();
        for (s, &alpha) in self.skeletons.iter().zip(&self.alphas) {
            for p in s {
                xs.push(p[0]);
                ys.push(p[1]);
            }
            if let Some(end) = s.last() {
                xs.push(end[0] + tick * alpha.cos());
                ys.push(end[1] + tick * alpha.sin());
            }
        }
        if let Some(w) = self.workspace {
            for sx in [-0.5, 0.5] {
                xs.push(w.center[0] + sx * w.size[0]);
            }
            for sy in [-0.5, 0.5] {
                ys.push(w.center[1] + sy * w.size[1]);
            }
        }
        if let Some(env) = &self.environment {
            for l in &env.lights {
                xs.push(l[0]);
                ys.push(l[1]);
            }
        }
        let (pw, ph) = self.size;
        equal_aspect(
            padded(xs.iter().copied()),
            padded(ys.iter().copied()),
            pw.saturating_sub(100),
            ph.saturating_sub(110),
        )
    }

    /// Every arm as a polyline from its base, with a dot on each joint after the base.
    fn draw_arms<DB: DrawingBackend>(&self, chart: &mut Chart2d<'_, DB>) -> Drawn {
        let arm = RGBColor(31, 119, 180);
        for (k, s) in self.skeletons.iter().enumerate() {
            let series = chart.draw_series(LineSeries::new(
                s.iter().map(|p| (p[0], p[1])),
                arm.mix(0.55).stroke_width(2),
            ))?;
            if k == 0 {
                series.label("arm configuration").legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], arm.stroke_width(2))
                });
            }
            chart.draw_series(
                s.iter()
                    .skip(1)
                    .map(|p| Circle::new((p[0], p[1]), 2, arm.filled())),
            )?;
        }
        Ok(())
    }

    /// The sensor's orientation alpha as a red tick of length `tick` at each arm's end.
    fn draw_sensor_ticks<DB: DrawingBackend>(
        &self,
        chart: &mut Chart2d<'_, DB>,
        tick: f64,
    ) -> Drawn {
        let red = RGBColor(214, 39, 40);
        let ticks = self
            .skeletons
            .iter()
            .zip(&self.alphas)
            .filter_map(|(s, &alpha)| {
                s.last().map(|e| {
                    PathElement::new(
                        vec![
                            (e[0], e[1]),
                            (e[0] + tick * alpha.cos(), e[1] + tick * alpha.sin()),
                        ],
                        red.stroke_width(2),
                    )
                })
            });
        chart
            .draw_series(ticks)?
            .label("sensor orientation alpha")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2)));
        Ok(())
    }
}

/// The working space: a faint green rectangle with a dashed border.
fn draw_workspace<DB: DrawingBackend>(chart: &mut Chart2d<'_, DB>, w: Workspace) -> Drawn {
    let (x0, x1) = (w.center[0] - w.size[0] / 2.0, w.center[0] + w.size[0] / 2.0);
    let (y0, y1) = (w.center[1] - w.size[1] / 2.0, w.center[1] + w.size[1] / 2.0);
    let green = RGBColor(44, 160, 44);
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(x0, y0), (x1, y1)],
            green.mix(0.08).filled(),
        )))?
        .label("working space")
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], green.stroke_width(2)));
    chart.draw_series(DashedLineSeries::new(
        [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)],
        8,
        5,
        green.stroke_width(2),
    ))?;
    Ok(())
}

/// The lights of `env`, gold discs ringed in black.
fn draw_lights<DB: DrawingBackend>(chart: &mut Chart2d<'_, DB>, env: &Environment) -> Drawn {
    let gold = RGBColor(255, 200, 0);
    chart
        .draw_series(
            env.lights
                .iter()
                .map(|l| Circle::new((l[0], l[1]), 6, gold.filled())),
        )?
        .label("lights (environment 1)")
        .legend(move |(x, y)| Circle::new((x + 10, y), 5, gold.filled()));
    chart.draw_series(
        env.lights
            .iter()
            .map(|l| Circle::new((l[0], l[1]), 6, BLACK.stroke_width(1))),
    )?;
    Ok(())
}

// ---------------------------------------------------------------------------------
// 3-D charts.

type Chart3d<'a, DB> =
    ChartContext<'a, DB, Cartesian3d<RangedCoordf64, RangedCoordf64, RangedCoordf64>>;

/// A titled 3-D chart; plotters' `y` axis is vertical, so the data's `(a, b, c)` are
/// drawn as `(x, z, y)`: `a` to the right, `b` into the depth, `c` up. Every tick label
/// names its axis (`m2 = 1.5`), since plotters draws no axis titles in 3-D.
fn chart_3d<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    title: &str,
    ranges: [Range<f64>; 3],
    labels: [&str; 3],
    yaw: f64,
) -> Result<Chart3d<'a, DB>, PlotError> {
    let [a, b, c] = ranges;
    let mut chart = ChartBuilder::on(area)
        .caption(title, title_font())
        .margin(16)
        .build_cartesian_3d(a, c, b)?;
    chart.with_projection(|mut p| {
        p.yaw = yaw;
        p.pitch = 0.35;
        p.scale = 0.78;
        p.into_matrix()
    });
    let [na, nb, nc] = labels;
    let fa = |v: &f64| format!("{na} = {}", tick_label(*v));
    let fb = |v: &f64| format!("{nb} = {}", tick_label(*v));
    let fc = |v: &f64| format!("{nc} = {}", tick_label(*v));
    chart
        .configure_axes()
        .label_style(tick_font())
        .x_formatter(&fa)
        .y_formatter(&fc)
        .z_formatter(&fb)
        .light_grid_style(RGBColor(238, 238, 238))
        .bold_grid_style(RGBColor(212, 212, 212))
        .max_light_lines(1)
        .x_labels(4)
        .y_labels(4)
        .z_labels(4)
        .draw()?;
    Ok(chart)
}

/// Maps data `(a, b, c)` to plotters' `(x, y, z)` (see [`chart_3d`]).
fn p3(a: f64, b: f64, c: f64) -> (f64, f64, f64) {
    (a, c, b)
}

/// Fig. 5b: kernel sets in motor space, two 3-D projections.
pub(super) struct KernelSets3d<'a> {
    pub(super) sets: ArrayView3<'a, f64>,
    pub(super) sample: Vec<usize>,
    pub(super) space: MotorSpace,
    pub(super) motor_unit: &'static str,
    pub(super) panel: (u32, u32),
}

impl Figure for KernelSets3d<'_> {
    fn size(&self) -> (u32, u32) {
        (2 * self.panel.0, self.panel.1)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let n = self.sets.len_of(Axis(2));
        let views: [([usize; 3], f64); 2] = if n >= 4 {
            [([0, 1, 2], 0.7), ([1, 2, 3], 0.7)]
        } else {
            [([0, 1, 2], 0.7), ([0, 1, 2], 2.3)]
        };
        let panels = root.split_evenly((1, 2));
        let total = self.sets.len_of(Axis(0));
        let periodic = !self.space.is_bounded();
        for (panel, (axes, yaw)) in panels.iter().zip(views) {
            let range = |a: usize| {
                motor_range(
                    self.space.motor(a),
                    self.sample
                        .iter()
                        .flat_map(move |&i| self.sets.index_axis(Axis(0), i).column(a).to_vec()),
                )
            };
            let labels = axes.map(|a| format!("m{}", a + 1));
            let title = format!(
                "Fig. 5b: {} of {} sets, motors in {}",
                self.sample.len(),
                total,
                self.motor_unit
            );
            let mut chart = chart_3d(
                panel,
                &title,
                axes.map(range),
                [&labels[0], &labels[1], &labels[2]],
                yaw,
            )?;
            for (k, &i) in self.sample.iter().enumerate() {
                let color = series_color(k);
                let set = self.sets.index_axis(Axis(0), i);
                let pts: Vec<[f64; 3]> = set
                    .rows()
                    .into_iter()
                    .map(|r| [r[axes[0]], r[axes[1]], r[axes[2]]])
                    .collect();
                for seg in wrap_segments(&pts, periodic, periodic) {
                    chart.draw_series(LineSeries::new(
                        seg.into_iter().map(|p| p3(p[0], p[1], p[2])),
                        color.stroke_width(2),
                    ))?;
                }
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// Fig. 5d

/// One probe orientation: its cells `(ix, iy) → set` and mean orientation.
pub(super) struct ProbeSurface {
    /// Mean pose alpha of its cells (radians).
    pub(super) alpha: f64,
    /// Grid cell → set index.
    pub(super) cells: BTreeMap<(i64, i64), usize>,
}

impl ProbeSurface {
    /// Grid edges between neighbouring cells present, as set pairs.
    pub(super) fn edges(&self) -> Vec<(usize, usize)> {
        let mut edges = Vec::new();
        for (&(ix, iy), &a) in &self.cells {
            for next in [(ix + 1, iy), (ix, iy + 1)] {
                if let Some(&b) = self.cells.get(&next) {
                    edges.push((a, b));
                }
            }
        }
        edges
    }
}

/// Groups the probe rows among the kept sets by orientation.
pub(super) fn probe_surfaces(
    probes: ArrayView2<'_, i64>,
    kept: &[usize],
    set_poses: &Array2<f64>,
) -> Vec<ProbeSurface> {
    /// Cells, and the sums of `sin alpha` and `cos alpha`.
    type Accumulated = (BTreeMap<(i64, i64), usize>, f64, f64);
    let mut by: BTreeMap<i64, Accumulated> = BTreeMap::new();
    for (set, &row) in kept.iter().enumerate() {
        let label = probes.row(row);
        if label[0] < 0 {
            continue;
        }
        let entry = by.entry(label[0]).or_default();
        entry.0.insert((label[1], label[2]), set);
        // Circular mean of the orientation.
        let alpha = set_poses[[set, 2]];
        entry.1 += alpha.sin();
        entry.2 += alpha.cos();
    }
    by.into_iter()
        .map(|(_, (cells, s, c))| ProbeSurface {
            alpha: s.atan2(c),
            cells,
        })
        .collect()
}

/// Fig. 5d: the embedding with the probe surfaces.
pub(super) struct EmbeddingProbes<'a> {
    pub(super) embedding: ArrayView2<'a, f64>,
    pub(super) set_poses: &'a Array2<f64>,
    pub(super) surfaces: &'a [ProbeSurface],
    pub(super) size: (u32, u32),
}

impl Figure for EmbeddingProbes<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let (plot, bar) = with_color_bar(root);
        let e = &self.embedding;
        let probe_sets: Vec<usize> = self
            .surfaces
            .iter()
            .flat_map(|s| s.cells.values().copied())
            .collect();
        let scale = ColorScale::linear(probe_sets.iter().map(|&i| self.set_poses[[i, 0]]));
        let rows = stride_sample(e.nrows(), MAX_SCATTER_POINTS);
        let title = format!(
            "Fig. 5d: {} sets, {} probe surfaces",
            e.nrows(),
            self.surfaces.len()
        );
        let edge_color = |a: usize, b: usize| {
            scale.color(0.5 * (self.set_poses[[a, 0]] + self.set_poses[[b, 0]]))
        };
        if e.ncols() >= 3 {
            let ranges = [0, 1, 2].map(|k| padded(e.column(k).iter().copied()));
            let mut chart = chart_3d(&plot, &title, ranges, ["q1", "q2", "q3"], 0.7)?;
            chart.draw_series(rows.iter().map(|&i| {
                Circle::new(
                    p3(e[[i, 0]], e[[i, 1]], e[[i, 2]]),
                    1,
                    GREY.mix(0.6).filled(),
                )
            }))?;
            for s in self.surfaces {
                chart.draw_series(s.edges().into_iter().map(|(a, b)| {
                    PathElement::new(
                        vec![
                            p3(e[[a, 0]], e[[a, 1]], e[[a, 2]]),
                            p3(e[[b, 0]], e[[b, 1]], e[[b, 2]]),
                        ],
                        edge_color(a, b).stroke_width(2),
                    )
                }))?;
                chart.draw_series(s.cells.values().map(|&a| {
                    Circle::new(
                        p3(e[[a, 0]], e[[a, 1]], e[[a, 2]]),
                        2,
                        scale.color(self.set_poses[[a, 0]]).filled(),
                    )
                }))?;
            }
        } else {
            let x = padded(e.column(0).iter().copied());
            let y = padded(e.column(1).iter().copied());
            let mut chart = chart_2d(&plot, &title, x, y, "embedding q1", "embedding q2")?;
            chart.draw_series(
                rows.iter()
                    .map(|&i| Circle::new((e[[i, 0]], e[[i, 1]]), 1, GREY.mix(0.6).filled())),
            )?;
            for s in self.surfaces {
                chart.draw_series(s.edges().into_iter().map(|(a, b)| {
                    PathElement::new(
                        vec![(e[[a, 0]], e[[a, 1]]), (e[[b, 0]], e[[b, 1]])],
                        edge_color(a, b).stroke_width(2),
                    )
                }))?;
                chart.draw_series(s.cells.values().map(|&a| {
                    Circle::new(
                        (e[[a, 0]], e[[a, 1]]),
                        2,
                        scale.color(self.set_poses[[a, 0]]).filled(),
                    )
                }))?;
            }
        }
        color_bar(&bar, scale, "probe x (m)")
    }
}

// ---------------------------------------------------------------------------------
// Embedding coloured by the pose.

/// The embedding coloured by each non-constant pose coordinate, one panel each.
pub(super) struct EmbeddingPose<'a> {
    pub(super) embedding: ArrayView2<'a, f64>,
    pub(super) set_poses: &'a Array2<f64>,
    /// The pose columns drawn (0 = x, 1 = y, 2 = alpha).
    pub(super) coordinates: Vec<usize>,
    pub(super) panel: (u32, u32),
}

impl Figure for EmbeddingPose<'_> {
    fn size(&self) -> (u32, u32) {
        (self.panel.0 * self.coordinates.len() as u32, self.panel.1)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let e = &self.embedding;
        let rows = stride_sample(e.nrows(), MAX_SCATTER_POINTS);
        let panels = root.split_evenly((1, self.coordinates.len()));
        let radius = if rows.len() > 2000 { 2 } else { 3 };
        for (panel, &c) in panels.iter().zip(&self.coordinates) {
            let values = self.set_poses.column(c);
            let scale = if c == 2 {
                ColorScale::Circular
            } else {
                ColorScale::linear(values.iter().copied())
            };
            let name = ["x", "y", "alpha"][c];
            let title = format!("embedding coloured by pose {name}");
            if e.ncols() == 1 {
                let x = padded(values.iter().copied());
                let y = padded(e.column(0).iter().copied());
                let mut chart = chart_2d(panel, &title, x, y, POSE_LABELS[c], "embedding q1")?;
                chart.draw_series(rows.iter().map(|&i| {
                    Circle::new(
                        (values[i], e[[i, 0]]),
                        radius,
                        scale.color(values[i]).filled(),
                    )
                }))?;
                continue;
            }
            let (plot, bar) = with_color_bar(panel);
            if e.ncols() >= 3 {
                let ranges = [0, 1, 2].map(|k| padded(e.column(k).iter().copied()));
                let mut chart = chart_3d(&plot, &title, ranges, ["q1", "q2", "q3"], 0.7)?;
                chart.draw_series(rows.iter().map(|&i| {
                    Circle::new(
                        p3(e[[i, 0]], e[[i, 1]], e[[i, 2]]),
                        radius,
                        scale.color(values[i]).filled(),
                    )
                }))?;
            } else {
                let x = padded(e.column(0).iter().copied());
                let y = padded(e.column(1).iter().copied());
                let mut chart = chart_2d(&plot, &title, x, y, "embedding q1", "embedding q2")?;
                chart.draw_series(rows.iter().map(|&i| {
                    Circle::new(
                        (e[[i, 0]], e[[i, 1]]),
                        radius,
                        scale.color(values[i]).filled(),
                    )
                }))?;
            }
            color_bar(&bar, scale, POSE_LABELS[c])?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// Persistence diagram.

/// Rips persistence diagram with the Betti numbers.
pub(super) struct PersistenceDiagram<'a> {
    pub(super) analysis: &'a AnalysisReport,
    pub(super) distance_unit: &'static str,
    pub(super) size: (u32, u32),
}

impl Figure for PersistenceDiagram<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let bars = &self.analysis.persistence;
        let finite_top = finite_extent(
            bars.iter()
                .flatten()
                .flat_map(|&(b, d)| [Some(b), d].into_iter().flatten()),
        )
        .map_or(1.0, |(_, hi)| hi);
        let threshold = self.analysis.homology.threshold;
        let top = if threshold.is_finite() && threshold > 0.0 {
            threshold.max(finite_top)
        } else {
            finite_top
        }
        .max(1e-9);
        let infinity = top * 1.06;
        let range = 0.0..top * 1.12;
        let betti = self
            .analysis
            .betti
            .iter()
            .map(|b| b.to_string())
            .collect::<Vec<_>>()
            .join(", ");
        let title = format!("Persistence diagram: Betti numbers b = [{betti}]");
        let mut chart = chart_2d(
            root,
            &title,
            range.clone(),
            range,
            &format!("birth ({})", self.distance_unit),
            &format!("death ({})", self.distance_unit),
        )?;
        chart.draw_series(LineSeries::new(
            [(0.0, 0.0), (top * 1.12, top * 1.12)],
            BLACK.mix(0.5).stroke_width(1),
        ))?;
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, infinity), (top * 1.12, infinity)],
                6,
                4,
                BLACK.mix(0.6).stroke_width(1),
            ))?
            .label("death = ∞ (alive at the threshold)")
            .legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.6).stroke_width(1))
            });
        for (dim, diagram) in bars.iter().enumerate() {
            let color = series_color(dim);
            let points: Vec<(f64, f64)> = diagram
                .iter()
                .map(|&(b, d)| (b, d.unwrap_or(infinity)))
                .collect();
            let infinite = diagram.iter().filter(|b| b.1.is_none()).count();
            let label = format!("H{dim}: {} bars, {infinite} infinite", diagram.len());
            match dim {
                0 => chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))?
                    .label(label)
                    .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled())),
                1 => chart
                    .draw_series(
                        points
                            .iter()
                            .map(|&p| TriangleMarker::new(p, 6, color.filled())),
                    )?
                    .label(label)
                    .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, color.filled())),
                _ => chart
                    .draw_series(
                        points
                            .iter()
                            .map(|&p| Cross::new(p, 5, color.stroke_width(2))),
                    )?
                    .label(label)
                    .legend(move |(x, y)| Cross::new((x + 10, y), 5, color.stroke_width(2))),
            };
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    }
}

// ---------------------------------------------------------------------------------
// dy–dx

/// CCA's `dy–dx` plot.
pub(super) struct DyDx<'a> {
    pub(super) pairs: ArrayView2<'a, f64>,
    pub(super) distance_unit: &'static str,
    pub(super) size: (u32, u32),
}

impl Figure for DyDx<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let rows = stride_sample(self.pairs.nrows(), MAX_SCATTER_POINTS);
        let dx = self.pairs.column(0);
        let dy = self.pairs.column(1);
        let hi = finite_extent(rows.iter().flat_map(|&i| [dx[i], dy[i]]))
            .map_or(1.0, |(_, hi)| hi)
            .max(1e-12);
        let range = 0.0..hi * 1.05;
        let title = format!(
            "dy-dx plot of the embedding ({} pairs{})",
            self.pairs.nrows(),
            if rows.len() < self.pairs.nrows() {
                format!(", {} drawn", rows.len())
            } else {
                String::new()
            }
        );
        let mut chart = chart_2d(
            root,
            &title,
            range.clone(),
            range,
            &format!("dx: learned set distance ({})", self.distance_unit),
            "dy: distance in the embedding",
        )?;
        let color = series_color(0);
        chart
            .draw_series(
                rows.iter()
                    .map(|&i| Circle::new((dx[i], dy[i]), 1, color.mix(0.3).filled())),
            )?
            .label("pair of sets")
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
        let red = series_color(3);
        chart
            .draw_series(LineSeries::new(
                [(0.0, 0.0), (hi * 1.05, hi * 1.05)],
                red.stroke_width(2),
            ))?
            .label("dy = dx")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2)));
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}

// ---------------------------------------------------------------------------------
// Invariance

/// Set distances and sensor distances in two environments.
pub(super) struct Invariance {
    /// `(d in environment 1, d in environment 2)` for the drawn pairs of sets.
    pub(super) set_pairs: Vec<(f64, f64)>,
    /// The same for sensor distances.
    pub(super) sensor_pairs: Vec<(f64, f64)>,
    pub(super) mantel: f64,
    pub(super) sensor_mantel: f64,
    pub(super) environments: (usize, usize),
    pub(super) distance_unit: &'static str,
    pub(super) panel: (u32, u32),
}

impl Figure for Invariance {
    fn size(&self) -> (u32, u32) {
        (2 * self.panel.0, self.panel.1)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let panels = root.split_evenly((1, 2));
        let (a, b) = (self.environments.0 + 1, self.environments.1 + 1);
        let specs = [
            (
                &self.set_pairs,
                self.mantel,
                "learned set distances (Hausdorff)".to_owned(),
                format!("({})", self.distance_unit),
                series_color(0),
            ),
            (
                &self.sensor_pairs,
                self.sensor_mantel,
                "raw sensor distances".to_owned(),
                "(arbitrary units)".to_owned(),
                series_color(1),
            ),
        ];
        for (panel, (pairs, mantel, what, unit, color)) in panels.iter().zip(specs) {
            let hi = finite_extent(pairs.iter().flat_map(|p| [p.0, p.1]))
                .map_or(1.0, |(_, hi)| hi)
                .max(1e-12);
            let range = 0.0..hi * 1.05;
            let mut chart = chart_2d(
                panel,
                &format!("{what}: environment {a} vs {b}"),
                range.clone(),
                range,
                &format!("distance in environment {a} {unit}"),
                &format!("distance in environment {b} {unit}"),
            )?;
            chart
                .draw_series(
                    pairs
                        .iter()
                        .map(|&p| Circle::new(p, 2, color.mix(0.35).filled())),
                )?
                .label(format!("pair of rows (Mantel r = {mantel:.4})"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
            let grey = BLACK.mix(0.6);
            chart
                .draw_series(LineSeries::new(
                    [(0.0, 0.0), (hi * 1.05, hi * 1.05)],
                    grey.stroke_width(1),
                ))?
                .label("same distance in both")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));
            legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// CCA stress

/// CCA stress per epoch.
pub(super) struct StressTrace<'a> {
    pub(super) stress: &'a [f64],
    pub(super) size: (u32, u32),
}

impl Figure for StressTrace<'_> {
    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let n = self.stress.len();
        let x = 0.5..n as f64 + 0.5;
        let y = {
            let r = padded(self.stress.iter().copied());
            r.start.min(0.0)..r.end
        };
        let mut chart = chart_2d(
            root,
            &format!("CCA stress per epoch ({n} epochs)"),
            x,
            y,
            "epoch",
            "stress (weighted squared distance errors)",
        )?;
        let color = series_color(0);
        let points = self
            .stress
            .iter()
            .enumerate()
            .map(|(k, &s)| ((k + 1) as f64, s));
        chart
            .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
            .label("stress")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        if n <= 200 {
            chart.draw_series(points.map(|p| Circle::new(p, 3, color.filled())))?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_segments_split_at_the_seam_and_close_loops() {
        let pts = [[3.0, 0.0], [3.1, 0.0], [-3.1, 0.0], [-3.0, 0.0]];
        let segs = wrap_segments(&pts, true, false);
        assert_eq!(segs.len(), 2);
        let segs = wrap_segments(&pts, false, false);
        assert_eq!(segs.len(), 1);
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let segs = wrap_segments(&square, true, true);
        assert_eq!(segs[0].len(), 5);
    }

    #[test]
    fn probe_surface_edges_connect_grid_neighbours() {
        let mut cells = BTreeMap::new();
        cells.insert((0, 0), 0);
        cells.insert((1, 0), 1);
        cells.insert((0, 1), 2);
        cells.insert((1, 1), 3);
        let s = ProbeSurface { alpha: 0.0, cells };
        let mut e = s.edges();
        e.sort_unstable();
        assert_eq!(e, vec![(0, 1), (0, 2), (1, 3), (2, 3)]);
    }
}
