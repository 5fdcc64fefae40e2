//! Times CCA, Isomap and MDS of 2500 points on a circle × plane (best of a few runs,
//! robust on a shared machine): `cargo run --release -p smspace --example embed_timing
//! [M] [repeats]`.

use std::time::Instant;

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::embed::{CcaParams, Embedding, IsomapParams, MdsParams};
use smspace::progress::Silent;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(2500);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let p = Array2::from_shape_fn((n, 4), |_| 0.0);
    let mut p = p;
    for i in 0..n {
        let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        p[[i, 0]] = a.cos();
        p[[i, 1]] = a.sin();
        p[[i, 2]] = rng.random_range(0.0..2.0);
        p[[i, 3]] = rng.random_range(0.0..2.0);
    }
    let d = Array2::from_shape_fn((n, n), |(i, j)| {
        let v = &p.row(i) - &p.row(j);
        v.dot(&v).sqrt()
    });
    let d = smspace::metric::DistanceMatrix::new(d).expect("Euclidean distances");
    let methods: Vec<Box<dyn Embedding>> = vec![
        Box::new(MdsParams::default().check().unwrap()),
        Box::new(CcaParams::default().epochs(50).check().unwrap()),
        Box::new(
            CcaParams {
                init_landmarks: None,
                ..CcaParams::default()
            }
            .check()
            .unwrap(),
        ),
        Box::new(IsomapParams::default().k(10).check().unwrap()),
    ];
    let repeats: usize = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(3);
    let only = std::env::args().nth(3);
    for m in methods {
        if only.as_deref().is_some_and(|o| o != m.name()) {
            continue;
        }
        let mut best = f64::INFINITY;
        let mut last = None;
        for _ in 0..repeats {
            let t = Instant::now();
            let e = m.fit(&d, &Silent).unwrap();
            best = best.min(t.elapsed().as_secs_f64());
            last = Some(e);
        }
        let e = last.expect("at least one run");
        let q = smspace::embed::quality::assess(d.view(), e.coordinates.view(), 10).unwrap();
        println!(
            "{:>6} M={n}: best of {repeats}: {best:.3} s; T(10) = {:.4}, C(10) = {:.4}, stress-1 = {:.4}",
            m.name(),
            q.trustworthiness,
            q.continuity,
            q.kruskal_stress,
        );
    }
}
