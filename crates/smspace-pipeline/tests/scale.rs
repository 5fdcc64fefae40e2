//! The scale path (issue 18): landmark distances and embeddings fitted on landmarks and
//! extended to every set, against known shapes and against the dense path.

use ndarray::{Array2, Array3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::embed::landmarks::fit_on_landmarks;
use smspace::embed::{CcaParams, Embedding, IsomapParams, MdsParams};
use smspace::metric::landmarks::{
    landmark_distances_with, LandmarkDistances, LandmarkParams, LandmarkSelection,
};
use smspace::metric::{distance_matrix, DistanceParams, MetricKind, Period};
use smspace::progress::Silent;

/// Points as sets of one point (the Hausdorff distance is then Euclidean).
fn as_sets(points: &Array2<f64>) -> Array3<f64> {
    let (m, n) = points.dim();
    Array3::from_shape_fn((m, 1, n), |(i, _, c)| points[[i, c]])
}

fn euclidean() -> DistanceParams {
    DistanceParams::new()
        .metric(MetricKind::Hausdorff)
        .period(Period::None)
}

fn landmarks_of(
    points: &Array2<f64>,
    count: usize,
    selection: LandmarkSelection,
    nearest: usize,
) -> LandmarkDistances {
    let sets = as_sets(points);
    let metric = euclidean().check().unwrap().set_metric();
    let params = LandmarkParams::new(count, selection, 7)
        .nearest(nearest)
        .check()
        .unwrap();
    landmark_distances_with(sets.view(), metric.as_ref(), &params, None, &Silent).unwrap()
}

/// A jittered `nx × ny` grid of spacing 1 (a flat 2-D manifold).
fn grid(nx: usize, ny: usize, seed: u64) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = Array2::zeros((nx * ny, 2));
    for i in 0..nx * ny {
        points[[i, 0]] = (i % nx) as f64 + rng.random_range(-0.25..0.25);
        points[[i, 1]] = (i / nx) as f64 + rng.random_range(-0.25..0.25);
    }
    points
}

/// The largest distance from the placed points to their true positions once the
/// similarity (rotation or reflection, scale, shift) that best maps the landmarks'
/// embedded coordinates onto their true ones is applied (planar Procrustes with complex
/// numbers), over the non-landmark rows.
fn error_after_similarity(truth: &Array2<f64>, y: &Array2<f64>, landmarks: &[usize]) -> f64 {
    let c = |a: &Array2<f64>, i: usize| (a[[i, 0]], a[[i, 1]]);
    let mean = |a: &Array2<f64>| {
        let n = landmarks.len() as f64;
        landmarks.iter().fold((0.0, 0.0), |s, &i| {
            (s.0 + c(a, i).0 / n, s.1 + c(a, i).1 / n)
        })
    };
    let (tm, ym) = (mean(truth), mean(y));
    let mut best = f64::INFINITY;
    for reflect in [1.0, -1.0] {
        // s = Σ conj(b) a / Σ |b|², b the centred embedded point (reflected), a the true.
        let (mut re, mut im, mut norm) = (0.0, 0.0, 0.0);
        for &i in landmarks {
            let (ax, ay) = (c(truth, i).0 - tm.0, c(truth, i).1 - tm.1);
            let (bx, by) = (c(y, i).0 - ym.0, reflect * (c(y, i).1 - ym.1));
            re += bx * ax + by * ay;
            im += bx * ay - by * ax;
            norm += bx * bx + by * by;
        }
        let (sr, si) = (re / norm, im / norm);
        let worst = (0..truth.nrows())
            .filter(|i| !landmarks.contains(i))
            .map(|i| {
                let (bx, by) = (c(y, i).0 - ym.0, reflect * (c(y, i).1 - ym.1));
                let (px, py) = (sr * bx - si * by + tm.0, sr * by + si * bx + tm.1);
                ((px - c(truth, i).0).powi(2) + (py - c(truth, i).1).powi(2)).sqrt()
            })
            .fold(0.0, f64::max);
        best = best.min(worst);
    }
    best
}

