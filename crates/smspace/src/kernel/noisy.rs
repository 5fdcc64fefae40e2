//! The sensory level set of readings with noise: the level set of the sensors' mean
//! law.
//!
//! Readings that change between two calls at the same motors (a robot, a simulator
//! with noise, [`crate::agent::NoisyAgent`]) cannot meet a tolerance of `10⁻¹²`, nor
//! give a Jacobian by differences `10⁻⁶` rad apart. With `[kernel] sensor_sigma = "auto"`
//! (the default) every start is read twice in one batch: readings equal to within the
//! exact corrector's own tolerance (`|s₁ − s₂| ≤ sensor_tolerance · max |s₁|` in every
//! sensor: rounding, from a simulator that is not bit-reproducible, is no noise) are
//! exact and the set is traced as an exact one (one sensor row more per set).
//! Otherwise the set is the level set of the sensors' mean law, `{ m | a(m) = a₀ }`: at every
//! point one batch of rows, the centre `m` read `N + 1` times and the `2N` rows
//! `m ± ρ e_j`, repeated `r` times, is a local regression whose intercept `a(m)` (the
//! mean of the centre's readings) is the level set's function and whose slope
//! `(s̄₊ − s̄₋)/2ρ` its Jacobian; the corrector is Gauss–Newton with minimum-norm steps
//! and a fresh regression at every iterate. The noise's standard deviation `σ` is
//! measured at the start from 16 repeats of a first regression (pooled over the rows
//! and sensors), or given (`sensor_sigma = σ` in sensor units; `0`: exact, no extra row).
//! With `g` the smallest of the `N − k` largest singular values of the slope, `ρ`
//! and `r` aim at a slope error of 2 % (`ρ ∈ [10⁻³, 0.1]` rad, `r ≤ 64`), and a
//! point's position is uncertain by `σ_pos = σ / (g √(r (N + 1)))`. Every tolerance
//! scales with it: a point is on the set when the residual's part in the slope's
//! range, `|Uᵀ r| / g`, is below `5 σ_pos` (and every residual component within the
//! noise; a last step is then taken); the corrector's steps are damped,
//! `Δ = Σ_e v_e (v_eᵀ Jᵀ r) / (λ_e + μ²)` with `μ = σ (√K + √N) / (ρ √(2r))` the
//! slope's noise, so that a direction the noise leaves uncertain does not throw the
//! point along the set; corrections below
//! `3 σ_pos` plus the tangent's noise times the step are nothing to do for the step
//! control, steps stay above `4 σ_pos`, loops close within
//! `max(closure_tolerance, 4 σ_pos)` after `min_steps` steps, and the tangent's own
//! noise is allowed on top of `max_turn`; each new tangent is oriented along the
//! path's heading over the last three nodes rather than along the last tangent, and a
//! seed of the piece search lands on a piece already found within
//! `max(piece_tolerance, 10 σ_pos)`; one that lands elsewhere is a new piece only
//! when, read again, the residual outside the slope's range passes a χ² test. A noisy null direction can still turn a trace
//! round: a trace that comes back to its start heading the other way, or whose curve
//! runs back over its own path (more than [`super::MAX_DOUBLED`] of the polyline through its
//! nodes, cut into 200 points `Δ` apart, lies within `1.5 Δ` of a point at least ten
//! points away along it, with parallel or antiparallel chords, `|cos| ≥ 0.8`; a simple
//! curve has none), is [`super::SetStatus::Retraced`], not kept, and the summary warns.
//! Sensors that jump between neighbouring postures (a rangefinder past an edge) are
//! told from smooth ones at two scales and left out of the slope where they jump.
//! `σ`, `σ_pos`, `ρ`, `r` and the doubled fraction are reported per set ([`super::SetReport::noise`]) and summarised ([`super::TraceSummary::noise`]); beyond a
//! median `σ_pos` of [`super::MAX_POSITION_UNCERTAINTY`] rad, or with most sets failed, the
//! summary warns ([`super::TraceSummary::warnings`]).
//!
//! ## The regression
//!
//! At a point `m`, one batch of rows, repeated `r` times, is a local regression of
//! the readings: the centre `m` read `N + 1` times and the `2N` rows `m ± ρ e_j`. The
//! intercept `a(m)` is the mean of the centre's `r (N + 1)` readings (no curvature
//! bias: the mean of the whole stencil would add `ρ²/(2N+1) Σ_j ∂²s/∂m_j²`, which is
//! not constant on a kernel set and moved the arm's sets by several hundredths of a
//! radian at `ρ = 0.1`), the slope `J_j = (s̄₊ − s̄₋) / 2ρ` (`s̄±` the means of the
//! repeats). The set through a start `m⁰` is `{ m | a(m) = a₀ }` with `a₀` the
//! intercept at the start from [`TARGET_REPEATS`] times as many repeats.
//!
//! The corrector is damped Gauss–Newton, `m ← m − Σ_e v_e (v_eᵀ Jᵀ (a(m) − a₀)) /
//! (λ_e + μ²)` over the eigenpairs `(λ_e, v_e)` of `JᵀJ` of its `N − k` largest
//! singular values, `μ = σ (√K + √N) / (ρ √(2r))` the expected spectral norm of the
//! slope's noise (a minimum-norm step where the slope stands well above its noise),
//! with a fresh regression at every iterate (no secant updates). With `σ` the noise's
//! standard deviation and `g` the smallest of those singular values at the start:
//! - `ρ = σ / (√2 ε g)`, clamped to `[RHO_MIN, RHO_MAX]`, and `r = ⌈(σ / (√2 ρ g ε))²⌉`
//!   clamped to `[1, MAX_REPEATS]`, so that the slope's relative error is about
//!   `ε = SLOPE_ERROR`;
//! - a point's position is uncertain by `σ_pos = σ / (g √(r (N + 1)))`: the corrector
//!   accepts a point when the residual's part in the slope's range, `|Uᵀ r| / g`, is
//!   at most [`TOLERANCE_POSITIONS`] `σ_pos` (`g` where it stands; unlike the step
//!   `|J⁺ r|`, it does not grow where a noisy slope's weakest direction is
//!   underestimated) and every residual component is within
//!   [`RESIDUAL_SIGMAS`] standard deviations of the residual's noise, and then takes
//!   that last step; where `g` falls below a tenth of the start's, the set is
//!   singular;
//! - the follower takes corrections below a few `σ_pos` as nothing to do, keeps its
//!   step above a few `σ_pos`, closes loops within a few `σ_pos`, and allows three
//!   times the noise of the turn between two nodes, `√2 · σ √K / (√2 ρ √r g)`, on
//!   top of `max_turn`.
//!
//! A seed of the piece search that lands away from the pieces found is a new piece only
//! when the point, read again with [`TARGET_REPEATS`] times the repeats, passes a χ²
//! test: the residual's part outside the slope's range, `(|r|² − |Uᵀ r|²) / (2σ² /
//! (4r (N + 1)))`, is at most `f + 6 √(2f)` for `f = K − (N − k)` degrees of freedom (a
//! seed that only came close to the set, where the mean readings approach the start's
//! without reaching them, leaves hundreds).
//!
//! `σ` is `[kernel] sensor_sigma` when given, otherwise measured at the start: the pooled
//! standard deviation of the [`ESTIMATE_REPEATS`] repeats of every row of a first
//! regression (`(r − 1)` degrees of freedom per row and sensor).
//!
//! **Discontinuous sensors.** A sensor that jumps between two neighbouring postures (a
//! rangefinder whose ray passes the edge of an obstacle) gives a slope of
//! `jump / 2ρ` wherever the stencil straddles the edge, which turns the null
//! direction anywhere. The two one-sided slopes `d± = ±(s̄± − a) / ρ` of a smooth
//! sensor differ by `ρ s''` (and the noise); across a jump one of them carries
//! `jump / ρ`. A sensor is *torn* at `m` when for some motor
//! `|d₊ − d₋| > JUMP_RATIO · min(|d₊|, |d₋|) + JUMP_SIGMAS · σ √(2/r + 4/(r(N+1))) / ρ`
//! (the second term: [`JUMP_SIGMAS`] standard deviations of `d₊ − d₋`'s noise). A
//! smooth sensor can be torn too (a strong curvature over `ρ`); a jump is told from it
//! at two scales: a smooth sensor's one-sided slope at `ρ/2` is `(d± + c)/2` to
//! `O(ρ²)` (`c` the central slope), while across a jump at `e ≤ ρ` it strays from that
//! by `3/4` or `5/4` of `jump / ρ`, that is of the gap `|d₊ − d₋|`. When the first
//! regression at a start finds a torn sensor, one more regression at `ρ/2` decides:
//! if some torn sensor strays by more than [`JUMP_SHARE`] of its gap (plus the noise),
//! the sensors are discontinuous: `ρ` is kept at most [`FIRST_RHO`] (a narrower
//! stencil straddles fewer edges) and in every regression the torn sensors' rows of
//! the slope are set to 0 (they still count in the residual, where the intercept,
//! read at the centre only, has no jump). With too few sensors left the slope loses
//! rank and the point is singular. Otherwise nothing changes.

