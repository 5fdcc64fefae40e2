//! The promises of `docs/RELIABILITY.md` that the library keeps whatever calls it (the
//! command line or the Python package): sizes checked before allocation, no non-finite
//! result, files read only when they are regular files, poses checked, figures at any
//! scale, and the distance backend's matrix checked before it is written.

#[path = "common/observe.rs"]
#[allow(dead_code, reason = "this file reads no stage records")]
mod observe;

use std::path::Path;

use ndarray::{Array2, Array3};
use observe::Quiet;
use smspace::agent::{
    AgentConfig, AgentError, CoordinateKind, Environment, GroundTruth, PoseCoordinate, PoseSpace,
};
use smspace::embed::{CcaParams, EmbedParams};
use smspace::explore::{explore_in, ExploreParams};
use smspace::kernel::{trace_sets, TraceParams};
use smspace::metric::{
    distance_matrix, knn, DistanceMatrix, DistanceParams, KnnParams, MetricError, Periodicity,
    SetsView,
};
use smspace::progress::{Progress, Silent};
use smspace_pipeline::stages::DistancesStage;
use smspace_pipeline::{DistanceBackend, Recompute, RunOptions};

fn random_sets(m: usize, p: usize, n: usize, seed: u64) -> Array3<f64> {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    Array3::from_shape_fn((m, p, n), |_| rng.random_range(-1.0..1.0))
}

#[test]
fn piece_starts_beyond_the_limit_are_refused_before_any_seed_is_made() {
    let params = TraceParams {
        piece_starts: 1_000_000_000,
        ..TraceParams::default()
    };
    let error = params.check().unwrap_err().to_string();
    assert!(error.contains("piece_starts"), "{error}");
    assert!(error.contains("at most 10000"), "{error}");
    let fits = TraceParams {
        piece_starts: smspace::kernel::MAX_PIECE_STARTS,
        ..TraceParams::default()
    };
    fits.check().unwrap();
    assert_eq!(fits.seeds_bytes(4), 10_000 * 4 * 8);
}

#[test]
fn epochs_beyond_the_limit_are_refused_before_the_stress_trace_is_made() {
    for epochs in [4_000_000_000usize, smspace::embed::cca::MAX_EPOCHS + 1] {
        let error = CcaParams::default()
            .epochs(epochs)
            .check()
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("epochs") && error.contains("at most 100000"),
            "{error}"
        );
    }
    let json = r#"{"method": "cca", "extend_epochs": 1000000000000}"#;
    let params: EmbedParams = serde_json::from_str(json).unwrap();
    let error = params.build().unwrap_err().to_string();
    assert!(error.contains("extend_epochs"), "{error}");
}

#[test]
fn distances_that_overflow_are_refused_not_returned() {
    let sets = random_sets(5, 4, 3, 1).mapv(|v| v * 1e300);
    let params = DistanceParams::new()
        .metric("hausdorff")
        .period(Periodicity::parse("none").unwrap());
    let error = distance_matrix(SetsView::new(sets.view()), &params, &Silent).unwrap_err();
    assert!(
        matches!(error, MetricError::NonFiniteDistance { value, .. } if value.is_infinite()),
        "{error}"
    );
    assert!(
        error.to_string().contains("too large for float64"),
        "{error}"
    );
    let error = knn(
        SetsView::new(sets.view()),
        &params,
        &KnnParams::new().k(2),
        0..5,
        &Silent,
    )
    .unwrap_err();
    assert!(
        matches!(error, MetricError::NonFiniteDistance { .. }),
        "{error}"
    );
    // Periodic coordinates wrap, and give finite distances.
    let periodic = DistanceParams::new().metric("hausdorff");
    let d = distance_matrix(SetsView::new(sets.view()), &periodic, &Silent).unwrap();
    assert!(d.view().iter().all(|v| v.is_finite()));
}

#[test]
fn an_environment_without_lights_is_refused_for_any_agent() {
    let agent = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let empty = Environment::from_lights(Vec::new());
    let error = empty.check_for(agent.as_ref()).unwrap_err().to_string();
    assert!(error.contains("no lights"), "{error}");
}

