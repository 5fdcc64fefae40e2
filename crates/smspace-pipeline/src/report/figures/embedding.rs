//! The learned manifold seen from outside (paper section 3.3): Fig. 5d, the embedding
//! with one probe sheet per orientation, and the embedding coloured by each pose
//! coordinate with a measure of how well each is recovered.
//!
//! **Views.** The paper's claim is that the sheets (translations of the sensor at one
//! orientation) stack around a circle, the circle of orientations. The views are
//! therefore taken in the frame of that ring ([`Frame::ring`]): its axis is the normal
//! of the plane through the sheets' centres. Fig. 5d's main view looks along that
//! axis, so that the ring faces the reader; a smaller oblique view (35° above the
//! ring's plane) shows the sheets' extent along the axis. Each panel of the embedding
//! coloured by a pose coordinate is seen from the view in which that coordinate
//! shows: of the view along the axis, two side views and the oblique one, the one
//! whose screen best predicts the coordinate from a point's nearest neighbours on
//! screen (the recovery `R²` below, on the 2-D projection). On the paper's arm that
//! is the view along the axis for alpha (the colour wheel round the ring) and a side
//! view for x (which runs along the axis).
//!
//! **Recovery.** How well the embedding `Y` encodes pose coordinate `c` is measured by
//! the share of its variance that a point's `k` nearest neighbours in `Y` predict
//! (`k = M/50`, between 3 and 10):
//! `R²_c = 1 − Σ_i Δ(c_i, ĉ_i)² / Σ_i s²`, with `ĉ_i` the (circular, for alpha) mean of
//! `c` over the neighbours, `Δ` the difference (wrapped into `[−π, π)` for alpha) and
//! `s² = mean_{i<j} Δ(c_i, c_j)² / 2` (the variance for a linear coordinate). `R² = 1`
//! when neighbours in the embedding share the coordinate, `0` when they say nothing of
//! it.

use ndarray::{Array2, ArrayView1, ArrayView2};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::HPos;
use rayon::prelude::*;

use super::super::plot::{
    chart_2d, color_bar, hue, label, padded, series_color, stride_sample, with_color_bar, Axis2d,
    ColorScale, Drawn, Figure, Legend, Mark, Print, TickStyle, Valign, GREY,
};
use super::super::view3d::{draw_box, draw_scene, BoxAxis, Camera, Frame, Item, Projection, V3};
use super::{point3, Panel, ProbeSurface, MAX_SCATTER_POINTS};
use smspace::agent::wrap_angle;

/// Neighbours of the recovery measure: `M / 50` sets, between 3 and 10 (a fixed 10
/// would average over a large part of a small run and understate the recovery).
pub(in crate::report) const RECOVERY_NEIGHBOURS: usize = 10;

/// Most points the recovery measure queries (evenly spaced rows beyond that).
const RECOVERY_QUERIES: usize = 4000;

/// How well the embedding recovers one pose coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(in crate::report) struct Recovery {
    /// The pose column (0 = x, 1 = y, 2 = alpha).
    pub(in crate::report) coordinate: usize,
    /// `R²` of the neighbours' prediction (module documentation).
    pub(in crate::report) r2: f64,
    /// The analysis' Spearman correlation of the learned distance with `|Δc|`.
    pub(in crate::report) spearman: Option<f64>,
    /// Neighbours of the prediction.
    pub(in crate::report) neighbours: usize,
}

/// The recovery of each pose column of `coordinates` by `embedding` (rows of
/// `set_poses`), with the analysis' Spearman correlation `spearman(c)` when known.
pub(in crate::report) fn recovery(
    embedding: ArrayView2<'_, f64>,
    set_poses: &Array2<f64>,
    coordinates: &[usize],
    spearman: impl Fn(usize) -> Option<f64>,
) -> Vec<Recovery> {
    let m = embedding.nrows();
    let k = recovery_neighbours(m);
    if k == 0 {
        return Vec::new();
    }
    let queries = stride_sample(m, RECOVERY_QUERIES);
    let near = neighbourhoods(embedding, &queries, k);
    // One coordinate per thread: each sums in the same order for any thread count.
    let scores: Vec<f64> = coordinates
        .par_iter()
        .map(|&c| {
            let v = set_poses.column(c);
            let variance = spread(&queries, v, c);
            r2(residual(&queries, &near, v, c), variance, queries.len())
        })
        .collect();
    coordinates
        .iter()
        .zip(scores)
        .map(|(&c, r2)| Recovery {
            coordinate: c,
            r2,
            spearman: spearman(c),
            neighbours: k,
        })
        .collect()
}

