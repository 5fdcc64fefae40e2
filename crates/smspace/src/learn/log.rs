//! A sensorimotor log, checked where it enters, and the fit of one log with its
//! held-out error.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use ndarray::{Array2, ArrayView2};
use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use super::law::{LocalModel, LogReport};
use super::noise::{estimate_local, LocalRank};
use super::{observe, LawValidParams, LearnError};
use crate::agent::{Motor, MotorSpace};
use crate::io;
use crate::params::InvalidParameter;
use crate::progress::Progress;

/// The two files of a log.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LogFiles {
    /// Motor commands `(S, N)`.
    pub motors: PathBuf,
    /// Sensor values `(S, K)`.
    pub sensors: PathBuf,
}

/// One motor as a log declares it (`--period`, `[data] period`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum MotorDeclaration {
    /// Periodic with this period (`2pi`: a hinge; or a number).
    Periodic(f64),
    /// Bounded in the declared range `low:high`; samples outside it are refused.
    Bounded(f64, f64),
    /// Bounded in the range the first log spans (`none`).
    DataRange,
}

/// Parses `2pi`, `none`, a period (`6.0`), a range (`-1:1`), or a comma-separated list
/// of these, one per motor (a single entry applies to every motor).
///
/// ```
/// use smspace::learn::{parse_motor_declarations, MotorDeclaration};
/// let d = parse_motor_declarations("2pi,none,-1:1")?;
/// assert_eq!(d[2], MotorDeclaration::Bounded(-1.0, 1.0));
/// # Ok::<(), String>(())
/// ```
pub fn parse_motor_declarations(spec: &str) -> Result<Vec<MotorDeclaration>, String> {
    spec.split(',')
        .map(|entry| {
            let entry = entry.trim();
            let bad = || {
                format!(
                    "'{entry}' is not a motor declaration; use 2pi (a hinge), none (bounded by the log's range), a period such as 6.0, or a range LOW:HIGH"
                )
            };
            match entry {
                "2pi" => Ok(MotorDeclaration::Periodic(TAU)),
                "none" => Ok(MotorDeclaration::DataRange),
                _ => {
                    if let Some((low, high)) = entry.split_once(':') {
                        let low: f64 = low.trim().parse().map_err(|_| bad())?;
                        let high: f64 = high.trim().parse().map_err(|_| bad())?;
                        if !(low.is_finite() && high.is_finite() && low < high) {
                            return Err(format!("range '{entry}' needs finite LOW < HIGH"));
                        }
                        Ok(MotorDeclaration::Bounded(low, high))
                    } else {
                        let period: f64 = entry.parse().map_err(|_| bad())?;
                        if !(period.is_finite() && period > 0.0) {
                            return Err(format!("period '{entry}' must be finite and positive"));
                        }
                        Ok(MotorDeclaration::Periodic(period))
                    }
                }
            }
        })
        .collect()
}

/// The motor space the declarations give the motors of a log (`motors` read from
/// `path`): one declaration for all motors, or one per motor column; `none` takes the
/// column's range in the log.
pub fn declared_space(
    declarations: &[MotorDeclaration],
    motors: ArrayView2<'_, f64>,
    path: &Path,
) -> Result<MotorSpace, LearnError> {
    let n = motors.ncols();
    if declarations.len() != 1 && declarations.len() != n {
        return Err(LearnError::MotorColumns {
            path: path.to_owned(),
            found: n,
            expected: declarations.len(),
        });
    }
    let mut space = Vec::with_capacity(n);
    for j in 0..n {
        let declaration = declarations[if declarations.len() == 1 { 0 } else { j }];
        space.push(match declaration {
            MotorDeclaration::Periodic(period) => Motor::Periodic { period },
            MotorDeclaration::Bounded(low, high) => Motor::Bounded { low, high },
            MotorDeclaration::DataRange => {
                let column = motors.column(j);
                let low = column.iter().copied().fold(f64::INFINITY, f64::min);
                let high = column.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                if low >= high {
                    return Err(InvalidParameter::new(
                        "data",
                        "period",
                        "none",
                        format!(
                            "motor m{} of {} spans no range ({low} to {high}): a motor that never moves cannot be learned; drop the column",
                            j + 1,
                            path.display()
                        ),
                    )
                    .into());
                }
                Motor::Bounded { low, high }
            }
        });
    }
    Ok(MotorSpace::new(space)?)
}

/// A log, checked: as many rows of motors as of sensors, finite, bounded motors in their
/// range (periodic ones wrapped into theirs), no constant sensor.
#[derive(Debug, Clone)]
pub struct SensorimotorLog {
    /// Motor commands `(S, N)`, periodic coordinates wrapped.
    pub motors: Array2<f64>,
    /// Sensor values `(S, K)`.
    pub sensors: Array2<f64>,
    /// Where they came from (for messages).
    pub files: LogFiles,
}