/// Each method fitted on 60 max–min landmarks of a flat 20 × 15 grid places the 240
/// other points within a stated distance of their true positions, up to the similarity
/// fitted on the landmarks: MDS exactly with every landmark measured (Euclidean
/// distances of rank 2) and within 0.5 spacings with the 16 nearest measured (the rest
/// bounded through them), Isomap within 0.6 spacings (the geodesics zigzag through the
/// graph of 60 landmarks about 2.2 spacings apart), CCA within 0.25 spacings.
#[test]
fn landmark_fits_place_a_flat_grid() {
    let truth = grid(20, 15, 1);
    let every = landmarks_of(&truth, 60, LandmarkSelection::MaxMin, 60);
    let mds = MdsParams::default().dim(2).check().unwrap();
    let fit = fit_on_landmarks(&mds, &every, &Silent).unwrap();
    let error = error_after_similarity(&truth, &fit.coordinates, &fit.fitted_rows);
    assert!(error < 1e-9, "mds, every landmark measured: {error}");
    let l = landmarks_of(&truth, 60, LandmarkSelection::MaxMin, 16);
    let methods: [(Box<dyn Embedding>, f64); 3] = [
        (Box::new(MdsParams::default().dim(2).check().unwrap()), 0.5),
        (
            Box::new(IsomapParams::default().dim(2).k(8).check().unwrap()),
            0.6,
        ),
        (
            Box::new(CcaParams::default().dim(2).epochs(60).check().unwrap()),
            0.25,
        ),
    ];
    for (method, tolerance) in methods {
        let fit = fit_on_landmarks(method.as_ref(), &l, &Silent).unwrap();
        assert_eq!(fit.coordinates.dim(), (300, 2));
        let error = error_after_similarity(&truth, &fit.coordinates, &fit.fitted_rows);
        assert!(
            error < tolerance,
            "{}: {error} ≥ {tolerance}",
            method.name()
        );
    }
}

/// Landmark Isomap (`k = 3`, 40 max–min landmarks) on 300 points of a 270° arc of the
/// unit circle (chord distances): every point lands within 0.02 of its arc length (up to sign and shift), and within
/// 0.02 of where Isomap on all 300 points puts it.
#[test]
fn landmark_isomap_unrolls_an_arc_like_the_full_fit() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let step = 1.5 * std::f64::consts::PI / 300.0;
    let angles: Vec<f64> = (0..300)
        .map(|i| (i as f64 + rng.random_range(-0.3..0.3)) * step)
        .collect();
    let points = Array2::from_shape_fn((300, 2), |(i, c)| {
        if c == 0 {
            angles[i].cos()
        } else {
            angles[i].sin()
        }
    });
    let isomap = IsomapParams::default().dim(1).k(3).check().unwrap();
    let l = landmarks_of(&points, 40, LandmarkSelection::MaxMin, 16);
    let fit = fit_on_landmarks(&isomap, &l, &Silent).unwrap();
    let y: Vec<f64> = fit.coordinates.column(0).to_vec();
    let full = isomap
        .fit(
            &distance_matrix(as_sets(&points).view(), &euclidean(), &Silent).unwrap(),
            &Silent,
        )
        .unwrap()
        .coordinates;
    let aligned = |reference: &[f64]| {
        [1.0, -1.0]
            .iter()
            .map(|s| {
                let shift =
                    y.iter().zip(reference).map(|(a, b)| a - s * b).sum::<f64>() / y.len() as f64;
                y.iter()
                    .zip(reference)
                    .map(|(a, b)| (a - s * b - shift).abs())
                    .fold(0.0, f64::max)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let full: Vec<f64> = full.column(0).to_vec();
    assert!(aligned(&angles) < 0.02, "{}", aligned(&angles));
    assert!(aligned(&full) < 0.02, "{}", aligned(&full));
}

/// With every set a landmark, the scale path's embedding is the dense fit, bit for bit.
#[test]
fn every_set_a_landmark_is_the_dense_fit() {
    let points = grid(9, 7, 2);
    let d = distance_matrix(as_sets(&points).view(), &euclidean(), &Silent).unwrap();
    let l = landmarks_of(&points, 63, LandmarkSelection::Random, 16);
    let methods: [Box<dyn Embedding>; 3] = [
        Box::new(MdsParams::default().dim(2).check().unwrap()),
        Box::new(IsomapParams::default().dim(2).k(6).check().unwrap()),
        Box::new(CcaParams::default().dim(2).epochs(10).check().unwrap()),
    ];
    for method in methods {
        let dense = method.fit(&d, &Silent).unwrap().coordinates;
        let scaled = fit_on_landmarks(method.as_ref(), &l, &Silent).unwrap();
        assert_eq!(scaled.coordinates, dense, "{}", method.name());
    }
}

/// The landmark distances and the extension give the same bits on 1 and 2 threads.
#[test]
fn one_and_two_threads_agree() {
    let points = grid(16, 12, 4);
    let with = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let l = landmarks_of(&points, 40, LandmarkSelection::Random, 16);
                let cca = CcaParams::default().dim(2).epochs(10).check().unwrap();
                let isomap = IsomapParams::default().dim(2).k(6).check().unwrap();
                (
                    fit_on_landmarks(&cca, &l, &Silent).unwrap().coordinates,
                    fit_on_landmarks(&isomap, &l, &Silent).unwrap().coordinates,
                    l,
                )
            })
    };
    assert_eq!(with(1), with(2));
}

