//! The arm's figures of the paper's section 3.3: Fig. 5a (explored configurations)
//! and Fig. 5b (kernel sets in motor space).

use std::ops::Range;

use ndarray::{ArrayView3, Axis};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::HPos;

use super::super::plot::{
    chart_2d, equal_aspect, label, lighten, padded, Axis2d, Chart2d, Dash, Drawn, Figure, Legend,
    Mark, Valign, DISTINCT,
};
use super::super::view3d::{draw_box, draw_scene, BoxAxis, Camera, Item, Projection};
use super::{motor_range, periods, wrap_curve, Panel};
use smspace::agent::{Environment, MotorSpace};
use smspace::explore::Workspace;

const ARM: RGBColor = RGBColor(31, 119, 180);
const SENSOR: RGBColor = RGBColor(214, 39, 40);
const WORKSPACE: RGBColor = RGBColor(44, 160, 44);
const LIGHT: RGBColor = RGBColor(255, 200, 0);

/// Fig. 5a: a sample of explored configurations of the arm.
pub(in crate::report) struct Configurations {
    /// Joint positions of each drawn configuration, base first.
    pub(in crate::report) skeletons: Vec<Vec<[f64; 2]>>,
    /// Sensor orientation of each.
    pub(in crate::report) alphas: Vec<f64>,
    pub(in crate::report) workspace: Option<Workspace>,
    pub(in crate::report) environment: Option<Environment>,
    pub(in crate::report) explored: usize,
    pub(in crate::report) panel: Panel,
}

impl Figure for Configurations {
    fn size(&self) -> (u32, u32) {
        self.panel.tall(1.3)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let legend = self.legend();
        let (plot, strip) = legend.split(root, print);
        let reach = self.reach();
        let tick = 0.3 * reach.max(1e-3);
        let (w, h) = plot.dim_in_pixel();
        let (x, y) = self.ranges(
            tick,
            w.saturating_sub(print.i(60.0) as u32),
            h.saturating_sub(print.i(50.0) as u32),
        );
        let title = format!(
            "Fig. 5a: {} of {} explored arms",
            self.skeletons.len(),
            self.explored
        );
        let mut chart = chart_2d(
            &plot,
            print,
            &title,
            Axis2d::new(x, "x (m)"),
            Axis2d::new(y, "y (m)"),
        )?;
        if let Some(w) = self.workspace {
            draw_workspace(&mut chart, w, self.panel)?;
        }
        self.draw_arms(&mut chart)?;
        self.draw_sensor_ticks(&mut chart, tick)?;
        let base = 0.04 * reach;
        chart.draw_series(std::iter::once(Rectangle::new(
            [(-base, -base), (base, base)],
            BLACK.filled(),
        )))?;
        if let Some(env) = &self.environment {
            draw_lights(&mut chart, env, self.panel)?;
        }
        legend.draw(&strip, print)
    }
}

impl Configurations {
    /// The legend: every kind of mark the figure draws.
    fn legend(&self) -> Legend {
        let mut legend = Legend::new();
        legend.add(Mark::Line(ARM, 1.0, Dash::Solid), "arm (joints as dots)");
        legend.add(
            Mark::Line(SENSOR, 1.0, Dash::Solid),
            "sensor orientation alpha",
        );
        legend.add(Mark::Square(BLACK), "base");
        if self.workspace.is_some() {
            legend.add(
                Mark::Patch(lighten(WORKSPACE, 0.88), WORKSPACE),
                "working space",
            );
        }
        if self.environment.is_some() {
            legend.add(Mark::Dot(LIGHT, 2.5), "lights (environment 1)");
        }
        legend
    }

    /// The longest link of any drawn arm: the scale of the sensor ticks and the base.
    fn reach(&self) -> f64 {
        self.skeletons
            .iter()
            .flat_map(|s| s.windows(2).map(|w| dist(w[0], w[1])))
            .fold(0.0, f64::max)
    }

