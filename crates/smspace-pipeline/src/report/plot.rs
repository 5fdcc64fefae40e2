//! Drawing machinery shared by the figures: the embedded font, the print geometry
//! (points to pixels), the two backends (PNG through the bitmap backend and the `png`
//! encoder, SVG as a string), colour maps and bars, legends, number formats, axis
//! ranges and 2-D chart frames.
//!
//! Every figure is a [`Figure`]: one generic `draw` that runs on either backend (and on
//! the text recorder of [`super::layout`]), so the PNG and the SVG of a figure show the
//! same thing. Sizes are in typographic points (1/72 in) and become pixels through
//! [`Print`]: a figure looks the same at any resolution, and its text is at least
//! [`MIN_FONT_PT`] at its print size. Nothing here reads the clock or a random source:
//! the same inputs give the same bytes.

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

// ---------------------------------------------------------------------------------
// Print geometry and text.

/// Size of titles, in points.
pub(super) const TITLE_PT: f64 = 10.0;
/// Size of axis titles, tick labels, legends and colour-bar labels, in points.
pub(super) const MIN_FONT_PT: f64 = 9.0;

/// plotters' text size is the font's line height, 1.24 em (its SVG backend writes
/// `font-size = size / 1.24`): a size of `1.24 × 9 pt` prints a 9-point font.
pub(super) const SIZE_PER_EM: f64 = 1.24;

/// DejaVu Sans, as a fraction of plotters' text size: cap height and descender.
const CAP: f64 = 0.626;
const DESCENDER: f64 = 0.203;

/// How a figure's points become pixels: `dpi / 72` pixels per point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Print {
    /// Pixels per inch of the PNG (and user units per inch of the SVG).
    pub(super) dpi: f64,
}

impl Print {
    /// Pixels of `pt` points.
    pub(super) fn px(self, pt: f64) -> f64 {
        pt * self.dpi / 72.0
    }

    /// Pixels of `pt` points, rounded.
    pub(super) fn i(self, pt: f64) -> i32 {
        self.px(pt).round() as i32
    }

    /// A line width of `pt` points, in whole pixels (at least 1).
    pub(super) fn stroke(self, pt: f64) -> u32 {
        (self.px(pt).round() as u32).max(1)
    }

    /// Pixels of `inches`, rounded.
    pub(super) fn inches(self, inches: f64) -> u32 {
        (inches * self.dpi).round() as u32
    }

    /// A text style of `pt` points.
    pub(super) fn font(self, pt: f64) -> TextStyle<'static> {
        (FONT, self.px(pt) * SIZE_PER_EM).into_font().into()
    }

    /// Titles.
    pub(super) fn title(self) -> TextStyle<'static> {
        self.font(TITLE_PT)
    }

    /// Axis titles, tick labels and legends.
    pub(super) fn text(self) -> TextStyle<'static> {
        self.font(MIN_FONT_PT)
    }

    /// The height of one line of [`Print::text`], with its spacing, in pixels.
    pub(super) fn line(self) -> i32 {
        self.i(MIN_FONT_PT * 1.45)
    }
}

/// Where a label's ink sits with respect to its position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Valign {
    /// The top of its capitals and digits at the position.
    Top,
    /// Its capitals and digits centred on the position.
    Middle,
    /// The bottom of its descenders at the position.
    Bottom,
}

/// Draws `text` at `(x, y)` of `area`, aligned horizontally by `h` and vertically by
/// its ink (plotters places a glyph's baseline half a text size below the top of its
/// layout box, whatever the font, so the anchor is computed here from the font's cap
/// height and descender).
pub(super) fn label<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    (x, y): (i32, i32),
    style: &TextStyle<'_>,
    h: HPos,
    v: Valign,
) -> Drawn {
    let size = style.font.get_size();
    let shift = match v {
        Valign::Top => (CAP - 0.5) * size,
        Valign::Middle => (0.5 * CAP - 0.5) * size,
        Valign::Bottom => -(0.5 + DESCENDER) * size,
    };
    let y = y + shift.round() as i32;
    area.draw(&Text::new(
        text.to_owned(),
        (x, y),
        style.pos(Pos::new(h, VPos::Top)),
    ))?;
    Ok(())
}