use ndarray::{ArrayView2, ArrayViewMut2};

use super::level_set::{oriented_null_vector, Decomposition, LevelSet, Sensor, Singular};
use super::{SensorNoise, SetNoise, SetStatus, TraceValidParams};

/// Repeats of the first regression at a start, whose spread measures the noise.
pub(crate) const ESTIMATE_REPEATS: usize = 16;
/// Offset `ρ` of the first regression at a start, radians; the largest `ρ` for
/// discontinuous sensors.
const FIRST_RHO: f64 = 0.05;
/// Smallest offset `ρ` of the regressions, radians.
const RHO_MIN: f64 = 1e-3;
/// Largest offset `ρ` of the regressions, radians.
const RHO_MAX: f64 = 0.1;
/// The relative error of the slope that `ρ` and the repeats aim at.
const SLOPE_ERROR: f64 = 0.02;
/// Most repeats of a regression.
const MAX_REPEATS: usize = 64;
/// The start's intercept takes this many times the repeats of the others.
pub(crate) const TARGET_REPEATS: usize = 4;
/// A point is on the set when its Gauss–Newton step is at most this many position
/// uncertainties.
pub(crate) const TOLERANCE_POSITIONS: f64 = 5.0;
/// ... and every residual component within this many standard deviations of its noise
/// (generous: the intercept's curvature bias differs along the set by a few of them;
/// the residuals this rules out, of points where the residual is only orthogonal to
/// the Jacobian's range, are of the order of the sensors' range).
pub(crate) const RESIDUAL_SIGMAS: f64 = 20.0;
/// A new piece of a noisy set is confirmed when the residual outside the slope's range
/// is within this many standard deviations of its χ² above the χ²'s mean.
const PIECE_SIGMAS: f64 = 6.0;
/// A point where `g` is below the start's over this ratio is singular.
const SINGULAR_RATIO: f64 = 10.0;
/// The turn between two nodes allowed on top of `max_turn`, in standard deviations of
/// the null vector's noise.
const TURN_SIGMAS: f64 = 3.0;
/// A sensor is torn (see the module docs) when its one-sided slopes differ by more
/// than this many times the smaller one...
pub(crate) const JUMP_RATIO: f64 = 2.0;
/// ... plus this many standard deviations of their difference's noise.
pub(crate) const JUMP_SIGMAS: f64 = 6.0;
/// A torn sensor jumps when its one-sided slope at `ρ/2` strays from the halfway
/// point of its one-sided and central slopes at `ρ` by more than this share of their
/// gap (a jump strays by 3/4 of it or more; a smooth sensor by `O(ρ²)`).
pub(crate) const JUMP_SHARE: f64 = 0.375;

