//! The kernel sets laid out for the fast kernels: structure of arrays, padded to whole
//! SIMD blocks, with a bounding box around every run of [`LANES`] consecutive points.

use super::curve::CurveLayout;
use super::{MetricError, Period, SetsView};

/// Points per SIMD block (and per bounding box). Eight `f64` fill one AVX-512 register
/// or two AVX2 registers.
pub(crate) const LANES: usize = 8;

/// Chunks per `f32` vector of the centre table: sixteen `f32` fill one AVX-512
/// register.
pub(crate) const WIDE: usize = 16;

/// Relative safety margin applied to the bounding boxes and to the lower bounds derived
/// from them, so that rounding never prunes a point that could win.
pub(crate) const BOUND_MARGIN: f64 = 1e-12;

/// Kernel sets `(M, P, N)` laid out for the fast metric kernels.
///
/// Coordinates are stored set by set, coordinate by coordinate (`[set][n][point]`), so
/// that eight consecutive points of one coordinate load as one vector. `P` is padded to
/// a multiple of eight (one SIMD block) by repeating the last point and `N` to 2, 4, 8 or 16 by
/// zero coordinates; neither changes any distance. With a periodic metric every
/// coordinate is first wrapped into `[-T/2, T/2)` (values already there are kept
/// bit for bit), so that a coordinate difference never exceeds one period.
///
/// Build it once with [`PreparedSets::new`] and reuse it for any number of row blocks.
#[derive(Debug, Clone)]
pub struct PreparedSets {
    sets: usize,
    points: usize,
    dims: usize,
    dims_pad: usize,
    points_pad: usize,
    period: f64,
    period_kind: Period,
    coords: Vec<f64>,
    points_aos: Vec<f64>,
    centers: Vec<f64>,
    centers_narrow: Vec<f32>,
    centers_wide: Vec<f32>,
    widths: Vec<f64>,
    curves: Option<CurveLayout>,
}

/// One prepared set, as the kernels see it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SetRef<'a> {
    /// `[n][point]`, `dims_pad × points_pad`.
    pub coords: &'a [f64],
    /// `[point][n]`, `points_pad × dims_pad`: the same coordinates point by point, for
    /// broadcasting one point against a block.
    pub points: &'a [f64],
    /// `[chunk][n]`, `chunks × dims_pad`: centres of the bounding boxes.
    pub centers: &'a [f64],
    /// `[chunk][n]`: the centres rounded to `f32`, for the centre table (which only
    /// orders the work and picks starting points, so its precision never changes a
    /// distance).
    pub centers_narrow: &'a [f32],
    /// `[n][chunk]`, `dims_pad × chunks_wide`: the same `f32` centres, sixteen chunks per
    /// vector (padded with copies of the last centre).
    pub centers_wide: &'a [f32],
    /// `[chunk][n]`: half-widths of the bounding boxes around the centres, per
    /// coordinate (periodic intervals, already enlarged by the margin).
    pub widths: &'a [f64],
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

/// Wraps `u` into `[-T/2, T/2)`, leaving values already there untouched.
pub(crate) fn wrap(x: f64, period: f64) -> f64 {
    if !period.is_finite() {
        return x;
    }
    let half = 0.5 * period;
    if (-half..half).contains(&x) {
        return x;
    }
    // The remainder is exact (fmod), so even a coordinate near 1e300 lands in range;
    // `rem_euclid` can round up to exactly `T` for a tiny negative `x`.
    let w = x.rem_euclid(period);
    if w >= half {
        w - period
    } else {
        w
    }
}

