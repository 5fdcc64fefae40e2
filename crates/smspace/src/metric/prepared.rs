//! The kernel sets laid out for the fast kernels: structure of arrays padded to whole
//! blocks of [`LANES`] points, an `f32` copy for the filtering passes with its proven
//! error bound, and a bounding box around every run of [`LANES`] consecutive points.

use super::curve::CurveLayout;
use super::period::{CoordinatePeriods, Periods};
use super::{MetricError, Period, SetsView};

pub(crate) use super::period::{fold, wrap};

/// Points per block (and per bounding box): the eight `f32` lanes of one AVX2 register.
pub(crate) const LANES: usize = 8;

/// Chunks per `f32` vector of the centre table.
pub(crate) const WIDE: usize = 16;

/// Points of the ring copies before and after every set (see [`SetRef::ring`]).
pub(crate) const RING: usize = 12;

/// Relative safety margin applied to the bounding boxes and to the lower bounds derived
/// from them, so that rounding never prunes a point that could win.
pub(crate) const BOUND_MARGIN: f64 = 1e-12;

/// Largest coordinate magnitude (after wrapping and centring) of the `f32` filter:
/// beyond it the squares could overflow `f32`, and the kernels compute every pair by
/// brute force in `f64` instead.
const FILTER_MAX: f64 = 1e15;

/// Kernel sets `(M, P, N)` laid out for the fast metric kernels.
///
/// Coordinates are stored set by set, coordinate by coordinate (`[set][n][point]`), so
/// that eight consecutive points of one coordinate load as one vector. `P` is padded to
/// a multiple of eight (one block) by repeating the last point and `N` to 2, 4, 8 or 16
/// by zero coordinates; neither changes any distance. Every periodic coordinate is
/// first wrapped into `[-T/2, T/2)` with its own period (values already there are kept
/// bit for bit), so that a coordinate difference never exceeds one period.
///
/// Besides the exact `f64` coordinates, an `f32` copy (unwrapped coordinates shifted by
/// their mid-range) feeds the filtering passes of the kernels, with proven bounds on
/// the error of any `f32` squared distance (see the `kernel` module): a decision taken
/// on an `f32` value is only trusted with that error to spare.
///
/// Build it once with [`PreparedSets::new`] and reuse it for any number of row blocks.
#[derive(Debug, Clone)]
pub struct PreparedSets {
    sets: usize,
    points: usize,
    dims: usize,
    dims_pad: usize,
    points_pad: usize,
    periods: Periods,
    /// Period of every padded coordinate (`+∞`: not wrapped).
    period_pad: Vec<f64>,
    filter: FilterBounds,
    /// Subtracted from every coordinate of the `f32` copy (see [`Self::offset`]).
    offset: Vec<f64>,
    wide: bool,
    coords: Vec<f64>,
    points_aos: Vec<f64>,
    coords32: Vec<f32>,
    ring32: Vec<f32>,
    centers_narrow: Vec<f32>,
    centers_wide: Vec<f32>,
    /// Boxed: the segment layout holds many buffers, and `PreparedSets` travels by
    /// value (inside the tiles' measures).
    curves: Option<Box<CurveLayout>>,
}

/// One prepared set, as the kernels see it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SetRef<'a> {
    /// `[n][point]`, `dims_pad × points_pad`.
    pub coords: &'a [f64],
    /// `[point][n]`, `points_pad × dims_pad`: the same coordinates point by point.
    pub points: &'a [f64],
    /// `[n][point]`, `dims_pad × points_pad`: the `f32` copy (unwrapped coordinates
    /// shifted by their mid-range).
    pub coords32: &'a [f32],
    /// `[r][n]`, `(P + 2·RING) × dims_pad`: the `f32` points around the ring, point
    /// `(r − RING) mod P` at row `r`, so that any window of up to `2·RING + 1`
    /// consecutive points (modulo `P`) is contiguous.
    pub ring32: &'a [f32],
    /// `[chunk][n]`, `chunks × dims_pad`: the centres of the runs of [`LANES`]
    /// consecutive points in the `f32` frame, for the centre table (which only
    /// orders the work and picks starting points, so its precision never changes a
    /// distance).
    pub centers_narrow: &'a [f32],
    /// `[n][chunk]`, `dims_pad × chunks_wide`: the same `f32` centres, sixteen chunks per
    /// row (padded with copies of the last centre).
    pub centers_wide: &'a [f32],
}

