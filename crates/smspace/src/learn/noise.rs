//! The sensor noise of a log, measured from the log itself (no truth): how far a
//! sample's reading lies from what its motor neighbours predict, extrapolated to
//! neighbours at distance zero.
//!
//! # The estimate
//!
//! A reading is `s_i = f(m_i) + ε_i` with `ε_i` independent noise of variance `σ²`
//! (per sensor). At a probe sample `i`, the affine least-squares fit `s ≈ a + bᵀ(m − m_i)`
//! to its `k` nearest other samples in motor space (not `i` itself) predicts
//! `ŝ_i = a`; the prediction error `e_i = s_i − ŝ_i` holds the probe's own noise, the
//! fit's noise (variance `σ² v_i`, `v_i = (XᵀX)⁻¹₀₀` for the fit's design
//! `X = [1, m_j − m_i]`) and the fit's bias, which the curvature of `f` makes of order
//! `r_i²` (`r_i²` the mean squared distance of the `k` neighbours):
//!
//! ```text
//! E[e_i² / (1 + v_i)] = σ² + c r_i⁴ + …
//! ```
//!
//! Over [`PROBES`] seeded probes and the neighbour counts `k ∈ {2, 3, 4} (N + 1)`, the
//! ordinary least-squares line of `y = e² / (1 + v)` against `x = r⁴` has the intercept
//! `σ̂²` (clamped at 0), per sensor. This is the nearest-neighbour difference estimator
//! (`E[(s_i − s_j)²] = 2σ² + O(‖m_i − m_j‖²)`, whose intercept in the squared distance
//! is `2σ²`) with the gradient fitted away, so that the line's slope is set by the
//! curvature only. The report gives `σ̂` per sensor (sensor units and relative to the
//! sensor's standard deviation), the overall relative `σ̂` (root mean square over the
//! sensors), and the **resolution**: the root mean square of `y` at the smallest
//! neighbour count, relative to the sensors' spread (noise and curvature at the data's
//! spacing). Unless `σ̂` makes nearly all of it (`σ̂ ≥ 0.95 resolution`), the
//! extrapolation is long and the noise is not measured: the data's spacing cannot tell
//! it from the law's curvature, and it is at most the resolution. The same holds when
//! the errors of a probe and of its nearest sample (each with its own fit at the
//! smallest count) are correlated (above 0.3): noise is independent between samples,
//! the law's unexplained change is shared; and when the resolution exceeds a fifth of
//! the sensors' spread ([`MAX_RESOLUTION`]: the data do not resolve the law at all)
//! ([`NoiseEstimate::measurable`]).
//!
//! # The rank of the sensory manifold
//!
//! The same probes give the **local dimension** of the sensory manifold: the slope `B`
//! (`K × N`) of the affine fit to the `4 (N + 1)` nearest samples, each sensor divided
//! by its standard deviation, has the singular values `β_1 ≥ … ≥ β_N`. Noise adds
//! about `K σ̂² q` to every squared singular value (`q = max_j ((XᵀX)⁻¹)_jj`, the
//! slope's variance per unit noise; `σ̂` the relative noise, zero when not measurable):
//! the **spectrum** is the median over the probes of `β_r² − K σ̂² q`, relative to that
//! of `β_1²`, square-rooted (negative medians read 0), and the **floor**
//! `sqrt(K σ̂² q)` on the same scale:
//!
//! ```text
//! spectrum_r = sqrt(median(β_r² − K σ̂² q) / median(β_1² − K σ̂² q)),   floor = sqrt(median(K σ̂² q) / median(β_1² − K σ̂² q)).
//! ```
//!
//! Values under a tenth of the floor ([`FLOOR_SHARE`]) never count; among the rest the
//! rank is `N` when the smallest value exceeds [`FULL_RANK_RATIO`], else the last `r`
//! whose ratio `spectrum_r / spectrum_{r+1}` is at least [`CLEAR_GAP`] (4), else the `r`
//! of the largest ratio ([`spectrum_rank`]). This is the rank of `∂s/∂m`, hence
//! the kernel dimension `N − r`, seen in
//! the data rather than in a fitted law ([`LocalRank`]).
//!
//! # Held-out prediction at each rank
//!
//! The same fits predict samples they did not see. With `v_1, …, v_N` the right
//! singular vectors of the probe's scaled slope `B` (strongest first), the affine fit
//! at rank `r` is held to the `r` strongest directions, `s ≈ a + C V_rᵀ (m − m_i)`; its
//! leave-one-out error at each of the `k` samples is `e_j / (1 − h_j)` (`e_j` the
//! residual, `h_j` the leverage of the design `[1, V_rᵀ (m_j − m_i)]`). The probe's
//! held-out error at rank `r` is the mean of the squared errors over the samples and
//! the sensors (each divided by its standard deviation); the **held-out errors** are
//! their medians over the probes, square-rooted, for `r = 0..=N`, and the rank they
//! read is the least `r` within [`HELD_OUT_TIE`] of the least error
//! ([`held_out_rank`]): the rank the data resolve at their spacing, a lower bound where
//! a weak direction changes the sensors less than the curvature across a
//! neighbourhood.

