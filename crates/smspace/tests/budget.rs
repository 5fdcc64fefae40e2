//! Learning from an agent within a budget of sensor rows (`learn::budget`): the rows
//! read never exceed the budget and are counted exactly, unreadable rows are left out,
//! a budget too small is refused with its minimum, and verification drops the sets the
//! agent's own readings contradict.

use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::agent::{Agent, Environment};
use smspace::learn::budget::{learn_from_agent, min_babble_rows, BudgetParams, BudgetedSets};
use smspace::learn::{law_trace_params, LawParams, LearnError};
use smspace::progress::Silent;

/// `x = sin m1 + sin(m2)/2`: the pose of a cart on two hinges.
fn cart_x(m: &[f64]) -> f64 {
    m[0].sin() + 0.5 * m[1].sin()
}

/// How an agent answers, on top of the cart's sensors `s = (x, x²/2)`.
#[derive(Debug, Clone, Copy)]
enum Kind {
    /// The cart's sensors.
    Cart,
    /// NaN where `m1 ∈ [0, 0.4)`.
    Holey,
    /// After `n` rows, the first sensor reads `x + 0.4 sin m2`: a sensor knocked out of
    /// calibration between babbling and verification.
    DriftsAfter(u64),
    /// The first sensor jumps by 0.6 where `m2 ∈ [0, 1)`.
    Jumps,
    /// Gaussian noise of this deviation on both sensors, a new draw at every reading.
    Noisy(f64),
}

