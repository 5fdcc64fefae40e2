//! The kernel sets laid out for the fast kernels: structure of arrays, padded to whole
//! SIMD blocks, with a bounding ball and box around every run of [`LANES`] consecutive points.

use ndarray::ArrayView3;

use super::{MetricError, Period};

/// Points per SIMD block (and per bounding ball). Eight `f64` fill one AVX-512 register
/// or two AVX2 registers.
pub(crate) const LANES: usize = 8;

/// Relative safety margin applied to the bounding-ball radii and to the lower bounds
/// derived from them, so that rounding never prunes a point that could win.
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
    centers_soa: Vec<f64>,
    widths: Vec<f64>,
    radii: Vec<f64>,
}

/// One prepared set, as the kernels see it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SetRef<'a> {
    /// `[n][point]`, `dims_pad × points_pad`.
    pub coords: &'a [f64],
    /// `[point][n]`, `points_pad × dims_pad`: the same coordinates point by point, for
    /// broadcasting one point against a block.
    pub points: &'a [f64],
    /// `[chunk][n]`, `chunks × dims_pad`: centres of the bounding balls and boxes.
    pub centers: &'a [f64],
    /// `[n][chunk]`, `dims_pad × chunks_pad`: the same centres, eight chunks per vector
    /// (padded with copies of the last centre).
    pub centers_soa: &'a [f64],
    /// `[chunk][n]`: half-widths of the bounding boxes around the centres, per
    /// coordinate (periodic intervals, already enlarged by the margin).
    pub widths: &'a [f64],
    /// `[chunk]`: radii of the bounding balls (already enlarged by the margin).
    pub radii: &'a [f64],
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
    let mut w = x - period * ((x + half) / period).floor();
    // Rounding can land exactly on the upper end or just below the lower one.
    if w >= half {
        w -= period;
    }
    if w < -half {
        w += period;
    }
    w
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

impl PreparedSets {
    /// Lays out `sets` (`(M, P, N)`: `M` sets of `P` points with `N` coordinates) for the
    /// fast kernels, under the point metric `period`.
    ///
    /// Errors when `P` or `N` is zero or a coordinate is not finite. `M` may be any
    /// number here; the matrix functions ask for at least two sets.
    pub fn new(sets: ArrayView3<'_, f64>, period: Period) -> Result<Self, MetricError> {
        let (m, p, n) = sets.dim();
        if p == 0 || n == 0 {
            return Err(MetricError::EmptySets { shape: (m, p, n) });
        }
        if let Some(((set, point, coord), value)) =
            sets.indexed_iter().find(|(_, v)| !v.is_finite())
        {
            return Err(MetricError::NonFinite {
                set,
                point,
                coord,
                value: *value,
            });
        }
        let period_value = period.radians();
        let dims_pad = match n {
            1..=2 => 2,
            3..=4 => 4,
            5..=8 => 8,
            9..=16 => 16,
            _ => n,
        };
        let points_pad = p.div_ceil(LANES) * LANES;
        let chunks = points_pad / LANES;
        let mut coords = vec![0.0; m * dims_pad * points_pad];
        let mut centers = vec![0.0; m * chunks * dims_pad];
        let mut points_aos = vec![0.0; m * points_pad * dims_pad];
        let chunks_pad = chunks.div_ceil(LANES) * LANES;
        let mut centers_soa = vec![0.0; m * dims_pad * chunks_pad];
        let mut radii = vec![0.0; m * chunks];
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
                let mut radius2: f64 = 0.0;
                for j in 0..LANES {
                    let mut d2 = 0.0;
                    for k in 0..dims_pad {
                        let w = fold(
                            block[k * points_pad + q * LANES + j] - center[k],
                            period_value,
                        );
                        d2 += w * w;
                    }
                    radius2 = radius2.max(d2);
                }
                radii[s * chunks + q] = radius2.sqrt() * (1.0 + BOUND_MARGIN);
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
                for q in 0..chunks_pad {
                    centers_soa[(s * dims_pad + k) * chunks_pad + q] =
                        centers[(s * chunks + q.min(chunks - 1)) * dims_pad + k];
                }
            }
        }
        Ok(Self {
            sets: m,
            points: p,
            dims: n,
            dims_pad,
            points_pad,
            period: period_value,
            period_kind: period,
            coords,
            points_aos,
            centers,
            centers_soa,
            widths,
            radii,
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
        ((2 * self.coords.len()
            + 2 * self.centers.len()
            + self.centers_soa.len()
            + self.radii.len())
            * 8) as u64
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

    pub(crate) fn chunks_pad(&self) -> usize {
        self.chunks().div_ceil(LANES) * LANES
    }

    pub(crate) fn set(&self, s: usize) -> SetRef<'_> {
        let per = self.dims_pad * self.points_pad;
        let chunks = self.chunks();
        let soa = self.dims_pad * self.chunks_pad();
        SetRef {
            coords: &self.coords[s * per..(s + 1) * per],
            points: &self.points_aos[s * per..(s + 1) * per],
            centers: &self.centers[s * chunks * self.dims_pad..(s + 1) * chunks * self.dims_pad],
            centers_soa: &self.centers_soa[s * soa..(s + 1) * soa],
            widths: &self.widths[s * chunks * self.dims_pad..(s + 1) * chunks * self.dims_pad],
            radii: &self.radii[s * chunks..(s + 1) * chunks],
        }
    }

    /// Estimated bytes a [`PreparedSets`] of this shape holds.
    pub fn estimate_bytes(sets: usize, points: usize, dims: usize) -> u64 {
        let dims_pad = dims.next_power_of_two().max(2);
        let points_pad = points.div_ceil(LANES) * LANES;
        let chunks = points_pad / LANES;
        let chunks_pad = chunks.div_ceil(LANES) * LANES;
        (sets as u64)
            * ((dims_pad * (2 * points_pad + 2 * chunks + chunks_pad) + chunks) as u64)
            * 8
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
