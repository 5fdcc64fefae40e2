//! Orthographic 3-D views, drawn on a 2-D area with the painter's algorithm: a frame
//! chosen from the data (the axis of the ring of probe sheets, section 3.3), a camera
//! at an azimuth and elevation in that frame, a box with axis titles and ticks, and a
//! scene of points, lines and polygons drawn back to front.
//!
//! plotters' own 3-D charts fix the view to their axes and label every tick with its
//! axis name, so that labels of two axes meet at the box's corners; here the labels
//! of each axis sit on the box edge that faces outwards on screen, with no tick at the
//! ends of an edge.

use std::ops::Range;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::HPos;

use super::plot::{label, label_vertical, text_width, Drawn, NumberFormat, Print, Valign};

/// A point or direction in 3-D.
pub(super) type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: V3) -> V3 {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        [a[0] / n, a[1] / n, a[2] / n]
    } else {
        [1.0, 0.0, 0.0]
    }
}

/// An orthonormal frame: an origin and three axes, right-handed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Frame {
    origin: V3,
    axes: [V3; 3],
}

/// How the ring frame was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum RingSource {
    /// The plane through the centres of the probe sheets (at least three).
    Sheets,
    /// The plane of largest spread of all points (no probe sheets).
    Points,
}

impl Frame {
    /// The frame's axes (the third is a ring's axis), in the data's coordinates.
    pub(super) fn axes(&self) -> [V3; 3] {
        self.axes
    }

    /// Coordinates of `p` in the frame.
    pub(super) fn coords(&self, p: V3) -> V3 {
        let d = sub(p, self.origin);
        [
            dot(d, self.axes[0]),
            dot(d, self.axes[1]),
            dot(d, self.axes[2]),
        ]
    }

    /// The frame of a ring: the third axis is the ring's axis (the normal of the plane
    /// that best fits the `centres` of the sheets, at least three, given with their
    /// orientation alpha; without them the direction of least spread of `points`),
    /// the first points from the ring's centre to the sheet of alpha nearest 0, and
    /// the axis is oriented so that alpha increases counter-clockwise seen from it.
    pub(super) fn ring(points: &[V3], centres: &[(V3, f64)]) -> (Self, RingSource) {
        let (fit, source): (Vec<V3>, _) = if centres.len() >= 3 {
            (centres.iter().map(|c| c.0).collect(), RingSource::Sheets)
        } else {
            (points.to_vec(), RingSource::Points)
        };
        let n = fit.len().max(1) as f64;
        let mut origin = [0.0; 3];
        for p in &fit {
            for k in 0..3 {
                origin[k] += p[k] / n;
            }
        }
        let mut cov = Matrix3::<f64>::zeros();
        for p in &fit {
            let d = Vector3::from(sub(*p, origin));
            cov += d * d.transpose();
        }
        let eigen = SymmetricEigen::new(cov);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let column = |k: usize| -> V3 {
            let c = eigen.eigenvectors.column(order[k]);
            [c[0], c[1], c[2]]
        };
        let mut axis = unit(column(2));
        let mut first = column(0);
        if source == RingSource::Sheets {
            if let Some(c) = centres
                .iter()
                .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            {
                let d = sub(c.0, origin);
                let along = dot(d, axis);
                first = sub(d, [axis[0] * along, axis[1] * along, axis[2] * along]);
            }
            if winding(centres, origin, unit(first), axis) < 0.0 {
                axis = [-axis[0], -axis[1], -axis[2]];
            }
        }
        let first = unit(first);
        let second = cross(axis, first);
        let frame = Self {
            origin,
            axes: [first, second, axis],
        };
        (frame, source)
    }
}