    /// The axis ranges, with equal aspect in a plot of `width × height` pixels: every
    /// joint, the end of every sensor tick (of length `tick`), the working space and
    /// the lights, padded.
    fn ranges(&self, tick: f64, width: u32, height: u32) -> (Range<f64>, Range<f64>) {
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
        equal_aspect(
            padded(xs.iter().copied()),
            padded(ys.iter().copied()),
            width,
            height,
        )
    }

    /// Every arm as a polyline from its base, with a dot on each joint after the base.
    fn draw_arms<DB: DrawingBackend>(&self, chart: &mut Chart2d<'_, DB>) -> Drawn {
        let print = self.panel.print;
        for s in &self.skeletons {
            chart.draw_series(LineSeries::new(
                s.iter().map(|p| (p[0], p[1])),
                ARM.mix(0.55).stroke_width(print.stroke(0.8)),
            ))?;
            chart.draw_series(
                s.iter()
                    .skip(1)
                    .map(|p| Circle::new((p[0], p[1]), print.i(1.0), ARM.filled())),
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
        let print = self.panel.print;
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
                        SENSOR.stroke_width(print.stroke(1.0)),
                    )
                })
            });
        chart.draw_series(ticks)?;
        Ok(())
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The working space: a faint green rectangle with a dashed border.
fn draw_workspace<DB: DrawingBackend>(
    chart: &mut Chart2d<'_, DB>,
    w: Workspace,
    panel: Panel,
) -> Drawn {
    let (x0, x1) = (w.center[0] - w.size[0] / 2.0, w.center[0] + w.size[0] / 2.0);
    let (y0, y1) = (w.center[1] - w.size[1] / 2.0, w.center[1] + w.size[1] / 2.0);
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x0, y0), (x1, y1)],
        WORKSPACE.mix(0.12).filled(),
    )))?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x0, y0), (x1, y1)],
        WORKSPACE.stroke_width(panel.print.stroke(0.8)),
    )))?;
    Ok(())
}

/// The lights of `env`, gold discs ringed in black.
fn draw_lights<DB: DrawingBackend>(
    chart: &mut Chart2d<'_, DB>,
    env: &Environment,
    panel: Panel,
) -> Drawn {
    let r = panel.print.i(2.5);
    chart.draw_series(
        env.lights
            .iter()
            .map(|l| Circle::new((l[0], l[1]), r, LIGHT.filled())),
    )?;
    chart.draw_series(
        env.lights
            .iter()
            .map(|l| Circle::new((l[0], l[1]), r, BLACK.stroke_width(1))),
    )?;
    Ok(())
}

/// Most kernel sets Fig. 5b draws: one distinct colour each.
pub(in crate::report) const MAX_LOOPS: usize = DISTINCT.len();

/// Fig. 5b: kernel sets in motor space, two 3-D projections of the motor torus.
pub(in crate::report) struct KernelSets3d<'a> {
    pub(in crate::report) sets: ArrayView3<'a, f64>,
    /// The drawn sets, at most [`MAX_LOOPS`].
    pub(in crate::report) sample: Vec<usize>,
    pub(in crate::report) space: MotorSpace,
    pub(in crate::report) motor_unit: &'static str,
    pub(in crate::report) panel: Panel,
}

