//! The text of a figure as drawn: a drawing backend that records the ink box of every
//! text element instead of drawing it, and the checks a reviewer would make by eye —
//! no two texts overlap or touch, none leaves the figure, none is smaller than
//! [`MIN_FONT_PT`] at the figure's print size.
//!
//! The boxes are the pixels the bitmap backend would colour: plotters' own layout box
//! is not where its glyphs land (the baseline sits half a text size below the top of
//! the box), so the recorder rasterises each text with the same font and transform as
//! the PNG and keeps the extent of the pixels it covers.

use std::cell::RefCell;
use std::fmt;
use std::rc::Rc;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};
use serde::Serialize;

use super::plot::{Figure, MIN_FONT_PT, SIZE_PER_EM};

/// One text element of a figure: its string and the box of its ink, in pixels
/// (`left..right`, `top..bottom`, exclusive ends).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TextBox {
    /// The text.
    pub text: String,
    /// Left edge.
    pub left: i32,
    /// Top edge.
    pub top: i32,
    /// Right edge (exclusive).
    pub right: i32,
    /// Bottom edge (exclusive).
    pub bottom: i32,
    /// The font's em size, in pixels.
    pub em_px: f64,
}

impl TextBox {
    /// Whether the boxes overlap once each is grown by `margin` pixels.
    fn meets(&self, other: &TextBox, margin: i32) -> bool {
        self.left - margin < other.right + margin
            && other.left - margin < self.right + margin
            && self.top - margin < other.bottom + margin
            && other.top - margin < self.bottom + margin
    }
}

/// Every text element of one figure, as drawn.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FigureText {
    /// The figure's file stem.
    pub name: String,
    /// Its size in pixels.
    pub size: (u32, u32),
    /// Pixels per inch at its print size.
    pub dpi: f64,
    /// Its texts, in drawing order.
    pub boxes: Vec<TextBox>,
}

impl FigureText {
    /// What a reviewer would object to, one sentence each: two texts closer than half a
    /// point (overlapping or touching), a text outside the figure, a font smaller than
    /// 9 pt (the smallest text size) at the print size. Empty when the figure is clean.
    pub fn problems(&self) -> Vec<String> {
        let pt = self.dpi / 72.0;
        let margin = (0.25 * pt).ceil() as i32;
        let (w, h) = (self.size.0 as i32, self.size.1 as i32);
        let mut out = Vec::new();
        for b in &self.boxes {
            if b.left < 0 || b.top < 0 || b.right > w || b.bottom > h {
                out.push(format!(
                    "{}: '{}' at ({}, {})-({}, {}) leaves the {w} x {h} figure",
                    self.name, b.text, b.left, b.top, b.right, b.bottom
                ));
            }
            if b.em_px < MIN_FONT_PT * pt - 0.01 {
                out.push(format!(
                    "{}: '{}' is {:.1} pt, less than {MIN_FONT_PT} pt",
                    self.name,
                    b.text,
                    b.em_px / pt
                ));
            }
        }
        for (i, a) in self.boxes.iter().enumerate() {
            for b in &self.boxes[i + 1..] {
                if a.meets(b, margin) {
                    out.push(format!(
                        "{}: '{}' ({}, {})-({}, {}) and '{}' ({}, {})-({}, {}) overlap",
                        self.name,
                        a.text,
                        a.left,
                        a.top,
                        a.right,
                        a.bottom,
                        b.text,
                        b.left,
                        b.top,
                        b.right,
                        b.bottom
                    ));
                }
            }
        }
        out
    }
}

/// The recorder's error type (it never fails).
#[derive(Debug)]
pub(super) struct NeverFails;

impl fmt::Display for NeverFails {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("the text recorder does not fail")
    }
}

impl std::error::Error for NeverFails {}

/// A drawing backend that records text and draws nothing else.
pub(super) struct Recorder {
    size: (u32, u32),
    /// The texts recorded, shared with [`record`], which reads them once drawn.
    boxes: Rc<RefCell<Vec<TextBox>>>,
}

/// Ink lighter than this coverage does not count (anti-aliasing fringes).
const INK: f64 = 0.15;

impl DrawingBackend for Recorder {
    type ErrorType = NeverFails;

    fn get_size(&self) -> (u32, u32) {
        self.size
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn draw_pixel(
        &mut self,
        _: BackendCoord,
        _: BackendColor,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        _: BackendCoord,
        _: BackendCoord,
        _: &S,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        _: BackendCoord,
        _: BackendCoord,
        _: &S,
        _: bool,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        _: I,
        _: &S,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        _: BackendCoord,
        _: u32,
        _: &S,
        _: bool,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        _: I,
        _: &S,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        Ok(())
    }

    /// The default `draw_text` of plotters' backends, keeping the extent of the
    /// covered pixels instead of colouring them.
    fn draw_text<TStyle: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &TStyle,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<NeverFails>> {
        if style.color().alpha == 0.0 || text.trim().is_empty() {
            return Ok(());
        }
        let font = |_| DrawingErrorKind::FontError(Box::new(NeverFails));
        let ((min_x, min_y), (max_x, max_y)) = style.layout_box(text).map_err(font)?;
        let (width, height) = (max_x - min_x, max_y - min_y);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let transform = style.transform();
        let mut ink: Option<(i32, i32, i32, i32)> = None;
        let drawn = style.draw(text, (0, 0), |x, y, color| {
            if color.alpha >= INK {
                let (x, y) = transform.transform(x + dx - min_x, y + dy - min_y);
                let (x, y) = (pos.0 + x, pos.1 + y);
                ink = Some(match ink {
                    None => (x, y, x + 1, y + 1),
                    Some((l, t, r, b)) => (l.min(x), t.min(y), r.max(x + 1), b.max(y + 1)),
                });
            }
            Ok::<(), NeverFails>(())
        });
        drawn
            .map_err(font)?
            .map_err(DrawingErrorKind::DrawingError)?;
        if let Some((left, top, right, bottom)) = ink {
            self.boxes.borrow_mut().push(TextBox {
                text: text.to_owned(),
                left,
                top,
                right,
                bottom,
                em_px: style.size() / SIZE_PER_EM,
            });
        }
        Ok(())
    }
}

/// Draws `figure` on a [`Recorder`] and returns its text.
pub(super) fn record<F: Figure>(figure: &F, name: &str, dpi: f64) -> Result<FigureText, String> {
    super::plot::register_font();
    let size = figure.size();
    let boxes = Rc::new(RefCell::new(Vec::new()));
    {
        let root = Recorder {
            size,
            boxes: Rc::clone(&boxes),
        }
        .into_drawing_area();
        figure.draw(&root).map_err(|e| e.0)?;
        root.present().map_err(|e| e.to_string())?;
    }
    let boxes = boxes.take();
    Ok(FigureText {
        name: name.to_owned(),
        size,
        dpi,
        boxes,
    })
}
