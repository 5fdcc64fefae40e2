//! Embeddings recover known shapes from their distance matrices; bad input is refused.

use approx::assert_abs_diff_eq;
use ndarray::{Array2, Axis, Slice};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::embed::quality::{shepard_pairs, stress, trustworthiness_continuity};
use smspace::embed::{
    CcaParams, EigenSolver, EmbedError, EmbedParams, Embedding, IsomapParams, KnnGraph,
    LandmarkChoice, MdsParams, Neighbourhood,
};
use smspace::metric::DistanceMatrix;
use smspace::progress::Silent;

/// `d` as a validated distance matrix.
fn dm(d: &Array2<f64>) -> DistanceMatrix {
    DistanceMatrix::new(d.clone()).unwrap()
}

/// Euclidean distances between the rows of `points`.
fn euclidean(points: &Array2<f64>) -> Array2<f64> {
    let n = points.nrows();
    Array2::from_shape_fn((n, n), |(i, j)| {
        let d = &points.row(i) - &points.row(j);
        d.dot(&d).sqrt()
    })
}

/// `n` points on the unit circle at random angles, as `(cos, sin)`.
fn circle(n: usize, seed: u64) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut a: Vec<f64> = (0..n)
        .map(|_| rng.random_range(0.0..std::f64::consts::TAU))
        .collect();
    a.sort_by(f64::total_cmp);
    Array2::from_shape_fn(
        (n, 2),
        |(i, c)| if c == 0 { a[i].cos() } else { a[i].sin() },
    )
}

/// Swiss roll points `(M, 3)` and their unrolled coordinates `(M, 2)` (arc length, height).
fn swiss_roll(n: usize, seed: u64) -> (Array2<f64>, Array2<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = Array2::zeros((n, 3));
    let mut truth = Array2::zeros((n, 2));
    let arc = |t: f64| 0.5 * (t * (1.0 + t * t).sqrt() + t.asinh());
    for i in 0..n {
        let t = rng.random_range(1.5 * std::f64::consts::PI..4.5 * std::f64::consts::PI);
        let h = rng.random_range(0.0..15.0);
        points[[i, 0]] = t * t.cos();
        points[[i, 1]] = h;
        points[[i, 2]] = t * t.sin();
        truth[[i, 0]] = arc(t);
        truth[[i, 1]] = h;
    }
    (points, truth)
}

fn fit(params: EmbedParams, d: &Array2<f64>) -> smspace::embed::Embedded {
    params.build().unwrap().fit(&dm(d), &Silent).unwrap()
}

#[test]
fn mds_reproduces_euclidean_points_up_to_rotation() {
    for (n, solver) in [
        (5, EigenSolver::Dense),
        (40, EigenSolver::Auto),
        (300, EigenSolver::Dense),
        (300, EigenSolver::Partial),
    ] {
        let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
        let points = Array2::from_shape_fn((n, 3), |_| rng.random_range(-1.0..1.0));
        let d = euclidean(&points);
        let e = fit(
            EmbedParams::from(MdsParams::default().dim(3).solver(solver)),
            &d,
        );
        let back = euclidean(&e.coordinates);
        for (a, b) in d.iter().zip(back.iter()) {
            assert_abs_diff_eq!(a, b, epsilon = 1e-8);
        }
        // Euclidean input: three positive eigenvalues, the rest zero.
        let ev = &e.report.eigenvalues;
        assert!(ev[2] > 1e-3, "{ev:?}");
        let scale = ev[0];
        for v in &ev[3..] {
            assert!(v.abs() < 1e-9 * scale * n as f64, "{solver:?} n={n}: {v}");
        }
        // Centred at the origin.
        for c in 0..3 {
            assert_abs_diff_eq!(e.coordinates.column(c).sum(), 0.0, epsilon = 1e-8);
        }
    }
}

#[test]
fn mds_reports_negative_eigenvalues_of_a_non_euclidean_metric() {
    // Geodesic (arc) distances on a circle are not Euclidean.
    let n = 60;
    let d = Array2::from_shape_fn((n, n), |(i, j)| {
        let k = (i as f64 - j as f64).abs();
        k.min(n as f64 - k) / n as f64
    });
    let e = fit(EmbedParams::from(MdsParams::default().dim(2)), &d);
    assert!(e.report.eigenvalues.iter().any(|&v| v < -1e-6));
    assert_eq!(e.report.eigenvalues.len(), n);
}

#[test]
fn isomap_and_cca_keep_circle_neighbours() {
    let points = circle(240, 1);
    let d = euclidean(&points);
    let methods = [
        EmbedParams::from(IsomapParams::default().dim(2).k(6)),
        EmbedParams::from(CcaParams::default().dim(2).epochs(30)),
        EmbedParams::from(
            CcaParams::default()
                .dim(2)
                .epochs(30)
                .neighbourhood(Neighbourhood::Exp),
        ),
    ];
    for params in methods {
        let e = fit(params.clone(), &d);
        let (t, c) = trustworthiness_continuity(d.view(), e.coordinates.view(), 10).unwrap();
        assert!(t >= 0.99 && c >= 0.99, "{params:?}: T = {t}, C = {c}");
    }
}