impl SensorimotorLog {
    /// Reads and checks a log for motors in `space`.
    pub fn load(files: LogFiles, space: &MotorSpace) -> Result<Self, LearnError> {
        let motors = io::read_matrix(&files.motors, None, "(S, N)")?;
        let sensors = io::read_matrix(&files.sensors, None, "(S, K)")?;
        Self::new(motors, sensors, files, space)
    }

    /// Checks a log for motors in `space` (see the type's docs).
    pub fn new(
        mut motors: Array2<f64>,
        sensors: Array2<f64>,
        files: LogFiles,
        space: &MotorSpace,
    ) -> Result<Self, LearnError> {
        if motors.nrows() != sensors.nrows() {
            return Err(LearnError::RowCount {
                motors: files.motors,
                motor_rows: motors.nrows(),
                sensors: files.sensors,
                sensor_rows: sensors.nrows(),
            });
        }
        if motors.ncols() != space.dim() {
            return Err(LearnError::MotorColumns {
                path: files.motors,
                found: motors.ncols(),
                expected: space.dim(),
            });
        }
        if motors.nrows() < 2 || sensors.ncols() == 0 {
            return Err(LearnError::TooFewSamples {
                path: files.motors,
                samples: motors.nrows(),
                reason: format!(
                    "a log needs samples and sensors, and this one has {} samples of {} sensors",
                    motors.nrows(),
                    sensors.ncols()
                ),
                fix: "record a longer log",
            });
        }
        io::check_finite(&files.motors, &motors)?;
        io::check_finite(&files.sensors, &sensors)?;
        check_ranges(&mut motors, space, &files.motors)?;
        for (column, values) in sensors.columns().into_iter().enumerate() {
            let first = values[0];
            if values.iter().all(|&v| v == first) {
                return Err(LearnError::ConstantSensor {
                    path: files.sensors,
                    column,
                    value: first,
                    samples: sensors.nrows(),
                });
            }
        }
        Ok(Self {
            motors,
            sensors,
            files,
        })
    }

    /// Samples `S`.
    pub fn samples(&self) -> usize {
        self.motors.nrows()
    }
}

/// Refuses a bounded motor outside its range; wraps periodic motors into theirs.
fn check_ranges(
    motors: &mut Array2<f64>,
    space: &MotorSpace,
    path: &Path,
) -> Result<(), LearnError> {
    for (row, mut values) in motors.outer_iter_mut().enumerate() {
        for (j, value) in values.iter_mut().enumerate() {
            match space.motor(j) {
                Motor::Bounded { low, high } => {
                    if !(low..=high).contains(value) {
                        return Err(LearnError::OutOfRange {
                            path: path.to_owned(),
                            row,
                            motor: j + 1,
                            value: *value,
                            low,
                            high,
                        });
                    }
                }
                motor @ Motor::Periodic { .. } => *value = motor.wrap(*value),
            }
        }
    }
    Ok(())
}

/// Fits one log, holding out samples, and measures the error on them; the noise and
/// the local rank measured on the fitted rows come with the report (the noise raises
/// the fit's neighbours, see [`LawValidParams::neighbours_for_noise`]).
pub(super) fn fit_log(
    log: &SensorimotorLog,
    space: &MotorSpace,
    params: &LawValidParams,
    progress: &dyn Progress,
) -> Result<(LocalModel, LogReport, Option<LocalRank>), LearnError> {
    let samples = log.samples();
    let n = space.dim();
    let held = params.holdout(samples);
    let neighbours = params.neighbours(n);
    if samples - held < neighbours + 1 {
        return Err(LearnError::TooFewSamples {
            path: log.files.motors.clone(),
            samples,
            reason: format!(
                "a {} fit with {n} motors holds {neighbours} samples, and {} remain after {held} held out",
                serde_json::to_value(params.method).ok().and_then(|v| v.as_str().map(str::to_owned)).unwrap_or_default(),
                samples - held
            ),
            fix: "record a longer log, lower neighbours or holdout, or use method = local-linear",
        });
    }
    let (fit, held_rows) = split_rows(samples, held, params.seed);
    let local = observe::stage(progress, observe::NOISE, 1, || {
        let local = estimate_local(log, &fit, params.seed);
        progress.advance(1);
        local
    });
    let mut chosen = params.clone();
    if let Some((noise, _)) = &local {
        chosen.neighbours = Some(params.neighbours_for_noise(n, noise, fit.len()));
    }
    let (model, images) = LocalModel::new(log, &fit, &chosen, space, progress)?;
    let mut report = held_out_report(
        log,
        (&held_rows, fit.len()),
        (model.bandwidth(), images),
        progress,
        |m, s| {
            if !model.covers(m) {
                return false;
            }
            model.evaluate(m, s, None);
            true
        },
    );
    report.neighbours = Some(chosen.neighbours(n));
    let rank = local.map(|(noise, rank)| {
        report.noise = Some(noise);
        rank
    });
    Ok((model, report, rank))
}