use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::tree::KdTree;
use super::SensorimotorLog;

/// Most probe samples of the estimate.
pub const PROBES: usize = 4096;

/// The neighbour counts of one probe, in multiples of the affine fit's `N + 1`
/// coefficients.
const LADDER: [usize; 3] = [2, 3, 4];

/// What the noise estimate found (in the law's report, per log).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseEstimate {
    /// `σ̂` per sensor, in the sensor's units.
    pub sigma: Vec<f64>,
    /// `σ̂` per sensor relative to the sensor's standard deviation over the log.
    pub relative: Vec<f64>,
    /// The root mean square of `relative` over the sensors.
    pub relative_overall: f64,
    /// The root mean square prediction error of the nearest affine fits
    /// (`k = 2 (N + 1)`), relative to the sensors' spread (root mean square over the
    /// sensors): noise plus the law's curvature at the data's spacing. Noise well below
    /// it cannot be told from the law's own change.
    pub resolution: f64,
    /// The correlation of the nearest fits' errors at a probe and at its nearest
    /// sample (mean over the sensors): about 0 for noise, large where the errors are
    /// the law's own change, which two near samples share.
    pub neighbour_correlation: f64,
    /// Probe samples.
    pub probes: usize,
}

impl NoiseEstimate {
    /// Whether `σ̂` stands out of the law's own change: the noise makes at least 90 %
    /// of the nearest fits' squared error (`σ̂ ≥ 0.95 resolution`), so that the
    /// extrapolation to zero spacing is short, and the errors at near samples are
    /// nearly uncorrelated (`neighbour_correlation` below [`MAX_CORRELATION`]), as
    /// independent noise makes them. Else `σ̂` is not measured: the noise is at most
    /// the resolution. (On the paper's arm at 10⁵ samples, with no noise, the fits'
    /// errors are 20 to 50 % of the sensors' spread at every neighbour count: the line
    /// cannot separate them from noise, their correlation can.)
    pub fn measurable(&self) -> bool {
        self.relative_overall >= MEASURABLE_SHARE * self.resolution
            && self.neighbour_correlation < MAX_CORRELATION
            && self.resolution < MAX_RESOLUTION
    }

    /// The relative noise the law should assume: `σ̂` when it is measurable, else 0
    /// (noise below the resolution is below the law's own error too).
    pub fn assumed_relative(&self) -> f64 {
        if self.measurable() {
            self.relative_overall
        } else {
            0.0
        }
    }
}

/// Per probe and neighbour count: `(step of the ladder, x = r⁴, y_c = e_c² / (1 + v))`.
type Rows = Vec<(usize, f64, Vec<f64>)>;

/// The least `σ̂ / resolution` of a measured noise ([`NoiseEstimate::measurable`]).
pub const MEASURABLE_SHARE: f64 = 0.95;

/// Fitted samples per coefficient of the affine fit (`N + 1`) below which the
/// estimate is not made: the probes' neighbourhoods would overlap too much.
pub const MIN_SAMPLES_PER_COEFFICIENT: usize = 100;

/// The largest `resolution` at which the noise is measured: where the nearest fits
/// miss by more than a fifth of the sensors' spread, the data do not resolve the law,
/// and its unresolved change looks like noise (the paper's arm at 2·10⁴ samples reads
/// 42 % with no noise).
pub const MAX_RESOLUTION: f64 = 0.2;

/// The largest `neighbour_correlation` of a measured noise.
pub const MAX_CORRELATION: f64 = 0.3;