/// Whether `value ≤ limit` (false when either is not a number).
fn within(value: f64, limit: f64) -> bool {
    matches!(
        value.partial_cmp(&limit),
        Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
    )
}

/// What the two readings of a start say ([`probe`]).
pub(crate) enum Probe<'a> {
    /// Equal readings, to within the exact corrector's tolerance (or `sensor_sigma = 0`): the exact level set, with the sensor and the
    /// start's reading when one was taken.
    Exact(Sensor<'a>, Option<Vec<f64>>),
    /// Readings with noise: the level set of their mean.
    Noisy(Box<NoisySensory<'a>>),
    /// Readings with noise, and the level set cannot be followed from this start.
    Failed(SetStatus, SetNoise, Sensor<'a>),
}

/// The level set of the mean law (see the module docs).
pub(crate) struct NoisySensory<'a> {
    sensor: Sensor<'a>,
    n: usize,
    k: usize,
    dimension: usize,
    rank_tolerance: f64,
    rho: f64,
    repeats: usize,
    target: Vec<f64>,
    noise: SetNoise,
    /// Standard deviation of a residual component.
    residual_sigma: f64,
    tangent_noise: f64,
    /// `g` at the start.
    g_start: f64,
    jacobian: Vec<f64>,
    eigenvalues: Vec<f64>,
    eigenvectors: Vec<f64>,
    probes: Vec<f64>,
    readings: Vec<f64>,
    /// Whether the first regression found a torn sensor: torn sensors are then left
    /// out of every slope.
    discontinuous: bool,
    /// The one-sided slopes `(d₊, d₋)` of the last regression, sensor by sensor and
    /// motor by motor.
    sides: Vec<(f64, f64)>,
    /// The noise `σ` the torn sensors are judged with: `σ` once known, else the
    /// spread of the last regression's repeats.
    torn_sigma: f64,
    /// The sensors left out of the last slope.
    torn: usize,
}

/// Reads the start twice in one batch (`sensor_sigma = "auto"`) and decides how to trace:
/// exactly when the readings are equal to within the exact corrector's tolerance
/// ([`repeats_exactly`]; or `sensor_sigma = 0`), otherwise on the level set of
/// the mean law, `σ` measured or given.
pub(crate) fn probe<'a>(
    mut sensor: Sensor<'a>,
    start: &[f64],
    params: &TraceValidParams,
    dimension: usize,
) -> Probe<'a> {
    let k = sensor.agent.sensor_dim();
    let given = match params.noise {
        SensorNoise::Sigma(0.0) => return Probe::Exact(sensor, None),
        SensorNoise::Sigma(sigma) if sigma < TINY_SIGMA => {
            // Below the rounding of the readings, a declared σ is exact readings.
            let mut reading = vec![0.0; k];
            sensor.sense_batch(
                ArrayView2::from_shape((1, start.len()), start).expect("1 × N row"),
                ArrayViewMut2::from_shape((1, k), &mut reading).expect("1 × K reading"),
            );
            let largest = reading.iter().fold(0.0, |a: f64, v| a.max(v.abs()));
            if sigma <= params.sensor_tolerance * largest {
                return Probe::Exact(sensor, Some(reading));
            }
            Some(sigma)
        }
        SensorNoise::Sigma(sigma) => Some(sigma),
        SensorNoise::Auto => {
            let rows = [start, start].concat();
            let mut readings = vec![0.0; 2 * k];
            let motors = ArrayView2::from_shape((2, start.len()), &rows).expect("2 × N rows");
            let out = ArrayViewMut2::from_shape((2, k), &mut readings).expect("2 × K readings");
            sensor.sense_batch(motors, out);
            let (first, second) = readings.split_at(k);
            if repeats_exactly(first, second, params.sensor_tolerance) {
                readings.truncate(k);
                return Probe::Exact(sensor, Some(readings));
            }
            None
        }
    };
    NoisySensory::probe_start(sensor, start, params, dimension, given)
}