impl Figure for KernelSets3d<'_> {
    fn size(&self) -> (u32, u32) {
        let (w, h) = self.panel.grid(2, 1);
        (w, (f64::from(h) * 1.25).round() as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let n = self.sets.len_of(Axis(2));
        let views: [[usize; 3]; 2] = if n >= 4 {
            [[0, 1, 2], [1, 2, 3]]
        } else {
            [[0, 1, 2], [0, 1, 2]]
        };
        let mut legend = Legend::new();
        legend.add(
            Mark::Line(DISTINCT[0], 1.2, Dash::Solid),
            format!(
                "{} kernel sets, one colour each (the same in both views)",
                self.sample.len()
            ),
        );
        if self.space.is_hinges() {
            legend.add(
                Mark::Ring(RGBColor(60, 60, 60), 2.0),
                "where a set leaves a face of the cube [\u{2212}\u{3c0}, \u{3c0}]\u{b3} and re-enters at the opposite face",
            );
        } else if views
            .iter()
            .flatten()
            .any(|&a| self.space.motor(a).is_periodic())
        {
            legend.add(
                Mark::Ring(RGBColor(60, 60, 60), 2.0),
                "where a set leaves a face of a periodic motor and re-enters at the opposite face",
            );
        }
        let (body, strip) = legend.split(root, print);
        let panels = body.split_evenly((1, 2));
        for (k, (panel, axes)) in panels.iter().zip(views).enumerate() {
            let azimuth = if n >= 4 || k == 0 { -0.9 } else { 0.7 };
            self.draw_view(panel, axes, azimuth)?;
        }
        legend.draw(&strip, print)
    }
}

impl KernelSets3d<'_> {
    /// One view: the motors `axes` of the sampled sets in their box, seen from `azimuth`.
    fn draw_view<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        axes: [usize; 3],
        azimuth: f64,
    ) -> Drawn {
        let print = self.panel.print;
        let names = axes.map(|a| format!("m{}", a + 1));
        let title = format!("motors {}, {}, {}", names[0], names[1], names[2]);
        label(
            area,
            &title,
            (area.dim_in_pixel().0 as i32 / 2, print.i(4.0)),
            &print.title(),
            HPos::Center,
            Valign::Top,
        )?;
        let ranges: [Range<f64>; 3] = axes.map(|a| {
            motor_range(
                self.space.motor(a),
                self.sample
                    .iter()
                    .flat_map(|&i| self.sets.index_axis(Axis(0), i).column(a).to_vec()),
            )
        });
        let corners: Vec<[f64; 3]> = (0..8)
            .map(|c| {
                std::array::from_fn(|k| {
                    if c >> k & 1 == 1 {
                        ranges[k].end
                    } else {
                        ranges[k].start
                    }
                })
            })
            .collect();
        let (w, h) = area.dim_in_pixel();
        let margin = print.i(40.0);
        let rect = (
            margin,
            print.i(22.0) + margin / 2,
            w as i32 - margin,
            h as i32 - margin,
        );
        let projection = Projection::fit(Camera::new(azimuth, 0.45), &corners, rect);
        let box_axes: [BoxAxis; 3] = std::array::from_fn(|j| {
            let title = format!("m{} ({})", axes[j] + 1, self.motor_unit);
            let motor = self.space.motor(axes[j]);
            let hinge = motor
                .period()
                .is_some_and(|t| (t - std::f64::consts::TAU).abs() < 1e-12)
                && (ranges[j].start + std::f64::consts::PI).abs() < 1e-9;
            if hinge {
                BoxAxis::angles(title)
            } else {
                BoxAxis::numbered(title, &ranges[j])
            }
        });
        draw_box(area, &projection, &ranges, &box_axes, print)?;
        let mut items = Vec::new();
        let periods = periods(&self.space, axes);
        let closed = !self.space.has_bounds();
        for (k, &i) in self.sample.iter().enumerate() {
            let color = DISTINCT[k % DISTINCT.len()].to_rgba();
            let set = self.sets.index_axis(Axis(0), i);
            let pts: Vec<[f64; 3]> = set
                .rows()
                .into_iter()
                .map(|r| [r[axes[0]], r[axes[1]], r[axes[2]]])
                .collect();
            let curve = wrap_curve(&pts, periods, closed);
            for piece in &curve.pieces {
                for w in piece.windows(2) {
                    items.push(Item::Line(w[0], w[1], print.stroke(1.2), color));
                }
            }
            for &c in &curve.crossings {
                items.push(Item::Ring(c, print.i(2.0), print.stroke(0.8), color));
            }
        }
        draw_scene(area, &projection, &items)
    }
}