/// The ratio of consecutive values of the spectrum that ends the rank
/// ([`spectrum_rank`]).
pub const CLEAR_GAP: f64 = 4.0;

/// A value of the debiased spectrum counts when it exceeds this share of the noise
/// floor.
pub const FLOOR_SHARE: f64 = 0.1;

/// A rank with `β_N / β_1` above this ratio is full (as for the law's Jacobian).
pub const FULL_RANK_RATIO: f64 = 0.1;

/// The local dimension of the sensory manifold (see the noise module's docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalRank {
    /// The rank of `∂s/∂m` the data show.
    pub rank: usize,
    /// The median over the probes of `β_r / β_1`, `r = 1..=N`.
    pub spectrum: Vec<f64>,
    /// The median over the probes of `β_floor / β_1`.
    pub floor: f64,
    /// Probes.
    pub probes: usize,
    /// The held-out prediction error at every rank `r = 0..=N`: the median over the
    /// probes of the leave-one-out error of the affine fit whose slope is held to its
    /// `r` strongest directions, relative to the sensors' spread (root mean square
    /// over them). Empty in a report written before it was measured.
    #[serde(default)]
    pub held_out: Vec<f64>,
    /// The rank the held-out errors read: the least `r` whose error is within
    /// [`HELD_OUT_TIE`] of the least ([`held_out_rank`]). Absent without them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_rank: Option<usize>,
}

/// Held-out errors within this factor of the least count as equal
/// ([`held_out_rank`]): 1.02.
pub const HELD_OUT_TIE: f64 = 1.02;

/// What one probe's fits found: the noise rows, and, from the largest fit, the
/// singular values of its scaled slope and `√q`.
struct Probe {
    rows: Rows,
    slope: Option<(Vec<f64>, f64)>,
    /// The prediction errors of the probe and of its nearest sample.
    pair: Option<(Vec<f64>, Vec<f64>)>,
    /// The leave-one-out prediction error at every rank `0..=N` (squared, relative).
    held_out: Option<Vec<f64>>,
}

/// Estimates the noise of `log` and the local rank of its sensory manifold from its rows
/// `fit` (see the module docs); `seed` picks the probes. `None` when there are too few
/// rows (fewer than `MIN_SAMPLES_PER_COEFFICIENT` `× (N + 1)`).
pub fn estimate_local(
    log: &SensorimotorLog,
    fit: &[u32],
    seed: u64,
) -> Option<(NoiseEstimate, LocalRank)> {
    let (n, k) = (log.motors.ncols(), log.sensors.ncols());
    let largest = LADDER[LADDER.len() - 1] * (n + 1);
    if fit.len() < MIN_SAMPLES_PER_COEFFICIENT * (n + 1) {
        return None;
    }
    let mut points = Vec::with_capacity(fit.len() * n);
    for &row in fit {
        points.extend(log.motors.row(row as usize).iter().copied());
    }
    let tree = KdTree::new(n, points, fit.to_vec());
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6e6f_6973);
    let probes = sample(&mut rng, fit.len(), PROBES.min(fit.len())).into_vec();
    let deviations = deviations(log);
    let found: Vec<Probe> = probes
        .par_iter()
        .map(|&p| probe_rows(log, &tree, fit[p], largest, &deviations))
        .collect();
    let mut slopes = Vec::with_capacity(found.len());
    let mut pairs = Vec::with_capacity(found.len());
    let mut held: Vec<Vec<f64>> = Vec::with_capacity(found.len());
    let mut rows: Rows = Vec::with_capacity(found.len() * LADDER.len());
    for probe in found {
        rows.extend(probe.rows);
        slopes.extend(probe.slope);
        pairs.extend(probe.pair);
        held.extend(probe.held_out);
    }
    if rows.len() < 3 || slopes.is_empty() {
        return None;
    }
    let mut sigma = vec![0.0; k];
    let mut relative = vec![0.0; k];
    let nearest: Vec<&(usize, f64, Vec<f64>)> = rows.iter().filter(|r| r.0 == 0).collect();
    let mut closest = 0.0;
    for c in 0..k {
        let (intercept, _) = line(rows.iter().map(|r| (r.1, r.2[c])));
        sigma[c] = intercept.max(0.0).sqrt();
        let spread = deviations[c].max(f64::MIN_POSITIVE);
        relative[c] = sigma[c] / spread;
        let error = nearest.iter().map(|r| r.2[c]).sum::<f64>() / nearest.len().max(1) as f64;
        closest += error / (spread * spread);
    }
    let relative_overall = (relative.iter().map(|r| r * r).sum::<f64>() / k as f64).sqrt();
    let correlation = (0..k)
        .map(|c| {
            let (mut xy, mut xx, mut yy) = (0.0, 0.0, 0.0);
            for (a, b) in &pairs {
                xy += a[c] * b[c];
                xx += a[c] * a[c];
                yy += b[c] * b[c];
            }
            xy / (xx * yy).sqrt().max(f64::MIN_POSITIVE)
        })
        .sum::<f64>()
        / k as f64;
    let noise = NoiseEstimate {
        sigma,
        relative,
        relative_overall,
        resolution: (closest / k as f64).sqrt(),
        neighbour_correlation: correlation,
        probes: probes.len(),
    };
    let mut rank = local_rank(&slopes, noise.assumed_relative(), n, k);
    if !held.is_empty() {
        rank.held_out = (0..=n)
            .map(|r| median(held.iter().map(|e| e[r]).collect()).sqrt())
            .collect();
        rank.held_out_rank = Some(held_out_rank(&rank.held_out));
    }
    Some((noise, rank))
}