/// Neighbours of the recovery measure among `m` points: `m / 50`, between 3 and
/// [`RECOVERY_NEIGHBOURS`], at most `m − 1` (0: nothing to measure).
fn recovery_neighbours(m: usize) -> usize {
    (m / 50)
        .clamp(3, RECOVERY_NEIGHBOURS)
        .min(m.saturating_sub(1))
}

/// The `k` nearest rows of `embedding` to each row of `queries` ([`nearest`]), the
/// queries shared among the threads (each list is the same for any thread count).
fn neighbourhoods(embedding: ArrayView2<'_, f64>, queries: &[usize], k: usize) -> Vec<Vec<usize>> {
    let rows = embedding.as_standard_layout();
    let points = Points {
        coordinates: rows.as_slice().unwrap_or_default(),
        dim: embedding.ncols(),
        len: embedding.nrows(),
    };
    queries
        .par_iter()
        .map_init(Vec::new, |scratch, &i| nearest(&points, i, k, scratch))
        .collect()
}

/// Points of `dim` coordinates, one after the other.
struct Points<'a> {
    coordinates: &'a [f64],
    dim: usize,
    len: usize,
}

impl Points<'_> {
    fn row(&self, j: usize) -> &[f64] {
        &self.coordinates[j * self.dim..(j + 1) * self.dim]
    }
}
/// The difference of two values of pose column `c`: wrapped into `[−π, π)` for alpha
/// (column 2).
fn delta(c: usize, a: f64, b: f64) -> f64 {
    if c == 2 {
        wrap_angle(a - b)
    } else {
        a - b
    }
}

/// `Σ_i Δ(c_i, ĉ_i)²` over the queries, `ĉ_i` the (circular, for alpha) mean of the
/// values `v` of column `c` over the neighbours `near` of query `i`.
fn residual(queries: &[usize], near: &[Vec<usize>], v: ArrayView1<'_, f64>, c: usize) -> f64 {
    let mut residual = 0.0;
    for (&i, near) in queries.iter().zip(near) {
        let predicted = if c == 2 {
            let (s, co) = near
                .iter()
                .fold((0.0, 0.0), |(s, co), &j| (s + v[j].sin(), co + v[j].cos()));
            s.atan2(co)
        } else {
            near.iter().map(|&j| v[j]).sum::<f64>() / near.len() as f64
        };
        residual += delta(c, v[i], predicted).powi(2);
    }
    residual
}

/// `s² = mean_{i<j} Δ(c_i, c_j)² / 2` over the queries: the variance of column `c`
/// (its circular counterpart for alpha).
fn spread(queries: &[usize], v: ArrayView1<'_, f64>, c: usize) -> f64 {
    let mut spread = 0.0;
    let mut pairs = 0.0_f64;
    for (a, &i) in queries.iter().enumerate() {
        for &j in &queries[a + 1..] {
            spread += 0.5 * delta(c, v[i], v[j]).powi(2);
            pairs += 1.0;
        }
    }
    spread / pairs.max(1.0)
}

/// `R² = 1 − residual / queries / variance` (NaN for a constant coordinate).
fn r2(residual: f64, variance: f64, queries: usize) -> f64 {
    if variance > 0.0 {
        1.0 - residual / queries as f64 / variance
    } else {
        f64::NAN
    }
}