mod pipeline_paths {
    use std::path::Path;

    use smspace::progress::{Progress, Silent};
    use smspace_pipeline::{BusyFolder, Recompute, RunObserver, RunOptions, RunSummary};

    /// The paper's arm, small: 240 babbled configurations and a 3 × 3 × 3 probe grid,
    /// the curve metric, CCA, homology of every set (`max_points` above `M`).
    const SMALL_ARM: &str = r#"
[agent]
kind = "planar-arm"
[environment]
lights = 10
seed = 1
[exploration]
n = 240
seed = 1
workspace_center = [1.75, 0.0]
workspace_size = [1.5, 2.0]
probes = "grid"
probe_positions = 3
probe_orientations = 3
[kernel]
method = "kinematic"
points = 30
[metric]
metric = "curve"
period = "2pi"
[embedding]
method = "cca"
dim = 3
epochs = 10
[analysis]
max_points = 400
mle_neighbors = 10
[report]
formats = "svg"
sample_configurations = 5
sample_sets = 3
"#;

    struct Quiet;
    impl RunObserver for Quiet {
        fn progress(&self) -> &dyn Progress {
            &Silent
        }
    }

    fn run(dir: &Path, name: &str, overrides: &[&str]) -> RunSummary {
        let file = dir.join("small-arm.toml");
        std::fs::write(&file, SMALL_ARM).unwrap();
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        let loaded = smspace_pipeline::config::load_experiment(&file, &overrides).unwrap();
        let plan = smspace_pipeline::check(&loaded).unwrap_or_else(|e| panic!("{e}"));
        let options = RunOptions {
            out_dir: dir.join(name),
            recompute: Recompute::Changed,
            memory_limit_bytes: None,
            busy: BusyFolder::Refuse,
        };
        smspace_pipeline::run(&plan, &options, &Quiet).unwrap_or_else(|e| panic!("{e}"))
    }

    fn coordinates(summary: &RunSummary) -> ndarray::Array2<f64> {
        smspace::io::read_matrix(&summary.dir.join("Y.npy"), Some(3), "(M, 3)").unwrap()
    }

    fn bars(summary: &RunSummary, dim: usize) -> Vec<(f64, Option<f64>)> {
        let mut bars = summary.analysis.persistence[dim].clone();
        bars.sort_by(|a, b| {
            a.0.total_cmp(&b.0).then(
                a.1.unwrap_or(f64::INFINITY)
                    .total_cmp(&b.1.unwrap_or(f64::INFINITY)),
            )
        });
        bars
    }