/// The median of `values` (not empty), the upper one of an even count.
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// The median spectrum of slopes whose squared singular values `β_r²` each carry the
/// noise's bias `b` (`(β, b)` per slope, `β` descending, at least `n` values): the
/// median over the slopes of `β_r² − b` relative to that of `β_1² − b`, square-rooted
/// (negative medians read 0), and the floor `sqrt(median(b) / median(β_1² − b))` (see
/// the noise module's docs). `slopes` is not empty.
pub(super) fn debiased_spectrum(slopes: &[(Vec<f64>, f64)], n: usize) -> (Vec<f64>, f64) {
    let squares: Vec<f64> = (0..n)
        .map(|r| median(slopes.iter().map(|(s, b)| s[r] * s[r] - b).collect()))
        .collect();
    let largest = squares[0].max(f64::MIN_POSITIVE);
    let spectrum = squares
        .iter()
        .map(|&l| (l.max(0.0) / largest).sqrt())
        .collect();
    let floor = (median(slopes.iter().map(|(_, b)| *b).collect()) / largest).sqrt();
    (spectrum, floor)
}

/// The rank from the probes' slope spectra (see the noise module's docs).
fn local_rank(slopes: &[(Vec<f64>, f64)], relative_noise: f64, n: usize, k: usize) -> LocalRank {
    // What noise alone adds to every squared singular value of a probe's slope.
    let noise = |q: f64| k as f64 * (relative_noise * q).powi(2);
    let biased: Vec<(Vec<f64>, f64)> = slopes.iter().map(|(s, q)| (s.clone(), noise(*q))).collect();
    let (spectrum, floor) = debiased_spectrum(&biased, n);
    LocalRank {
        rank: spectrum_rank(&spectrum, FLOOR_SHARE * floor),
        spectrum,
        floor,
        probes: slopes.len(),
        held_out: Vec::new(),
        held_out_rank: None,
    }
}

/// The rank that held-out errors `errors[r]` (`r = 0..=N`) read: the least `r` whose
/// error is within [`HELD_OUT_TIE`] of the least, the rank whose fits predict unseen
/// samples best at the data's spacing. Directions weaker than the curvature across a
/// neighbourhood do not improve the prediction, so it reads at most the rank the data
/// resolve (the paper's arm at 10⁶ samples: 2 of 3, its position seen through lights
/// 4 to 6 units away changing the sensors less than the orientation's curvature).
pub fn held_out_rank(errors: &[f64]) -> usize {
    let least = errors.iter().copied().fold(f64::INFINITY, f64::min);
    errors
        .iter()
        .position(|&e| e <= HELD_OUT_TIE * least)
        .unwrap_or(errors.len().saturating_sub(1))
}

