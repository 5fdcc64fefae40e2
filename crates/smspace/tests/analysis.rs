//! Known spaces with known answers: circle, torus, sphere, segment and cylinder, each
//! checked against the `ripser` program (Debian package `ripser`) where installed.

use std::f64::consts::TAU;
use std::path::Path;
use std::process::Command;

use approx::assert_abs_diff_eq;
use ndarray::{Array2, ArrayView2};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::analysis::{
    agreement, analyze, dimension, maxmin_landmarks, rips_persistence, AnalysisError,
    AnalysisParams, BettiRule, Persistence,
};
use smspace::metric::DistanceMatrix;
use smspace::progress::Silent;

/// `d` as a validated distance matrix.
fn dm(d: &Array2<f64>) -> DistanceMatrix {
    DistanceMatrix::new(d.clone()).unwrap()
}

fn euclidean(points: &Array2<f64>) -> Array2<f64> {
    let n = points.nrows();
    Array2::from_shape_fn((n, n), |(i, j)| {
        points
            .row(i)
            .iter()
            .zip(points.row(j).iter())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    })
}

fn points<const D: usize>(
    n: usize,
    seed: u64,
    mut f: impl FnMut(&mut ChaCha8Rng) -> [f64; D],
) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let data: Vec<f64> = (0..n).flat_map(|_| f(&mut rng)).collect();
    Array2::from_shape_vec((n, D), data).unwrap()
}

fn circle(n: usize, seed: u64) -> Array2<f64> {
    points(n, seed, |rng| {
        let a = rng.random_range(0.0..TAU);
        [a.cos(), a.sin()]
    })
}

/// Flat torus in ℝ⁴, on a jittered grid so that no region is left empty.
fn torus(side: usize, seed: u64) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut data = Vec::new();
    for i in 0..side {
        for j in 0..side {
            let a = (i as f64 + rng.random_range(0.0..0.5)) * TAU / side as f64;
            let b = (j as f64 + rng.random_range(0.0..0.5)) * TAU / side as f64;
            data.extend_from_slice(&[a.cos(), a.sin(), b.cos(), b.sin()]);
        }
    }
    Array2::from_shape_vec((side * side, 4), data).unwrap()
}

fn sphere(n: usize, seed: u64) -> Array2<f64> {
    points(n, seed, |rng| loop {
        let p: [f64; 3] = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        if (0.1..=1.0).contains(&r) {
            break [p[0] / r, p[1] / r, p[2] / r];
        }
    })
}

fn betti(d: &Array2<f64>, max_dim: usize) -> (Vec<usize>, Persistence) {
    let persistence = rips_persistence(d.view(), max_dim, None, &Silent).unwrap();
    (BettiRule::default().betti(&persistence), persistence)
}

/// Persistence diagrams as `[birth, death]` pairs, by dimension.
type Diagrams = Vec<Vec<(f64, Option<f64>)>>;

/// Why the comparisons with the `ripser` program are ignored by default: they need
/// the program, which `.ci/run` installs and then runs them with `--ignored`.
const NEEDS_RIPSER: &str = "needs the `ripser` program (apt-get install ripser): cargo test -p smspace --test analysis -- --ignored ripser";