/// Draws `text` turned to read upwards, its ink centred on `(x, y)` (plotters turns a
/// text about its position: the glyphs' offsets below the top of the layout box become
/// offsets to the right).
pub(super) fn label_vertical<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    (x, y): (i32, i32),
    style: &TextStyle<'_>,
) -> Drawn {
    let size = style.font.get_size();
    // Ink from `0.5 - CAP` to `0.5 + DESCENDER` sizes below the box's top, unturned.
    let middle = 0.5 + 0.5 * (DESCENDER - CAP);
    let turned = style
        .transform(FontTransform::Rotate270)
        .pos(Pos::new(HPos::Center, VPos::Top));
    area.draw(&Text::new(
        text.to_owned(),
        (x - (middle * size).round() as i32, y),
        turned,
    ))?;
    Ok(())
}

/// The width of `text` in `style` on `area`, in pixels.
pub(super) fn text_width<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    style: &TextStyle<'_>,
) -> i32 {
    area.estimate_text_size(text, style)
        .map_or(0, |(w, _)| w as i32)
}

// ---------------------------------------------------------------------------------
// Rendering and files.

/// A figure drawn in memory: its files' names and bytes (written by the report's one
/// [`smspace::io::Outputs`], and kept for `report.html`).
#[derive(Debug, Default)]
pub(super) struct Rendered {
    /// Its files, relative to the report folder.
    pub(super) files: Vec<PathBuf>,
    /// The PNG bytes, when PNG was asked for.
    pub(super) png: Option<Vec<u8>>,
    /// The SVG text, when SVG was asked for.
    pub(super) svg: Option<String>,
    /// Its print size in inches, `(width, height)` (`None` when not drawn).
    pub(super) print_inches: Option<(f64, f64)>,
}

fn draw_error(name: &str, error: PlotError) -> ReportError {
    ReportError::Draw {
        figure: name.to_owned(),
        reason: error.0,
    }
}

/// One image file of a figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ImageFormat {
    /// `figures/<name>.png`, through the bitmap backend.
    Png,
    /// `figures/<name>.svg`.
    Svg,
}

impl FigureFormats {
    /// The image files of each figure, in the order of a figure's files (PNG first).
    pub(super) fn images(self) -> &'static [ImageFormat] {
        match self {
            FigureFormats::PngAndSvg => &[ImageFormat::Png, ImageFormat::Svg],
            FigureFormats::Png => &[ImageFormat::Png],
            FigureFormats::Svg => &[ImageFormat::Svg],
        }
    }
}

impl Rendered {
    /// The files of `self` then those of `other` (two formats of one figure drawn
    /// apart).
    pub(super) fn merge(mut self, other: Rendered) -> Rendered {
        self.files.extend(other.files);
        self.png = self.png.or(other.png);
        self.svg = self.svg.or(other.svg);
        self.print_inches = self.print_inches.or(other.print_inches);
        self
    }
}