#[test]
fn isomap_unrolls_a_swiss_roll() {
    let (points, truth) = swiss_roll(800, 7);
    let d = euclidean(&points);
    let truth_d = euclidean(&truth);
    let e = fit(EmbedParams::from(IsomapParams::default().dim(2).k(8)), &d);
    let (t, c) = trustworthiness_continuity(truth_d.view(), e.coordinates.view(), 10).unwrap();
    assert!(t > 0.97 && c > 0.97, "isomap: T = {t}, C = {c}");
    // Straight MDS cannot unroll it.
    let m = fit(EmbedParams::from(MdsParams::default().dim(2)), &d);
    let (tm, _) = trustworthiness_continuity(truth_d.view(), m.coordinates.view(), 10).unwrap();
    assert!(tm < t - 0.03, "mds T = {tm}, isomap T = {t}");
    // Landmark Isomap does nearly as well.
    let l = fit(
        EmbedParams::from(IsomapParams::default().dim(2).k(8).landmarks(Some(60))),
        &d,
    );
    let (tl, cl) = trustworthiness_continuity(truth_d.view(), l.coordinates.view(), 10).unwrap();
    assert!(
        tl > 0.95 && cl > 0.95,
        "landmark isomap: T = {tl}, C = {cl}"
    );
    assert_eq!(l.report.landmarks.len(), 60);
}

#[test]
fn circle_times_segment_is_recovered_in_3d() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let n = 400;
    let points = Array2::from_shape_fn((n, 3), |_| 0.0);
    let mut points = points;
    for i in 0..n {
        let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        points[[i, 0]] = a.cos();
        points[[i, 1]] = a.sin();
        points[[i, 2]] = rng.random_range(0.0..1.5);
    }
    let d = euclidean(&points);
    for params in [
        EmbedParams::from(CcaParams::default().dim(3).epochs(30)),
        EmbedParams::from(IsomapParams::default().dim(3).k(10)),
    ] {
        let e = fit(params.clone(), &d);
        let (t, c) = trustworthiness_continuity(d.view(), e.coordinates.view(), 10).unwrap();
        assert!(t > 0.98 && c > 0.98, "{params:?}: T = {t}, C = {c}");
    }
}

#[test]
fn cca_stress_decreases_and_dydx_hugs_the_diagonal() {
    let (points, _) = swiss_roll(300, 2);
    let d = euclidean(&points);
    let e = fit(
        EmbedParams::from(CcaParams::default().dim(2).epochs(40)),
        &d,
    );
    let trace = &e.report.stress_trace;
    assert_eq!(trace.len(), 40);
    assert!(trace.iter().all(|s| s.is_finite() && *s >= 0.0));
    assert!(trace[39] < trace[0], "{trace:?}");
    let lambda = e.report.lambda_end.unwrap();
    // Small output distances match their input distances (the dy–dx plot's diagonal).
    let pairs = shepard_pairs(d.view(), e.coordinates.view(), 20_000, 1).unwrap();
    assert_eq!(pairs.ncols(), 2);
    let near: Vec<f64> = pairs
        .rows()
        .into_iter()
        .filter(|r| r[1] < lambda)
        .map(|r| (r[0] - r[1]).abs() / r[0].max(1e-12))
        .collect();
    assert!(!near.is_empty());
    let mean = near.iter().sum::<f64>() / near.len() as f64;
    assert!(mean < 0.15, "mean relative error of short distances {mean}");
    let (kruskal, raw) = stress(d.view(), e.coordinates.view()).unwrap();
    assert!(kruskal.is_finite() && raw > 0.0);
}