/// The diagrams of the `ripser` program; panics, saying how to install it, when it
/// cannot run (the tests that call it are ignored unless asked for).
fn ripser(d: ArrayView2<f64>, max_dim: usize, threshold: Option<f64>) -> Diagrams {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("d.txt");
    // The full matrix: unambiguous, where the lower-triangular reader is sensitive to
    // the layout of its first rows.
    let mut text = String::new();
    for i in 0..d.nrows() {
        let row: Vec<String> = (0..d.ncols())
            .map(|j| format!("{:.17e}", d[[i, j]]))
            .collect();
        text.push_str(&row.join(","));
        text.push('\n');
    }
    std::fs::write(&path, text).unwrap();
    let mut command = Command::new("ripser");
    command.args(["--format", "distance", "--dim", &max_dim.to_string()]);
    if let Some(t) = threshold {
        command.args(["--threshold", &format!("{t:.17e}")]);
    }
    let output = command
        .arg(Path::new(&path))
        .output()
        .unwrap_or_else(|e| panic!("cannot run `ripser` ({e}): {NEEDS_RIPSER}"));
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut diagrams: Diagrams = Vec::new();
    for line in String::from_utf8(output.stdout).unwrap().lines() {
        if line.starts_with("persistence intervals in dim") {
            diagrams.push(Vec::new());
        } else if let Some(bar) = line.trim().strip_prefix('[') {
            let bar = bar.trim_end_matches(')');
            let (b, e) = bar.split_once(',').unwrap();
            let e = e.trim();
            diagrams.last_mut().unwrap().push((
                b.parse().unwrap(),
                (!e.is_empty()).then(|| e.parse().unwrap()),
            ));
        }
    }
    diagrams
}

/// Our diagrams equal Ripser's up to its single-precision output: same number of bars
/// longer than `tol` in every dimension, with matching endpoints.
fn assert_matches_ripser(d: &Array2<f64>, ours: &Persistence, max_dim: usize) {
    assert_matches_ripser_up_to(d, ours, max_dim, None);
}

/// [`assert_matches_ripser`] with Ripser run up to `threshold` (`None`: its default,
/// the enclosing radius).
fn assert_matches_ripser_up_to(
    d: &Array2<f64>,
    ours: &Persistence,
    max_dim: usize,
    threshold: Option<f64>,
) {
    let theirs = ripser(d.view(), max_dim, threshold);
    let tol = 1e-4 * ours.threshold;
    for dim in 0..=max_dim {
        let key = |bars: Vec<(f64, Option<f64>)>| {
            let mut v: Vec<(f64, f64)> = bars
                .into_iter()
                .map(|(b, e)| (b, e.unwrap_or(f64::INFINITY)))
                .filter(|(b, e)| e - b > tol)
                .collect();
            v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.total_cmp(&b.0)));
            v
        };
        let ours_d = key(ours.diagrams[dim]
            .iter()
            .map(|b| (b.birth, b.death))
            .collect());
        let theirs_d = key(theirs.get(dim).cloned().unwrap_or_default());
        assert_eq!(
            ours_d.len(),
            theirs_d.len(),
            "dimension {dim}: {ours_d:?} vs {theirs_d:?}"
        );
        for (a, b) in ours_d.iter().zip(&theirs_d) {
            assert_abs_diff_eq!(a.0, b.0, epsilon = tol);
            if a.1.is_finite() || b.1.is_finite() {
                assert_abs_diff_eq!(a.1, b.1, epsilon = tol);
            }
        }
    }
}

#[test]
fn circle_has_one_loop_and_dimension_one() {
    let d = euclidean(&circle(200, 1));
    let (b, _) = betti(&d, 1);
    assert_eq!(b, vec![1, 1]);
    let twonn = dimension::twonn(d.view(), 0.1).unwrap();
    let mle = dimension::mle(d.view(), 20).unwrap();
    assert_abs_diff_eq!(twonn.dimension, 1.0, epsilon = 0.15);
    assert_abs_diff_eq!(mle.dimension, 1.0, epsilon = 0.15);
}

#[test]
fn torus_has_two_loops_and_dimension_two() {
    let d = euclidean(&torus(22, 2));
    let (b, _) = betti(&d, 1);
    assert_eq!(b, vec![1, 2]);
    // TwoNN assumes Poisson-like sampling, which a jittered grid is not.
    let uniform = euclidean(&points(600, 22, |rng| {
        let (a, b) = (rng.random_range(0.0..TAU), rng.random_range(0.0..TAU));
        [a.cos(), a.sin(), b.cos(), b.sin()]
    }));
    let twonn = dimension::twonn(uniform.view(), 0.1).unwrap();
    assert_abs_diff_eq!(twonn.dimension, 2.0, epsilon = 0.3);
}