/// The signed turn of the sheets' centres around `axis`, taken in order of alpha: positive
/// when alpha increases counter-clockwise seen from the axis.
fn winding(centres: &[(V3, f64)], origin: V3, first: V3, axis: V3) -> f64 {
    let second = cross(axis, first);
    let mut sorted: Vec<(f64, f64)> = centres
        .iter()
        .map(|(c, alpha)| {
            let d = sub(*c, origin);
            (*alpha, dot(d, second).atan2(dot(d, first)))
        })
        .collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    sorted
        .windows(2)
        .map(|w| smspace::agent::wrap_angle(w[1].1 - w[0].1))
        .sum()
}

/// An orthographic camera: the screen's right and up directions and the direction
/// towards the viewer, in frame coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Camera {
    right: V3,
    up: V3,
    toward: V3,
}

impl Camera {
    /// Looking from azimuth `azimuth` (around the third axis, from the first) and
    /// elevation `elevation` above the plane of the first two axes, radians.
    pub(super) fn new(azimuth: f64, elevation: f64) -> Self {
        let (sa, ca) = azimuth.sin_cos();
        let (se, ce) = elevation.sin_cos();
        Self {
            right: [-sa, ca, 0.0],
            up: [-se * ca, -se * sa, ce],
            toward: [ce * ca, ce * sa, se],
        }
    }

    /// Where `p` lands on the screen, `(right, up)`, before scaling.
    pub(super) fn screen(&self, p: V3) -> [f64; 2] {
        [dot(p, self.right), dot(p, self.up)]
    }

    /// Looking down the third axis: the first axis to the right, the second up.
    pub(super) fn from_above() -> Self {
        Self {
            right: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            toward: [0.0, 0.0, 1.0],
        }
    }
}

/// A camera fitted into a rectangle of pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Projection {
    camera: Camera,
    scale: f64,
    /// Screen coordinates of the rectangle's centre.
    middle: (f64, f64),
    /// The rectangle's centre in pixels.
    pixel: (f64, f64),
}

impl Projection {
    /// The projection that fits `points` (frame coordinates) into the pixel rectangle
    /// `rect = (left, top, right, bottom)`, with the same scale on both screen axes.
    pub(super) fn fit(camera: Camera, points: &[V3], rect: (i32, i32, i32, i32)) -> Self {
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for &p in points {
            let (x, y) = (dot(p, camera.right), dot(p, camera.up));
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
        if !lo.0.is_finite() {
            (lo, hi) = ((-1.0, -1.0), (1.0, 1.0));
        }
        let (w, h) = (
            f64::from((rect.2 - rect.0).max(1)),
            f64::from((rect.3 - rect.1).max(1)),
        );
        let span = ((hi.0 - lo.0) / w).max((hi.1 - lo.1) / h).max(1e-12);
        Self {
            camera,
            scale: 1.0 / span,
            middle: (0.5 * (lo.0 + hi.0), 0.5 * (lo.1 + hi.1)),
            pixel: (
                0.5 * f64::from(rect.0 + rect.2),
                0.5 * f64::from(rect.1 + rect.3),
            ),
        }
    }

    /// The pixel of `p`.
    pub(super) fn px(&self, p: V3) -> (i32, i32) {
        let x = dot(p, self.camera.right) - self.middle.0;
        let y = dot(p, self.camera.up) - self.middle.1;
        (
            (self.pixel.0 + x * self.scale).round() as i32,
            (self.pixel.1 - y * self.scale).round() as i32,
        )
    }

    /// How near `p` is to the viewer (larger is nearer).
    pub(super) fn depth(&self, p: V3) -> f64 {
        dot(p, self.camera.toward)
    }
}

/// One thing to draw, at a depth.
pub(super) enum Item {
    /// A disc of the radius (pixels) and colour.
    Point(V3, i32, RGBAColor),
    /// A hollow circle of the radius and line width (pixels) and colour.
    Ring(V3, i32, u32, RGBAColor),
    /// A line of the width (pixels) and colour.
    Line(V3, V3, u32, RGBAColor),
    /// A filled polygon with an outline.
    Polygon(Vec<V3>, RGBAColor, RGBAColor, u32),
}

impl Item {
    fn depth(&self, p: &Projection) -> f64 {
        match self {
            Item::Point(a, ..) | Item::Ring(a, ..) => p.depth(*a),
            Item::Line(a, b, ..) => 0.5 * (p.depth(*a) + p.depth(*b)),
            Item::Polygon(v, ..) => {
                v.iter().map(|&a| p.depth(a)).sum::<f64>() / v.len().max(1) as f64
            }
        }
    }
}

/// Draws `items` back to front (farthest first).
pub(super) fn draw_scene<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    projection: &Projection,
    items: &[Item],
) -> Drawn {
    let mut order: Vec<(f64, usize)> = items
        .iter()
        .enumerate()
        .map(|(k, item)| (item.depth(projection), k))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    for (_, k) in order {
        match &items[k] {
            Item::Point(a, r, color) => {
                area.draw(&Circle::new(projection.px(*a), *r, color.filled()))?;
            }
            Item::Ring(a, r, width, color) => {
                area.draw(&Circle::new(
                    projection.px(*a),
                    *r,
                    color.stroke_width(*width),
                ))?;
            }
            Item::Line(a, b, width, color) => {
                area.draw(&PathElement::new(
                    vec![projection.px(*a), projection.px(*b)],
                    color.stroke_width(*width),
                ))?;
            }
            Item::Polygon(vertices, fill, edge, width) => {
                let pixels: Vec<(i32, i32)> = vertices.iter().map(|&v| projection.px(v)).collect();
                area.draw(&Polygon::new(pixels.clone(), fill.filled()))?;
                let mut closed = pixels;
                if let Some(&first) = closed.first() {
                    closed.push(first);
                }
                area.draw(&PathElement::new(closed, edge.stroke_width(*width)))?;
            }
        }
    }
    Ok(())
}