/// The rank of a descending spectrum (`spectrum[0] = 1`) whose values at or under
/// `floor` do not count (see the noise module's docs): `N` when the smallest value
/// exceeds [`FULL_RANK_RATIO`]; else the last `r` whose ratio `spectrum_r /
/// spectrum_{r+1}` reaches [`CLEAR_GAP`] (a weak direction of change, such as the
/// position seen through far lights, stays above the leak of the kernel's direction
/// into a fitted slope, however strong the first one), else the `r` of the largest
/// ratio; at most the count of values above the floor.
pub fn spectrum_rank(spectrum: &[f64], floor: f64) -> usize {
    let n = spectrum.len();
    let above = spectrum.iter().take_while(|&&b| b > floor).count();
    if n == 0 || above == 0 {
        return 0;
    }
    let gap = |r: usize| spectrum[r - 1] / spectrum[r].max(f64::MIN_POSITIVE);
    let by_gap = if spectrum[n - 1] > FULL_RANK_RATIO {
        n
    } else if let Some(r) = (1..n).rev().find(|&r| gap(r) >= CLEAR_GAP) {
        r
    } else {
        (1..n)
            .max_by(|&a, &b| gap(a).total_cmp(&gap(b)).then(b.cmp(&a)))
            .unwrap_or(n)
    };
    by_gap.min(above)
}

/// The standard deviation of every sensor over the log.
pub(super) fn deviations(log: &SensorimotorLog) -> Vec<f64> {
    log.sensors
        .columns()
        .into_iter()
        .map(|c| {
            let mean = c.mean().unwrap_or(0.0);
            (c.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / c.len().max(1) as f64).sqrt()
        })
        .collect()
}

/// The `count` samples nearest to log row `row` in `tree`, other than `row`.
fn nearest_others(log: &SensorimotorLog, tree: &KdTree, row: u32, count: usize) -> Vec<(f64, u32)> {
    let centre: Vec<f64> = log.motors.row(row as usize).to_vec();
    tree.nearest_rows(&centre, count + 1)
        .into_iter()
        .filter(|&(_, r)| r != row)
        .take(count)
        .collect()
}

/// The affine fit at log row `row` to the samples `near` (not `row`): `(XᵀX)⁻¹` and
/// the prediction errors `e_c / √(1 + v)` of every sensor at `row` (see the
/// noise module's docs); `None` when `XᵀX` is singular.
fn affine_loo(
    log: &SensorimotorLog,
    row: u32,
    near: &[(f64, u32)],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = log.motors.ncols();
    let p = n + 1;
    let centre = log.motors.row(row as usize);
    let displacement = |r: u32, j: usize| log.motors[(r as usize, j)] - centre[j];
    let mut gram = vec![0.0; p * p];
    let mut design = vec![1.0; p];
    for &(_, r) in near {
        for j in 0..n {
            design[1 + j] = displacement(r, j);
        }
        for a in 0..p {
            for b in 0..p {
                gram[a * p + b] += design[a] * design[b];
            }
        }
    }
    let inverse = invert(&gram, p)?;
    // The prediction at the probe is row 0 of (XᵀX)⁻¹ Xᵀ s: Σ_j w_j s_j.
    let weights: Vec<f64> = near
        .iter()
        .map(|&(_, r)| {
            inverse[0]
                + (0..n)
                    .map(|j| inverse[1 + j] * displacement(r, j))
                    .sum::<f64>()
        })
        .collect();
    let scale = 1.0 / (1.0 + inverse[0]).sqrt();
    let errors = log
        .sensors
        .row(row as usize)
        .iter()
        .enumerate()
        .map(|(c, &s)| {
            let predicted: f64 = weights
                .iter()
                .zip(near)
                .map(|(w, &(_, r))| w * log.sensors[(r as usize, c)])
                .sum();
            (s - predicted) * scale
        })
        .collect();
    Some((inverse, errors))
}

/// The rows of one probe (log row `row`): for every neighbour count of the ladder, the
/// affine fit to that many nearest other samples, its prediction error at the probe;
/// at the smallest count, the errors of the probe and of its nearest sample (each with
/// its own fit), for their correlation.
fn probe_rows(
    log: &SensorimotorLog,
    tree: &KdTree,
    row: u32,
    largest: usize,
    deviations: &[f64],
) -> Probe {
    let n = log.motors.ncols();
    let centre: Vec<f64> = log.motors.row(row as usize).to_vec();
    let near = nearest_others(log, tree, row, largest);
    let mut out = Vec::with_capacity(LADDER.len());
    let (mut slope, mut pair, mut held_out) = (None, None, None);
    for (step, &multiple) in LADDER.iter().enumerate() {
        let count = multiple * (n + 1);
        if near.len() < count {
            break;
        }
        let Some((inverse, errors)) = affine_loo(log, row, &near[..count]) else {
            continue;
        };
        if count == largest {
            slope = scaled_slope(log, &near[..count], &inverse, &centre, deviations);
            held_out = held_out_by_rank(log, &near[..count], &inverse, &centre, deviations);
        }
        if step == 0 {
            let other = near[0].1;
            let around = nearest_others(log, tree, other, count);
            pair = affine_loo(log, other, &around).map(|(_, e)| (errors.clone(), e));
        }
        let mean_d2 = near[..count].iter().map(|&(d2, _)| d2).sum::<f64>() / count as f64;
        let squares = errors.iter().map(|e| e * e).collect();
        out.push((step, mean_d2 * mean_d2, squares));
    }
    Probe {
        rows: out,
        slope,
        pair,
        held_out,
    }
}

