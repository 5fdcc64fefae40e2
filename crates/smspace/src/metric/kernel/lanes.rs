//! Eight `f32` lanes, the vector type of the filtering kernels: one 256-bit register
//! through `pulp`'s safe `V4` token on CPUs with AVX-512 (F, BW, CD, DQ, VL: the
//! comparisons write mask registers, and the compiler has 32 vector registers and the
//! EVEX encodings), through its `V3` token on CPUs with AVX2 + FMA, or plain arrays
//! elsewhere. Every operation rounds the same way on all three, so the kernels give the
//! same bits on each. Every method is `#[inline(always)]`, so that it is compiled in
//! the caller's target-feature context (a helper that is not inlined loses the
//! features and calls the software `fma`).

#[cfg(target_arch = "x86_64")]
use pulp::x86::{V3, V4};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::{__m256, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ};

/// Lanes per vector.
pub(crate) const WIDTH: usize = 8;

/// `[f(0), …, f(N − 1)]` by a plain loop, always inlined: `std::array::from_fn` was
/// often compiled apart (outside the caller's AVX2 context, its vectors passed through
/// memory), about 1 % of the curve kernel's instructions. `zero` only fills the array
/// before the loop.
#[inline(always)]
pub(crate) fn each<T: Copy, const N: usize>(zero: T, f: impl Fn(usize) -> T) -> [T; N] {
    let mut out = [zero; N];
    for (k, slot) in out.iter_mut().enumerate() {
        *slot = f(k);
    }
    out
}