/// The `k` rows of `points` nearest to row `i` (Euclidean), ties by index; `scratch`
/// holds the distances to every row.
fn nearest(points: &Points<'_>, i: usize, k: usize, scratch: &mut Vec<(f64, usize)>) -> Vec<usize> {
    let row = points.row(i);
    scratch.clear();
    scratch.extend((0..points.len).filter(|&j| j != i).map(|j| {
        let s: f64 = points
            .row(j)
            .iter()
            .zip(row)
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        (s, j)
    }));
    let k = k.min(scratch.len());
    scratch.select_nth_unstable_by(k.saturating_sub(1), |a, b| {
        a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
    });
    // A fresh list of `k`: the report keeps one per query.
    scratch[..k].iter().map(|&(_, j)| j).collect()
}

/// The ring frame of the embedding ([`Frame::ring`]) from its first three coordinates
/// and the centres of the probe sheets: the frame of Fig. 5d, of `embedding-pose` and
/// of the interactive view (whose camera looks down its third axis, the ring's axis).
pub(in crate::report) fn ring_frame(
    embedding: ArrayView2<'_, f64>,
    surfaces: &[ProbeSurface],
) -> Frame {
    let rows = stride_sample(embedding.nrows(), MAX_SCATTER_POINTS);
    let points: Vec<V3> = rows.iter().map(|&i| point3(embedding, i)).collect();
    let centres: Vec<(V3, f64)> = surfaces
        .iter()
        .map(|s| (s.centre(embedding), s.alpha))
        .collect();
    Frame::ring(&points, &centres).0
}

/// The two ring views of Fig. 5d, `(title, camera)`: the main one along the ring's
/// axis (the ring faces the viewer), and a smaller oblique one.
fn ring_views() -> [(&'static str, Camera); 2] {
    [
        ("along the ring's axis", Camera::from_above()),
        ("oblique view", Camera::new(-1.0, 0.6)),
    ]
}

/// The views a panel of the embedding coloured by a pose coordinate chooses from, in
/// the ring frame: along the ring's axis, from the side (looking along `u`, along
/// `v`), and obliquely.
fn candidate_views() -> [Camera; 4] {
    [
        Camera::from_above(),
        Camera::new(0.0, 0.0),
        Camera::new(std::f64::consts::FRAC_PI_2, 0.0),
        Camera::new(-1.0, 0.6),
    ]
}

/// Most points the choice of a view scores (evenly spaced rows beyond that).
const VIEW_CHOICE_POINTS: usize = 1500;

/// The 3-D views of the panels of [`EmbeddingPose`]: the ring frame and, for each
/// coordinate drawn, the camera in which it shows. Chosen once per figure
/// ([`PoseViews::choose`]) and read by every drawing of it: the PNG, the SVG and the
/// layout check.
#[derive(Debug, Clone, PartialEq)]
pub(in crate::report) struct PoseViews {
    frame: Frame,
    /// One camera per coordinate of the figure, in its order.
    cameras: Vec<Camera>,
}

impl PoseViews {
    /// For each pose column of `coordinates`, the view in which it shows: of
    /// [`candidate_views`], the one whose screen (the 2-D projection of the drawn
    /// points in `frame`) predicts the column best from a point's nearest neighbours
    /// on screen (the recovery `R²` of the module docs, on the projection); ties, and
    /// a coordinate that predicts nothing anywhere, go to the first (along the ring's
    /// axis). Each view's neighbours are found once and score every coordinate.
    pub(in crate::report) fn choose(
        embedding: ArrayView2<'_, f64>,
        frame: Frame,
        set_poses: &Array2<f64>,
        coordinates: &[usize],
    ) -> Self {
        let rows = stride_sample(embedding.nrows(), MAX_SCATTER_POINTS);
        let sample = stride_sample(rows.len(), VIEW_CHOICE_POINTS);
        let points: Vec<V3> = sample
            .iter()
            .map(|&s| frame.coords(point3(embedding, rows[s])))
            .collect();
        let poses = Array2::from_shape_fn((sample.len(), set_poses.ncols()), |(i, k)| {
            set_poses[[rows[sample[i]], k]]
        });
        let views = candidate_views();
        let k = recovery_neighbours(sample.len());
        if k == 0 {
            let cameras = vec![views[0]; coordinates.len()];
            return Self { frame, cameras };
        }
        let queries = stride_sample(sample.len(), RECOVERY_QUERIES);
        // The spread of a coordinate does not depend on the view.
        let spreads: Vec<f64> = coordinates
            .par_iter()
            .map(|&c| spread(&queries, poses.column(c), c))
            .collect();
        let scores: Vec<Vec<f64>> = views
            .iter()
            .map(|camera| {
                let screen =
                    Array2::from_shape_fn((points.len(), 2), |(i, j)| camera.screen(points[i])[j]);
                let near = neighbourhoods(screen.view(), &queries, k);
                coordinates
                    .iter()
                    .zip(&spreads)
                    .map(|(&c, &variance)| {
                        let v = poses.column(c);
                        r2(residual(&queries, &near, v, c), variance, queries.len())
                    })
                    .collect()
            })
            .collect();
        let cameras = (0..coordinates.len())
            .map(|n| {
                let mut best = (f64::NEG_INFINITY, 0);
                for (view, score) in scores.iter().enumerate() {
                    if score[n] > best.0 + 1e-9 {
                        best = (score[n], view);
                    }
                }
                views[best.1]
            })
            .collect();
        Self { frame, cameras }
    }
}

/// A view's title, centred at the top of `area`.
fn view_title<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    print: Print,
    title: &str,
) -> Drawn {
    label(
        area,
        title,
        (area.dim_in_pixel().0 as i32 / 2, print.i(4.0)),
        &print.title(),
        HPos::Center,
        Valign::Top,
    )
}