/// The affine fit's slope `B = ((XᵀX)⁻¹ Xᵀ S)_{1..}` (`K × N`) at `centre` with every
/// sensor divided by its standard deviation; `inverse` is `(XᵀX)⁻¹`.
fn slope_matrix(
    log: &SensorimotorLog,
    near: &[(f64, u32)],
    inverse: &[f64],
    centre: &[f64],
    deviations: &[f64],
) -> faer::Mat<f64> {
    let (n, k) = (log.motors.ncols(), log.sensors.ncols());
    let p = n + 1;
    let mut slope = faer::Mat::<f64>::zeros(k, n);
    let mut x = vec![1.0; p];
    for &(_, r) in near {
        for j in 0..n {
            x[1 + j] = log.motors[(r as usize, j)] - centre[j];
        }
        for j in 0..n {
            let w: f64 = (0..p).map(|q| inverse[(1 + j) * p + q] * x[q]).sum();
            for c in 0..k {
                slope[(c, j)] +=
                    w * log.sensors[(r as usize, c)] / deviations[c].max(f64::MIN_POSITIVE);
            }
        }
    }
    slope
}

/// The singular values (descending) of the affine fit's scaled slope
/// ([`slope_matrix`]) and `√q` (see the noise module's docs).
fn scaled_slope(
    log: &SensorimotorLog,
    near: &[(f64, u32)],
    inverse: &[f64],
    centre: &[f64],
    deviations: &[f64],
) -> Option<(Vec<f64>, f64)> {
    let n = log.motors.ncols();
    let p = n + 1;
    let slope = slope_matrix(log, near, inverse, centre, deviations);
    let mut sigma = crate::linalg::singular_values(slope.as_ref()).ok()?;
    sigma.sort_by(|a, b| b.total_cmp(a));
    sigma.resize(n, 0.0);
    if !(sigma[0].is_finite() && sigma[0] > 0.0) {
        return None;
    }
    let q = (1..p).map(|j| inverse[j * p + j]).fold(0.0, f64::max);
    Some((sigma, q.sqrt()))
}