/// A declared `σ` below this is compared with the start's reading: at most
/// `sensor_tolerance` times its largest value (the rounding of the readings, the exact
/// corrector's own tolerance), the readings are traced as exact.
const TINY_SIGMA: f64 = 1e-8;

/// Whether two readings of the same motors are exact: they differ nowhere by more
/// than the exact corrector's own tolerance, `sensor_tolerance` times the largest
/// sensor value of the first (the scale of [`super::level_set::Sensory`]'s residual),
/// so that a simulator whose readings differ only by rounding (not bit-reproducible)
/// is traced as exact. Readings that are not finite are never exact.
fn repeats_exactly(first: &[f64], second: &[f64], sensor_tolerance: f64) -> bool {
    if first
        .iter()
        .zip(second)
        .all(|(a, b)| a.to_bits() == b.to_bits())
    {
        return true;
    }
    let largest = first.iter().fold(0.0, |a: f64, v| a.max(v.abs()));
    let scale = if largest > 0.0 { largest } else { 1.0 };
    first
        .iter()
        .zip(second)
        .all(|(a, b)| (a - b).abs() <= sensor_tolerance * scale)
}

impl<'a> NoisySensory<'a> {
    /// Measures (or takes) `σ` and the slope at the start, picks `ρ` and the repeats,
    /// and reads the start's intercept.
    fn probe_start(
        sensor: Sensor<'a>,
        start: &[f64],
        params: &TraceValidParams,
        dimension: usize,
        given: Option<f64>,
    ) -> Probe<'a> {
        let (n, k) = (sensor.agent.motor_dim(), sensor.agent.sensor_dim());
        let mut set = Self {
            sensor,
            n,
            k,
            dimension,
            rank_tolerance: params.rank_tolerance,
            rho: FIRST_RHO,
            repeats: ESTIMATE_REPEATS,
            target: vec![0.0; k],
            noise: SetNoise::default(),
            residual_sigma: 0.0,
            tangent_noise: 0.0,
            g_start: 1.0,
            jacobian: vec![0.0; k * n],
            eigenvalues: vec![0.0; n],
            eigenvectors: vec![0.0; n * n],
            probes: Vec::new(),
            readings: Vec::new(),
            discontinuous: false,
            torn: 0,
            sides: Vec::new(),
            torn_sigma: 0.0,
        };
        let mut intercept = vec![0.0; k];
        // The first regression, and whether its sensors jump (σ from its own repeats).
        let spread = set.regress(start, &mut intercept);
        set.discontinuous = set.jumps(start);
        if set.discontinuous {
            set.leave_out_torn();
        }
        set.noise.discontinuous = set.discontinuous;
        let sigma = given.unwrap_or(spread);
        set.noise.sigma = sigma;
        let singular = set.decompose().is_err();
        let g = set
            .eigenvalues
            .get(dimension)
            .map_or(0.0, |e| e.max(0.0).sqrt());
        if singular
            || g.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            || !(sigma / g).is_finite()
        {
            return Probe::Failed(SetStatus::Singular, set.noise, set.sensor);
        }
        set.g_start = g;
        let rho_max = if set.discontinuous {
            FIRST_RHO
        } else {
            RHO_MAX
        };
        set.rho = (sigma / (std::f64::consts::SQRT_2 * SLOPE_ERROR * g)).clamp(RHO_MIN, rho_max);
        let repeats = (sigma / (std::f64::consts::SQRT_2 * set.rho * g * SLOPE_ERROR)).powi(2);
        set.repeats = (repeats.ceil() as usize).clamp(1, MAX_REPEATS);
        // The intercept averages the r (N + 1) readings of the centre.
        let rows = (set.repeats * (n + 1)) as f64;
        set.noise.stencil = set.rho;
        set.noise.repeats = set.repeats;
        set.noise.position = sigma / (g * rows.sqrt());
        // The null vector moves by about |ΔJ v| / g, ΔJ v of K entries of the slope's
        // noise each; the turn between two nodes carries two such errors.
        set.tangent_noise =
            TURN_SIGMAS * sigma * (k as f64).sqrt() / (set.rho * (set.repeats as f64).sqrt() * g);
        set.residual_sigma = sigma * (1.0 / rows + 1.0 / (TARGET_REPEATS as f64 * rows)).sqrt();
        let repeats = set.repeats;
        set.repeats = TARGET_REPEATS * repeats;
        let mut target = vec![0.0; k];
        set.regress(start, &mut target);
        set.repeats = repeats;
        set.target = target;
        Probe::Noisy(Box::new(set))
    }

    /// One regression at `m` (see the module docs): the intercept into `intercept`, the
    /// slope into the Jacobian; returns the pooled standard deviation of the repeats
    /// (0 with one repeat).
    fn regress(&mut self, m: &[f64], intercept: &mut [f64]) -> f64 {
        let (n, k, r, rho) = (self.n, self.k, self.repeats, self.rho);
        // Every repeat: the centre `N + 1` times, then m ± ρ e_j.
        let centre = n + 1;
        let types = centre + 2 * n;
        self.probes.clear();
        for _ in 0..r {
            for row in 0..types {
                self.probes.extend_from_slice(m);
                if row >= centre {
                    let j = (row - centre) / 2;
                    let at = self.probes.len() - n + j;
                    self.probes[at] += if (row - centre) % 2 == 0 { rho } else { -rho };
                }
            }
        }
        self.readings.clear();
        self.readings.resize(r * types * k, 0.0);
        let motors = ArrayView2::from_shape((r * types, n), &self.probes).expect("probe rows");
        let out =
            ArrayViewMut2::from_shape((r * types, k), &mut self.readings).expect("reading rows");
        self.sensor.sense_batch(motors, out);
        // Means of every row type over the repeats, and the spread about them.
        let mut means = vec![0.0; types * k];
        for repeat in self.readings.chunks_exact(types * k) {
            for (mean, v) in means.iter_mut().zip(repeat) {
                *mean += v / r as f64;
            }
        }
        let mut squares = 0.0;
        for repeat in self.readings.chunks_exact(types * k) {
            squares += repeat
                .iter()
                .zip(&means)
                .map(|(v, mean)| (v - mean).powi(2))
                .sum::<f64>();
        }
        for (i, a) in intercept.iter_mut().enumerate() {
            *a = (0..centre).map(|row| means[row * k + i]).sum::<f64>() / centre as f64;
        }
        for j in 0..n {
            let plus = &means[(centre + 2 * j) * k..];
            let minus = &means[(centre + 2 * j + 1) * k..];
            for i in 0..k {
                self.jacobian[i * n + j] = (plus[i] - minus[i]) / (2.0 * rho);
            }
        }
        let spread = if r < 2 {
            0.0
        } else {
            (squares / ((r - 1) * types * k) as f64).sqrt()
        };
        // The one-sided slopes d± of every sensor and motor, for the torn sensors.
        self.sides.clear();
        for (i, a) in intercept.iter().enumerate() {
            for j in 0..n {
                let plus = (means[(centre + 2 * j) * k + i] - a) / rho;
                let minus = (a - means[(centre + 2 * j + 1) * k + i]) / rho;
                self.sides.push((plus, minus));
            }
        }
        self.torn_sigma = if self.noise.sigma > 0.0 {
            self.noise.sigma
        } else {
            spread
        };
        if self.discontinuous {
            self.leave_out_torn();
        }
        spread
    }

    /// The standard deviation of `d₊ − d₋` (see the module docs) in the last
    /// regression, times [`JUMP_SIGMAS`].
    fn torn_noise(&self) -> f64 {
        let (n, r) = (self.n as f64, self.repeats as f64);
        JUMP_SIGMAS * self.torn_sigma * (2.0 / r + 4.0 / (r * (n + 1.0))).sqrt() / self.rho
    }

    /// Whether the last regression tears sensor `i` along motor `j` (see the module
    /// docs; not finite: torn as well).
    fn is_torn(&self, i: usize, j: usize, noise: f64) -> bool {
        let (plus, minus) = self.sides[i * self.n + j];
        !within(
            (plus - minus).abs(),
            JUMP_RATIO * plus.abs().min(minus.abs()) + noise,
        )
    }

    /// Sets to 0 the slope's rows of the sensors the last regression tears (see the
    /// module docs); counts them in `torn`.
    fn leave_out_torn(&mut self) {
        let (n, noise) = (self.n, self.torn_noise());
        self.torn = 0;
        for i in 0..self.k {
            if (0..n).any(|j| self.is_torn(i, j, noise)) {
                self.jacobian[i * n..(i + 1) * n].fill(0.0);
                self.torn += 1;
            }
        }
    }

    /// Whether the sensors jump at `m`, after a first regression there (see the module
    /// docs): a sensor torn along a motor whose one-sided slopes at `ρ/2` stray from
    /// the halfway point of those at `ρ` and the central slope by more than
    /// [`JUMP_SHARE`] of the gap between them (a smooth sensor's stray by `O(ρ²)`
    /// only). One more regression, at `ρ/2`, when some sensor is torn; the first
    /// regression's slope is kept.
    fn jumps(&mut self, m: &[f64]) -> bool {
        let (n, k, noise) = (self.n, self.k, self.torn_noise());
        let torn: Vec<usize> = (0..k * n)
            .filter(|&e| self.is_torn(e / n, e % n, noise))
            .collect();
        if torn.is_empty() {
            return false;
        }
        let (first, jacobian) = (self.sides.clone(), self.jacobian.clone());
        let mut intercept = vec![0.0; k];
        self.rho /= 2.0;
        self.regress(m, &mut intercept);
        // The noise of a one-sided slope at ρ/2 (ρ is halved here).
        let half_noise =
            JUMP_SIGMAS * self.torn_sigma * (2.0 / self.repeats as f64).sqrt() / self.rho;
        let jump = torn.iter().any(|&e| {
            let ((plus, minus), (half_plus, half_minus)) = (first[e], self.sides[e]);
            let central = 0.5 * (plus + minus);
            let gap = (plus - minus).abs();
            let stray = (half_plus - 0.5 * (plus + central))
                .abs()
                .max((half_minus - 0.5 * (minus + central)).abs());
            !within(stray, JUMP_SHARE * gap + half_noise)
        });
        self.rho *= 2.0;
        self.sides = first;
        self.jacobian = jacobian;
        jump
    }

    /// The norm of the residual's projection on the slope's range, `|Uᵀ r|`.
    fn range_norm(&self, r: &[f64]) -> f64 {
        let (n, k) = (self.n, self.k);
        let jt_r: Vec<f64> = (0..n)
            .map(|j| (0..k).map(|i| self.jacobian[i * n + j] * r[i]).sum())
            .collect();
        let mut squares = 0.0;
        for e in self.dimension..n {
            let v = &self.eigenvectors[e * n..(e + 1) * n];
            let lambda = self.eigenvalues[e];
            if lambda > 0.0 {
                squares += v.iter().zip(&jt_r).map(|(a, b)| a * b).sum::<f64>().powi(2) / lambda;
            }
        }
        squares.sqrt()
    }

    /// The expected spectral norm of the slope's noise, `σ (√K + √N) / (ρ √(2r))`.
    fn slope_noise(&self) -> f64 {
        self.noise.sigma * ((self.k as f64).sqrt() + (self.n as f64).sqrt())
            / (self.rho * (2.0 * self.repeats as f64).sqrt())
    }

    /// The smallest of the `N − k` largest singular values of the current slope.
    fn g(&self) -> f64 {
        self.eigenvalues[self.dimension].max(0.0).sqrt()
    }

    fn decompose(&mut self) -> Result<(), Singular> {
        let decomposition = Decomposition {
            eigenvalues: &mut self.eigenvalues,
            eigenvectors: &mut self.eigenvectors,
        };
        decomposition.of(
            &self.jacobian,
            self.k,
            self.n,
            self.dimension,
            self.rank_tolerance,
        )
    }
}