/// A standard normal draw from the `n`-th reading (splitmix64 and Box–Muller).
fn normal(n: u64) -> f64 {
    let mix = |mut z: u64| {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let u1 = ((mix(2 * n) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (mix(2 * n + 1) >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
}

/// An agent of two hinges without ground truth that counts the rows it is read at.
#[derive(Debug)]
struct Counting {
    kind: Kind,
    rows: AtomicU64,
    /// Rows answered with NaN.
    nan_rows: AtomicU64,
}

impl Counting {
    fn new(kind: Kind) -> Self {
        Self {
            kind,
            rows: AtomicU64::new(0),
            nan_rows: AtomicU64::new(0),
        }
    }
}

impl Agent for Counting {
    fn motor_dim(&self) -> usize {
        2
    }
    fn sensor_dim(&self) -> usize {
        2
    }
    fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
        let read = self.rows.fetch_add(1, Ordering::SeqCst);
        let mut x = cart_x(m);
        match self.kind {
            Kind::Cart => {}
            Kind::Holey if (0.0..0.4).contains(&m[0]) => {
                self.nan_rows.fetch_add(1, Ordering::SeqCst);
                x = f64::NAN;
            }
            Kind::Holey => {}
            Kind::DriftsAfter(n) if read >= n => x += 0.4 * m[1].sin(),
            Kind::DriftsAfter(_) => {}
            Kind::Jumps if (0.0..1.0).contains(&m[1]) => {
                s[0] = x + 0.6;
                s[1] = x * x / 2.0;
                return;
            }
            Kind::Jumps => {}
            Kind::Noisy(sigma) => {
                s[0] = x + sigma * normal(2 * read);
                s[1] = x * x / 2.0 + sigma * normal(2 * read + 1);
                return;
            }
        }
        s[0] = x;
        s[1] = x * x / 2.0;
    }
    fn name(&self) -> &str {
        "counting-cart"
    }
}

/// `m` seeded uniform starts on the torus.
fn starts(m: usize) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    Array2::from_shape_fn((m, 2), |_| rng.random_range(-PI..PI))
}

fn run(agent: &Counting, budget: u64, starts: &Array2<f64>) -> Result<BudgetedSets, LearnError> {
    run_with(agent, BudgetParams::new(budget), starts)
}

fn run_with(
    agent: &Counting,
    budget: BudgetParams,
    starts: &Array2<f64>,
) -> Result<BudgetedSets, LearnError> {
    let law = LawParams::default().check().unwrap();
    let budget = budget.check().unwrap();
    let environment = Environment::from_lights(Vec::new());
    learn_from_agent(
        agent,
        &environment,
        starts.view(),
        None,
        &budget,
        &law,
        &law_trace_params(),
        None,
        &Silent,
    )
}

/// The largest `|x(p) − x(start)|` over each kept set.
fn x_errors(found: &BudgetedSets, starts: &Array2<f64>) -> Vec<f64> {
    let traced = &found.traced;
    traced
        .kept
        .iter()
        .enumerate()
        .map(|(i, &row)| {
            let x0 = cart_x(starts.row(row).as_slice().unwrap());
            traced
                .sets
                .outer_iter()
                .nth(i)
                .unwrap()
                .outer_iter()
                .map(|p| (cart_x(&[p[0], p[1]]) - x0).abs())
                .fold(0.0, f64::max)
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn a_budget_of_twenty_thousand_rows_traces_the_carts_kernels_and_counts_every_row() {
    let agent = Counting::new(Kind::Cart);
    let starts = starts(12);
    let found = run(&agent, 20_000, &starts).unwrap();
    let rows = found.rows;
    assert_eq!(agent.rows.load(Ordering::SeqCst), rows.total);
    assert!(rows.total <= 20_000);
    // Reserved: each start's verification (2 + 8 rows) and the agent's own slope at 12
    // starts (2N + 2 = 6 rows each).
    assert_eq!(rows.babble, 20_000 - 12 * 10 - 12 * 6);
    assert_eq!(rows.agent_rank, 12 * 6);
    assert_eq!(rows.non_finite, 0);
    assert_eq!(rows.babble + rows.agent_rank + rows.verify, rows.total);
    let agent_rank = found.agent_rank.as_ref().unwrap();
    assert_eq!(
        (agent_rank.rank, agent_rank.starts),
        (1, 12),
        "{agent_rank:?}"
    );
    assert_eq!(rows.verify, 10 * found.verification.len() as u64);
    assert!(found.traced.kept.len() >= 8, "{:?}", found.verification);
    let errors = x_errors(&found, &starts);
    assert!(median(errors) < 0.05);
    // The verified sets are the kept ones, in the starts' order.
    let passed: Vec<usize> = found
        .verification
        .iter()
        .filter(|v| v.passed)
        .map(|v| v.index)
        .collect();
    assert_eq!(found.traced.kept, passed);
    assert!(
        found.warnings().is_empty(),
        "{:?} {:?}",
        found.warnings(),
        found.traced.report.summary.by_status
    );
    // The report serialises without the sets.
    let report = serde_json::to_value(&found).unwrap();
    assert_eq!(report["rows"]["total"], rows.total);
}

#[test]
fn the_same_sets_and_verdicts_on_one_thread() {
    let starts = starts(4);
    let many = run(&Counting::new(Kind::Cart), 12_000, &starts).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let one = pool
        .install(|| run(&Counting::new(Kind::Cart), 12_000, &starts))
        .unwrap();
    assert_eq!(many.traced.sets, one.traced.sets);
    assert_eq!(many.verification, one.verification);
    assert_eq!(many.rows, one.rows);
}

#[test]
fn rows_the_agent_cannot_read_are_counted_named_and_left_out() {
    let agent = Counting::new(Kind::Holey);
    let starts = starts(6);
    let found = run(&agent, 20_000, &starts).unwrap();
    let rows = found.rows;
    assert_eq!(agent.rows.load(Ordering::SeqCst), rows.total);
    assert!(rows.total <= 20_000);
    // Every babbled NaN counted (verification's and the agent slope's own readings are
    // not babbling).
    let verify_nan = found
        .verification
        .iter()
        .filter(|v| v.error.is_infinite())
        .count();
    assert!(rows.non_finite <= agent.nan_rows.load(Ordering::SeqCst));
    assert!(rows.non_finite > 0);
    assert!(
        agent.nan_rows.load(Ordering::SeqCst) - rows.non_finite
            <= 10 * verify_nan as u64 + rows.agent_rank,
        "{rows:?}"
    );
    // Babbled once, uniformly: about 0.4 / 2π of the rows.
    let uniform = Counting::new(Kind::Holey);
    let once = run_with(
        &uniform,
        BudgetParams {
            rounds: 1,
            ..BudgetParams::new(20_000)
        },
        &starts,
    )
    .unwrap();
    let expected = 0.4 / (2.0 * PI) * once.rows.babble as f64;
    assert!(
        (once.rows.non_finite as f64 - expected).abs() < 0.15 * expected,
        "{:?}",
        once.rows
    );
    assert_eq!(found.non_finite_motors.len(), 5);
    assert!(found
        .non_finite_motors
        .iter()
        .all(|m| (0.0..0.4).contains(&m[0])));
    // Learned from the finite rows only.
    assert_eq!(
        found.law.logs[0].samples as u64,
        rows.babble - rows.non_finite
    );
    assert!(found.warnings()[0].contains("not finite"));
}

#[test]
fn a_budget_below_the_minimum_is_refused_with_it_before_any_row_is_read() {
    let agent = Counting::new(Kind::Cart);
    let starts = starts(10);
    let law = LawParams::default().check().unwrap();
    let minimum = min_babble_rows(&law, 2);
    assert!(minimum >= 4096);
    let err = run(&agent, 3000, &starts).unwrap_err();
    let needed = minimum + 10 * 10 + 10 * 6;
    assert!(
        matches!(err, LearnError::Budget { needed: n, .. } if n == needed),
        "{err}"
    );
    let message = err.to_string();
    assert!(message.contains(&format!("at least {needed}")), "{message}");
    assert_eq!(agent.rows.load(Ordering::SeqCst), 0);
    assert!(BudgetParams::new(0).check().is_err());
    let toml_like: Result<BudgetParams, _> =
        serde_json::from_str(r#"{"budget": 10, "verify_point": 3}"#);
    assert!(toml_like.is_err());
}

#[test]
fn readings_that_changed_since_the_babbling_fail_verification_and_are_dropped() {
    // The sets are traced on the law of the first sensor's calibration; the agent
    // reads the second one when verifying: sets along which m2 changes fail.
    let starts = starts(12);
    // Every row but the verification's: the babbling and the agent's own slope.
    let agent = Counting::new(Kind::DriftsAfter(20_000 - 12 * 10));
    let found = run(&agent, 20_000, &starts).unwrap();
    assert_eq!(agent.rows.load(Ordering::SeqCst), found.rows.total);
    let failed = found.failed().count();
    assert!(failed > 0, "{:?}", found.verification);
    assert_eq!(found.traced.kept.len() + failed, found.verification.len());
    assert!(found.failed().all(|v| v.error > found.threshold));
    assert!(found
        .warnings()
        .iter()
        .any(|w| w.contains("failed verification")));
}

#[test]
fn sensors_that_jump_give_sets_that_fail_verification() {
    let starts = starts(12);
    let agent = Counting::new(Kind::Jumps);
    let found = run(&agent, 20_000, &starts).unwrap();
    assert_eq!(agent.rows.load(Ordering::SeqCst), found.rows.total);
    // The invariants of the smooth basis cannot jump: the sets are level sets of `x`,
    // and every one that crosses the band reads the jump there.
    let failed: Vec<_> = found.failed().collect();
    assert!(2 * failed.len() > found.verification.len(), "{failed:?}");
    let jump = 0.6 / found.spread[0];
    for v in failed {
        assert!((v.error - jump).abs() < 0.05 * jump, "{v:?} vs {jump}");
    }
    for (i, set) in found.traced.sets.outer_iter().enumerate() {
        assert!(
            set.outer_iter().all(|p| !(0.0..1.0).contains(&p[1])),
            "kept set {i} enters the band"
        );
    }
}

#[test]
fn a_second_round_reads_around_the_sets_where_the_first_left_them_sparse() {
    let agent = Counting::new(Kind::Cart);
    let starts = starts(12);
    let found = run_with(
        &agent,
        BudgetParams {
            rounds: 3,
            ..BudgetParams::new(30_000)
        },
        &starts,
    )
    .unwrap();
    let rounds = &found.rounds;
    assert_eq!(rounds.len(), 3);
    // Half the babbling in the first round, the rest in equal parts.
    let babble = found.rows.babble;
    assert_eq!(rounds.iter().map(|r| r.rows).sum::<u64>(), babble);
    assert_eq!(rounds[0].rows, (babble as f64 / 2.0).round() as u64);
    // The rows go where the sets are: the spacing along them falls faster than the
    // rows grow (uniform rows would shrink it by (3/2)^(1/2) = 1.22 in two dimensions).
    assert!(
        rounds[2].spacing_median < rounds[0].spacing_median / 1.4,
        "{rounds:?}"
    );
    let errors = x_errors(&found, &starts);
    assert!(median(errors) < 0.05);
}

#[test]
fn rounds_out_of_their_domain_are_refused_with_the_key() {
    for (rounds, first_round) in [(0, 0.5), (17, 0.5), (2, 0.0), (2, 1.5), (2, f64::NAN)] {
        let error = BudgetParams {
            rounds,
            first_round,
            ..BudgetParams::new(20_000)
        }
        .check()
        .unwrap_err()
        .to_string();
        let key = if rounds == 2 { "first_round" } else { "rounds" };
        assert!(error.contains(key), "{error}");
    }
}

#[test]
fn the_two_readings_of_each_start_measure_the_noise_that_sets_the_threshold() {
    // Exact sensors: the two readings agree, no noise allowance.
    let exact = run(&Counting::new(Kind::Cart), 12_000, &starts(4)).unwrap();
    assert_eq!(exact.noise, vec![0.0, 0.0]);
    assert_eq!(exact.threshold, BudgetParams::new(1).verify_tolerance);
    // Noise of 0.04 on both sensors: measured from the pairs, relative to the spread.
    let sigma = 0.04;
    let starts = starts(40);
    let found = run(&Counting::new(Kind::Noisy(sigma)), 30_000, &starts).unwrap();
    for (k, (&noise, &spread)) in found.noise.iter().zip(&found.spread).enumerate() {
        let truth = sigma / spread;
        assert!(
            (noise - truth).abs() < 0.4 * truth,
            "sensor {k}: measured {noise}, true {truth}"
        );
    }
    let tolerance = BudgetParams::new(1).verify_tolerance;
    assert!(found.threshold > tolerance + 3.0 * sigma / found.spread[0]);
    // Sets on the kernel pass, though their readings change by more than the tolerance
    // alone allows.
    assert!(
        found.traced.kept.len() as f64 >= 0.9 * starts.nrows() as f64,
        "{:?}",
        found.verification
    );
    assert!(
        found
            .verification
            .iter()
            .any(|v| v.passed && v.error > tolerance),
        "{:?}",
        found.verification
    );
    assert!(median(x_errors(&found, &starts)) < 0.05);
}
