//! Drawing machinery shared by the figures: the embedded font, the two backends (PNG
//! through the bitmap backend and the `png` encoder, SVG as a string), colour maps,
//! colour bars, axis ranges and chart frames.
//!
//! Every figure is a [`Figure`]: one generic `draw` that runs on either backend, so the
//! PNG and the SVG of a figure show the same thing. Nothing here reads the clock or a
//! random source: the same inputs give the same bytes.

use std::error::Error;
use std::ops::Range;
use std::path::PathBuf;
use std::sync::Once;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{FigureFormats, ReportError};

/// DejaVu Sans (Bitstream Vera licence, see `assets/DejaVuSans-LICENSE`): the only
/// font the figures use, so that PNG text does not depend on the system's fonts.
static DEJAVU_SANS: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// The family name every text style of the figures uses.
pub(super) const FONT: &str = "sans-serif";

/// Registers the embedded font under [`FONT`], once per process.
pub(super) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TrueType font, checked by the tests; a failure here
        // would only leave the text undrawn.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, DEJAVU_SANS);
    });
}

/// A drawing failure, with the backend's message.
#[derive(Debug)]
pub(super) struct PlotError(pub(super) String);

impl<E: Error + Send + Sync> From<DrawingAreaErrorKind<E>> for PlotError {
    fn from(error: DrawingAreaErrorKind<E>) -> Self {
        PlotError(error.to_string())
    }
}

/// The result of drawing.
pub(super) type Drawn = Result<(), PlotError>;

/// A figure: its pixel size and how to draw it on any backend.
pub(super) trait Figure {
    /// Width and height in pixels.
    fn size(&self) -> (u32, u32);
    /// Draws the figure on `root` (already filled white).
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn;
}

/// A figure drawn in memory: its files' names and bytes (written by the report's one
/// [`crate::io::Outputs`], and kept for `report.html`).
#[derive(Debug, Default)]
pub(super) struct Rendered {
    /// Its files, relative to the report folder.
    pub(super) files: Vec<PathBuf>,
    /// The PNG bytes, when PNG was asked for.
    pub(super) png: Option<Vec<u8>>,
    /// The SVG text, when SVG was asked for.
    pub(super) svg: Option<String>,
}

fn draw_error(name: &str, error: PlotError) -> ReportError {
    ReportError::Draw {
        figure: name.to_owned(),
        reason: error.0,
    }
}

/// Renders `figure` as `figures/<name>.png` and/or `.svg`, in memory.
pub(super) fn render<F: Figure>(
    figure: &F,
    name: &str,
    formats: FigureFormats,
) -> Result<Rendered, ReportError> {
    register_font();
    let (width, height) = figure.size();
    let mut rendered = Rendered::default();
    let (want_png, want_svg) = match formats {
        FigureFormats::PngAndSvg => (true, true),
        FigureFormats::Png => (true, false),
        FigureFormats::Svg => (false, true),
    };
    if want_png {
        let mut pixels = vec![255_u8; width as usize * height as usize * 3];
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| draw_error(name, e.into()))?;
            figure.draw(&root).map_err(|e| draw_error(name, e))?;
            root.present().map_err(|e| draw_error(name, e.into()))?;
        }
        let bytes = encode_png(&pixels, width, height).map_err(|reason| ReportError::Draw {
            figure: name.to_owned(),
            reason,
        })?;
        let relative = PathBuf::from("figures").join(format!("{name}.png"));
        rendered.files.push(relative);
        rendered.png = Some(bytes);
    }
    if want_svg {
        let mut text = String::new();
        {
            let root = SVGBackend::with_string(&mut text, (width, height)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| draw_error(name, e.into()))?;
            figure.draw(&root).map_err(|e| draw_error(name, e))?;
            root.present().map_err(|e| draw_error(name, e.into()))?;
        }
        let relative = PathBuf::from("figures").join(format!("{name}.svg"));
        rendered.files.push(relative);
        rendered.svg = Some(text);
    }
    Ok(rendered)
}

fn encode_png(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Default);
        let mut writer = encoder
            .write_header()
            .map_err(|e| format!("PNG encoder: {e}"))?;
        writer
            .write_image_data(rgb)
            .map_err(|e| format!("PNG encoder: {e}"))?;
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------
// Text styles.