impl LevelSet for NoisySensory<'_> {
    fn motor_dim(&self) -> usize {
        self.n
    }

    fn rows(&self) -> usize {
        self.k
    }

    fn residual(&mut self, m: &[f64], r: &mut [f64]) {
        // Every reading is a regression: the linearisation comes with it.
        let _ = self.linearize(m, r);
    }

    /// The residual's part in the slope's range over `g`, `|Uᵀ r| / g` (radians: the
    /// Gauss–Newton step along the weakest direction), or more when a residual component is
    /// beyond the noise (a point where the residual is only orthogonal to the
    /// Jacobian's range is not on the set).
    fn residual_norm(&self, r: &[f64]) -> f64 {
        let step = self.range_norm(r) / self.g();
        let largest = r.iter().fold(0.0, |a: f64, v| a.max(v.abs()));
        let noise = RESIDUAL_SIGMAS * self.residual_sigma;
        if largest.is_nan() {
            return f64::NAN;
        }
        step.max(self.tolerance() * largest / noise)
    }

    /// [`TOLERANCE_POSITIONS`] times the position uncertainty at the current
    /// linearisation (`g` there rather than at the start).
    fn tolerance(&self) -> f64 {
        TOLERANCE_POSITIONS * self.noise.position * self.g_start / self.g()
    }

    fn newton_step_tolerance(&self) -> f64 {
        self.tolerance()
    }

    fn final_step(&self) -> bool {
        true
    }

    fn position_noise(&self) -> f64 {
        self.noise.position
    }

    fn tangent_noise(&self) -> f64 {
        self.tangent_noise * self.g_start / self.g()
    }

    fn noise(&self) -> Option<SetNoise> {
        Some(self.noise)
    }

    fn linearize(&mut self, m: &[f64], r: &mut [f64]) -> Result<(), Singular> {
        let mut intercept = vec![0.0; self.k];
        self.regress(m, &mut intercept);
        for ((ri, a), t) in r.iter_mut().zip(&intercept).zip(&self.target) {
            *ri = a - t;
        }
        self.decompose()?;
        // Where the slope is much weaker than at the start, the readings do not fix
        // the position: as singular as a lost rank.
        if (self.g() * SINGULAR_RATIO).partial_cmp(&self.g_start)
            != Some(std::cmp::Ordering::Greater)
        {
            return Err(Singular);
        }
        Ok(())
    }

    fn null_vector(&self, reference: &[f64], t: &mut [f64]) {
        oriented_null_vector(&self.eigenvectors[..self.n], reference, t);
    }

    /// The damped Gauss–Newton step `Σ_e v_e (v_eᵀ Jᵀ r) / (λ_e + μ²)` over the
    /// range's eigenvectors, `μ` the slope's noise ([`Self::slope_noise`]): the
    /// minimum-norm step where the slope is well above its noise, shortened along the
    /// directions its noise makes uncertain.
    fn correction(&self, r: &[f64], delta: &mut [f64]) {
        let (n, k) = (self.n, self.k);
        let jt_r: Vec<f64> = (0..n)
            .map(|j| (0..k).map(|i| self.jacobian[i * n + j] * r[i]).sum())
            .collect();
        let mu = self.slope_noise();
        delta.fill(0.0);
        for e in self.dimension..n {
            let v = &self.eigenvectors[e * n..(e + 1) * n];
            let c = v.iter().zip(&jt_r).map(|(a, b)| a * b).sum::<f64>()
                / (self.eigenvalues[e].max(0.0) + mu * mu);
            for (d, vj) in delta.iter_mut().zip(v) {
                *d += c * vj;
            }
        }
    }

    fn jacobian(&self) -> (&[f64], usize) {
        (&self.jacobian, self.k)
    }

    fn null_basis(&self, k: usize, basis: &mut [f64]) {
        basis[..k * self.n].copy_from_slice(&self.eigenvectors[..k * self.n]);
    }

    fn newton(&self) -> bool {
        true
    }

    fn covers(&self, m: &[f64]) -> bool {
        self.sensor.agent.covers(m)
    }

    fn sensor_rows(&self) -> u64 {
        self.sensor.rows
    }

    fn sensor_row_phases(&self) -> Option<super::SensorRowPhases> {
        Some(self.sensor.phases)
    }

    fn set_phase(&mut self, phase: super::RowPhase) {
        self.sensor.phase = phase;
    }

    /// Reads `m` again with [`TARGET_REPEATS`] times the repeats and tests the
    /// residual's part outside the slope's range, `|r|² − |Uᵀ r|²`, against its noise:
    /// on the set it is a χ² of `K − (N − k)` degrees of freedom in units of the
    /// residual's variance; a seed that only came close to the set (where the mean
    /// readings approach the start's without reaching them) leaves more than
    /// [`PIECE_SIGMAS`] standard deviations of that χ² above its mean.
    fn confirms_piece(&mut self, m: &[f64]) -> bool {
        let freedom = self.k.saturating_sub(self.n - self.dimension);
        if freedom == 0 {
            return true;
        }
        let repeats = self.repeats;
        self.repeats = TARGET_REPEATS * repeats;
        let mut r = vec![0.0; self.k];
        let linearized = self.linearize(m, &mut r);
        self.repeats = repeats;
        if linearized.is_err() {
            return false;
        }
        // Both intercepts averaged TARGET_REPEATS r (N + 1) readings.
        let rows = (TARGET_REPEATS * repeats * (self.n + 1)) as f64;
        let variance = 2.0 * self.noise.sigma.powi(2) / rows;
        let outside = (r.iter().map(|x| x * x).sum::<f64>() - self.range_norm(&r).powi(2)).max(0.0)
            / variance;
        let freedom = freedom as f64;
        outside <= freedom + PIECE_SIGMAS * (2.0 * freedom).sqrt()
    }
}