#[test]
fn sphere_has_no_loop_and_one_cavity() {
    let d = euclidean(&sphere(180, 3));
    let (b, _) = betti(&d, 2);
    assert_eq!(b, vec![1, 0, 1]);
    let mle = dimension::mle(d.view(), 20).unwrap();
    assert_abs_diff_eq!(mle.dimension, 2.0, epsilon = 0.3);
}

#[test]
fn segment_is_contractible_and_one_dimensional() {
    let d = euclidean(&segment());
    let (b, _) = betti(&d, 1);
    assert_eq!(b, vec![1, 0]);
    let twonn = dimension::twonn(d.view(), 0.1).unwrap();
    assert_abs_diff_eq!(twonn.dimension, 1.0, epsilon = 0.15);
}

#[test]
fn circle_times_segment_has_one_loop_and_dimension_two() {
    let d = euclidean(&circle_times_segment());
    let (b, _) = betti(&d, 1);
    assert_eq!(b, vec![1, 1]);
    let twonn = dimension::twonn(d.view(), 0.1).unwrap();
    let mle = dimension::mle(d.view(), 20).unwrap();
    assert_abs_diff_eq!(twonn.dimension, 2.0, epsilon = 0.3);
    assert_abs_diff_eq!(mle.dimension, 2.0, epsilon = 0.3);
}

fn segment() -> Array2<f64> {
    points(150, 4, |rng| [rng.random_range(0.0..1.0)])
}

fn circle_times_segment() -> Array2<f64> {
    points(500, 5, |rng| {
        let a = rng.random_range(0.0..TAU);
        [a.cos(), a.sin(), rng.random_range(0.0..0.8)]
    })
}

#[test]
#[ignore = "needs the `ripser` program (apt-get install ripser); .ci/run installs it and runs the comparisons with --ignored"]
fn shapes_match_ripser() {
    for (name, points, max_dim) in [
        ("circle", circle(200, 1), 1),
        ("torus", torus(22, 2), 1),
        ("sphere", sphere(180, 3), 2),
        ("segment", segment(), 1),
        ("circle × segment", circle_times_segment(), 1),
    ] {
        eprintln!("{name}");
        let d = euclidean(&points);
        let (_, persistence) = betti(&d, max_dim);
        assert_matches_ripser(&d, &persistence, max_dim);
    }
}

#[test]
#[ignore = "needs the `ripser` program (apt-get install ripser); .ci/run installs it and runs the comparisons with --ignored"]
fn diagrams_match_ripser_on_random_clouds_of_several_sizes() {
    for (seed, n) in [(10u64, 20usize), (11, 60), (12, 120)] {
        let d = euclidean(&points(n, seed, |rng| {
            [
                rng.random_range(0.0..1.0),
                rng.random_range(0.0..1.0),
                rng.random_range(0.0..1.0),
            ]
        }));
        let persistence = rips_persistence(d.view(), 2, None, &Silent).unwrap();
        assert_matches_ripser(&d, &persistence, 2);
    }
}

#[test]
#[ignore = "needs the `ripser` program (apt-get install ripser); .ci/run installs it and runs the comparisons with --ignored"]
fn ties_in_distances_match_ripser() {
    // Points on a regular grid: many equal distances, so many apparent and emergent pairs.
    let mut data = Vec::new();
    for i in 0..8 {
        for j in 0..8 {
            data.extend_from_slice(&[i as f64, j as f64]);
        }
    }
    let d = euclidean(&Array2::from_shape_vec((64, 2), data).unwrap());
    let persistence = rips_persistence(d.view(), 2, None, &Silent).unwrap();
    assert_matches_ripser(&d, &persistence, 2);
}