/// The leave-one-out prediction error of the affine fits to `near` whose slope is held
/// to the `r` strongest motor directions of the full fit, for `r = 0..=N`: the mean
/// over the samples `j` and the sensors `c` of `(e_jc / (1 − h_j))² / σ_c²` (`e` the
/// fit's residual, `h` its leverage; see the module docs, "held-out prediction at each
/// rank"). `None` when a fit is singular.
fn held_out_by_rank(
    log: &SensorimotorLog,
    near: &[(f64, u32)],
    inverse: &[f64],
    centre: &[f64],
    deviations: &[f64],
) -> Option<Vec<f64>> {
    let (n, k) = (log.motors.ncols(), log.sensors.ncols());
    let slope = slope_matrix(log, near, inverse, centre, deviations);
    let gram = slope.transpose() * &slope;
    let (values, vectors) = crate::linalg::self_adjoint_eigen(gram.as_ref()).ok()?;
    // The motor directions from the strongest down.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let scaled =
        |r: u32, c: usize| log.sensors[(r as usize, c)] / deviations[c].max(f64::MIN_POSITIVE);
    let mut errors = Vec::with_capacity(n + 1);
    for rank in 0..=n {
        let p = rank + 1;
        // Each sample's design row `[1, v_1ᵀ x, …, v_rᵀ x]`.
        let design: Vec<Vec<f64>> = near
            .iter()
            .map(|&(_, r)| {
                let mut y = Vec::with_capacity(p);
                y.push(1.0);
                for &d in &order[..rank] {
                    y.push(
                        (0..n)
                            .map(|j| vectors[(j, d)] * (log.motors[(r as usize, j)] - centre[j]))
                            .sum(),
                    );
                }
                y
            })
            .collect();
        let mut normal = vec![0.0; p * p];
        for y in &design {
            for a in 0..p {
                for b in 0..p {
                    normal[a * p + b] += y[a] * y[b];
                }
            }
        }
        let inv = invert(&normal, p)?;
        // Coefficients `(YᵀY)⁻¹ Yᵀ s` of every sensor.
        let mut coefficients = vec![0.0; p * k];
        for (y, &(_, r)) in design.iter().zip(near) {
            for a in 0..p {
                let w: f64 = (0..p).map(|b| inv[a * p + b] * y[b]).sum();
                for c in 0..k {
                    coefficients[a * k + c] += w * scaled(r, c);
                }
            }
        }
        let mut sum = 0.0;
        let mut counted = 0usize;
        for (y, &(_, r)) in design.iter().zip(near) {
            let leverage: f64 = (0..p)
                .map(|a| y[a] * (0..p).map(|b| inv[a * p + b] * y[b]).sum::<f64>())
                .sum();
            if leverage >= 1.0 - 1e-9 {
                continue;
            }
            for c in 0..k {
                let fitted: f64 = (0..p).map(|a| coefficients[a * k + c] * y[a]).sum();
                let e = (scaled(r, c) - fitted) / (1.0 - leverage);
                sum += e * e;
            }
            counted += k;
        }
        if counted == 0 {
            return None;
        }
        errors.push(sum / counted as f64);
    }
    Some(errors)
}

/// The inverse of a symmetric positive definite `p × p` matrix (Gauss–Jordan with
/// partial pivoting), `None` when it is singular.
fn invert(matrix: &[f64], p: usize) -> Option<Vec<f64>> {
    let mut a = matrix.to_vec();
    let mut inverse = vec![0.0; p * p];
    for i in 0..p {
        inverse[i * p + i] = 1.0;
    }
    let scale = (0..p).map(|i| a[i * p + i].abs()).fold(0.0, f64::max);
    for col in 0..p {
        let pivot =
            (col..p).max_by(|&x, &y| a[x * p + col].abs().total_cmp(&a[y * p + col].abs()))?;
        if a[pivot * p + col].abs() <= 1e-12 * scale {
            return None;
        }
        for j in 0..p {
            a.swap(col * p + j, pivot * p + j);
            inverse.swap(col * p + j, pivot * p + j);
        }
        let d = 1.0 / a[col * p + col];
        for j in 0..p {
            a[col * p + j] *= d;
            inverse[col * p + j] *= d;
        }
        for r in 0..p {
            if r != col {
                let f = a[r * p + col];
                if f != 0.0 {
                    for j in 0..p {
                        a[r * p + j] -= f * a[col * p + j];
                        inverse[r * p + j] -= f * inverse[col * p + j];
                    }
                }
            }
        }
    }
    Some(inverse)
}

/// The ordinary least-squares line `y = intercept + slope x` of the pairs.
fn line(pairs: impl Iterator<Item = (f64, f64)> + Clone) -> (f64, f64) {
    let (mut count, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (x, y) in pairs.clone() {
        count += 1.0;
        sx += x;
        sy += y;
    }
    let (mx, my) = (sx / count, sy / count);
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for (x, y) in pairs {
        sxx += (x - mx) * (x - mx);
        sxy += (x - mx) * (y - my);
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - slope * mx, slope)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_through_exact_points_is_found() {
        let points = [(0.0, 1.0), (1.0, 3.0), (2.0, 5.0)];
        let (a, b) = line(points.iter().copied());
        approx::assert_abs_diff_eq!(a, 1.0, epsilon = 1e-12);
        approx::assert_abs_diff_eq!(b, 2.0, epsilon = 1e-12);
    }

    #[test]
    fn the_inverse_inverts() {
        let m = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let inv = invert(&m, 3).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let v: f64 = (0..3).map(|q| m[i * 3 + q] * inv[q * 3 + j]).sum();
                approx::assert_abs_diff_eq!(v, if i == j { 1.0 } else { 0.0 }, epsilon = 1e-12);
            }
        }
        assert!(invert(&[1.0, 2.0, 2.0, 4.0], 2).is_none());
    }
}