/// An axis of a box: its title and the values that get a tick.
pub(super) struct BoxAxis {
    /// The title, with its unit.
    pub(super) title: String,
    /// Ticks with their labels (none: the title only).
    pub(super) ticks: Vec<(f64, String)>,
}

impl BoxAxis {
    /// An axis with ticks at round values of `range`, none within 12 % of its ends
    /// (where the labels of two axes would meet at a corner).
    pub(super) fn numbered(title: impl Into<String>, range: &Range<f64>) -> Self {
        let span = range.end - range.start;
        let values: Vec<f64> = super::plot::ticks(range, 4)
            .into_iter()
            .filter(|v| (v - range.start) > 0.12 * span && (range.end - v) > 0.12 * span)
            .collect();
        let format = NumberFormat::for_ticks(&values);
        Self {
            title: format!("{}{}", title.into(), format.suffix()),
            ticks: values.iter().map(|&v| (v, format.label(v))).collect(),
        }
    }

    /// An axis of a hinge (the range `[−π, π]`): ticks at `−π/2`, `0` and `π/2`, a
    /// quarter of the edge from its ends, so that the labels of two axes never crowd
    /// at the corner where their edges meet.
    pub(super) fn angles(title: impl Into<String>) -> Self {
        let half = std::f64::consts::FRAC_PI_2;
        Self {
            title: title.into(),
            ticks: vec![
                (-half, "\u{2212}\u{3c0}/2".to_owned()),
                (0.0, "0".to_owned()),
                (half, "\u{3c0}/2".to_owned()),
            ],
        }
    }

    /// An axis with a title and no ticks.
    pub(super) fn titled(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            ticks: Vec::new(),
        }
    }
}

/// The eight corners of the box `ranges`, corner `c` taking the high end of axis `k`
/// when bit `k` of `c` is set.
fn corner(ranges: &[Range<f64>; 3], c: usize) -> V3 {
    [0, 1, 2].map(|k| {
        if c >> k & 1 == 1 {
            ranges[k].end
        } else {
            ranges[k].start
        }
    })
}

/// A rectangle of pixels, `(left, top, right, bottom)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rect(f64, f64, f64, f64);