/// A noisy circle times a short segment in ℝ³: enough edges for the reduction's
/// diameter bands, and a loop that lives through most of them.
fn thick_circle(n: usize, seed: u64) -> Array2<f64> {
    points(n, seed, |rng| {
        let a = rng.random_range(0.0..TAU);
        let r = 1.0 + rng.random_range(-0.15..0.15);
        [r * a.cos(), r * a.sin(), rng.random_range(0.0..0.4)]
    })
}

#[test]
fn banded_reduction_keeps_a_long_lived_loop() {
    // 500 points: ~10⁵ edges, so the reduction runs in dozens of bands and the
    // loop's column is restarted from its partial reduction in each.
    let d = euclidean(&thick_circle(500, 21));
    let (betti, _) = betti(&d, 1);
    assert_eq!(betti, vec![1, 1]);
}

#[test]
#[ignore = "needs the `ripser` program (apt-get install ripser); .ci/run installs it and runs the comparisons with --ignored"]
fn banded_reduction_matches_ripser_with_a_long_lived_loop() {
    let d = euclidean(&thick_circle(500, 21));
    let (_, persistence) = betti(&d, 1);
    assert_matches_ripser(&d, &persistence, 1);
    // Below the enclosing radius too (the bands end at the given threshold).
    let persistence = rips_persistence(d.view(), 1, Some(1.2), &Silent).unwrap();
    assert_matches_ripser_up_to(&d, &persistence, 1, Some(1.2));
}

#[test]
fn threshold_below_the_loop_death_leaves_an_infinite_bar() {
    let d = euclidean(&circle(100, 6));
    let persistence = rips_persistence(d.view(), 1, Some(1.0), &Silent).unwrap();
    let infinite = persistence.diagrams[1]
        .iter()
        .filter(|b| b.death.is_none())
        .count();
    assert_eq!(infinite, 1);
    assert_eq!(BettiRule::default().betti(&persistence), vec![1, 1]);
}

#[test]
fn identical_metrics_agree_perfectly() {
    let poses = points(120, 7, |rng| {
        [
            rng.random_range(0.0..2.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-3.0..3.0),
        ]
    });
    // The learned metric is exactly the pose metric (alpha scaled like the module's).
    let a = agreement::agreement(pose_metric(&poses).view(), poses.view(), 10).unwrap();
    assert_abs_diff_eq!(a.spearman, 1.0, epsilon = 1e-12);
    assert_abs_diff_eq!(a.trustworthiness, 1.0, epsilon = 1e-12);
    assert_abs_diff_eq!(a.continuity, 1.0, epsilon = 1e-12);
    // A monotone transform keeps every rank.
    let squared = pose_metric(&poses).mapv(|x| x * x + x);
    let b = agreement::agreement(squared.view(), poses.view(), 10).unwrap();
    assert_abs_diff_eq!(b.spearman, 1.0, epsilon = 1e-12);
    assert_abs_diff_eq!(b.trustworthiness, 1.0, epsilon = 1e-12);
}

/// The module's pose metric: coordinates scaled by their RMS pair difference, alpha
/// wrapped.
fn pose_metric(poses: &Array2<f64>) -> Array2<f64> {
    let n = poses.nrows();
    let delta = |i: usize, j: usize, c: usize| {
        let d = poses[[i, c]] - poses[[j, c]];
        if c == 2 {
            smspace::agent::wrap_angle(d)
        } else {
            d
        }
    };
    let mut scales = [0.0; 3];
    for (c, s) in scales.iter_mut().enumerate() {
        let mut sum = 0.0;
        for i in 0..n {
            for j in i + 1..n {
                sum += delta(i, j, c).powi(2);
            }
        }
        *s = (sum / (n * (n - 1) / 2) as f64).sqrt();
    }
    Array2::from_shape_fn((n, n), |(i, j)| {
        (0..3)
            .map(|c| (delta(i, j, c) / scales[c]).powi(2))
            .sum::<f64>()
            .sqrt()
    })
}