/// Renders `figure` as `figures/<name>.png` or `.svg`, in memory. The SVG states its
/// print size in inches (`dpi` pixels per inch).
pub(super) fn render<F: Figure>(
    figure: &F,
    name: &str,
    format: ImageFormat,
    print: Print,
) -> Result<Rendered, ReportError> {
    register_font();
    let (width, height) = figure.size();
    let mut rendered = Rendered {
        print_inches: Some((f64::from(width) / print.dpi, f64::from(height) / print.dpi)),
        ..Rendered::default()
    };
    match format {
        ImageFormat::Png => {
            let mut pixels = vec![255_u8; width as usize * height as usize * 3];
            {
                let root =
                    BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
                root.fill(&WHITE).map_err(|e| draw_error(name, e.into()))?;
                figure.draw(&root).map_err(|e| draw_error(name, e))?;
                root.present().map_err(|e| draw_error(name, e.into()))?;
            }
            let bytes = encode_png(&pixels, width, height, print.dpi).map_err(|reason| {
                ReportError::Draw {
                    figure: name.to_owned(),
                    reason,
                }
            })?;
            rendered
                .files
                .push(PathBuf::from("figures").join(format!("{name}.png")));
            rendered.png = Some(bytes);
        }
        ImageFormat::Svg => {
            let mut text = String::new();
            {
                let root = SVGBackend::with_string(&mut text, (width, height)).into_drawing_area();
                root.fill(&WHITE).map_err(|e| draw_error(name, e.into()))?;
                figure.draw(&root).map_err(|e| draw_error(name, e))?;
                root.present().map_err(|e| draw_error(name, e.into()))?;
            }
            let text = svg_print_size(&text, (width, height), print.dpi);
            rendered
                .files
                .push(PathBuf::from("figures").join(format!("{name}.svg")));
            rendered.svg = Some(text);
        }
    }
    Ok(rendered)
}

/// Gives the SVG document its print size: `width="W" height="H"` in pixels become
/// inches at `dpi`, the `viewBox` keeps the pixel coordinates.
fn svg_print_size(svg: &str, (width, height): (u32, u32), dpi: f64) -> String {
    let pixels = format!("<svg width=\"{width}\" height=\"{height}\"");
    let inches = format!(
        "<svg width=\"{:.3}in\" height=\"{:.3}in\"",
        f64::from(width) / dpi,
        f64::from(height) / dpi
    );
    svg.replacen(&pixels, &inches, 1)
}

/// Encodes RGB pixels as PNG, with the physical size (`pHYs`) of `dpi`.
fn encode_png(rgb: &[u8], width: u32, height: u32, dpi: f64) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Balanced);
        let per_metre = (dpi / 0.0254).round() as u32;
        encoder.set_pixel_dims(Some(png::PixelDimensions {
            xppu: per_metre,
            yppu: per_metre,
            unit: png::Unit::Meter,
        }));
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