#[test]
fn out_of_sample_points_land_next_to_their_neighbours() {
    let all = circle(220, 5);
    let d_all = euclidean(&all);
    let new: Vec<usize> = (0..220).filter(|i| i % 11 == 5).collect();
    let old: Vec<usize> = (0..220).filter(|i| i % 11 != 5).collect();
    let d_old = Array2::from_shape_fn((old.len(), old.len()), |(a, b)| d_all[[old[a], old[b]]]);
    let new_to_old =
        Array2::from_shape_fn((new.len(), old.len()), |(a, b)| d_all[[new[a], old[b]]]);
    for params in [
        EmbedParams::from(CcaParams::default().dim(2).epochs(20)),
        EmbedParams::from(MdsParams::default().dim(2)),
        EmbedParams::from(IsomapParams::default().dim(2).k(6)),
        EmbedParams::from(IsomapParams::default().dim(2).k(6).landmarks(Some(30))),
    ] {
        let e = fit(params.clone(), &d_old);
        let placed = e.extend(new_to_old.view()).unwrap();
        assert_eq!(placed.dim(), (new.len(), 2));
        for (a, row) in new_to_old.rows().into_iter().enumerate() {
            // The input's two nearest old points.
            let mut by_x: Vec<usize> = (0..old.len()).collect();
            by_x.sort_by(|&i, &j| row[i].total_cmp(&row[j]));
            // The output's nearest old point.
            let y = placed.row(a);
            let nearest_y = (0..old.len())
                .min_by(|&i, &j| {
                    let di = (&e.coordinates.row(i) - &y).mapv(|v| v * v).sum();
                    let dj = (&e.coordinates.row(j) - &y).mapv(|v| v * v).sum();
                    di.total_cmp(&dj)
                })
                .unwrap();
            assert!(
                by_x[..2].contains(&nearest_y),
                "{params:?}: new point {a} lands next to {nearest_y}, not {:?}",
                &by_x[..2]
            );
        }
    }
}

#[test]
fn extending_with_embedded_points_returns_them_for_triangulation() {
    let points = circle(50, 9);
    let d = euclidean(&points);
    let e = fit(EmbedParams::from(MdsParams::default().dim(2)), &d);
    let again = e.extend(d.slice_axis(Axis(0), Slice::from(..10))).unwrap();
    for (a, b) in again
        .iter()
        .zip(e.coordinates.slice_axis(Axis(0), Slice::from(..10)).iter())
    {
        assert_abs_diff_eq!(a, b, epsilon = 1e-9);
    }
}

#[test]
fn landmark_isomap_from_a_knn_graph_matches_the_dense_input() {
    let (points, _) = swiss_roll(300, 4);
    let d = euclidean(&points);
    let params = IsomapParams::default()
        .dim(2)
        .k(8)
        .landmarks(Some(40))
        .landmark_choice(LandmarkChoice::Random);
    let dense = params
        .clone()
        .check()
        .unwrap()
        .fit(&dm(&d), &Silent)
        .unwrap();
    // The metric stage's layout: (M, K) int64 indices and f64 distances, K ≥ k.
    let graph = KnnGraph::from_distances(d.view(), 12).unwrap();
    let indices = Array2::from_shape_fn((300, 12), |(i, c)| graph.neighbour(i, c).0 as i64);
    let dists = Array2::from_shape_fn((300, 12), |(i, c)| graph.neighbour(i, c).1);
    let graph = KnnGraph::from_arrays(indices.view(), dists.view()).unwrap();
    let knn = params.check().unwrap().fit_knn(&graph, &Silent).unwrap();
    assert_eq!(dense.coordinates, knn.coordinates);
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let (points, _) = swiss_roll(400, 8);
    let d = euclidean(&points);
    let run = |threads: usize, params: EmbedParams| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| fit(params, &d).coordinates)
    };
    for params in [
        EmbedParams::from(CcaParams::default().dim(3).epochs(10).seed(4)),
        EmbedParams::from(IsomapParams::default().dim(2).k(8)),
        EmbedParams::from(IsomapParams::default().k(8).landmarks(Some(50))),
        EmbedParams::from(MdsParams::default().solver(EigenSolver::Partial)),
    ] {
        let one = run(1, params.clone());
        let two = run(2, params.clone());
        let three = run(3, params.clone());
        assert!(one == two && two == three, "{params:?}");
    }
    // A different seed gives a different CCA.
    let a = run(2, EmbedParams::from(CcaParams::default().epochs(5).seed(1)));
    let b = run(2, EmbedParams::from(CcaParams::default().epochs(5).seed(2)));
    assert!(a != b);
}