#[test]
fn a_pose_whose_quaternion_is_not_unit_is_refused() {
    let space = PoseSpace::spatial();
    let good = Array2::from_shape_vec((1, 7), vec![1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0]).unwrap();
    GroundTruth::new(space.clone(), good).unwrap();
    let scaled = Array2::from_shape_vec(
        (2, 7),
        vec![
            0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, //
            1.0, 2.0, 3.0, 5.0, 0.0, 0.0, 0.0,
        ],
    )
    .unwrap();
    let error = GroundTruth::new(space.clone(), scaled).unwrap_err();
    assert!(
        matches!(error, AgentError::NonUnitQuaternion { row: 1, column: 3, norm } if norm == 5.0),
        "{error}"
    );
    assert!(error.to_string().contains("unit quaternion"), "{error}");
    let nan = Array2::from_shape_vec((1, 7), vec![0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0]).unwrap();
    assert!(GroundTruth::new(space, nan).is_err());
    // Planar poses have no quaternion: unchanged.
    let planar = PoseSpace::new(vec![
        PoseCoordinate::new("x", CoordinateKind::Linear),
        PoseCoordinate::new("alpha", CoordinateKind::Angle),
    ])
    .unwrap();
    GroundTruth::new(planar, Array2::from_elem((3, 2), 7.0)).unwrap();
}