impl Rect {
    /// Whether the rectangles come closer than `gap`.
    fn meets(&self, other: &Rect, gap: f64) -> bool {
        self.0 - gap < other.2
            && other.0 - gap < self.2
            && self.1 - gap < other.3
            && other.1 - gap < self.3
    }
}

/// Where a label's ink lies when drawn by [`label`] at `(x, y)`, `width` pixels wide,
/// in text of size `size` (plotters' size: caps are 0.63 of it, descenders 0.2).
fn label_box((x, y): (f64, f64), width: f64, size: f64, h: HPos, v: Valign) -> Rect {
    let (cap, descender) = (0.63 * size, 0.21 * size);
    let (left, right) = match h {
        HPos::Left => (x, x + width),
        HPos::Right => (x - width, x),
        HPos::Center => (x - width / 2.0, x + width / 2.0),
    };
    let (top, bottom) = match v {
        Valign::Top => (y, y + cap + descender),
        Valign::Middle => (y - cap / 2.0, y + cap / 2.0 + descender),
        Valign::Bottom => (y - cap - descender, y),
    };
    Rect(left, top, right, bottom)
}

/// Draws the twelve edges of the box `ranges` (frame coordinates), faint, and on one
/// outward-facing edge of each axis its ticks, their labels and the axis title, each
/// title pushed outwards until it clears every label drawn before it.
pub(super) fn draw_box<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    projection: &Projection,
    ranges: &[Range<f64>; 3],
    axes: &[BoxAxis; 3],
    print: Print,
) -> Drawn {
    let edge_style = RGBColor(190, 190, 190).stroke_width(print.stroke(0.5));
    let mut centre = (0.0, 0.0);
    for c in 0..8 {
        let p = projection.px(corner(ranges, c));
        centre.0 += f64::from(p.0) / 8.0;
        centre.1 += f64::from(p.1) / 8.0;
        for k in 0..3 {
            if c >> k & 1 == 0 {
                let q = projection.px(corner(ranges, c | 1 << k));
                area.draw(&PathElement::new(vec![p, q], edge_style))?;
            }
        }
    }
    let mut placed = Vec::new();
    let mut titles = Vec::new();
    for (k, axis) in axes.iter().enumerate() {
        if let Some(title) = draw_box_ticks(
            area,
            projection,
            ranges,
            k,
            axis,
            centre,
            print,
            &mut placed,
        )? {
            titles.push((axis.title.as_str(), title));
        }
    }
    for (text, (middle, normal, horizontal)) in titles {
        // A title of a few letters stays upright beside a vertical edge.
        let turned = horizontal && text.chars().count() > 3;
        draw_box_title(area, text, middle, normal, turned, print, &mut placed)?;
    }
    Ok(())
}

/// Where an axis title goes: the middle of its edge, the outward normal, and whether
/// the normal is mostly horizontal on screen.
type TitleSpot = ((f64, f64), (f64, f64), bool);