/// The projection of `points` into `area` below its title, with room for the box's
/// labels.
fn fit(area_size: (u32, u32), print: Print, camera: Camera, points: &[V3]) -> Projection {
    let (w, h) = area_size;
    let margin = print.i(24.0);
    Projection::fit(
        camera,
        points,
        (
            margin,
            print.i(20.0) + margin / 2,
            w as i32 - margin,
            h as i32 - margin,
        ),
    )
}

/// The corners of the box around `points`.
fn bounds(points: &[V3]) -> [std::ops::Range<f64>; 3] {
    std::array::from_fn(|k| padded(points.iter().map(|p| p[k])))
}

/// The corners of a box.
fn corners(ranges: &[std::ops::Range<f64>; 3]) -> Vec<V3> {
    (0..8)
        .map(|c: usize| {
            std::array::from_fn(|k| {
                if c >> k & 1 == 1 {
                    ranges[k].end
                } else {
                    ranges[k].start
                }
            })
        })
        .collect()
}

/// The titles of the ring frame's axes.
fn ring_axes() -> [BoxAxis; 3] {
    [
        BoxAxis::titled("u"),
        BoxAxis::titled("v"),
        BoxAxis::titled("w: ring axis"),
    ]
}

/// Fig. 5d: the embedding with the probe sheets, coloured by orientation.
pub(in crate::report) struct EmbeddingProbes<'a> {
    pub(in crate::report) embedding: ArrayView2<'a, f64>,
    pub(in crate::report) surfaces: &'a [ProbeSurface],
    /// The ring frame ([`ring_frame`]) of a 3-D embedding; `None` draws the plane
    /// `(q1, q2)`.
    pub(in crate::report) frame: Option<Frame>,
    pub(in crate::report) panel: Panel,
}

impl Figure for EmbeddingProbes<'_> {
    fn size(&self) -> (u32, u32) {
        let (w, h) = self.panel.grid(2, 1);
        let columns = if self.embedding.ncols() >= 3 {
            1.0
        } else {
            0.6
        };
        (
            (f64::from(w) * columns).round() as u32,
            (f64::from(h) * 1.35).round() as u32,
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let mut legend = Legend::new();
        legend.add(Mark::Dot(GREY, 1.5), "kernel sets");
        legend.add(
            Mark::Patch(hue(0.1), hue(0.1)),
            "probe sheet (sensor positions at one orientation), coloured by its alpha",
        );
        let (body, strip) = legend.split(root, print);
        let (plot, bar) = with_color_bar(&body, print);
        if let Some(frame) = &self.frame {
            let rows = stride_sample(self.embedding.nrows(), MAX_SCATTER_POINTS);
            let points: Vec<V3> = rows
                .iter()
                .map(|&i| frame.coords(point3(self.embedding, i)))
                .collect();
            let items = self.scene(frame, &points);
            let ranges = bounds(&points);
            let main_width = (f64::from(plot.dim_in_pixel().0) * 0.6).round() as u32;
            let (main, side) = plot.split_horizontally(main_width);
            for (area, (title, camera)) in [main, side].iter().zip(ring_views()) {
                view_title(area, print, title)?;
                let projection = fit(area.dim_in_pixel(), print, camera, &corners(&ranges));
                draw_box(area, &projection, &ranges, &ring_axes(), print)?;
                draw_scene(area, &projection, &items)?;
            }
        } else {
            self.draw_plane(&plot)?;
        }
        color_bar(&bar, print, ColorScale::Circular, "alpha (rad)")?;
        legend.draw(&strip, print)
    }
}