#[test]
fn alpha_is_circular_in_the_agreement() {
    // Poses on a circle of orientations; the learned metric is the chord distance,
    // which agrees with the wrapped difference and not with the raw one.
    let n = 80;
    let alphas: Vec<f64> = (0..n).map(|i| -3.1 + 6.2 * i as f64 / n as f64).collect();
    let poses = Array2::from_shape_fn((n, 3), |(i, c)| if c == 2 { alphas[i] } else { 0.0 });
    let learned = Array2::from_shape_fn((n, n), |(i, j)| {
        2.0 * (0.5 * (alphas[i] - alphas[j])).sin().abs()
    });
    let a = agreement::agreement(learned.view(), poses.view(), 5).unwrap();
    assert!(a.spearman > 0.999, "{a:?}");
    assert_eq!(a.coordinates["x"], None);
    assert!(a.coordinates["alpha"].unwrap() > 0.999);
}

#[test]
fn trustworthiness_drops_when_neighbourhoods_are_scrambled() {
    let poses = points(100, 8, |rng| {
        [rng.random_range(0.0..1.0), rng.random_range(0.0..1.0), 0.0]
    });
    let random = euclidean(&points(100, 10, |r| {
        [r.random_range(0.0..1.0), r.random_range(0.0..1.0)]
    }));
    let a = agreement::agreement(random.view(), poses.view(), 10).unwrap();
    assert!(a.trustworthiness < 0.7 && a.continuity < 0.7, "{a:?}");
    assert!(a.spearman.abs() < 0.2, "{a:?}");
}

#[test]
fn analyze_reports_the_contract_keys() {
    let poses = points(150, 11, |rng| {
        [
            rng.random_range(0.0..2.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-3.1..3.1),
        ]
    });
    let d = pose_metric(&poses);
    let params = AnalysisParams {
        max_points: 100,
        ..AnalysisParams::default()
    }
    .check()
    .unwrap();
    let report = analyze(&dm(&d), Some(poses.view()), &params, &Silent).unwrap();
    assert_eq!(report.homology.subsampling.method, "max-min");
    assert_eq!(report.homology.subsampling.points, 100);
    let json = serde_json::to_value(&report).unwrap();
    for key in [
        "/betti",
        "/persistence/0",
        "/intrinsic_dimension/twonn",
        "/intrinsic_dimension/mle",
        "/agreement/spearman",
        "/agreement/trustworthiness",
        "/agreement/continuity",
    ] {
        assert!(json.pointer(key).is_some(), "missing {key} in {json}");
    }
    assert_eq!(report.betti[0], 1);
    assert_abs_diff_eq!(
        report.agreement.as_ref().unwrap().spearman,
        1.0,
        epsilon = 1e-12
    );
    let again = analyze(&dm(&d), Some(poses.view()), &params, &Silent).unwrap();
    assert_eq!(serde_json::to_value(&again).unwrap(), json);
}

#[test]
fn landmarks_cover_the_space() {
    let d = euclidean(&circle(300, 12));
    let (rows, radius) = maxmin_landmarks(d.view(), 30);
    assert_eq!(rows.len(), 30);
    assert_eq!(rows[0], 0);
    // 30 landmarks on a unit circle leave gaps of about 2π/30.
    assert!(radius < 0.3, "{radius}");
    let mut sorted = rows.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), 30);
}

