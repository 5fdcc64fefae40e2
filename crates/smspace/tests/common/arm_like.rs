//! Seeded synthetic "arm-like" kernel sets for the metric tests and benchmarks: smooth
//! closed curves on the 4-torus that depend smoothly on a hidden 3-D pose, wind once
//! around the first coordinate, wrap around `±π`, start at random phases, run in either
//! direction and are sampled unevenly, as traced kernel sets are.

use std::f64::consts::{PI, TAU};

use ndarray::Array3;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

/// `(m, p, 4)` closed curves, coordinates wrapped into `[-π, π)`.
pub fn arm_like_sets(m: usize, p: usize, seed: u64) -> Array3<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Coefficients shared by the whole family: offset, amplitude and phase of two
    // harmonics per coordinate, each affine in the pose.
    let family: Vec<[f64; 4]> = (0..4 * 5)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect();
    let winding = [1.0, 0.0, 0.0, 0.0];
    let mut sets = Array3::zeros((m, p, 4));
    for i in 0..m {
        let pose: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..1.0));
        let affine = |c: &[f64; 4]| c[0] + c[1] * pose[0] + c[2] * pose[1] + c[3] * pose[2];
        let phase = rng.random_range(0.0..TAU);
        let direction = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        for k in 0..p {
            let s = TAU * k as f64 / p as f64;
            let t = phase + direction * (s + 0.25 * s.sin());
            for n in 0..4 {
                let c = &family[5 * n..5 * n + 5];
                let offset = 2.0 * affine(&c[0]);
                let first = 0.8 * affine(&c[1]) * (t + 1.5 * affine(&c[2])).cos();
                let second = 0.3 * affine(&c[3]) * (2.0 * t + 1.5 * affine(&c[4])).sin();
                let x = winding[n] * t + offset + first + second;
                sets[[i, k, n]] = (x + PI).rem_euclid(TAU) - PI;
            }
        }
    }
    sets
}

#[allow(dead_code, reason = "used by the tests, not by the benchmarks")]
/// `(m, p, n)` points uniform in `[-π, π)`.
pub fn uniform_sets(m: usize, p: usize, n: usize, seed: u64) -> Array3<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Array3::from_shape_fn((m, p, n), |_| rng.random_range(-PI..PI))
}