/// Operations on eight `f32` lanes.
pub(crate) trait Lanes: Copy {
    /// The vector.
    type V: Copy;
    /// Every lane `x`.
    fn splat(self, x: f32) -> Self::V;
    /// Eight values.
    fn load(self, x: &[f32; WIDTH]) -> Self::V;
    /// The lanes as an array.
    fn array(self, a: Self::V) -> [f32; WIDTH];
    /// `a + b`.
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a − b`.
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a · b`.
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// The smaller of `a` and `b` (`b` where either is NaN).
    fn min(self, a: Self::V, b: Self::V) -> Self::V;
    /// The larger of `a` and `b` (`b` where either is NaN).
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a · b + c`, rounded once.
    fn mul_add(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `c − a · b`, rounded once.
    fn neg_mul_add(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `|u|`.
    fn abs(self, u: Self::V) -> Self::V;
    /// `min(|u|, t − |u|)`: a coordinate difference folded with period `t` (`+∞`: `|u|`).
    fn fold(self, u: Self::V, t: Self::V) -> Self::V;
    /// `u − t · round(u · inv)` (`inv = 1/t`; `0` without a period): the signed
    /// difference brought near `[−t/2, t/2]`.
    fn swrap(self, u: Self::V, t: Self::V, inv: Self::V) -> Self::V;
    /// Bit `l` set where `a[l] ≤ b[l]`.
    fn le(self, a: Self::V, b: Self::V) -> u32;
    /// Bit `l` set where `a[l] > b[l]`.
    fn gt(self, a: Self::V, b: Self::V) -> u32;
    /// `x` where `a < b`, else `y`.
    fn select_lt(self, a: Self::V, b: Self::V, x: Self::V, y: Self::V) -> Self::V;
    /// The smallest lane.
    fn hmin(self, a: Self::V) -> f32;
}

#[cfg(target_arch = "x86_64")]
impl Lanes for V3 {
    type V = __m256;
    #[inline(always)]
    fn splat(self, x: f32) -> __m256 {
        self.avx._mm256_set1_ps(x)
    }
    #[inline(always)]
    fn load(self, x: &[f32; WIDTH]) -> __m256 {
        pulp::cast(*x)
    }
    #[inline(always)]
    fn array(self, a: __m256) -> [f32; WIDTH] {
        pulp::cast(a)
    }
    #[inline(always)]
    fn add(self, a: __m256, b: __m256) -> __m256 {
        self.avx._mm256_add_ps(a, b)
    }
    #[inline(always)]
    fn sub(self, a: __m256, b: __m256) -> __m256 {
        self.avx._mm256_sub_ps(a, b)
    }
    #[inline(always)]
    fn mul(self, a: __m256, b: __m256) -> __m256 {
        self.avx._mm256_mul_ps(a, b)
    }
    #[inline(always)]
    fn min(self, a: __m256, b: __m256) -> __m256 {
        self.avx._mm256_min_ps(a, b)
    }
    #[inline(always)]
    fn max(self, a: __m256, b: __m256) -> __m256 {
        self.avx._mm256_max_ps(a, b)
    }
    #[inline(always)]
    fn mul_add(self, a: __m256, b: __m256, c: __m256) -> __m256 {
        self.fma._mm256_fmadd_ps(a, b, c)
    }
    #[inline(always)]
    fn neg_mul_add(self, a: __m256, b: __m256, c: __m256) -> __m256 {
        self.fma._mm256_fnmadd_ps(a, b, c)
    }
    #[inline(always)]
    fn abs(self, u: __m256) -> __m256 {
        let magnitude = self
            .avx
            ._mm256_castsi256_ps(self.avx._mm256_set1_epi32(0x7fff_ffff));
        self.avx._mm256_and_ps(u, magnitude)
    }
    #[inline(always)]
    fn fold(self, u: __m256, t: __m256) -> __m256 {
        let magnitude = self
            .avx
            ._mm256_castsi256_ps(self.avx._mm256_set1_epi32(0x7fff_ffff));
        let a = self.avx._mm256_and_ps(u, magnitude);
        self.avx._mm256_min_ps(a, self.avx._mm256_sub_ps(t, a))
    }
    #[inline(always)]
    fn swrap(self, u: __m256, t: __m256, inv: __m256) -> __m256 {
        // Round to nearest, no exceptions.
        let k = self
            .avx
            ._mm256_round_ps::<0x08>(self.avx._mm256_mul_ps(u, inv));
        self.fma._mm256_fnmadd_ps(k, t, u)
    }
    #[inline(always)]
    fn le(self, a: __m256, b: __m256) -> u32 {
        self.avx
            ._mm256_movemask_ps(self.avx._mm256_cmp_ps::<_CMP_LE_OQ>(a, b)) as u32
    }
    #[inline(always)]
    fn gt(self, a: __m256, b: __m256) -> u32 {
        self.avx
            ._mm256_movemask_ps(self.avx._mm256_cmp_ps::<_CMP_GT_OQ>(a, b)) as u32
    }
    #[inline(always)]
    fn select_lt(self, a: __m256, b: __m256, x: __m256, y: __m256) -> __m256 {
        let m = self.avx._mm256_cmp_ps::<_CMP_LT_OQ>(a, b);
        self.avx._mm256_blendv_ps(y, x, m)
    }
    #[inline(always)]
    fn hmin(self, a: __m256) -> f32 {
        let hi = self.avx._mm256_extractf128_ps::<1>(a);
        let lo = self.avx._mm256_castps256_ps128(a);
        let m = self.sse._mm_min_ps(lo, hi);
        let m = self.sse._mm_min_ps(m, self.sse._mm_movehl_ps(m, m));
        let m = self.sse._mm_min_ss(m, self.sse._mm_shuffle_ps::<1>(m, m));
        self.sse._mm_cvtss_f32(m)
    }
}

/// AVX-512: the AVX2 + FMA operations in the AVX-512 context (EVEX forms, 32
/// registers), with comparisons and blends through AVX-512VL mask registers.
#[cfg(target_arch = "x86_64")]
impl Lanes for V4 {
    type V = __m256;
    #[inline(always)]
    fn splat(self, x: f32) -> __m256 {
        (*self).splat(x)
    }
    #[inline(always)]
    fn load(self, x: &[f32; WIDTH]) -> __m256 {
        pulp::cast(*x)
    }
    #[inline(always)]
    fn array(self, a: __m256) -> [f32; WIDTH] {
        pulp::cast(a)
    }
    #[inline(always)]
    fn add(self, a: __m256, b: __m256) -> __m256 {
        (*self).add(a, b)
    }
    #[inline(always)]
    fn sub(self, a: __m256, b: __m256) -> __m256 {
        (*self).sub(a, b)
    }
    #[inline(always)]
    fn mul(self, a: __m256, b: __m256) -> __m256 {
        (*self).mul(a, b)
    }
    #[inline(always)]
    fn min(self, a: __m256, b: __m256) -> __m256 {
        (*self).min(a, b)
    }
    #[inline(always)]
    fn max(self, a: __m256, b: __m256) -> __m256 {
        (*self).max(a, b)
    }
    #[inline(always)]
    fn mul_add(self, a: __m256, b: __m256, c: __m256) -> __m256 {
        (*self).mul_add(a, b, c)
    }
    #[inline(always)]
    fn neg_mul_add(self, a: __m256, b: __m256, c: __m256) -> __m256 {
        (*self).neg_mul_add(a, b, c)
    }
    #[inline(always)]
    fn abs(self, u: __m256) -> __m256 {
        (*self).abs(u)
    }
    #[inline(always)]
    fn fold(self, u: __m256, t: __m256) -> __m256 {
        (*self).fold(u, t)
    }
    #[inline(always)]
    fn swrap(self, u: __m256, t: __m256, inv: __m256) -> __m256 {
        (*self).swrap(u, t, inv)
    }
    #[inline(always)]
    fn le(self, a: __m256, b: __m256) -> u32 {
        u32::from(self.avx512f._mm256_cmp_ps_mask::<_CMP_LE_OQ>(a, b))
    }
    #[inline(always)]
    fn gt(self, a: __m256, b: __m256) -> u32 {
        u32::from(self.avx512f._mm256_cmp_ps_mask::<_CMP_GT_OQ>(a, b))
    }
    #[inline(always)]
    fn select_lt(self, a: __m256, b: __m256, x: __m256, y: __m256) -> __m256 {
        let m = self.avx512f._mm256_cmp_ps_mask::<_CMP_LT_OQ>(a, b);
        self.avx512f._mm256_mask_blend_ps(m, y, x)
    }
    #[inline(always)]
    fn hmin(self, a: __m256) -> f32 {
        (*self).hmin(a)
    }
}

/// The same operations on arrays, for CPUs without AVX2 + FMA (and the tests).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Portable;

impl Lanes for Portable {
    type V = [f32; WIDTH];
    #[inline(always)]
    fn splat(self, x: f32) -> Self::V {
        [x; WIDTH]
    }
    #[inline(always)]
    fn load(self, x: &[f32; WIDTH]) -> Self::V {
        *x
    }
    #[inline(always)]
    fn array(self, a: Self::V) -> [f32; WIDTH] {
        a
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        std::array::from_fn(|l| a[l] + b[l])
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        std::array::from_fn(|l| a[l] - b[l])
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        std::array::from_fn(|l| a[l] * b[l])
    }
    #[inline(always)]
    fn min(self, a: Self::V, b: Self::V) -> Self::V {
        // As the x86 instruction: `b` unless `a < b`.
        std::array::from_fn(|l| if a[l] < b[l] { a[l] } else { b[l] })
    }
    #[inline(always)]
    fn max(self, a: Self::V, b: Self::V) -> Self::V {
        std::array::from_fn(|l| if a[l] > b[l] { a[l] } else { b[l] })
    }
    #[inline(always)]
    fn mul_add(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        std::array::from_fn(|l| a[l].mul_add(b[l], c[l]))
    }
    #[inline(always)]
    fn neg_mul_add(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        std::array::from_fn(|l| (-a[l]).mul_add(b[l], c[l]))
    }
    #[inline(always)]
    fn abs(self, u: Self::V) -> Self::V {
        u.map(f32::abs)
    }
    #[inline(always)]
    fn fold(self, u: Self::V, t: Self::V) -> Self::V {
        std::array::from_fn(|l| {
            let a = u[l].abs();
            let v = t[l] - a;
            if a < v {
                a
            } else {
                v
            }
        })
    }
    #[inline(always)]
    fn swrap(self, u: Self::V, t: Self::V, inv: Self::V) -> Self::V {
        std::array::from_fn(|l| (-(u[l] * inv[l]).round_ties_even()).mul_add(t[l], u[l]))
    }
    #[inline(always)]
    fn le(self, a: Self::V, b: Self::V) -> u32 {
        (0..WIDTH).fold(0, |m, l| m | (u32::from(a[l] <= b[l]) << l))
    }
    #[inline(always)]
    fn gt(self, a: Self::V, b: Self::V) -> u32 {
        (0..WIDTH).fold(0, |m, l| m | (u32::from(a[l] > b[l]) << l))
    }
    #[inline(always)]
    fn select_lt(self, a: Self::V, b: Self::V, x: Self::V, y: Self::V) -> Self::V {
        std::array::from_fn(|l| if a[l] < b[l] { x[l] } else { y[l] })
    }
    #[inline(always)]
    fn hmin(self, a: Self::V) -> f32 {
        a.iter()
            .fold(f32::INFINITY, |m, &x| if x < m { x } else { m })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every operation of the lanes `s` against the portable ones, bit for bit.
    #[inline(always)]
    fn agrees_with_portable<S: Lanes>(s: S) {
        let a = [-3.5f32, 0.0, 1.25, 7.0, -0.1, 3.0, 6.2, -6.2];
        let b = [1.0f32, -0.0, 1.25, -2.0, 0.3, 3.5, 0.1, 6.3];
        let t = [std::f32::consts::TAU; WIDTH];
        let inv = [1.0 / std::f32::consts::TAU; WIDTH];
        let p = Portable;
        let (x, y) = (s.load(&a), s.load(&b));
        let (tv, iv) = (s.load(&t), s.load(&inv));
        let pairs: [([f32; WIDTH], [f32; WIDTH]); 10] = [
            (s.array(s.abs(x)), p.abs(a)),
            (s.array(s.add(x, y)), p.add(a, b)),
            (s.array(s.sub(x, y)), p.sub(a, b)),
            (s.array(s.mul(x, y)), p.mul(a, b)),
            (s.array(s.min(x, y)), p.min(a, b)),
            (s.array(s.max(x, y)), p.max(a, b)),
            (s.array(s.mul_add(x, y, x)), p.mul_add(a, b, a)),
            (s.array(s.neg_mul_add(x, y, x)), p.neg_mul_add(a, b, a)),
            (s.array(s.fold(x, tv)), p.fold(a, t)),
            (s.array(s.swrap(x, tv, iv)), p.swrap(a, t, inv)),
        ];
        for (fast, slow) in pairs {
            assert_eq!(fast.map(f32::to_bits), slow.map(f32::to_bits));
        }
        assert_eq!(s.le(x, y), p.le(a, b));
        assert_eq!(s.gt(x, y), p.gt(a, b));
        assert_eq!(s.le(y, x), p.le(b, a));
        assert_eq!(s.gt(y, x), p.gt(b, a));
        assert_eq!(s.hmin(x), p.hmin(a));
        assert_eq!(s.array(s.select_lt(x, y, x, y)), p.select_lt(a, b, a, b));
        assert_eq!(s.array(s.select_lt(y, x, x, y)), p.select_lt(b, a, a, b));
    }

    /// The AVX2 lanes and the portable ones agree bit for bit on every operation.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_portable_lanes_agree() {
        if let Some(v3) = V3::try_new() {
            v3.vectorize(
                #[inline(always)]
                || agrees_with_portable(v3),
            );
        }
    }

    /// The AVX-512 lanes and the portable ones agree bit for bit on every operation.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx512_and_portable_lanes_agree() {
        if let Some(v4) = V4::try_new() {
            v4.vectorize(
                #[inline(always)]
                || agrees_with_portable(v4),
            );
        }
    }
}