/// Twelve distinguishable colours (Paul Tol's "muted" nine and three of his "light"
/// scheme), for figures that give each drawn object its own colour.
pub(super) const DISTINCT: [RGBColor; 12] = [
    RGBColor(51, 34, 136),
    RGBColor(136, 204, 238),
    RGBColor(68, 170, 153),
    RGBColor(17, 119, 51),
    RGBColor(153, 153, 51),
    RGBColor(221, 204, 119),
    RGBColor(204, 102, 119),
    RGBColor(136, 34, 85),
    RGBColor(170, 68, 153),
    RGBColor(238, 136, 102),
    RGBColor(119, 170, 221),
    RGBColor(0, 0, 0),
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

    /// The colour bar's ticks and their labels.
    fn ticks(self) -> Vec<(f64, String)> {
        match self {
            ColorScale::Circular => {
                let pi = std::f64::consts::PI;
                [
                    (-pi, "\u{2212}\u{3c0}"),
                    (-pi / 2.0, "\u{2212}\u{3c0}/2"),
                    (0.0, "0"),
                    (pi / 2.0, "\u{3c0}/2"),
                    (pi, "\u{3c0}"),
                ]
                .map(|(v, s)| (v, s.to_owned()))
                .to_vec()
            }
            ColorScale::Linear { .. } => {
                let (lo, hi) = self.range();
                let values: Vec<f64> = RangedCoordf64::from(lo..hi)
                    .key_points(5)
                    .into_iter()
                    .filter(|v| (lo..=hi).contains(v))
                    .collect();
                let format = NumberFormat::for_ticks(&values);
                values.iter().map(|&v| (v, format.label(v))).collect()
            }
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

/// Mixes `color` with white: `0` keeps it, `1` gives white.
pub(super) fn lighten(color: RGBColor, by: f64) -> RGBColor {
    let mix = |c: u8| (f64::from(c) + (255.0 - f64::from(c)) * by).round() as u8;
    RGBColor(mix(color.0), mix(color.1), mix(color.2))
}

/// Width of the strip [`with_color_bar`] keeps for a colour bar, in points.
const COLOR_BAR_PT: f64 = 66.0;

/// Splits `area` into a plot and a colour-bar strip on its right.
pub(super) fn with_color_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    print: Print,
) -> (DrawingArea<DB, Shift>, DrawingArea<DB, Shift>) {
    let (w, _) = area.dim_in_pixel();
    let bar = (print.px(COLOR_BAR_PT) as u32).min(w / 3);
    area.split_horizontally(w - bar)
}

/// Draws a vertical colour bar for `scale` in `strip` (from [`with_color_bar`]):
/// `title` above it, tick marks on its right and their labels a gap further right.
pub(super) fn color_bar<DB: DrawingBackend>(
    strip: &DrawingArea<DB, Shift>,
    print: Print,
    scale: ColorScale,
    title: &str,
) -> Drawn {
    let (_, h) = strip.dim_in_pixel();
    let style = print.text();
    let x0 = print.i(4.0);
    let x1 = x0 + print.i(9.0);
    let top = print.i(MIN_FONT_PT * 3.2);
    let bottom = h as i32 - print.i(MIN_FONT_PT * 3.6);
    if bottom <= top {
        return Ok(());
    }
    label(
        strip,
        title,
        (x0, print.i(MIN_FONT_PT * 1.2)),
        &style,
        HPos::Left,
        Valign::Top,
    )?;
    let (lo, hi) = scale.range();
    let to_y = |v: f64| bottom - ((v - lo) / (hi - lo) * f64::from(bottom - top)).round() as i32;
    let steps = 120;
    let y_at = |k: i32| bottom - ((bottom - top) * k + steps / 2) / steps;
    for k in 0..steps {
        let v = lo + (hi - lo) * (f64::from(k) + 0.5) / f64::from(steps);
        strip.draw(&Rectangle::new(
            [(x0, y_at(k + 1)), (x1, y_at(k))],
            scale.color(v).filled(),
        ))?;
    }
    let line = BLACK.stroke_width(print.stroke(0.5));
    strip.draw(&Rectangle::new([(x0, top), (x1, bottom)], line))?;
    let tick = print.i(3.0);
    for (v, text) in scale.ticks() {
        let y = to_y(v);
        strip.draw(&PathElement::new(vec![(x1, y), (x1 + tick, y)], line))?;
        label(
            strip,
            &text,
            (x1 + tick + print.i(2.5), y),
            &style,
            HPos::Left,
            Valign::Middle,
        )?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------
// Numbers.

/// One format for all the tick labels of an axis: the same number of decimals, and a
/// common power of ten taken out of large or small values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct NumberFormat {
    /// Decimals shown.
    pub(super) decimals: usize,
    /// The labels show `v / 10^power`.
    pub(super) power: i32,
}

impl NumberFormat {
    /// The format that writes every value of `ticks` exactly with the fewest decimals.
    pub(super) fn for_ticks(ticks: &[f64]) -> Self {
        let largest = ticks.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let power = if largest >= 1e5 || (largest > 0.0 && largest < 1e-2) {
            largest.log10().floor() as i32
        } else {
            0
        };
        let scale = 10_f64.powi(power);
        let decimals = (0..=6)
            .find(|&d| {
                let f = 10_f64.powi(d as i32);
                ticks.iter().all(|v| {
                    let x = v / scale * f;
                    (x - x.round()).abs() < 1e-6 * x.abs().max(1.0)
                })
            })
            .unwrap_or(6);
        Self { decimals, power }
    }

    /// The label of `v`, with a true minus sign.
    pub(super) fn label(self, v: f64) -> String {
        let x = v / 10_f64.powi(self.power);
        let s = format!("{x:.*}", self.decimals);
        let s = if s
            .trim_start_matches('-')
            .chars()
            .all(|c| c == '0' || c == '.')
        {
            s.trim_start_matches('-').to_owned()
        } else {
            s
        };
        s.replace('-', "\u{2212}")
    }

    /// What an axis title adds: ` (×10^p)` when the labels are scaled.
    pub(super) fn suffix(self) -> String {
        if self.power == 0 {
            String::new()
        } else {
            format!(" (\u{d7}10{})", superscript(self.power))
        }
    }
}

/// `n` in superscript digits (`−3` → `⁻³`).
pub(super) fn superscript(n: i32) -> String {
    n.to_string()
        .chars()
        .map(|c| match c {
            '-' => '\u{207b}',
            '0' => '\u{2070}',
            '1' => '\u{b9}',
            '2' => '\u{b2}',
            '3' => '\u{b3}',
            d => char::from_u32(0x2070 + d.to_digit(10).unwrap_or(0)).unwrap_or(d),
        })
        .collect()
}

/// The tick values plotters draws for `range` when asked for `count` labels.
pub(super) fn ticks(range: &Range<f64>, count: usize) -> Vec<f64> {
    RangedCoordf64::from(range.clone()).key_points(count)
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

/// A 2-D chart of `area` with a title, axis descriptions and a light grid.
pub(super) type Chart2d<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Tick labels per axis of a 2-D chart.
const X_TICKS: usize = 5;
const Y_TICKS: usize = 6;

/// One axis of a 2-D chart: its range, its title and how its ticks are written.
pub(super) struct Axis2d<'t> {
    /// The data range.
    pub(super) range: Range<f64>,
    /// The axis title, with its unit.
    pub(super) title: &'t str,
    /// Tick labels: numbers in one [`NumberFormat`], powers of ten (for an axis that
    /// shows `log10` of its values), or names.
    pub(super) ticks: TickStyle<'t>,
}

/// How the ticks of an axis are labelled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum TickStyle<'t> {
    /// Plain numbers.
    Numbers,
    /// The axis holds `log10(v)`: integer ticks labelled `10ᵏ`, no others.
    Decades,
    /// Categories: a name at each of these values, no other label.
    Names(&'t [(f64, &'t str)]),
}