impl EmbeddingProbes<'_> {
    /// The grey sets and the sheets' squares, in the ring frame.
    fn scene(&self, frame: &Frame, points: &[V3]) -> Vec<Item> {
        let print = self.panel.print;
        let grey = GREY.mix(0.55);
        let mut items: Vec<Item> = points
            .iter()
            .map(|&p| Item::Point(p, print.i(0.7), grey))
            .collect();
        for s in self.surfaces {
            let color = ColorScale::Circular.color(s.alpha);
            let edge = RGBColor(color.0 / 2, color.1 / 2, color.2 / 2).to_rgba();
            for quad in s.quads() {
                let corners = quad
                    .iter()
                    .map(|&i| frame.coords(point3(self.embedding, i)))
                    .collect();
                items.push(Item::Polygon(
                    corners,
                    color.mix(0.85),
                    edge,
                    print.stroke(0.3),
                ));
            }
        }
        items
    }

    /// A 2-D embedding: the sets and the sheets in the plane `(q1, q2)`.
    fn draw_plane<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let e = &self.embedding;
        let rows = stride_sample(e.nrows(), MAX_SCATTER_POINTS);
        let title = format!(
            "Fig. 5d: {} sets, {} sheets",
            e.nrows(),
            self.surfaces.len()
        );
        let mut chart = chart_2d(
            area,
            print,
            &title,
            Axis2d::new(padded(e.column(0).iter().copied()), "embedding q1"),
            Axis2d::new(padded(e.column(1).iter().copied()), "embedding q2"),
        )?;
        chart.draw_series(
            rows.iter().map(|&i| {
                Circle::new((e[[i, 0]], e[[i, 1]]), print.i(0.7), GREY.mix(0.6).filled())
            }),
        )?;
        for s in self.surfaces {
            let color = ColorScale::Circular.color(s.alpha);
            chart.draw_series(s.quads().into_iter().map(|quad| {
                Polygon::new(
                    quad.iter()
                        .map(|&i| (e[[i, 0]], e[[i, 1]]))
                        .collect::<Vec<_>>(),
                    color.mix(0.8).filled(),
                )
            }))?;
        }
        Ok(())
    }
}

/// The embedding coloured by each non-constant pose coordinate, one panel each, and a
/// panel of how well each is recovered.
pub(in crate::report) struct EmbeddingPose<'a> {
    pub(in crate::report) embedding: ArrayView2<'a, f64>,
    pub(in crate::report) set_poses: &'a Array2<f64>,
    /// The pose columns drawn (0 = x, 1 = y, 2 = alpha).
    pub(in crate::report) coordinates: Vec<usize>,
    pub(in crate::report) recovery: Vec<Recovery>,
    /// The views of a 3-D embedding's panels; `None` draws them in the plane
    /// `(q1, q2)` (or against the coordinate, for a 1-D embedding).
    pub(in crate::report) views: Option<PoseViews>,
    pub(in crate::report) panel: Panel,
}

impl EmbeddingPose<'_> {
    fn panels(&self) -> u32 {
        self.coordinates.len() as u32 + u32::from(!self.recovery.is_empty())
    }

    fn columns(&self) -> u32 {
        self.panels().clamp(1, 2)
    }
}