#[test]
fn bad_matrices_and_parameters_are_errors() {
    use smspace::metric::MatrixError;
    // A matrix is checked where it enters, as a DistanceMatrix.
    let check = |d: Array2<f64>| DistanceMatrix::new(d).map(|_| ());
    let err = check(Array2::zeros((3, 4))).unwrap_err();
    assert!(matches!(
        err,
        MatrixError::NotSquare {
            rows: 3,
            columns: 4,
            ..
        }
    ));
    let mut d = euclidean(&circle(5, 13));
    d[[1, 2]] += 0.5;
    let err = check(d).unwrap_err().to_string();
    assert!(err.contains("[1, 2]") && err.contains("symmetric"), "{err}");
    let mut d = euclidean(&circle(5, 13));
    d[[3, 3]] = 1.0;
    assert!(check(d)
        .unwrap_err()
        .to_string()
        .contains("itself must be 0"));
    let mut d = euclidean(&circle(5, 13));
    d[[0, 1]] = -1.0;
    d[[1, 0]] = -1.0;
    assert!(check(d).unwrap_err().to_string().contains("negative"));
    for params in [
        AnalysisParams {
            max_homology_dim: 3,
            ..AnalysisParams::default()
        },
        AnalysisParams {
            threshold: Some(-1.0),
            ..AnalysisParams::default()
        },
        AnalysisParams {
            gap_ratio: 0.5,
            ..AnalysisParams::default()
        },
        AnalysisParams {
            mle_neighbors: 1,
            ..AnalysisParams::default()
        },
    ] {
        let err = params.check().unwrap_err();
        let invalid = err.invalid_parameter().expect("a parameter error");
        assert_eq!(invalid.table, "analysis", "{err}");
        assert!(err.to_string().contains(invalid.key), "{err}");
    }
    let small = euclidean(&circle(10, 14));
    let params = AnalysisParams::default().check().unwrap();
    let err = analyze(&dm(&small), None, &params, &Silent)
        .unwrap_err()
        .to_string();
    assert!(err.contains("mle_neighbors") && err.contains("10"), "{err}");
    let poses = Array2::zeros((9, 3));
    let params = AnalysisParams {
        mle_neighbors: 5,
        ..AnalysisParams::default()
    }
    .check()
    .unwrap();
    let err = analyze(&dm(&small), Some(poses.view()), &params, &Silent).unwrap_err();
    assert!(matches!(err, AnalysisError::PosesShape { rows: 9, .. }));
}

#[test]
fn h2_of_too_many_points_is_refused() {
    let d = Array2::<f64>::zeros((1000, 1000));
    let err = rips_persistence(d.view(), 2, None, &Silent).unwrap_err();
    assert!(matches!(err, AnalysisError::TooLarge { .. }));
}

mod invariance {
    use super::*;
    use smspace::agent::{Agent, AgentConfig, Environment, EnvironmentConfig};
    use smspace::explore::{explore, ExploreParams};
    use smspace::invariance::{agent_metric, invariance};
    use smspace::kernel::{TraceMethod, TraceParams};
    use smspace::metric::MetricKind;

    fn setup(name: &str, n: usize) -> (Box<dyn Agent>, Array2<f64>) {
        let agent = AgentConfig::preset(name).unwrap().build().unwrap();
        let params = ExploreParams {
            n,
            seed: 3,
            ..ExploreParams::default()
        };
        let motors = explore(agent.as_ref(), &params).unwrap().motors;
        (agent, motors)
    }

    fn env(agent: &dyn Agent, seed: u64, lights: Option<usize>) -> Environment {
        EnvironmentConfig {
            seed,
            lights,
            ..EnvironmentConfig::default()
        }
        .build(agent)
        .unwrap()
    }

    fn sensory(points: usize) -> smspace::kernel::TraceValidParams {
        TraceParams {
            method: TraceMethod::Sensory,
            points,
            ..TraceParams::default()
        }
        .check()
        .unwrap()
    }

    #[test]
    fn the_same_environment_twice_gives_zero_differences() {
        let (arm, motors) = setup("planar-arm", 6);
        let e = env(arm.as_ref(), 1, None);
        let report = invariance(
            arm.as_ref(),
            motors.view(),
            &[e.clone(), e],
            None,
            &sensory(30),
            agent_metric(MetricKind::Hausdorff, arm.as_ref()).as_ref(),
            &Silent,
        )
        .unwrap();
        assert!(report.common_sets >= 2, "{report:?}");
        assert_eq!(report.max_set_distance, 0.0);
        assert_eq!(report.max_distance_difference, 0.0);
        assert_abs_diff_eq!(report.min_mantel, 1.0);
        assert_abs_diff_eq!(report.max_sensor_mantel, 1.0);
        assert_eq!(report.min_sensor_difference_relative, 0.0);
    }