/// Coordinates per point after padding with zeros: the next of 2, 4, 8, …, 64 (the
/// coordinate counts the kernels are compiled for), or `N` itself above 64.
pub(crate) fn pad_dims(n: usize) -> usize {
    if n <= 64 {
        n.next_power_of_two().max(2)
    } else {
        n
    }
}

/// Checks that sets `(M, P, N)` have points (`P, N ≥ 1`) and finite coordinates; the
/// error names the first bad entry.
pub(crate) fn check_points(sets: ndarray::ArrayView3<'_, f64>) -> Result<(), MetricError> {
    let (m, p, n) = sets.dim();
    if p == 0 || n == 0 {
        return Err(MetricError::EmptySets { shape: (m, p, n) });
    }
    if let Some(((set, point, coord), &value)) = sets.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(MetricError::NonFinite {
            set,
            point,
            coord,
            value,
        });
    }
    Ok(())
}

/// How far an `f32` squared distance `s̃` computed by the kernels can be from the exact
/// one `g²` of the same points: `√g² ≤ √(s̃·(1 + rel)) + delta` and
/// `√s̃ ≤ √(g²·(1 + rel)) + delta` (see [`FilterBounds::new`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FilterBounds {
    /// `‖δ‖` of the point distances `g²(a, b)`.
    pub point_delta: f64,
    /// `‖δ‖` of the lifted distances from a point of a segment to a point or a segment
    /// (the `curve` kernels).
    pub segment_delta: f64,
    /// Relative error of the `N` rounded multiply-adds of a sum of squares.
    pub rel: f64,
}

impl FilterBounds {
    /// The bounds for coordinates whose `f32` inputs have magnitude at most `max_abs[n]`
    /// and period `periods[n]` (`+∞`: none).
    ///
    /// A squared distance is `Σ_n x_n²`, where `x_n` is a coordinate difference (folded
    /// or lifted) computed in `f32` as `x̃_n`. With `u = 2⁻²⁴` every input is within
    /// `u·|input|` of its value and every operation rounds once, so
    /// `|x̃_n − x_n| ≤ δ_n` with, for the point metric, `δ_n = 5u·(2x_n + T_n')`
    /// (`T_n' = T_n` when periodic, else 0: two rounded inputs, the difference, the
    /// fold's `T_n − |d|`) and, for the lifted segment quantities, `δ_n = 12u·S_n` with
    /// `S_n` a bound of every intermediate (`1.5·T_n` periodic, `6x_n` unwrapped).
    /// By the triangle inequality in `ℝ^N`, `|‖x̃‖ − ‖x‖| ≤ ‖δ‖`, and the fused
    /// multiply-add chain that sums the squares (all terms non-negative) is within a
    /// relative `N·u` of `‖x̃‖²`; `rel = 2Nu`. Every bound carries 1 % to spare.
    pub fn new(max_abs: &[f64], periods: &[f64]) -> Self {
        let u = f64::from(f32::EPSILON) / 2.0;
        let (mut point, mut segment) = (0.0, 0.0);
        let mut largest: f64 = 0.0;
        for (&x, &t) in max_abs.iter().zip(periods) {
            let (d_point, s) = if t.is_finite() {
                (5.0 * u * (2.0 * x + t), 1.5 * t)
            } else {
                (5.0 * u * 2.0 * x, 6.0 * x)
            };
            let d_segment = 12.0 * u * s;
            largest = largest.max(s);
            point += d_point * d_point;
            segment += d_segment * d_segment;
        }
        // The foot `σ̃` of a lifted point-to-segment distance is itself rounded: with it
        // the distance grows by at most `|w|·|σ̃ − σ*| ≤ 2N·u·S` (Pythagoras), added here.
        let n = max_abs.len() as f64;
        Self {
            point_delta: 1.01 * f64::sqrt(point),
            segment_delta: 1.01 * (f64::sqrt(segment) + 4.0 * n * u * largest),
            rel: 2.02 * max_abs.len() as f64 * u,
        }
    }
}

