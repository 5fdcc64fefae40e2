//! The `surface` metric (points against tangent disks) on sets whose distances are
//! known: sampled parallel planes, in the matrix, the nearest-neighbour search and a
//! run's checks.

use approx::assert_abs_diff_eq;
use ndarray::{Array3, Axis};
use rand::{RngExt, SeedableRng};
use smspace::metric::{
    distance_matrix_with, knn_with, reference, DistanceParams, KnnParams, Period, SetMetric,
    Surface, SurfaceParams,
};
use smspace::progress::Silent;

/// `m` samples of the planes `z = h_i` of R³ (no period): every set is the same
/// `side × side` grid of spacing `step`, shifted in the plane by at most a fifth of a step
/// in each direction (so its points never coincide with another set's), at a random
/// height. Returns the sets and the heights.
fn planes(m: usize, side: usize, step: f64, seed: u64) -> (Array3<f64>, Vec<f64>) {
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let mut sets = Array3::zeros((m, side * side, 3));
    let mut heights = Vec::with_capacity(m);
    for s in 0..m {
        let h = rng.random_range(-1.0..1.0);
        let (dx, dy) = (
            rng.random_range(-0.2..0.2) * step,
            rng.random_range(-0.2..0.2) * step,
        );
        for i in 0..side {
            for j in 0..side {
                let p = i * side + j;
                sets[[s, p, 0]] = i as f64 * step + dx;
                sets[[s, p, 1]] = j as f64 * step + dy;
                sets[[s, p, 2]] = h;
            }
        }
        heights.push(h);
    }
    (sets, heights)
}

fn surface() -> Surface {
    Surface::new(SurfaceParams::default(), Period::None.into()).unwrap()
}

#[test]
fn sampled_parallel_planes_are_as_far_as_their_heights() {
    // Every point of one plane's grid projects inside a disk of the other's: the disks'
    // radius is one step (the grid's nearest-neighbour distance), and a foot is within
    // half a step of a point of the other grid in each direction inside it (0.71 step in
    // all) and within 0.4 step at the rim (the shifts differ by at most that). So the
    // surface metric is |h_i − h_j| exactly, where the point metric adds the sampling:
    // √(Δh² + shift²).
    let (sets, heights) = planes(12, 7, 0.3, 5);
    let d = distance_matrix_with(sets.view(), &surface(), &DistanceParams::new(), &Silent).unwrap();
    let mut floor = 0.0f64;
    for i in 0..12 {
        for j in 0..12 {
            assert_abs_diff_eq!(d[[i, j]], (heights[i] - heights[j]).abs(), epsilon = 1e-12);
            if i != j {
                let point = reference::hausdorff(
                    sets.index_axis(Axis(0), i),
                    sets.index_axis(Axis(0), j),
                    Period::None,
                );
                floor = floor.max(point - d[[i, j]]);
            }
        }
    }
    // The point metric's floor: at least a tenth of a step somewhere.
    assert!(floor > 0.03, "{floor}");
}

#[test]
fn the_matrix_equals_the_pair_calls_for_any_thread_count() {
    // Curved sheets in the 3-torus, some across the seam.
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(9);
    let (m, side) = (9, 6);
    let sets = Array3::from_shape_fn((m, side * side, 3), |(s, p, c)| {
        let (i, j) = ((p / side) as f64, (p % side) as f64);
        let base = 2.9 + 0.13 * s as f64;
        match c {
            0 => base + 0.25 * i,
            1 => -0.5 + 0.25 * j,
            _ => 0.4 * (0.7 * i + 0.1 * s as f64).sin() + 0.05 * j,
        }
    });
    let sets = sets.mapv(|x| x + rng.random_range(-1e-3..1e-3));
    let metric = Surface::new(SurfaceParams::default(), Period::TwoPi.into()).unwrap();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                distance_matrix_with(sets.view(), &metric, &DistanceParams::new(), &Silent).unwrap()
            })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
    for i in 0..m {
        for j in 0..m {
            let pair = metric
                .distance(sets.index_axis(Axis(0), i), sets.index_axis(Axis(0), j))
                .unwrap();
            assert_eq!(one[[i, j]], pair, "({i}, {j})");
        }
    }
    // The k nearest sets are the matrix's smallest entries of every row.
    let found = knn_with(
        sets.view(),
        &metric,
        &DistanceParams::new(),
        &KnnParams::new().k(3),
        0..m,
        &Silent,
    )
    .unwrap();
    for i in 0..m {
        let mut row: Vec<(f64, usize)> = (0..m)
            .filter(|&j| j != i)
            .map(|j| (one[[i, j]], j))
            .collect();
        row.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let expected: Vec<f64> = row[..3].iter().map(|r| r.0).collect();
        let got: Vec<f64> = found.distances.row(i).to_vec();
        assert_eq!(got, expected, "row {i}");
    }
}

#[test]
fn a_run_names_a_dimension_that_is_not_the_kernels() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("arm5.toml");
    std::fs::write(
        &file,
        r#"
name = "arm5"
[agent]
kind = "planar-arm"
link_lengths = [1.0, 1.0, 1.0, 1.0]
[exploration]
n = 20
workspace_center = [2.25, 0.0]
workspace_size = [2.0, 2.5]
[kernel]
method = "kinematic"
points = 40
[metric]
metric = "surface"
[metric.params]
dimension = 3
"#,
    )
    .unwrap();
    let loaded = smspace_pipeline::config::load_experiment(&file, &[]).unwrap();
    let err = smspace_pipeline::check(&loaded).unwrap_err().to_string();
    assert!(
        err.contains("dimension") && err.contains("set dimension = 2"),
        "{err}"
    );
    let err =
        smspace_pipeline::config::load_experiment(&file, &["metric.params.dimension=2".to_owned()])
            .map(|l| smspace_pipeline::check(&l).map(|_| ()))
            .unwrap();
    assert!(err.is_ok(), "{err:?}");
}