impl Figure for EmbeddingPose<'_> {
    fn size(&self) -> (u32, u32) {
        let rows = self.panels().div_ceil(self.columns());
        self.panel.grid(self.columns(), rows)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn {
        let rows = self.panels().div_ceil(self.columns());
        let areas = root.split_evenly((rows as usize, self.columns() as usize));
        for (n, (area, &c)) in areas.iter().zip(&self.coordinates).enumerate() {
            let view = self
                .views
                .as_ref()
                .map(|views| (&views.frame, views.cameras[n]));
            self.draw_coordinate(area, c, view)?;
        }
        if let Some(area) = areas.get(self.coordinates.len()) {
            if !self.recovery.is_empty() {
                self.draw_recovery(area)?;
            }
        }
        Ok(())
    }
}

impl EmbeddingPose<'_> {
    /// One panel: the embedding coloured by pose column `c`, in 3-D from `view` (the
    /// ring frame and the panel's camera) when given.
    fn draw_coordinate<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        c: usize,
        view: Option<(&Frame, Camera)>,
    ) -> Drawn {
        let print = self.panel.print;
        let e = &self.embedding;
        let rows = stride_sample(e.nrows(), MAX_SCATTER_POINTS);
        let values = self.set_poses.column(c);
        let scale = if c == 2 {
            ColorScale::Circular
        } else {
            ColorScale::linear(values.iter().copied())
        };
        let name = super::coordinate_name(c);
        let r2 = self
            .recovery
            .iter()
            .find(|r| r.coordinate == c)
            .map(|r| format!(" (R\u{b2} = {:.2})", r.r2))
            .unwrap_or_default();
        let title = format!("coloured by {name}{r2}");
        let radius = print.i(if rows.len() > 2000 { 0.8 } else { 1.3 });
        if e.ncols() == 1 {
            let mut chart = chart_2d(
                area,
                print,
                &title,
                Axis2d::new(padded(values.iter().copied()), super::coordinate_label(c)),
                Axis2d::new(padded(e.column(0).iter().copied()), "embedding q1"),
            )?;
            chart.draw_series(rows.iter().map(|&i| {
                Circle::new(
                    (values[i], e[[i, 0]]),
                    radius,
                    scale.color(values[i]).filled(),
                )
            }))?;
            return Ok(());
        }
        let (plot, bar) = with_color_bar(area, print);
        if let Some((frame, camera)) = view {
            let points: Vec<V3> = rows.iter().map(|&i| frame.coords(point3(*e, i))).collect();
            view_title(&plot, print, &title)?;
            let ranges = bounds(&points);
            let projection = fit(plot.dim_in_pixel(), print, camera, &corners(&ranges));
            draw_box(&plot, &projection, &ranges, &ring_axes(), print)?;
            let items: Vec<Item> = rows
                .iter()
                .zip(&points)
                .map(|(&i, &p)| Item::Point(p, radius, scale.color(values[i]).to_rgba()))
                .collect();
            draw_scene(&plot, &projection, &items)?;
        } else {
            let mut chart = chart_2d(
                &plot,
                print,
                &title,
                Axis2d::new(padded(e.column(0).iter().copied()), "embedding q1"),
                Axis2d::new(padded(e.column(1).iter().copied()), "embedding q2"),
            )?;
            chart.draw_series(rows.iter().map(|&i| {
                Circle::new(
                    (e[[i, 0]], e[[i, 1]]),
                    radius,
                    scale.color(values[i]).filled(),
                )
            }))?;
        }
        color_bar(&bar, print, scale, super::coordinate_label(c))
    }

    /// The recovery panel: per coordinate, `R²` of the neighbours' prediction and the
    /// analysis' Spearman correlation.
    fn draw_recovery<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Drawn {
        let print = self.panel.print;
        let mut legend = Legend::new();
        legend.add(
            Mark::Square(series_color(0)),
            format!(
                "R\u{b2}: predicted by the {} nearest sets",
                self.recovery
                    .first()
                    .map_or(RECOVERY_NEIGHBOURS, |r| r.neighbours)
            ),
        );
        let with_spearman = self.recovery.iter().any(|r| r.spearman.is_some());
        if with_spearman {
            legend.add(
                Mark::Square(series_color(1)),
                "Spearman of set distance and |\u{394}c| (analysis)",
            );
        }
        let (plot, strip) = legend.split(area, print);
        let n = self.recovery.len();
        let low = self
            .recovery
            .iter()
            .flat_map(|r| [Some(r.r2), r.spearman])
            .flatten()
            .filter(|v| v.is_finite())
            .fold(0.0_f64, f64::min);
        let names: Vec<(f64, &str)> = self
            .recovery
            .iter()
            .enumerate()
            .map(|(k, r)| (k as f64, super::coordinate_name(r.coordinate)))
            .collect();
        let mut chart = chart_2d(
            &plot,
            print,
            "how well each coordinate is recovered",
            Axis2d {
                // One category alone gets a panel as wide as three would, so that its
                // bars are as wide as usual.
                range: if n == 1 {
                    -1.2..1.2
                } else {
                    -0.6..n as f64 - 0.4
                },
                title: "pose coordinate",
                ticks: TickStyle::Names(&names),
            },
            Axis2d::new(low.min(0.0)..1.05, "score"),
        )?;
        let width = if with_spearman { 0.35 } else { 0.6 };
        for (k, r) in self.recovery.iter().enumerate() {
            let x = k as f64;
            let bars = [(Some(r.r2), 0), (r.spearman, 1)];
            for (value, series) in bars {
                let Some(v) = value.filter(|v| v.is_finite()) else {
                    continue;
                };
                let left = if with_spearman {
                    x - width + width * series as f64
                } else {
                    x - width / 2.0
                };
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(left, 0.0), (left + width, v)],
                    series_color(series).filled(),
                )))?;
            }
        }
        legend.draw(&strip, print)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_coordinate_gets_the_view_in_which_it_shows_whatever_is_chosen_with_it() {
        // A cylinder: alpha round the axis, x along it. Alpha shows looking down the
        // axis, x from the side; choosing both at once (one neighbour search per view)
        // picks what choosing each alone picks.
        let m = 600;
        let alpha = |i: usize| -3.0 + 6.0 * (i * 7 % m) as f64 / m as f64;
        let x = |i: usize| -0.3 + 0.6 * (i * 13 % m) as f64 / m as f64;
        let embedding = Array2::from_shape_fn((m, 3), |(i, k)| match k {
            0 => alpha(i).cos(),
            1 => alpha(i).sin(),
            _ => x(i),
        });
        let set_poses =
            Array2::from_shape_fn((m, 3), |(i, c)| [x(i), 0.1 * alpha(i).sin(), alpha(i)][c]);
        let frame = ring_frame(embedding.view(), &[]);
        let both = PoseViews::choose(embedding.view(), frame, &set_poses, &[0, 2]);
        let views = candidate_views();
        assert_eq!(both.cameras[1], views[0], "alpha not seen along the axis");
        assert_ne!(both.cameras[0], views[0], "x seen along the axis");
        for (n, c) in [0, 2].into_iter().enumerate() {
            let alone = PoseViews::choose(embedding.view(), frame, &set_poses, &[c]);
            assert_eq!(alone.cameras[0], both.cameras[n], "coordinate {c}");
        }
    }

    #[test]
    fn nearest_rows_are_found_and_do_not_keep_the_scan() {
        // Points on a line at 0, 1, 2, …: the nearest of row 500 are 499, 501, 498, 502, …
        let m = 1000;
        let embedding =
            ndarray::Array2::from_shape_fn((m, 2), |(i, c)| if c == 0 { i as f64 } else { 0.0 });
        let points = Points {
            coordinates: embedding.as_slice().unwrap(),
            dim: 2,
            len: m,
        };
        let mut scratch = Vec::new();
        let mut near = nearest(&points, 500, 4, &mut scratch);
        near.sort_unstable();
        assert_eq!(near, vec![498, 499, 501, 502]);
        // One list of `k` per query: the report keeps thousands of them, so a list
        // must not hold on to the `m` distances scanned for it.
        let near = nearest(&points, 0, 10, &mut scratch);
        assert_eq!(near.len(), 10);
        assert!(near.capacity() < 2 * 10, "capacity {}", near.capacity());
    }
}