impl<'t> Axis2d<'t> {
    /// A numeric axis over `range` titled `title`.
    pub(super) fn new(range: Range<f64>, title: &'t str) -> Self {
        Self {
            range,
            title,
            ticks: TickStyle::Numbers,
        }
    }

    /// How many ticks the chart's mesh may draw for `count` asked: one per name for
    /// names (plotters puts tick marks on its own round values, so more would leave
    /// unlabelled marks between the categories), `count` otherwise.
    fn mesh_ticks(&self, count: usize) -> usize {
        match self.ticks {
            TickStyle::Names(names) => names.len().max(1),
            TickStyle::Numbers | TickStyle::Decades => count,
        }
    }

    /// The tick values and labels for `count` ticks, and the suffix of the title.
    fn labels(&self, count: usize) -> (Vec<(f64, String)>, String) {
        let values = ticks(&self.range, count);
        match self.ticks {
            TickStyle::Numbers => {
                let format = NumberFormat::for_ticks(&values);
                let labels = values.iter().map(|&v| (v, format.label(v))).collect();
                (labels, format.suffix())
            }
            TickStyle::Decades => {
                let lo = self.range.start.ceil() as i32;
                let hi = self.range.end.floor() as i32;
                let step = ((hi - lo) / count as i32).max(1);
                let labels = (lo..=hi)
                    .step_by(step as usize)
                    .map(|k| (f64::from(k), format!("10{}", superscript(k))))
                    .collect();
                (labels, String::new())
            }
            TickStyle::Names(names) => (
                names.iter().map(|&(v, s)| (v, s.to_owned())).collect(),
                String::new(),
            ),
        }
    }
}