#[test]
fn bad_distance_matrices_are_refused_with_the_reason() {
    use smspace::metric::MatrixError;
    let good = euclidean(&circle(20, 1));
    let mds = MdsParams::default().dim(2).check().unwrap();
    // A matrix is checked once, where it enters: as a DistanceMatrix.
    let err = |d: &Array2<f64>| DistanceMatrix::new(d.clone()).unwrap_err();

    let e = err(&Array2::zeros((3, 4)));
    assert!(
        matches!(
            e,
            MatrixError::NotSquare {
                rows: 3,
                columns: 4,
                ..
            }
        ),
        "{e}"
    );
    let mut d = good.clone();
    d[[2, 5]] += 1e-6;
    let e = err(&d);
    assert!(
        e.to_string().contains("not symmetric") && e.to_string().contains("[2, 5]"),
        "{e}"
    );
    let mut d = good.clone();
    d[[2, 5]] += 1e-12; // within tolerance
    assert!(mds.fit(&dm(&d), &Silent).is_ok());
    let mut d = good.clone();
    d[[1, 3]] = -1.0;
    d[[3, 1]] = -1.0;
    assert!(matches!(err(&d), MatrixError::Negative { .. }));
    let mut d = good.clone();
    d[[4, 4]] = f64::NAN;
    assert!(matches!(err(&d), MatrixError::NonFinite { i: 4, j: 4, .. }));
    // The check of a view for the lower-level entry points says the same.
    let e = smspace::embed::check_distances(d.view()).unwrap_err();
    assert!(
        matches!(e, EmbedError::Distances(MatrixError::NonFinite { .. })),
        "{e}"
    );

    let e = MdsParams::default()
        .dim(20)
        .check()
        .unwrap()
        .fit(&dm(&good), &Silent)
        .unwrap_err();
    assert!(
        matches!(
            e,
            EmbedError::DimTooLarge {
                dim: 20,
                points: 20
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("between 1 and 19"), "{e}");
    let few = EmbedError::DimTooLarge { dim: 1, points: 1 }.to_string();
    assert!(few.contains("at least 2 points"), "{few}");
    let e = IsomapParams::default()
        .k(20)
        .check()
        .unwrap()
        .fit(&dm(&good), &Silent)
        .unwrap_err();
    assert!(
        matches!(e, EmbedError::KTooLarge { k: 20, points: 20 }),
        "{e}"
    );
    // Planar points have two positive eigen-directions, not three.
    let e = MdsParams::default()
        .dim(3)
        .check()
        .unwrap()
        .fit(&dm(&good), &Silent)
        .unwrap_err();
    assert!(e.to_string().contains("only 2 positive"), "{e}");
    // CCA starts from the two and a small seeded third coordinate.
    let cca = CcaParams::default().dim(3).epochs(2).check().unwrap();
    assert!(cca.fit(&dm(&good), &Silent).is_ok());
    assert!(MdsParams::default().dim(0).check().is_err());
    assert!(CcaParams::default().epochs(0).check().is_err());
    assert!(CcaParams::default().alpha(0.5, 0.9).check().is_err());
    let wrong = CcaParams::default()
        .check()
        .unwrap()
        .fit(&dm(&good), &Silent)
        .unwrap();
    assert!(matches!(
        wrong.extend(Array2::zeros((2, 19)).view()),
        Err(EmbedError::ExtendShape { .. })
    ));
}

#[test]
fn a_disconnected_graph_names_its_components_and_the_fix() {
    // Two far-apart circles.
    let a = circle(30, 1);
    let mut both = Array2::zeros((60, 2));
    both.slice_axis_mut(Axis(0), Slice::from(..30)).assign(&a);
    both.slice_axis_mut(Axis(0), Slice::from(30..))
        .assign(&(&a + 10.0));
    let d = euclidean(&both);
    let e = IsomapParams::default()
        .dim(2)
        .k(5)
        .check()
        .unwrap()
        .fit(&dm(&d), &Silent)
        .unwrap_err();
    assert!(
        matches!(e, EmbedError::Disconnected { components: 2, .. }),
        "{e}"
    );
    assert!(
        e.to_string().contains("2 connected components") && e.to_string().contains("larger --k")
    );
}

#[test]
fn parameters_parse_by_method_name_and_refuse_unknown_fields() {
    let registry = smspace::embed::EmbeddingRegistry::builtin();
    let p: EmbedParams = serde_json::from_str(r#"{"method": "cca", "epochs": 7}"#).unwrap();
    let (resolved, _) = p.resolve(&registry).unwrap();
    assert_eq!(resolved, EmbedParams::from(CcaParams::default().epochs(7)));
    let p: EmbedParams =
        serde_json::from_str(r#"{"method": "isomap", "k": 12, "landmarks": 100}"#).unwrap();
    assert_eq!(
        p.resolve(&registry).unwrap().0,
        EmbedParams::from(IsomapParams::default().k(12).landmarks(Some(100)))
    );
    // A key of another method, and an unknown method, are errors that name them.
    let mds: EmbedParams = serde_json::from_str(r#"{"method": "mds", "epochs": 3}"#).unwrap();
    let err = mds.build().unwrap_err().to_string();
    assert!(err.contains("mds") && err.contains("epochs"), "{err}");
    let tsne: EmbedParams = serde_json::from_str(r#"{"method": "tsne"}"#).unwrap();
    let err = tsne.build().unwrap_err().to_string();
    assert!(
        err.contains("tsne") && err.contains("cca, isomap, mds"),
        "{err}"
    );
    // The JSON of the resolved parameters reads back as the same parameters.
    let json = serde_json::to_string(&resolved).unwrap();
    assert_eq!(
        serde_json::from_str::<EmbedParams>(&json).unwrap(),
        resolved
    );
    let m = EmbedParams::default().build().unwrap();
    assert_eq!(m.name(), "cca");
    assert_eq!(m.dim(), 3);
}