    #[test]
    fn redundant_toy_sets_do_not_depend_on_the_lights_but_its_sensations_do() {
        let (toy, motors) = setup("toy-redundant", 25);
        let environments = [
            env(toy.as_ref(), 1, None),
            env(toy.as_ref(), 2, Some(8)),
            env(toy.as_ref(), 3, Some(3)),
        ];
        let report = invariance(
            toy.as_ref(),
            motors.view(),
            &environments,
            None,
            &sensory(20),
            agent_metric(MetricKind::Hausdorff, toy.as_ref()).as_ref(),
            &Silent,
        )
        .unwrap();
        assert_eq!(report.pairs.len(), 3);
        assert!(report.common_sets >= 20, "{report:?}");
        assert!(report.max_set_distance_relative < 1e-6, "{report:?}");
        assert!(report.min_mantel > 1.0 - 1e-9, "{report:?}");
        // The paper's section 2.2: the sensory manifold changes with the environment.
        assert!(report.min_sensor_difference_relative > 0.1, "{report:?}");
        assert!(report.max_sensor_mantel < 0.99, "{report:?}");
    }

    #[test]
    fn kinematic_tracing_and_a_single_environment_are_refused() {
        let (toy, motors) = setup("toy-redundant", 4);
        let e = env(toy.as_ref(), 1, None);
        let kinematic = TraceParams::default().check().unwrap();
        let err = invariance(
            toy.as_ref(),
            motors.view(),
            &[e.clone(), e.clone()],
            None,
            &kinematic,
            agent_metric(MetricKind::Hausdorff, toy.as_ref()).as_ref(),
            &Silent,
        )
        .unwrap_err();
        assert!(err.to_string().contains("sensory"), "{err}");
        let err = invariance(
            toy.as_ref(),
            motors.view(),
            &[e],
            None,
            &sensory(10),
            agent_metric(MetricKind::Hausdorff, toy.as_ref()).as_ref(),
            &Silent,
        )
        .unwrap_err();
        assert!(err.to_string().contains("at least 2"), "{err}");
    }
}

mod learned {
    use super::*;
    use smspace::agent::AgentConfig;
    use smspace::analysis::{analyze, AnalysisParams};
    use smspace::explore::{explore, ExploreParams};
    use smspace::kernel::{trace_sets, StepControl, TraceParams};
    use smspace::metric::{distance_matrix, DistanceParams, Period};