/// Builds a titled 2-D chart on `area`, whose label areas are sized from the labels
/// they hold so that tick labels and axis titles never meet.
pub(super) fn chart_2d<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    print: Print,
    title: &str,
    x: Axis2d<'_>,
    y: Axis2d<'_>,
) -> Result<Chart2d<'a, DB>, PlotError> {
    let text = print.text();
    let (x_labels, x_suffix) = x.labels(X_TICKS);
    let (y_labels, y_suffix) = y.labels(Y_TICKS);
    let widest = y_labels
        .iter()
        .map(|(_, s)| text_width(area, s, &text))
        .max()
        .unwrap_or(0);
    let tick = print.i(3.0);
    let line = print.line();
    let mut builder = ChartBuilder::on(area);
    if !title.is_empty() {
        builder.caption(title, print.title());
    }
    let mut chart = builder
        .margin_top(print.i(4.0))
        .margin_bottom(print.i(2.0))
        .margin_left(print.i(2.0))
        .margin_right(print.i(10.0))
        .x_label_area_size(2 * tick + line + print.i(2.0) + line)
        .y_label_area_size(2 * tick + widest + print.i(4.0) + line)
        .build_cartesian_2d(x.range.clone(), y.range.clone())?;
    let x_title = format!("{}{x_suffix}", x.title);
    let y_title = format!("{}{y_suffix}", y.title);
    let x_text = |v: &f64| nearest_label(&x_labels, *v);
    let y_text = |v: &f64| nearest_label(&y_labels, *v);
    let axis = BLACK.stroke_width(print.stroke(0.6));
    chart
        .configure_mesh()
        .x_desc(x_title)
        .y_desc(y_title)
        .axis_desc_style(print.text())
        .label_style(print.text())
        .axis_style(axis)
        .set_all_tick_mark_size(tick)
        .x_labels(x.mesh_ticks(X_TICKS))
        .y_labels(y.mesh_ticks(Y_TICKS))
        .x_label_formatter(&x_text)
        .y_label_formatter(&y_text)
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(220, 220, 220).stroke_width(print.stroke(0.3)))
        .draw()?;
    Ok(chart)
}

/// The label of the tick at `v` (empty when `v` is not one of the labelled ticks).
fn nearest_label(labels: &[(f64, String)], v: f64) -> String {
    labels
        .iter()
        .find(|(t, _)| (t - v).abs() <= 1e-9 * t.abs().max(1.0))
        .map(|(_, s)| s.clone())
        .unwrap_or_default()
}

// ---------------------------------------------------------------------------------
// Legends, drawn in a strip of their own so that they never cover data.

/// The mark of a legend entry, drawn as in the plot.
#[derive(Debug, Clone, Copy)]
pub(super) enum Mark {
    /// A line of the colour and width (points), solid or dashed.
    Line(RGBColor, f64, Dash),
    /// A filled disc of the colour and radius (points).
    Dot(RGBColor, f64),
    /// A hollow circle of the colour and radius (points).
    Ring(RGBColor, f64),
    /// A filled triangle.
    Triangle(RGBColor),
    /// A cross.
    Cross(RGBColor),
    /// A filled square.
    Square(RGBColor),
    /// A filled patch with a border of the second colour.
    Patch(RGBColor, RGBColor),
}

/// Solid or dashed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Dash {
    /// A solid line.
    Solid,
    /// A dashed line (4 pt on, 2.5 pt off).
    Dashed,
}

/// Length of a legend's line mark, in points.
const MARK_PT: f64 = 16.0;