    /// The landmark path with every set a landmark gives the dense path's numbers: the
    /// embedding bit for bit, the persistence bars, TwoNN, MLE and the agreement
    /// exactly; with 100 landmarks, the same
    /// Betti numbers and dimension, and trustworthiness within 0.05. It writes no D.npy.
    #[test]
    fn the_landmark_path_agrees_with_the_dense_path() {
        let dir = tempfile::tempdir().unwrap();
        let dense = run(dir.path(), "dense", &[]);
        let m = dense.analysis.points;
        assert!(dense.dir.join("D.npy").is_file());
        assert!(dense.analysis.scale.is_none());
        let all = run(
            dir.path(),
            "all",
            &["scale.path=landmarks", "scale.landmarks=20000"],
        );
        assert!(!all.dir.join("D.npy").exists());
        assert!(all.dir.join("D.nearest-landmarks.npy").is_file());
        assert!(all.dir.join("landmarks.nearest.npy").is_file());
        let scale = all.analysis.scale.as_ref().unwrap();
        assert_eq!((scale.sets, scale.landmarks), (m, m));
        assert_eq!(coordinates(&all), coordinates(&dense));
        assert_eq!(all.analysis.betti, dense.analysis.betti);
        for dim in 0..2 {
            assert_eq!(bars(&all, dim), bars(&dense, dim), "H{dim}");
        }
        let (a, d) = (
            &all.analysis.intrinsic_dimension,
            &dense.analysis.intrinsic_dimension,
        );
        assert_eq!((a.twonn, a.mle, a.sets_used), (d.twonn, d.mle, d.sets_used));
        let (a, d) = (
            all.analysis.agreement.as_ref().unwrap(),
            dense.analysis.agreement.as_ref().unwrap(),
        );
        assert_eq!(
            (a.spearman, a.trustworthiness, a.continuity),
            (d.spearman, d.trustworthiness, d.continuity)
        );

        let some = run(
            dir.path(),
            "some",
            &["scale.path=landmarks", "scale.landmarks=100"],
        );
        assert_eq!(some.analysis.scale.as_ref().unwrap().landmarks, 100);
        assert_eq!(some.analysis.betti, dense.analysis.betti);
        let (s, d) = (
            &some.analysis.intrinsic_dimension,
            &dense.analysis.intrinsic_dimension,
        );
        assert_eq!(s.twonn, d.twonn);
        let (s, d) = (
            some.analysis.agreement.as_ref().unwrap(),
            dense.analysis.agreement.as_ref().unwrap(),
        );
        assert!(
            (s.trustworthiness - d.trustworthiness).abs() < 0.05,
            "{} {}",
            s.trustworthiness,
            d.trustworthiness
        );
        assert_eq!(coordinates(&some).nrows(), m);
        // The run reads back what it wrote.
        let again = run(
            dir.path(),
            "some",
            &["scale.path=landmarks", "scale.landmarks=100"],
        );
        assert!(again.manifest.stages.iter().all(|s| s.cached));
    }

    /// Above `report.max_sets` the figures are drawn from a sample that the report
    /// names: every probe-grid set and seeded babbled sets, the same for the same seed.
    #[test]
    fn a_large_run_is_drawn_from_a_named_sample() {
        let dir = tempfile::tempdir().unwrap();
        let sampled = run(
            dir.path(),
            "sampled",
            &[
                "scale.path=landmarks",
                "scale.landmarks=60",
                "report.max_sets=100",
            ],
        );
        let m = sampled.analysis.points;
        assert!(m > 100);
        let html = std::fs::read_to_string(sampled.dir.join("report.html")).unwrap();
        let note = format!(
            "drawn from a sample of 100 of the {m} sets: every probe-grid set (27) and 73 babbled sets"
        );
        assert!(html.contains(&note), "{note}");
        let whole = run(
            dir.path(),
            "whole",
            &["scale.path=landmarks", "scale.landmarks=60"],
        );
        let html = std::fs::read_to_string(whole.dir.join("report.html")).unwrap();
        assert!(!html.contains("drawn from a sample"));
        let err = smspace_pipeline::config::load_experiment(
            &dir.path().join("small-arm.toml"),
            &["report.max_sets=10".to_owned()],
        )
        .map_err(|e| e.to_string())
        .and_then(|loaded| {
            smspace_pipeline::check(&loaded)
                .map(|_| ())
                .map_err(|e| e.to_string())
        })
        .unwrap_err();
        assert!(err.contains("max_sets"), "{err}");
    }

    /// A kNN graph too small for the dimension estimates is refused before anything
    /// runs, naming the key.
    #[test]
    fn too_few_nearest_sets_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("small-arm.toml");
        std::fs::write(&file, SMALL_ARM).unwrap();
        let loaded =
            smspace_pipeline::config::load_experiment(&file, &["scale.knn=5".to_owned()]).unwrap();
        let err = smspace_pipeline::check(&loaded).unwrap_err().to_string();
        assert!(err.contains("scale") && err.contains("knn"), "{err}");
    }
}