/// Title of a panel.
pub(super) fn title_font() -> TextStyle<'static> {
    (FONT, 19).into_font().into()
}

/// Axis descriptions.
pub(super) fn label_font() -> TextStyle<'static> {
    (FONT, 15).into_font().into()
}

/// Tick labels and legends.
pub(super) fn tick_font() -> TextStyle<'static> {
    (FONT, 13).into_font().into()
}

// ---------------------------------------------------------------------------------
// Colours.

/// A qualitative palette (Tableau 10) for series.
pub(super) const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// The series colour number `i`.
pub(super) fn series_color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// Grey of the background points.
pub(super) const GREY: RGBColor = RGBColor(170, 170, 170);

/// How a scalar becomes a colour.
#[derive(Debug, Clone, Copy)]
pub(super) enum ColorScale {
    /// Viridis over `[min, max]`.
    Linear {
        /// Value at the dark end.
        min: f64,
        /// Value at the bright end.
        max: f64,
    },
    /// A hue wheel over `[-π, π)`: angles close on the circle get close colours.
    Circular,
}

impl ColorScale {
    /// A linear scale over the finite values of `values`.
    pub(super) fn linear(values: impl IntoIterator<Item = f64>) -> Self {
        let (min, max) = finite_extent(values).unwrap_or((0.0, 1.0));
        ColorScale::Linear { min, max }
    }

    /// The colour of `value`.
    pub(super) fn color(self, value: f64) -> RGBColor {
        match self {
            ColorScale::Linear { min, max } => {
                let t = if max > min {
                    ((value - min) / (max - min)).clamp(0.0, 1.0)
                } else {
                    0.5
                };
                ViridisRGB::get_color(t)
            }
            ColorScale::Circular => {
                let t = (value + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    / std::f64::consts::TAU;
                hue(t)
            }
        }
    }

    /// The range the colour bar shows.
    pub(super) fn range(self) -> (f64, f64) {
        match self {
            ColorScale::Linear { min, max } if max > min => (min, max),
            ColorScale::Linear { min, .. } => (min - 0.5, min + 0.5),
            ColorScale::Circular => (-std::f64::consts::PI, std::f64::consts::PI),
        }
    }
}

/// A saturated colour of hue `t ∈ [0, 1)` (HSL with `s = 0.75`, `l = 0.47`).
pub(super) fn hue(t: f64) -> RGBColor {
    let (s, l) = (0.75, 0.47);
    let c = (1.0 - (2.0 * l - 1.0_f64).abs()) * s;
    let h = t.rem_euclid(1.0) * 6.0;
    let x = c * (1.0 - (h.rem_euclid(2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = l - c / 2.0;
    let to = |v: f64| ((v + m) * 255.0).round().clamp(0.0, 255.0) as u8;
    RGBColor(to(r), to(g), to(b))
}

/// Draws a vertical colour bar for `scale` in `area`, titled `label`.
pub(super) fn color_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    scale: ColorScale,
    label: &str,
) -> Drawn {
    let (lo, hi) = scale.range();
    let mut chart = ChartBuilder::on(area)
        .margin_top(40)
        .margin_bottom(55)
        .margin_right(4)
        .y_label_area_size(0)
        .right_y_label_area_size(58)
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    let steps = 96;
    chart.draw_series((0..steps).map(|k| {
        let a = lo + (hi - lo) * k as f64 / steps as f64;
        let b = lo + (hi - lo) * (k + 1) as f64 / steps as f64;
        Rectangle::new([(0.0, a), (1.0, b)], scale.color(0.5 * (a + b)).filled())
    }))?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(0.0, lo), (1.0, hi)],
        BLACK.stroke_width(1),
    )))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_y_mesh()
        .disable_x_axis()
        .y_labels(6)
        .y_label_style(tick_font())
        .y_label_formatter(&|v| tick_label(*v))
        .draw()?;
    area.draw(&Text::new(
        label.to_owned(),
        (2, 14),
        tick_font().pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    Ok(())
}

// ---------------------------------------------------------------------------------
// Ranges and frames.

/// The smallest and largest finite values, if any.
pub(super) fn finite_extent(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
}

/// An axis range around the finite values, padded by 5 % on each side (±0.5 around a
/// single value, `[0, 1]` without values).
pub(super) fn padded(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    match finite_extent(values) {
        None => 0.0..1.0,
        Some((lo, hi)) if hi - lo <= 1e-12 * lo.abs().max(1.0) => lo - 0.5..hi + 0.5,
        Some((lo, hi)) => {
            let pad = 0.05 * (hi - lo);
            lo - pad..hi + pad
        }
    }
}

/// Grows `x` or `y` so that one unit has the same length on both axes in a plot of
/// `width × height` pixels.
pub(super) fn equal_aspect(
    x: Range<f64>,
    y: Range<f64>,
    width: u32,
    height: u32,
) -> (Range<f64>, Range<f64>) {
    let (w, h) = (x.end - x.start, y.end - y.start);
    let ratio = f64::from(width.max(1)) / f64::from(height.max(1));
    if w / h < ratio {
        let grow = (h * ratio - w) / 2.0;
        (x.start - grow..x.end + grow, y)
    } else {
        let grow = (w / ratio - h) / 2.0;
        (x, y.start - grow..y.end + grow)
    }
}

/// A tick label with at most 4 significant digits.
pub(super) fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".to_owned();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.1e}");
    }
    let digits = (3 - a.log10().floor() as i32).clamp(0, 4) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// A 2-D chart of `area` with a title, axis descriptions and a light grid.