impl Mark {
    /// Draws the mark with its left end at `(x, y)` (its centre line at `y`).
    pub(super) fn draw<DB: DrawingBackend>(
        self,
        area: &DrawingArea<DB, Shift>,
        print: Print,
        (x, y): (i32, i32),
    ) -> Drawn {
        let c = (x + print.i(MARK_PT / 2.0), y);
        match self {
            Mark::Line(color, width, dash) => dashed_line(
                area,
                &[(x, y), (x + print.i(MARK_PT), y)],
                color.stroke_width(print.stroke(width)),
                dash,
                print,
            ),
            Mark::Dot(color, r) => {
                area.draw(&Circle::new(c, print.i(r), color.filled()))?;
                Ok(())
            }
            Mark::Ring(color, r) => {
                let style = color.stroke_width(print.stroke(0.8));
                area.draw(&Circle::new(c, print.i(r), style))?;
                Ok(())
            }
            Mark::Triangle(color) => {
                area.draw(&TriangleMarker::new(c, print.i(3.5), color.filled()))?;
                Ok(())
            }
            Mark::Cross(color) => {
                let style = color.stroke_width(print.stroke(1.0));
                area.draw(&Cross::new(c, print.i(3.0), style))?;
                Ok(())
            }
            Mark::Square(color) => {
                let r = print.i(3.0);
                area.draw(&Rectangle::new(
                    [(c.0 - r, c.1 - r), (c.0 + r, c.1 + r)],
                    color.filled(),
                ))?;
                Ok(())
            }
            Mark::Patch(fill, border) => {
                let (hw, hh) = (print.i(MARK_PT / 2.0), print.i(4.0));
                let corners = [(c.0 - hw, c.1 - hh), (c.0 + hw, c.1 + hh)];
                area.draw(&Rectangle::new(corners, fill.filled()))?;
                area.draw(&Rectangle::new(
                    corners,
                    border.stroke_width(print.stroke(0.8)),
                ))?;
                Ok(())
            }
        }
    }
}

/// Draws a polyline of pixel points, solid or dashed.
pub(super) fn dashed_line<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    points: &[(i32, i32)],
    style: ShapeStyle,
    dash: Dash,
    print: Print,
) -> Drawn {
    if dash == Dash::Solid {
        area.draw(&PathElement::new(points.to_vec(), style))?;
        return Ok(());
    }
    let (on, off) = (print.px(4.0), print.px(2.5));
    // The dash pattern runs on across the polyline's corners: `left` pixels remain
    // of the current dash (`drawing`) or gap.
    let (mut drawing, mut left) = (true, on);
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (dx, dy) = (f64::from(b.0 - a.0), f64::from(b.1 - a.1));
        let length = dx.hypot(dy);
        let at = |s: f64| {
            (
                a.0 + (dx * s / length).round() as i32,
                a.1 + (dy * s / length).round() as i32,
            )
        };
        let mut t = 0.0;
        while length - t > 1e-9 {
            let step = left.min(length - t);
            if drawing {
                area.draw(&PathElement::new(vec![at(t), at(t + step)], style))?;
            }
            t += step;
            left -= step;
            if left <= 1e-9 {
                drawing = !drawing;
                left = if drawing { on } else { off };
            }
        }
    }
    Ok(())
}

/// A legend: marks with their labels, laid out in a grid in a strip under a chart.
#[derive(Debug, Clone, Default)]
pub(super) struct Legend {
    entries: Vec<(Mark, String)>,
}

/// Where a legend's entries go: per entry, its column's left edge, its first row and
/// its lines of text; and the number of rows.
struct LegendLayout {
    placed: Vec<(i32, i32, Vec<String>)>,
    rows: i32,
}

impl Legend {
    /// An empty legend.
    pub(super) fn new() -> Self {
        Self::default()
    }

    /// Adds an entry.
    pub(super) fn add(&mut self, mark: Mark, label: impl Into<String>) {
        self.entries.push((mark, label.into()));
    }