/// The rows of a log held out of the fit (seeded), sorted, and the fitted rows.
pub(super) fn split_rows(samples: usize, held: usize, seed: u64) -> (Vec<u32>, Vec<u32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut is_held = vec![false; samples];
    let mut held_rows: Vec<u32> = sample(&mut rng, samples, held)
        .into_iter()
        .map(|i| i as u32)
        .collect();
    held_rows.sort_unstable();
    for &i in &held_rows {
        is_held[i as usize] = true;
    }
    let fit = (0..samples as u32)
        .filter(|&i| !is_held[i as usize])
        .collect();
    (fit, held_rows)
}

/// The report of one log: its law's error on the held-out rows (of `fitted` rows
/// fitted), where `predict(m, ŝ)` writes the law's sensor values and returns whether
/// the law covers `m` (uncovered rows are counted apart); the stage
/// [`observe::HELD_OUT`] of `progress`.
pub(super) fn held_out_report(
    log: &SensorimotorLog,
    (held_rows, fitted): (&[u32], usize),
    (bandwidth, images): (f64, f64),
    progress: &dyn Progress,
    predict: impl Fn(&[f64], &mut [f64]) -> bool + Sync + Send,
) -> LogReport {
    let k = log.sensors.ncols();
    progress.start(observe::HELD_OUT, held_rows.len() as u64);
    let errors: Vec<Option<(f64, f64)>> = observe::map_rows(held_rows, progress, |i| {
        let i = i as usize;
        let m = log.motors.row(i).to_vec();
        let mut s = vec![0.0; k];
        if !predict(&m, &mut s) {
            return None;
        }
        let (mut squares, mut largest) = (0.0, 0.0f64);
        for (a, b) in s.iter().zip(log.sensors.row(i)) {
            squares += (a - b) * (a - b);
            largest = largest.max((a - b).abs());
        }
        Some((squares, largest))
    });
    progress.finish();
    let covered: Vec<(f64, f64)> = errors.iter().flatten().copied().collect();
    let mean_variance = log
        .sensors
        .columns()
        .into_iter()
        .map(|c| {
            let mean = c.mean().unwrap_or(0.0);
            c.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / c.len() as f64
        })
        .sum::<f64>()
        / k as f64;
    let rms = if covered.is_empty() {
        0.0
    } else {
        (covered.iter().map(|e| e.0).sum::<f64>() / (covered.len() * k) as f64).sqrt()
    };
    LogReport {
        motors: log.files.motors.display().to_string(),
        sensors: log.files.sensors.display().to_string(),
        samples: log.samples(),
        fitted,
        held_out: held_rows.len(),
        bandwidth,
        images_per_sample: images,
        held_out_relative_rms: rms / mean_variance.sqrt().max(f64::MIN_POSITIVE),
        held_out_max_abs: covered.iter().map(|e| e.1).fold(0.0, f64::max),
        held_out_uncovered: errors.len() - covered.len(),
        neighbours: None,
        noise: None,
        repeated: 0,
    }
}

/// Two motor values within this fraction of their motor's scale (its period, or its
/// range in the log) are the same command: a row whose every motor is the same as an
/// earlier row's repeats it (a robot holding still records the same configuration
/// again, with the same readings or with fresh sensor noise).
pub const REPEAT_TOLERANCE: f64 = 1e-9;

/// Which rows of `log` repeat an earlier row's motor command (see
/// [`REPEAT_TOLERANCE`]), and how many do.
pub(crate) fn repeated_rows(log: &SensorimotorLog, space: &MotorSpace) -> (Vec<bool>, usize) {
    let steps: Vec<f64> = space
        .motors()
        .iter()
        .zip(log.motors.columns())
        .map(|(motor, column)| {
            let range = column.iter().fold(f64::NEG_INFINITY, |a, &v| a.max(v))
                - column.iter().fold(f64::INFINITY, |a, &v| a.min(v));
            let scale = motor.period().unwrap_or(range);
            if scale > 0.0 && scale.is_finite() {
                REPEAT_TOLERANCE * scale
            } else {
                1.0
            }
        })
        .collect();
    let mut seen = std::collections::HashSet::with_capacity(log.samples());
    let mut count = 0;
    let flags = log
        .motors
        .outer_iter()
        .map(|row| {
            let key: Vec<i64> = row
                .iter()
                .zip(&steps)
                .map(|(&v, step)| (v / step).round() as i64)
                .collect();
            let repeat = !seen.insert(key);
            count += usize::from(repeat);
            repeat
        })
        .collect();
    (flags, count)
}

/// `log` without the rows `repeated` marks: one sample per motor command. A repeat
/// would pair with its own twin as its nearest sensory neighbour, a pair that every
/// function of the motors leaves unchanged, and with enough of them every function
/// passes for an invariant.
pub(crate) fn without_repeats(log: &SensorimotorLog, repeated: &[bool]) -> SensorimotorLog {
    let rows: Vec<usize> = (0..log.samples()).filter(|&i| !repeated[i]).collect();
    SensorimotorLog {
        motors: log.motors.select(ndarray::Axis(0), &rows),
        sensors: log.sensors.select(ndarray::Axis(0), &rows),
        files: log.files.clone(),
    }
}