pub(super) type Chart2d<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Builds a titled 2-D chart with described axes.
pub(super) fn chart_2d<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    title: &str,
    x: Range<f64>,
    y: Range<f64>,
    x_desc: &str,
    y_desc: &str,
) -> Result<Chart2d<'a, DB>, PlotError> {
    let mut chart = ChartBuilder::on(area)
        .caption(title, title_font())
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(64)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .axis_desc_style(label_font())
        .label_style(tick_font())
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .max_light_lines(1)
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    Ok(chart)
}

/// Draws the legend of `chart` in its upper right corner.
pub(super) fn legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart2d<'a, DB>,
    position: SeriesLabelPosition,
) -> Drawn {
    chart
        .configure_series_labels()
        .position(position)
        .label_font(tick_font())
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(120, 120, 120))
        .draw()?;
    Ok(())
}

/// Splits `area` into a plot and a colour-bar strip on its right.
pub(super) fn with_color_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
) -> (DrawingArea<DB, Shift>, DrawingArea<DB, Shift>) {
    let (w, _) = area.dim_in_pixel();
    let bar = 92.min(w / 3);
    area.split_horizontally(w - bar)
}

/// At most `limit` indices out of `0..n`, evenly spaced (all when `n ≤ limit`).
pub(super) fn stride_sample(n: usize, limit: usize) -> Vec<usize> {
    if n <= limit || limit == 0 {
        return (0..n).collect();
    }
    (0..limit).map(|k| k * n / limit).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(1.5), "1.5");
        assert_eq!(tick_label(-1.23456), "-1.235");
        assert_eq!(tick_label(1234.0), "1234");
        assert_eq!(tick_label(2.0e-5), "2.0e-5");
    }

    #[test]
    fn hue_wheel_is_circular() {
        assert_eq!(hue(0.0), hue(1.0));
        let a = ColorScale::Circular.color(-std::f64::consts::PI);
        let b = ColorScale::Circular.color(std::f64::consts::PI - 1e-9);
        let close = |x: u8, y: u8| (i16::from(x) - i16::from(y)).abs() <= 2;
        assert!(close(a.0, b.0) && close(a.1, b.1) && close(a.2, b.2));
    }

    #[test]
    fn ranges_pad_and_keep_aspect() {
        let r = padded([1.0, 3.0]);
        assert!((r.start - 0.9).abs() < 1e-12 && (r.end - 3.1).abs() < 1e-12);
        let r = padded([2.0, 2.0]);
        assert!((r.start - 1.5).abs() < 1e-12);
        let (x, y) = equal_aspect(0.0..1.0, 0.0..1.0, 200, 100);
        assert!(((x.end - x.start) - 2.0 * (y.end - y.start)).abs() < 1e-12);
        assert_eq!(stride_sample(10, 4), vec![0, 2, 5, 7]);
        assert!(DEJAVU_SANS.len() > 100_000);
    }
}