    /// Lays the entries out in as many equal columns as the widest fits in `width`
    /// pixels (entries wider than the strip are wrapped at spaces onto more rows).
    fn layout<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        print: Print,
        width: i32,
    ) -> LegendLayout {
        let style = print.text();
        let mark = print.i(MARK_PT + 4.0);
        let spacing = print.i(14.0);
        let text_room = (width - mark).max(1);
        let lines: Vec<Vec<String>> = self
            .entries
            .iter()
            .map(|(_, text)| wrap(area, text, &style, text_room))
            .collect();
        let widest = lines
            .iter()
            .flatten()
            .map(|l| text_width(area, l, &style))
            .max()
            .unwrap_or(0)
            + mark;
        let columns =
            ((width + spacing) / (widest + spacing)).clamp(1, self.entries.len().max(1) as i32);
        let column_width = if columns > 1 {
            (width + spacing) / columns
        } else {
            width
        };
        let mut placed = Vec::new();
        let mut row = 0;
        let mut tallest = 0;
        for (k, l) in lines.into_iter().enumerate() {
            let column = k as i32 % columns;
            if column == 0 && k > 0 {
                row += tallest;
                tallest = 0;
            }
            tallest = tallest.max(l.len() as i32);
            placed.push((column * column_width, row, l));
        }
        LegendLayout {
            placed,
            rows: row + tallest,
        }
    }

    /// Splits `area` into the chart's part and the legend's strip at its bottom (an
    /// empty strip without entries).
    pub(super) fn split<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        print: Print,
    ) -> (DrawingArea<DB, Shift>, DrawingArea<DB, Shift>) {
        let (w, h) = area.dim_in_pixel();
        let indent = print.i(8.0);
        let rows = self.layout(area, print, w as i32 - 2 * indent).rows;
        let strip = if rows == 0 {
            0
        } else {
            rows * print.line() + print.i(4.0)
        };
        area.split_vertically(h as i32 - strip)
    }

    /// Draws the legend in `strip` (from [`Legend::split`]).
    pub(super) fn draw<DB: DrawingBackend>(
        &self,
        strip: &DrawingArea<DB, Shift>,
        print: Print,
    ) -> Drawn {
        let (w, _) = strip.dim_in_pixel();
        let indent = print.i(8.0);
        let style = print.text();
        let layout = self.layout(strip, print, w as i32 - 2 * indent);
        for ((mark, _), (x, row, lines)) in self.entries.iter().zip(&layout.placed) {
            let y = |r: i32| print.i(2.0) + (row + r) * print.line() + print.line() / 2;
            mark.draw(strip, print, (indent + x, y(0)))?;
            for (r, line) in lines.iter().enumerate() {
                label(
                    strip,
                    line,
                    (indent + x + print.i(MARK_PT + 4.0), y(r as i32)),
                    &style,
                    HPos::Left,
                    Valign::Middle,
                )?;
            }
        }
        Ok(())
    }
}

/// `text` cut at spaces into lines at most `width` pixels wide (a word wider than that
/// stands alone on its line).
fn wrap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    style: &TextStyle<'_>,
    width: i32,
) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut current = String::new();
    for word in text.split(' ') {
        let candidate = if current.is_empty() {
            word.to_owned()
        } else {
            format!("{current} {word}")
        };
        if current.is_empty() || text_width(area, &candidate, style) <= width {
            current = candidate;
        } else {
            lines.push(std::mem::replace(&mut current, word.to_owned()));
        }
    }
    lines.push(current);
    lines
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
    fn one_format_per_axis() {
        let f = NumberFormat::for_ticks(&[0.0, 0.5, 1.0, 1.5]);
        assert_eq!(f.decimals, 1);
        assert_eq!(
            [0.0, 0.5, 1.0].map(|v| f.label(v)),
            ["0.0", "0.5", "1.0"].map(str::to_owned)
        );
        assert_eq!(f.label(-1.5), "\u{2212}1.5");
        let f = NumberFormat::for_ticks(&[50_000.0, 100_000.0, 300_000.0]);
        assert_eq!((f.power, f.decimals), (5, 1));
        assert_eq!(f.label(300_000.0), "3.0");
        assert_eq!(f.suffix(), " (\u{d7}10\u{2075})");
        assert_eq!(NumberFormat::for_ticks(&[1.0, 2.0, 3.0]).decimals, 0);
        assert_eq!(superscript(-12), "\u{207b}\u{b9}\u{b2}");
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

    #[test]
    fn svg_states_its_print_size() {
        let svg = "<svg width=\"600\" height=\"300\" viewBox=\"0 0 600 300\">";
        let out = svg_print_size(svg, (600, 300), 300.0);
        assert!(
            out.starts_with("<svg width=\"2.000in\" height=\"1.000in\" viewBox=\"0 0 600 300\"")
        );
    }
}