/// Periodic difference `h(u)` folded to its magnitude, for `|u| < T` (inputs wrapped).
#[inline(always)]
pub(crate) fn fold(u: f64, period: f64) -> f64 {
    let u = u.abs();
    let v = period - u;
    if v < u {
        v
    } else {
        u
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

impl PreparedSets {
    /// Lays out `sets` (`(M, P, N)`: `M` sets of `P` points with `N` coordinates) for the
    /// fast kernels, under the point metric `period`. When the sets come with their
    /// [`Closure`](super::Closure) ([`SetsView::with_closure`]) their segments are laid
    /// out too, for the `curve` metric.
    ///
    /// Errors when `P` or `N` is zero, a coordinate is not finite, or the closures do
    /// not match the sets (one per set; at least 2 points per set). `M` may be any
    /// number here; the matrix functions ask for at least two sets.
    pub fn new<'a>(sets: impl Into<SetsView<'a>>, period: Period) -> Result<Self, MetricError> {
        let view: SetsView<'a> = sets.into();
        let sets = view.points();
        let (m, p, n) = sets.dim();
        check_points(sets)?;
        let period_value = period.radians();
        let dims_pad = pad_dims(n);
        let points_pad = p.div_ceil(LANES) * LANES;
        let chunks = points_pad / LANES;
        let mut coords = vec![0.0; m * dims_pad * points_pad];
        let mut centers = vec![0.0; m * chunks * dims_pad];
        let mut points_aos = vec![0.0; m * points_pad * dims_pad];
        let chunks_wide = chunks.div_ceil(WIDE) * WIDE;
        let mut centers_wide = vec![0.0; m * dims_pad * chunks_wide];
        let mut widths = vec![0.0; m * chunks * dims_pad];
        for (s, set) in sets.outer_iter().enumerate() {
            let block = &mut coords[s * dims_pad * points_pad..(s + 1) * dims_pad * points_pad];
            for k in 0..n {
                let row = &mut block[k * points_pad..(k + 1) * points_pad];
                for (j, slot) in row.iter_mut().enumerate() {
                    *slot = wrap(set[[j.min(p - 1), k]], period_value);
                }
            }
            for q in 0..chunks {
                let center = &mut centers[(s * chunks + q) * dims_pad..][..dims_pad];
                for k in 0..n {
                    let row = &block[k * points_pad..(k + 1) * points_pad];
                    let anchor = row[q * LANES];
                    let mut shift = 0.0;
                    for j in 0..LANES {
                        shift += wrap(row[q * LANES + j] - anchor, period_value);
                    }
                    center[k] = wrap(anchor + shift / LANES as f64, period_value);
                }
                for k in 0..dims_pad {
                    let mut width: f64 = 0.0;
                    for j in 0..LANES {
                        let u = fold(
                            block[k * points_pad + q * LANES + j] - center[k],
                            period_value,
                        );
                        width = width.max(u);
                    }
                    widths[(s * chunks + q) * dims_pad + k] = width * (1.0 + BOUND_MARGIN) + 1e-13;
                }
            }
            for j in 0..points_pad {
                for k in 0..dims_pad {
                    points_aos[(s * points_pad + j) * dims_pad + k] = block[k * points_pad + j];
                }
            }
            for k in 0..dims_pad {
                for q in 0..chunks_wide {
                    centers_wide[(s * dims_pad + k) * chunks_wide + q] =
                        centers[(s * chunks + q.min(chunks - 1)) * dims_pad + k] as f32;
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
                Some(CurveLayout::new(
                    &coords,
                    m,
                    p,
                    points_pad,
                    n,
                    dims_pad,
                    period_value,
                    closure,
                ))
            }
        };
        Ok(Self {
            curves,
            sets: m,
            points: p,
            dims: n,
            dims_pad,
            points_pad,
            period: period_value,
            period_kind: period,
            coords,
            points_aos,
            centers_narrow: centers.iter().map(|&x| x as f32).collect(),
            centers,
            centers_wide,
            widths,
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

    /// The point metric's period.
    pub fn period(&self) -> Period {
        self.period_kind
    }

    /// Bytes held by the layout.
    pub fn bytes(&self) -> u64 {
        ((2 * self.coords.len() + 2 * self.centers.len()) * 8
            + (self.centers_narrow.len() + self.centers_wide.len()) * 4) as u64
            + self.curves.as_ref().map_or(0, CurveLayout::bytes)
    }

    /// True when the sets were prepared with their closures, as the `curve` metric
    /// needs.
    pub fn has_closure(&self) -> bool {
        self.curves.is_some()
    }

    /// The closure of every set, when it was given.
    pub fn closure(&self) -> Option<&[super::Closure]> {
        self.curves.as_ref().map(|c| c.closure.as_slice())
    }

    pub(crate) fn curves(&self) -> Option<&CurveLayout> {
        self.curves.as_ref()
    }

    pub(crate) fn period_value(&self) -> f64 {
        self.period
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

    pub(crate) fn set(&self, s: usize) -> SetRef<'_> {
        let per = self.dims_pad * self.points_pad;
        let chunks = self.chunks();
        let wide = self.dims_pad * self.chunks_wide();
        SetRef {
            coords: &self.coords[s * per..(s + 1) * per],
            points: &self.points_aos[s * per..(s + 1) * per],
            centers: &self.centers[s * chunks * self.dims_pad..(s + 1) * chunks * self.dims_pad],
            centers_narrow: &self.centers_narrow
                [s * chunks * self.dims_pad..(s + 1) * chunks * self.dims_pad],
            centers_wide: &self.centers_wide[s * wide..(s + 1) * wide],
            widths: &self.widths[s * chunks * self.dims_pad..(s + 1) * chunks * self.dims_pad],
        }
    }

    /// Estimated bytes a [`PreparedSets`] of this shape holds, with the segment layout of
    /// the `curve` metric.
    pub fn estimate_bytes_with_curves(sets: usize, points: usize, dims: usize) -> u64 {
        let dims_pad = pad_dims(dims);
        let points_pad = points.div_ceil(LANES) * LANES;
        Self::estimate_bytes(sets, points, dims)
            + CurveLayout::estimate_bytes(sets, points_pad, dims_pad)
    }

    /// Estimated bytes a [`PreparedSets`] of this shape holds.
    pub fn estimate_bytes(sets: usize, points: usize, dims: usize) -> u64 {
        let dims_pad = pad_dims(dims);
        let points_pad = points.div_ceil(LANES) * LANES;
        let chunks = points_pad / LANES;
        let chunks_wide = chunks.div_ceil(WIDE) * WIDE;
        let per_set =
            dims_pad * (2 * points_pad + 2 * chunks) * 8 + dims_pad * (chunks + chunks_wide) * 4;
        (sets as u64) * per_set as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn wrap_keeps_values_in_range_bit_for_bit() {
        let t = 2.0 * PI;
        for x in [-PI, -1.0, 0.0, 1.0, PI - 1e-12] {
            assert_eq!(wrap(x, t).to_bits(), x.to_bits());
        }
        for x in [PI, 3.0 * PI + 0.5, -7.0, 100.0] {
            let w = wrap(x, t);
            assert!((-PI..PI).contains(&w), "{x} -> {w}");
            let back = (x - w) / t;
            assert!((back - back.round()).abs() < 1e-9);
        }
        assert_eq!(wrap(123.0, f64::INFINITY), 123.0);
    }
}