    /// Traces `n` kernel sets of a preset agent and analyses their Hausdorff distances.
    fn learned_report(name: &str, n: usize, period: Period) -> smspace::analysis::AnalysisReport {
        let agent = AgentConfig::preset(name).unwrap().build().unwrap();
        let exploration = explore(
            agent.as_ref(),
            &ExploreParams {
                n,
                seed: 5,
                ..ExploreParams::default()
            },
        )
        .unwrap();
        let params = TraceParams {
            points: 40,
            step_control: StepControl::Adaptive,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        let traced = trace_sets(
            agent.as_ref(),
            None,
            exploration.motors.view(),
            None,
            &params,
            &Silent,
        )
        .unwrap();
        let d = distance_matrix(
            traced.sets.view(),
            &DistanceParams::new()
                .metric(smspace::metric::MetricKind::Hausdorff)
                .period(period),
            &Silent,
        )
        .unwrap();
        let poses = exploration
            .planar_poses()
            .unwrap()
            .select(ndarray::Axis(0), &traced.kept);
        let params = AnalysisParams::default().check().unwrap();
        analyze(&d, Some(poses.view()), &params, &Silent).unwrap()
    }

    #[test]
    fn redundant_toy_learns_a_segment() {
        let report = learned_report("toy-redundant", 200, Period::None);
        assert_eq!(report.betti, vec![1, 0]);
        let dim = &report.intrinsic_dimension;
        assert_abs_diff_eq!(dim.twonn, 1.0, epsilon = 0.2);
        assert_abs_diff_eq!(dim.mle, 1.0, epsilon = 0.2);
        let agreement = report.agreement.unwrap();
        assert!(agreement.spearman > 0.9, "{agreement:?}");
        // A segment has no loop, so no circle, and the report says why.
        assert!(report.circle.is_none(), "{:?}", report.circle);
        assert!(report.circle_missing.is_some());
    }

    #[test]
    fn arm_learns_a_circle_times_a_plane() {
        let report = learned_report("planar-arm", 600, Period::TwoPi);
        assert_eq!(
            report.betti,
            vec![1, 1],
            "{:?}",
            report.homology.longest_bars
        );
        let dim = &report.intrinsic_dimension;
        assert!((2.5..4.0).contains(&dim.mle), "{dim:?}");
        let agreement = report.agreement.unwrap();
        assert!(agreement.trustworthiness > 0.9, "{agreement:?}");
        // The loop as a number: one class, and the coordinate follows the orientation
        // measured from the bearing seen from the base (the circular module's docs say
        // why not the world's alpha as closely).
        let circle = report
            .circle
            .expect("the arm's loop gives a circular coordinate");
        assert_eq!(circle.classes, 1);
        assert_eq!(circle.largest_integer, 1);
        assert_eq!(circle.values.len(), report.points);
        let relative = circle.agreement[smspace::analysis::circular::BEARING_RELATIVE];
        assert!(
            relative.circular_correlation > 0.95,
            "{:?}",
            circle.agreement
        );
        let world = circle.agreement["alpha"];
        assert!(world.circular_correlation > 0.7, "{:?}", circle.agreement);
        // At fixed circle coordinate, the plane's two coordinates carry the position.
        let plane = circle.plane.expect("the arm's poses have x and y");
        assert!(plane.r_squared > 0.8, "{plane:?}");
    }
}

/// Diagrams as the paper's arm explored anywhere in reach gives them: the sets near
/// the base form families of their own, and no bar stands out: the reading is flagged.
#[test]
fn an_unclear_betti_reading_is_flagged_with_its_remedy() {
    use smspace::analysis::Bar;
    let bar = |birth: f64, death: Option<f64>| Bar { birth, death };
    let mixed = Persistence {
        threshold: 4.57,
        diagrams: vec![
            vec![
                bar(0.0, Some(2.62)),
                bar(0.0, Some(2.60)),
                bar(0.0, Some(1.11)),
                bar(0.0, None),
            ],
            vec![
                bar(0.5, Some(1.99)),
                bar(0.6, Some(2.09)),
                bar(0.7, Some(1.81)),
                bar(0.2, Some(1.14)),
            ],
        ],
    };
    let rule = BettiRule::default();
    assert_eq!(rule.betti(&mixed), vec![1, 0]);
    let flagged = rule.ambiguities(&mixed);
    assert_eq!(flagged.len(), 2, "{flagged:?}");
    assert!(
        flagged[0].starts_with("H0: b0 = 1 is ambiguous"),
        "{flagged:?}"
    );
    assert!(
        flagged[1].starts_with("H1: b1 = 0 is ambiguous"),
        "{flagged:?}"
    );
    assert!(flagged[1].contains("working space"), "{flagged:?}");
    // A circle × plane read clearly: one long H1 bar, the rest near the noise floor.
    let clear = Persistence {
        threshold: 4.0,
        diagrams: vec![
            vec![bar(0.0, Some(0.3)), bar(0.0, Some(0.2)), bar(0.0, None)],
            vec![
                bar(0.4, Some(3.0)),
                bar(0.5, Some(0.9)),
                bar(0.2, Some(0.4)),
            ],
        ],
    };
    assert_eq!(rule.betti(&clear), vec![1, 1]);
    assert!(rule.ambiguities(&clear).is_empty());
}