#[test]
fn an_arm_of_long_links_traces_its_sets() {
    // Links of 10⁶: the pose residual's precision is 10⁶ times coarser than at the
    // paper's scale, so an absolute 1e-11 failed every set.
    for scale in [1.0, 1e6] {
        let mut config = AgentConfig::preset("planar-arm").unwrap();
        config.params.insert(
            "link_lengths".into(),
            toml::Value::Array(vec![toml::Value::Float(scale); 3]),
        );
        let agent = config.build().unwrap();
        // The default working space is the paper's (units of 1): explore without one.
        let params = ExploreParams {
            n: 6,
            seed: 2,
            ..ExploreParams::default()
        };
        let motors = explore_in(agent.as_ref(), &params, None).unwrap().motors;
        let params = TraceParams {
            points: 10,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        let traced = trace_sets(agent.as_ref(), None, motors.view(), None, &params, &Silent)
            .unwrap_or_else(|e| panic!("links of {scale}: {e}"));
        assert_eq!(
            traced.kept.len(),
            6,
            "links of {scale}: {:?}",
            traced.report.summary.by_status
        );
    }
}

#[test]
fn embedding_figures_are_the_same_at_any_finite_scale() {
    let sets = random_sets(30, 6, 3, 8);
    let params = DistanceParams::new()
        .metric("hausdorff")
        .period(Periodicity::parse("none").unwrap());
    let d = distance_matrix(SetsView::new(sets.view()), &params, &Silent)
        .unwrap()
        .into_array();
    let embed = |d: &Array2<f64>| {
        let matrix = DistanceMatrix::new(d.clone()).unwrap();
        let method = smspace::embed::MdsParams::default().dim(2).check().unwrap();
        let y = smspace::embed::Embedding::fit(&method, &matrix, &Silent)
            .unwrap()
            .coordinates;
        smspace::embed::quality::measure(d.view(), y.view(), 5, 100, 0).unwrap()
    };
    let (reference, reference_dydx) = embed(&d);
    let reference = reference.unwrap();
    for scale in [1e-200, 1e-300, 1e160, 1e300] {
        let (quality, dydx) = embed(&d.mapv(|v| v * scale));
        let quality = quality.unwrap();
        let dydx = dydx.unwrap();
        assert!(dydx.iter().all(|v| v.is_finite()), "scale {scale}");
        for (a, b) in [
            (quality.trustworthiness, reference.trustworthiness),
            (quality.continuity, reference.continuity),
            (quality.kruskal_stress, reference.kruskal_stress),
        ] {
            assert!(
                (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                "scale {scale}: {a} vs {b}"
            );
        }
        let first = reference_dydx.as_ref().unwrap()[[0, 0]] * scale;
        assert!(
            (dydx[[0, 0]] - first).abs() <= 1e-9 * first.abs(),
            "scale {scale}"
        );
        assert!(quality.raw_stress.is_finite());
    }
}

#[test]
fn devices_fifos_and_folders_are_never_read() {
    let dir = tempfile::tempdir().unwrap();
    let zero = Path::new("/dev/zero");
    if zero.exists() {
        let error = smspace::io::read_f64(zero).unwrap_err().to_string();
        assert!(error.contains("not a regular file"), "{error}");
        let error = smspace_pipeline::config::load_experiment(zero, &[])
            .unwrap_err()
            .to_string();
        assert!(error.contains("not a regular file"), "{error}");
        // Through a symbolic link too.
        #[cfg(unix)]
        {
            let link = dir.path().join("D.npy");
            std::os::unix::fs::symlink(zero, &link).unwrap();
            let error = smspace::io::read_f64(&link).unwrap_err().to_string();
            assert!(error.contains("not a regular file"), "{error}");
            assert!(smspace_pipeline::manifest::hash_file(&link).is_err());
        }
    }
    let error = smspace::io::read_f64(dir.path()).unwrap_err().to_string();
    assert!(error.contains("a folder"), "{error}");
    #[cfg(unix)]
    {
        let fifo = dir.path().join("fifo.npy");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // Opening a FIFO for reading blocks until a writer comes: it is refused first.
            let error = smspace::io::read_f64(&fifo).unwrap_err().to_string();
            assert!(error.contains("not a regular file"), "{error}");
        }
    }
    let big = dir.path().join("big.toml");
    std::fs::write(&big, vec![b'#'; 100]).unwrap();
    let error = smspace::io::read_text_bounded(&big, 10)
        .unwrap_err()
        .to_string();
    assert!(error.contains("more than 10 bytes"), "{error}");
}

/// A backend that answers a 3 × 3 matrix whatever it is asked.
struct ThreeByThree;

impl DistanceBackend for ThreeByThree {
    fn distances(
        &self,
        _: &DistancesStage,
        _: SetsView<'_>,
        _: Option<u64>,
        _: &dyn Progress,
    ) -> smspace_pipeline::Result<DistanceMatrix> {
        Ok(DistanceMatrix::new(Array2::zeros((3, 3))).unwrap())
    }

    fn remote(&self) -> Option<String> {
        Some("a test cluster".to_owned())
    }
}

const TINY: &str = r#"
name = "tiny"
[agent]
kind = "toy-redundant"
[exploration]
n = 12
[kernel]
points = 8
[metric]
period = "none"
[embedding]
method = "mds"
dim = 1
[report]
formats = "svg"
"#;

fn tiny_plan(
    dir: &Path,
    overrides: &[&str],
) -> Result<smspace_pipeline::Plan, smspace_pipeline::Error> {
    let path = dir.join("tiny.toml");
    std::fs::write(&path, TINY).unwrap();
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let loaded = smspace_pipeline::config::load_experiment(&path, &overrides)?;
    Ok(smspace_pipeline::check(&loaded)?)
}

#[test]
fn a_backend_matrix_of_the_wrong_shape_fails_the_distances_stage() {
    let dir = tempfile::tempdir().unwrap();
    let plan = tiny_plan(dir.path(), &[]).unwrap();
    let out = dir.path().join("run");
    let options = RunOptions {
        out_dir: out.clone(),
        recompute: Recompute::Changed,
        memory_limit_bytes: None,
        busy: smspace_pipeline::BusyFolder::Refuse,
    };
    let error = smspace_pipeline::run_with(&plan, &options, &Quiet, &ThreeByThree)
        .unwrap_err()
        .to_string();
    assert!(error.contains("distances"), "{error}");
    assert!(
        error.contains(
            "the distance backend (a test cluster) failed: it returned a 3 × 3 matrix for"
        ),
        "{error}"
    );
    assert!(!out.join("D.npy").exists());
}

#[test]
fn a_run_of_fewer_than_two_sets_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let error = tiny_plan(dir.path(), &["exploration.n=1"])
        .unwrap_err()
        .to_string();
    assert!(error.contains("at least 2 sets"), "{error}");
    assert!(error.contains("exploration.n"), "{error}");
    assert!(!error.contains("could be traced"), "{error}");
}