impl PreparedSets {
    /// Lays out `sets` (`(M, P, N)`: `M` sets of `P` points with `N` coordinates) for the
    /// fast kernels, under the point metric with `periods`: a uniform [`Period`], or
    /// [`Periods`] (one per coordinate). When the sets come with their
    /// [`Closure`](super::Closure) ([`SetsView::with_closure`]) their segments are laid
    /// out too, for the `curve` metric.
    ///
    /// Errors when `P` or `N` is zero, a coordinate is not finite, the periods were
    /// given for another number of coordinates, or the closures do not match the sets
    /// (one per set; at least 2 points per set). `M` may be any number here; the matrix
    /// functions ask for at least two sets.
    pub fn new<'a>(
        sets: impl Into<SetsView<'a>>,
        periods: impl CoordinatePeriods,
    ) -> Result<Self, MetricError> {
        let view: SetsView<'a> = sets.into();
        let sets = view.points();
        let (m, p, n) = sets.dim();
        check_points(sets)?;
        let periods = periods.for_dims(n)?;
        let dims_pad = pad_dims(n);
        let points_pad = p.div_ceil(LANES) * LANES;
        let chunks = points_pad / LANES;
        let period_pad: Vec<f64> = (0..dims_pad)
            .map(|k| {
                if k < n {
                    periods.radians(k)
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        let mut coords = vec![0.0; m * dims_pad * points_pad];
        for (s, set) in sets.outer_iter().enumerate() {
            let block = &mut coords[s * dims_pad * points_pad..(s + 1) * dims_pad * points_pad];
            for k in 0..n {
                let row = &mut block[k * points_pad..(k + 1) * points_pad];
                for (j, slot) in row.iter_mut().enumerate() {
                    *slot = wrap(set[[j.min(p - 1), k]], period_pad[k]);
                }
            }
        }
        let centers = box_centers(&coords, m, points_pad, dims_pad, &period_pad);
        let shape = Shape {
            sets: m,
            points: p,
            points_pad,
            dims_pad,
        };
        let filter = Filter::new(&coords, shape, &period_pad);
        let points_aos = transpose(&coords, m, dims_pad, points_pad);
        let chunks_wide = chunks.div_ceil(WIDE) * WIDE;
        let centers_narrow: Vec<f32> = centers
            .chunks(dims_pad)
            .flat_map(|c| (0..dims_pad).map(|k| (c[k] - filter.offset[k]) as f32))
            .collect();
        let mut centers_wide = vec![0.0; m * dims_pad * chunks_wide];
        for s in 0..m {
            for k in 0..dims_pad {
                for q in 0..chunks_wide {
                    centers_wide[(s * dims_pad + k) * chunks_wide + q] =
                        centers_narrow[(s * chunks + q.min(chunks - 1)) * dims_pad + k];
                }
            }
        }
        let curves = match view.closure() {
            None => None,
            Some(closure) => {
                if closure.len() != m {
                    return Err(MetricError::ClosureLength {
                        found: closure.len(),
                        sets: m,
                    });
                }
                if p < 2 {
                    return Err(MetricError::TooFewPoints { points: p });
                }
                if let Some(pieces) = view.pieces() {
                    if pieces.dim() != (m, p) {
                        return Err(MetricError::ClosureLength {
                            found: pieces.nrows(),
                            sets: m,
                        });
                    }
                }
                Some(Box::new(CurveLayout::new(
                    &coords,
                    m,
                    p,
                    points_pad,
                    n,
                    dims_pad,
                    &period_pad,
                    closure,
                    view.pieces(),
                    &filter.offset,
                )))
            }
        };
        Ok(Self {
            curves,
            sets: m,
            points: p,
            dims: n,
            dims_pad,
            points_pad,
            periods,
            period_pad,
            filter: filter.bounds,
            offset: filter.offset,
            wide: filter.wide,
            coords32: filter.coords32,
            ring32: filter.ring32,
            coords,
            points_aos,
            centers_narrow,
            centers_wide,
        })
    }

    /// Number of sets `M`.
    pub fn len(&self) -> usize {
        self.sets
    }

    /// True when there is no set.
    pub fn is_empty(&self) -> bool {
        self.sets == 0
    }

    /// Points per set `P`.
    pub fn points(&self) -> usize {
        self.points
    }

    /// Coordinates per point `N`.
    pub fn dims(&self) -> usize {
        self.dims
    }

    /// The period of every coordinate of the point metric.
    pub fn periods(&self) -> &Periods {
        &self.periods
    }

    /// The uniform period of the point metric, when every coordinate has the same.
    pub fn period(&self) -> Option<Period> {
        self.periods.as_uniform()
    }

    /// Bytes held by the layout.
    pub fn bytes(&self) -> u64 {
        ((self.coords.len() + self.points_aos.len()) * 8
            + (self.coords32.len()
                + self.ring32.len()
                + self.centers_narrow.len()
                + self.centers_wide.len())
                * 4) as u64
            + self.curves.as_deref().map_or(0, CurveLayout::bytes)
    }

    /// True when the sets were prepared with their closures, as the `curve` metric
    /// needs.
    pub fn has_closure(&self) -> bool {
        self.curves.is_some()
    }

    /// The closure of every set, when it was given.
    pub fn closure(&self) -> Option<&[super::Closure]> {
        self.curves.as_deref().map(|c| c.closure.as_slice())
    }

    pub(crate) fn curves(&self) -> Option<&CurveLayout> {
        self.curves.as_deref()
    }

    /// Period of every padded coordinate (`+∞`: not wrapped).
    pub(crate) fn period_pad(&self) -> &[f64] {
        &self.period_pad
    }

    /// What is subtracted from every coordinate of the `f32` copy before it is rounded
    /// (the mid-range of an unwrapped coordinate; 0 for a periodic one), per padded
    /// coordinate: a point `x` of the sets' range is `(x_n − offset_n) as f32` there.
    pub(crate) fn offset(&self) -> &[f64] {
        &self.offset
    }

    /// The bounds of the error of the `f32` squared distances.
    pub(crate) fn filter(&self) -> FilterBounds {
        self.filter
    }

    /// True when coordinates are too large for the `f32` filter: pairs are computed by
    /// brute force in `f64`.
    pub(crate) fn is_wide(&self) -> bool {
        self.wide
    }

    pub(crate) fn dims_pad(&self) -> usize {
        self.dims_pad
    }

    pub(crate) fn points_pad(&self) -> usize {
        self.points_pad
    }

    pub(crate) fn chunks(&self) -> usize {
        self.points_pad / LANES
    }

    pub(crate) fn chunks_wide(&self) -> usize {
        self.chunks().div_ceil(WIDE) * WIDE
    }

    #[inline(always)]
    pub(crate) fn set(&self, s: usize) -> SetRef<'_> {
        let per = self.dims_pad * self.points_pad;
        let chunks = self.chunks();
        let wide = self.dims_pad * self.chunks_wide();
        let ring = (self.points + 2 * RING) * self.dims_pad;
        let boxes = chunks * self.dims_pad;
        SetRef {
            coords: &self.coords[s * per..(s + 1) * per],
            points: &self.points_aos[s * per..(s + 1) * per],
            coords32: &self.coords32[s * per..(s + 1) * per],
            ring32: &self.ring32[s * ring..(s + 1) * ring],
            centers_narrow: &self.centers_narrow[s * boxes..(s + 1) * boxes],
            centers_wide: &self.centers_wide[s * wide..(s + 1) * wide],
        }
    }

    /// Estimated bytes a [`PreparedSets`] of this shape holds, with the segment layout of
    /// the `curve` metric.
    pub fn estimate_bytes_with_curves(sets: usize, points: usize, dims: usize) -> u64 {
        let dims_pad = pad_dims(dims);
        let points_pad = points.div_ceil(LANES) * LANES;
        Self::estimate_bytes(sets, points, dims)
            + CurveLayout::estimate_bytes(sets, points, points_pad, dims_pad)
    }

    /// Estimated bytes a [`PreparedSets`] of this shape holds.
    pub fn estimate_bytes(sets: usize, points: usize, dims: usize) -> u64 {
        let dims_pad = pad_dims(dims);
        let points_pad = points.div_ceil(LANES) * LANES;
        let chunks = points_pad / LANES;
        let chunks_wide = chunks.div_ceil(WIDE) * WIDE;
        let per_set = dims_pad * 2 * points_pad * 8
            + dims_pad * (points_pad + points + 2 * RING + chunks + chunks_wide) * 4;
        (sets as u64) * per_set as u64
    }
}

/// The shape of the padded layout.
#[derive(Debug, Clone, Copy)]
struct Shape {
    sets: usize,
    points: usize,
    points_pad: usize,
    dims_pad: usize,
}

/// `[set][n][point]` → `[set][point][n]`.
fn transpose(coords: &[f64], m: usize, dims_pad: usize, points_pad: usize) -> Vec<f64> {
    let per = dims_pad * points_pad;
    let mut out = vec![0.0; m * per];
    for s in 0..m {
        for j in 0..points_pad {
            for k in 0..dims_pad {
                out[s * per + j * dims_pad + k] = coords[s * per + k * points_pad + j];
            }
        }
    }
    out
}

/// Centres (periodic means) of every run of [`LANES`] consecutive points.
fn box_centers(
    coords: &[f64],
    m: usize,
    points_pad: usize,
    dims_pad: usize,
    period: &[f64],
) -> Vec<f64> {
    let chunks = points_pad / LANES;
    let mut centers = vec![0.0; m * chunks * dims_pad];
    for s in 0..m {
        let block = &coords[s * dims_pad * points_pad..(s + 1) * dims_pad * points_pad];
        for q in 0..chunks {
            let at = (s * chunks + q) * dims_pad;
            for k in 0..dims_pad {
                let row = &block[k * points_pad..(k + 1) * points_pad];
                let anchor = row[q * LANES];
                let mut shift = 0.0;
                for j in 0..LANES {
                    shift += wrap(row[q * LANES + j] - anchor, period[k]);
                }
                centers[at + k] = wrap(anchor + shift / LANES as f64, period[k]);
            }
        }
    }
    centers
}

/// The `f32` copy of the coordinates and its error bound.
struct Filter {
    /// Subtracted from every coordinate before rounding (mid-range of an unwrapped
    /// coordinate over all sets; 0 for a periodic one).
    offset: Vec<f64>,
    coords32: Vec<f32>,
    ring32: Vec<f32>,
    bounds: FilterBounds,
    wide: bool,
}

impl Filter {
    fn new(coords: &[f64], shape: Shape, period: &[f64]) -> Self {
        let Shape {
            sets: m,
            points: p,
            points_pad,
            dims_pad,
        } = shape;
        let per = dims_pad * points_pad;
        let mut offset = vec![0.0; dims_pad];
        let mut max_abs = vec![0.0f64; dims_pad];
        for k in 0..dims_pad {
            if period[k].is_finite() {
                max_abs[k] = 0.5 * period[k];
                continue;
            }
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for s in 0..m {
                for &x in &coords[s * per + k * points_pad..][..points_pad] {
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
            }
            if lo <= hi {
                offset[k] = 0.5 * lo + 0.5 * hi;
                max_abs[k] = (hi - offset[k]).max(offset[k] - lo);
            }
        }
        let wide = max_abs
            .iter()
            .zip(period)
            .any(|(&x, &t)| x > FILTER_MAX || t > FILTER_MAX && t.is_finite());
        let coords32: Vec<f32> = coords
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let k = (i % per) / points_pad;
                if wide {
                    0.0
                } else {
                    (x - offset[k]) as f32
                }
            })
            .collect();
        let ring_rows = p + 2 * RING;
        let mut ring32 = vec![0.0; m * ring_rows * dims_pad];
        for s in 0..m {
            for r in 0..ring_rows {
                let j = (r + RING * p - RING) % p;
                for k in 0..dims_pad {
                    ring32[(s * ring_rows + r) * dims_pad + k] =
                        coords32[s * per + k * points_pad + j];
                }
            }
        }
        // The mid-range subtraction rounds in f64 (relative 2⁻⁵³, far below the f32
        // terms): enlarge the magnitudes a little for it.
        let inputs: Vec<f64> = max_abs.iter().map(|x| x * (1.0 + 1e-9)).collect();
        Self {
            bounds: FilterBounds::new(&inputs, period),
            offset,
            coords32,
            ring32,
            wide,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use std::f64::consts::{PI, TAU};

    /// The `f32` squared distance as the kernels compute it, on the prepared copy.
    fn filtered(a: &[f32], b: &[f32], period: &[f64]) -> f64 {
        let mut acc = 0.0f32;
        for k in 0..a.len() {
            let u = (a[k] - b[k]).abs();
            let v = period[k] as f32 - u;
            let w = if u < v { u } else { v };
            acc = w.mul_add(w, acc);
        }
        f64::from(acc)
    }

    /// The error bounds hold on random points, periodic, unwrapped (shifted) and
    /// mixed, both ways, and are small for angles.
    #[test]
    fn the_filter_error_bound_holds() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(5);
        let cases: [(Vec<f64>, f64); 3] = [
            (vec![TAU; 4], PI),
            (vec![f64::INFINITY; 3], 50.0),
            (vec![TAU, 1.5, f64::INFINITY], 7.0),
        ];
        for (period, spread) in cases {
            let n = period.len();
            let sets = ndarray::Array3::from_shape_fn((20, 9, n), |_| {
                rng.random_range(-spread..spread) + 1000.0
            });
            let periods =
                Periods::new(period.iter().map(|&t| t.is_finite().then_some(t)).collect()).unwrap();
            let prepared = PreparedSets::new(sets.view(), &periods).unwrap();
            let bounds = prepared.filter();
            let (pp, dp) = (prepared.points_pad(), prepared.dims_pad());
            let point32 = |s: usize, j: usize| -> Vec<f32> {
                (0..n)
                    .map(|k| prepared.set(s).coords32[k * pp + j])
                    .collect()
            };
            let point64 = |s: usize, j: usize| -> Vec<f64> {
                (0..n).map(|k| prepared.set(s).points[j * dp + k]).collect()
            };
            for s in 0..20 {
                for t in 0..20 {
                    for j in 0..9 {
                        let (a, b) = (point64(s, j), point64(t, (j * 7) % 9));
                        let exact: f64 = (0..n).map(|k| fold(a[k] - b[k], period[k]).powi(2)).sum();
                        let fast = filtered(&point32(s, j), &point32(t, (j * 7) % 9), &period);
                        let grow = 1.0 + bounds.rel;
                        assert!(exact.sqrt() <= (fast * grow).sqrt() + bounds.point_delta);
                        assert!(fast.sqrt() <= (exact * grow).sqrt() + bounds.point_delta);
                    }
                }
            }
            if period[0].is_finite() && n == 4 {
                assert!(bounds.point_delta < 1e-5, "{bounds:?}");
                assert!(bounds.segment_delta < 3e-5, "{bounds:?}");
            }
        }
    }

    #[test]
    fn huge_coordinates_leave_the_filter() {
        let sets = ndarray::Array3::from_shape_fn((2, 3, 2), |(s, j, _)| 1e30 * (s + j) as f64);
        let prepared = PreparedSets::new(sets.view(), Period::None).unwrap();
        assert!(prepared.is_wide());
        let sets = ndarray::Array3::from_shape_fn((2, 3, 2), |(s, j, _)| (s + j) as f64);
        assert!(!PreparedSets::new(sets.view(), Period::None)
            .unwrap()
            .is_wide());
    }
}