/// The ticks and labels of axis `k` of the box, on the edge parallel to it whose
/// middle lies farthest out (and lowest) from the box's centre on screen; returns
/// where its title goes (`None` when the axis points at the viewer). The labels' boxes
/// are added to `placed`.
// The box, its projection and the axis are what the function draws; grouping them in
// a struct for one call would only rename them.
#[allow(clippy::too_many_arguments)]
fn draw_box_ticks<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    projection: &Projection,
    ranges: &[Range<f64>; 3],
    k: usize,
    axis: &BoxAxis,
    centre: (f64, f64),
    print: Print,
    placed: &mut Vec<Rect>,
) -> Result<Option<TitleSpot>, super::plot::PlotError> {
    let ends = |c: usize| {
        (
            projection.px(corner(ranges, c)),
            projection.px(corner(ranges, c | 1 << k)),
        )
    };
    let outward = |c: usize| {
        let (a, b) = ends(c);
        let (dx, dy) = (f64::from(b.0 - a.0), f64::from(b.1 - a.1));
        let length = dx.hypot(dy).max(1e-9);
        let mut normal = (-dy / length, dx / length);
        let middle = (0.5 * f64::from(a.0 + b.0), 0.5 * f64::from(a.1 + b.1));
        let away = (middle.0 - centre.0) * normal.0 + (middle.1 - centre.1) * normal.1;
        if away < 0.0 {
            normal = (-normal.0, -normal.1);
        }
        (
            away.abs() + 0.25 * (middle.1 - centre.1),
            normal,
            middle,
            length,
        )
    };
    let Some(best) = (0..8)
        .filter(|c| c >> k & 1 == 0)
        .max_by(|&a, &b| outward(a).0.total_cmp(&outward(b).0))
    else {
        return Ok(None);
    };
    let (_, normal, middle, length) = outward(best);
    if length < print.px(6.0) {
        // The axis points at the viewer: nothing to label.
        return Ok(None);
    }
    let start = corner(ranges, best);
    let style = print.text();
    let size = style.font.get_size();
    let horizontal = normal.0.abs() > normal.1.abs();
    let (h, v) = if horizontal {
        (
            if normal.0 > 0.0 {
                HPos::Left
            } else {
                HPos::Right
            },
            Valign::Middle,
        )
    } else {
        (
            HPos::Center,
            if normal.1 > 0.0 {
                Valign::Top
            } else {
                Valign::Bottom
            },
        )
    };
    let at = |p: (f64, f64), d: f64| (p.0 + normal.0 * d, p.1 + normal.1 * d);
    let round = |p: (f64, f64)| (p.0.round() as i32, p.1.round() as i32);
    let tick = print.px(3.0);
    let line = BLACK.stroke_width(print.stroke(0.5));
    for (value, text) in &axis.ticks {
        let mut p = start;
        p[k] = *value;
        let q = projection.px(p);
        let q = (f64::from(q.0), f64::from(q.1));
        area.draw(&PathElement::new(vec![round(q), round(at(q, tick))], line))?;
        let spot = at(q, tick + print.px(2.0));
        label(area, text, round(spot), &style, h, v)?;
        let width = f64::from(text_width(area, text, &style));
        placed.push(label_box(spot, width, size, h, v));
    }
    Ok(Some((middle, normal, horizontal)))
}

/// Draws an axis title outside the box (turned to read upwards when `turned`), moved
/// out along the normal until it clears every box in `placed` (to which it is then
/// added).
fn draw_box_title<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    middle: (f64, f64),
    normal: (f64, f64),
    turned: bool,
    print: Print,
    placed: &mut Vec<Rect>,
) -> Drawn {
    let style = print.text();
    let size = style.font.get_size();
    let width = f64::from(text_width(area, text, &style));
    let thickness = 0.84 * size;
    let gap = print.px(3.0);
    let bounds = |d: f64| {
        let c = (middle.0 + normal.0 * d, middle.1 + normal.1 * d);
        if turned {
            Rect(
                c.0 - thickness / 2.0,
                c.1 - width / 2.0,
                c.0 + thickness / 2.0,
                c.1 + width / 2.0,
            )
        } else {
            Rect(
                c.0 - width / 2.0,
                c.1 - thickness / 2.0,
                c.0 + width / 2.0,
                c.1 + thickness / 2.0,
            )
        }
    };
    // How far the title reaches along the normal from its centre.
    let reach = if turned {
        thickness / 2.0
    } else {
        0.5 * (width * normal.0.abs() + thickness * normal.1.abs())
    };
    let mut d = print.px(5.0) + reach;
    for _ in 0..80 {
        if !placed.iter().any(|p| p.meets(&bounds(d), gap)) {
            break;
        }
        d += print.px(1.5);
    }
    let b = bounds(d);
    placed.push(b);
    let centre = (
        ((b.0 + b.2) / 2.0).round() as i32,
        ((b.1 + b.3) / 2.0).round() as i32,
    );
    if turned {
        label_vertical(area, text, centre, &style)
    } else {
        label(area, text, centre, &style, HPos::Center, Valign::Middle)
    }
}
