//! Issue 15: the pupil agent and the compensability filter.
//!
//! The dimension `d` of the compensable sensory changes: 3 for the paper's arm, 3 for
//! the pupil arm under rigid displacements of the scene, 4 with a common luminance
//! change added (3 once the commuting pupil ↔ luminance pair is removed), and 3 for a
//! control agent whose extra motor is spatial (a prismatic joint moving the retina
//! along its optical axis), whose motor is kept.

use ndarray::{Array2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use smspace::agent::{
    Agent, AgentConfig, ArmParams, Environment, EnvironmentConfig, Motor, MotorSpace, PlanarArm,
};
use smspace::analysis::compensability::{
    compensability, BasePoint, CompensabilityParams, CompensabilityReport, SceneChange,
};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{trace_sets, StepControl, TraceMethod, TraceParams};
use smspace::progress::Silent;

fn pupil_arm() -> Box<dyn Agent> {
    let config: AgentConfig =
        toml::from_str("kind = \"planar-arm\"\n[retina]\naperture = [0.5, 1.5]\n").unwrap();
    config.build().unwrap()
}

fn paper_arm() -> PlanarArm {
    PlanarArm::new(&ArmParams::default()).unwrap()
}

fn environment() -> Environment {
    EnvironmentConfig::default().build(&paper_arm()).unwrap()
}

/// 60 babbled configurations of the paper's arm in its working space, with `extra`
/// more columns drawn uniformly from `range` (seeded).
fn base_points(extra: usize, range: [f64; 2]) -> Array2<f64> {
    let params = ExploreParams {
        n: 60,
        ..Default::default()
    };
    let arm = explore(&paper_arm(), &params).unwrap().motors;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    Array2::from_shape_fn((arm.nrows(), 4 + extra), |(r, c)| {
        if c < 4 {
            arm[[r, c]]
        } else {
            rng.random_range(range[0]..range[1])
        }
    })
}

fn analyse(
    agent: &dyn Agent,
    motors: &Array2<f64>,
    changes: &[SceneChange],
) -> CompensabilityReport {
    let params = CompensabilityParams {
        changes: changes.to_vec(),
        ..Default::default()
    }
    .check()
    .unwrap();
    compensability(agent, &environment(), motors.view(), &params).unwrap()
}

/// `d` is the report's value, held by most points, with few ambiguous ones.
/// The first base point whose ranks were clear.
fn first_clear(report: &CompensabilityReport) -> &BasePoint {
    let clear = report.points.iter().find(|b| b.ambiguous.is_empty());
    clear.expect("a base point with clear ranks")
}

fn assert_dimension(report: &CompensabilityReport, d: usize, spatial: usize) {
    let clear = report.base_points - report.ambiguous;
    assert!(
        report.ambiguous * 4 <= report.base_points,
        "{} ambiguous of {}",
        report.ambiguous,
        report.base_points
    );
    assert_eq!(report.dimension, Some(d), "{:?}", report.histogram);
    assert!(
        report.histogram[d] * 10 >= clear * 8,
        "d = {d} at {} of {clear} clear points: {:?}",
        report.histogram[d],
        report.histogram
    );
    assert_eq!(
        report.spatial_dimension,
        Some(spatial),
        "{:?}",
        report.spatial_histogram
    );
}

#[test]
fn the_paper_arm_compensates_rigid_displacements_in_three_dimensions() {
    let motors = base_points(0, [0.0, 1.0]);
    let report = analyse(&paper_arm(), &motors, &[SceneChange::Rigid]);
    assert_dimension(&report, 3, 3);
    assert!(report.non_spatial_motors.is_empty());
    // A common luminance change is not compensable without a pupil.
    let report = analyse(
        &paper_arm(),
        &motors,
        &[SceneChange::Rigid, SceneChange::Luminance],
    );
    assert_dimension(&report, 3, 3);
    assert!(report.non_spatial_motors.is_empty());
    let point = first_clear(&report);
    assert_eq!((point.motor_rank, point.environment_rank), (3, 4));
    assert_eq!(point.joint_rank, 4);
}

#[test]
fn the_pupil_arm_compensates_displacements_in_three_and_luminance_in_four() {
    let agent = pupil_arm();
    let motors = base_points(1, [0.5, 1.5]);
    let rigid = analyse(agent.as_ref(), &motors, &[SceneChange::Rigid]);
    assert_dimension(&rigid, 3, 3);
    assert!(rigid.non_spatial_motors.is_empty());
    let both = analyse(
        agent.as_ref(),
        &motors,
        &[SceneChange::Rigid, SceneChange::Luminance],
    );
    // 4 before commutation, 3 after: the pupil ↔ luminance pair commutes with every
    // compensable change, and its motor direction is the aperture's axis.
    assert_dimension(&both, 4, 3);
    assert_eq!(both.non_spatial_motors, vec![4]);
    let point = first_clear(&both);
    assert_eq!(point.compensable_directions.len(), 4);
    assert!(point.non_spatial_directions[0][4].abs() > 0.999);
}

/// The paper's arm with a prismatic joint after the retina's hinge that moves the lens
/// by `m_5 ∈ [0, 0.5]` along its optical axis: the retina's pose is still `(x, y,
/// alpha)`, and the extra motor is spatial. Sensing at the moved lens is sensing at
/// the arm's lens in the scene translated back by the same amount.
#[derive(Debug)]
struct Telescope(PlanarArm);

impl Agent for Telescope {
    fn motor_dim(&self) -> usize {
        5
    }
    fn sensor_dim(&self) -> usize {
        self.0.sensor_dim()
    }
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        let alpha = self.0.planar_pose(&motors[..4]).alpha;
        let shift = [-motors[4] * alpha.cos(), -motors[4] * alpha.sin(), 0.0];
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        self.0.sense(
            &environment.displaced(&identity, shift),
            &motors[..4],
            sensors,
        );
    }
    fn name(&self) -> &str {
        "telescope"
    }
    fn motor_space(&self) -> MotorSpace {
        let mut motors = vec![Motor::HINGE; 4];
        motors.push(Motor::Bounded {
            low: 0.0,
            high: 0.5,
        });
        MotorSpace::new(motors).unwrap()
    }
}

#[test]
fn a_spatial_extra_motor_is_kept() {
    let motors = base_points(1, [0.0, 0.5]);
    let telescope = Telescope(paper_arm());
    let report = analyse(
        &telescope,
        &motors,
        &[SceneChange::Rigid, SceneChange::Luminance],
    );
    assert_dimension(&report, 3, 3);
    assert!(report.non_spatial_motors.is_empty(), "{report:?}");
    assert!(report
        .points
        .iter()
        .all(|b| b.commuting == 0 || !b.ambiguous.is_empty()));
}

#[test]
fn the_pupil_arm_has_five_motors_and_curves_for_kernels() {
    let agent = pupil_arm();
    assert_eq!(agent.motor_dim(), 5);
    assert_eq!(agent.ground_truth().unwrap().pose_space().dim(), 3);
    assert_eq!(agent.attribute_motors(), vec![4]);
    let motors = base_points(1, [0.5, 1.5]).select(Axis(0), &[0, 1, 2, 3, 4, 5]);
    let env = environment();
    for method in [TraceMethod::Kinematic, TraceMethod::Sensory] {
        let params = TraceParams {
            method,
            step_control: StepControl::Adaptive,
            points: 40,
            ..Default::default()
        }
        .check()
        .unwrap();
        let traced = trace_sets(
            agent.as_ref(),
            Some(&env),
            motors.view(),
            None,
            &params,
            &Silent,
        )
        .unwrap();
        assert!(
            traced.kept.len() >= 4,
            "{method:?}: {:?}",
            traced.report.summary
        );
        assert!(traced.dimensions().iter().all(|&k| k == 1));
        // The aperture stays at its start on every set (it changes the sensations).
        for (set, &row) in traced.sets.outer_iter().zip(&traced.kept) {
            for point in set.outer_iter() {
                assert!((point[4] - motors[[row, 4]]).abs() < 1e-6, "{method:?}");
            }
        }
    }
}

#[test]
fn an_aperture_is_checked_and_chains_take_one() {
    let err =
        toml::from_str::<AgentConfig>("kind = \"planar-arm\"\n[retina]\naperture = [1.5, 0.5]\n")
            .unwrap()
            .build()
            .unwrap_err();
    let located = err.invalid_parameter().unwrap();
    assert_eq!((located.table, located.key), ("agent", "retina.aperture"));
    let chain: AgentConfig = toml::from_str(
        r#"
        kind = "chain"
        joints = [
            { axis = [0, 0, 1], link = [1.0, 0, 0] },
            { axis = [0, 0, 1], link = [1.0, 0, 0] },
            { axis = [0, 0, 1], link = [0, 0, 0] },
        ]
        [retina]
        aperture = [0.5, 2.0]
        "#,
    )
    .unwrap();
    let built = chain.build().unwrap();
    assert_eq!(built.motor_dim(), 4);
    assert_eq!(
        built.motor_space().motors()[3],
        Motor::Bounded {
            low: 0.5,
            high: 2.0
        }
    );
    let env = Environment::from_lights(vec![[3.0, 0.2], [2.5, -0.5]]);
    let (mut half, mut one) = ([0.0; 6], [0.0; 6]);
    built.sense(&env, &[0.1, 0.2, -0.1, 1.0], &mut one);
    built.sense(&env, &[0.1, 0.2, -0.1, 0.5], &mut half);
    for (h, o) in half.iter().zip(&one) {
        assert!((2.0 * h - o).abs() < 1e-14);
    }
    // An arm without a pupil resolves without a retina table (keys of old runs).
    let plain: AgentConfig = toml::from_str("kind = \"planar-arm\"").unwrap();
    let resolved = smspace::agent::AgentRegistry::builtin()
        .build(&plain)
        .unwrap();
    assert!(!resolved.config.params.contains_key("retina"));
}

/// `experiments/pupil-space.toml`, reduced: 40 babbled sets of 15 points × 3 aperture
/// values. The sets are spanned along the aperture (motor 4), each slice its own piece
/// (15 points and the loop's closing copy), `analysis.json` holds the compensability
/// report, and the `curve` metric reads the slices as polylines: its matrix is that
/// between the traced loops at one common aperture (`kernel::spatial`'s module docs),
/// the same in two runs.
#[test]
fn the_pipeline_spans_the_sets_along_the_aperture() {
    use smspace::progress::Progress;
    use smspace_pipeline::{Recompute, RunObserver, RunOptions};
    struct Quiet;
    impl RunObserver for Quiet {
        fn progress(&self) -> &dyn Progress {
            &Silent
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let source = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../experiments/pupil-space.toml"
    );
    let overrides: Vec<String> = [
        "exploration.n=40",
        "kernel.points=15",
        "kernel.spatial_samples=3",
        "analysis.max_points=40",
        "embedding.epochs=2",
        "report.sample_configurations=4",
        "report.sample_sets=3",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let options = RunOptions {
        out_dir: dir.path().join("run"),
        recompute: Recompute::Changed,
        memory_limit_bytes: None,
        busy: smspace_pipeline::BusyFolder::Wait,
    };
    // First the point metric (the slices' points, the loops' closing copies included).
    let mut hausdorff = overrides.clone();
    hausdorff.push("metric.metric=hausdorff".into());
    let loaded =
        smspace_pipeline::config::load_experiment(std::path::Path::new(source), &hausdorff)
            .unwrap();
    let plan = smspace_pipeline::check(&loaded).unwrap_or_else(|e| panic!("{e}"));
    smspace_pipeline::run(&plan, &options, &Quiet).unwrap_or_else(|e| panic!("{e}"));
    let sets = smspace::kernel::TracedSets::load(&options.out_dir.join("sets.npy")).unwrap();
    assert_eq!(sets.sets.dim().1, 48);
    assert_eq!(sets.report.extended_along, vec![4]);
    for row in sets.pieces.outer_iter() {
        let expected: Vec<i64> = (0..3).flat_map(|t| [t; 16]).collect();
        assert_eq!(row.to_vec(), expected);
    }
    assert!(sets.dimensions().iter().all(|&k| k == 2));
    let analysis: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(options.out_dir.join("analysis.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(analysis["compensability"]["dimension"], 4);
    assert_eq!(analysis["compensability"]["spatial_dimension"], 3);
    // The curve metric reads each slice as a polyline: the matrix is that of the
    // first slices alone (the traced loops, all at the lowest aperture), and the same
    // in a second run.
    let mut curve = overrides.clone();
    curve.push("metric.metric=curve".into());
    let loaded =
        smspace_pipeline::config::load_experiment(std::path::Path::new(source), &curve).unwrap();
    let plan = smspace_pipeline::check(&loaded).unwrap();
    let run = |name: &str| {
        let options = RunOptions {
            out_dir: dir.path().join(name),
            ..options.clone()
        };
        smspace_pipeline::run(&plan, &options, &Quiet).unwrap_or_else(|e| panic!("{e}"));
        smspace::metric::DistanceMatrix::load(&options.out_dir.join("D.npy")).unwrap()
    };
    let d = run("curve");
    assert_eq!(run("again").view(), d.view());
    let first = sets.sets.slice_axis(Axis(1), (0..16).into()).to_owned();
    let closure = vec![smspace::kernel::Closure::Open; first.dim().0];
    let tau = Some(std::f64::consts::TAU);
    let periods = smspace::metric::Periods::new(vec![tau, tau, tau, tau, None]).unwrap();
    let params = smspace::metric::DistanceParams::new()
        .metric(smspace::metric::MetricKind::Curve)
        .period(smspace::metric::Periodicity::PerCoordinate(periods));
    let view = smspace::metric::SetsView::new(first.view()).with_closure(&closure);
    let direct = smspace::metric::distance_matrix(view, &params, &Silent).unwrap();
    for (a, b) in d.view().iter().zip(direct.view().iter()) {
        assert!((a - b).abs() < 1e-9, "{a} {b}");
    }
    assert!(direct.view().iter().any(|&x| x > 0.01));
}

/// The 7-joint arm in 3-D of `experiments/arm-3d.toml` (4 × 4 retina, 30 lights in a
/// volume), with `retina` lines added to its `[retina]` table.
fn arm_3d(retina: &str) -> (Box<dyn Agent>, Environment) {
    let text = format!(
        r#"
kind = "chain"
joints = [
    {{ axis = [0, 0, 1], link = [0, 0, 0.5] }},
    {{ axis = [0, 1, 0], link = [0, 0, 0] }},
    {{ axis = [1, 0, 0], link = [1.0, 0, 0] }},
    {{ axis = [0, 1, 0], link = [1.0, 0, 0] }},
    {{ axis = [1, 0, 0], link = [0, 0, 0] }},
    {{ axis = [0, 1, 0], link = [0.5, 0, 0] }},
    {{ axis = [0, 0, 1], link = [0, 0, 0] }},
]
[retina]
cells = [4, 4]
{retina}
"#
    );
    let agent = toml::from_str::<AgentConfig>(&text)
        .unwrap()
        .build()
        .unwrap();
    let environment = EnvironmentConfig {
        lights: Some(30),
        ..Default::default()
    }
    .build(agent.as_ref())
    .unwrap();
    (agent, environment)
}

/// The compensability of `agent` in `environment` at 40 babbled configurations.
fn analyse_in(
    agent: &dyn Agent,
    environment: &Environment,
    changes: &[SceneChange],
) -> CompensabilityReport {
    let explored = explore(
        agent,
        &ExploreParams {
            n: 40,
            ..Default::default()
        },
    )
    .unwrap();
    let params = CompensabilityParams {
        changes: changes.to_vec(),
        ..Default::default()
    }
    .check()
    .unwrap();
    compensability(agent, environment, explored.motors.view(), &params).unwrap()
}

/// Rigid displacements in 3-D (6 parameters: rotations about x, y, z and translations).
/// The sensation depends on the scene only through the lights' positions in the
/// retina's frame, `R^T (l − p)`: displacing every light by `(R_e, t_e)` senses as
/// displacing the retina by the inverse, so `T_E` is the space of sensory changes of
/// small retina displacements. The 7 joints move the retina with a Jacobian of rank 6
/// away from singular postures, so `T_M` is that same space: `T_M = T_E`, `d = 6`, the
/// dimension of the retina's configuration space (Philipona et al. 2003, Table 1: 6
/// for rigid motion in 3-D). The Lie algebra se(3) has no centre (no displacement
/// commutes with every other), so none is removed: spatial dimension 6.
#[test]
fn a_three_dimensional_arm_compensates_the_six_rigid_displacements() {
    let (agent, environment) = arm_3d("");
    assert_eq!(agent.motor_dim(), 7);
    let report = analyse_in(agent.as_ref(), &environment, &[SceneChange::Rigid]);
    assert_eq!(report.environment_parameters, 6);
    assert_dimension(&report, 6, 6);
    assert!(report.non_spatial_motors.is_empty());
    let point = first_clear(&report);
    assert_eq!((point.motor_rank, point.environment_rank), (6, 6));
    assert_eq!(point.joint_rank, 6);
}

/// The same arm with a pupil (an eighth motor, the aperture, scaling every cell) and a
/// common change of luminance: the aperture's sensory change `∂s/∂a = s/a` is the
/// luminance change's `∂s/∂λ = s`, so both add the same direction to `T_M` and `T_E`:
/// `d = 7` (Philipona et al. 2003, Table 1: 7 when a controlled diaphragm can mimic a
/// common change of all luminances). Luminance commutes with every displacement (the
/// intensities ride with the lights) and se(3) has no centre, so exactly that
/// direction is removed: spatial dimension 6, and the non-spatial motor is the
/// aperture (motor 7).
#[test]
fn a_three_dimensional_pupil_arm_compensates_seven_and_keeps_six() {
    let (agent, environment) = arm_3d("aperture = [0.5, 1.5]");
    assert_eq!(agent.motor_dim(), 8);
    let report = analyse_in(
        agent.as_ref(),
        &environment,
        &[SceneChange::Rigid, SceneChange::Luminance],
    );
    assert_eq!(report.environment_parameters, 7);
    assert_dimension(&report, 7, 6);
    assert_eq!(report.non_spatial_motors, vec![7]);
}

/// Per-light intensities (one parameter per light) add no compensable direction. The
/// compensable changes lie in `T_M`, so `d ≤ rank T_M`: the sensations depend on the
/// motors only through the retina's pose (3 in the plane) and, with a pupil, the
/// aperture (`s = a · f(pose)`), so `rank T_M` is 3 without a pupil and 4 with one.
/// With rigid displacements alone `T_M`'s pose directions are already in `T_E`, and
/// the aperture's direction `s` is the sum of the per-light directions
/// (`Σ_l ∂s/∂λ_l = s` for intensities `exp(λ_l)`): every motor direction is
/// compensable, `d = rank T_M` (3, 4), and more environment parameters cannot raise
/// it. (The spatial dimension is not asserted here: with 13 environment parameters
/// and 6 cells, the environment direction of a compensable change, `J_E⁺ u`, is one
/// of many, so the commutation test reads a particular mixture.)
#[test]
fn per_light_intensities_add_no_compensable_direction() {
    let changes = [SceneChange::Rigid, SceneChange::Intensities];
    let paper = analyse(&paper_arm(), &base_points(0, [0.0, 1.0]), &changes);
    assert_eq!(paper.environment_parameters, 3 + environment().lights.len());
    assert_eq!(paper.dimension, Some(3), "{:?}", paper.histogram);
    let agent = pupil_arm();
    let pupil = analyse(agent.as_ref(), &base_points(1, [0.5, 1.5]), &changes);
    assert_eq!(pupil.dimension, Some(4), "{:?}", pupil.histogram);
    // Every clear base point: d = rank T_M, whatever the intensities.
    for report in [&paper, &pupil] {
        let clear: Vec<_> = report
            .points
            .iter()
            .filter(|b| b.ambiguous.is_empty())
            .collect();
        assert!(clear.len() * 4 >= report.base_points * 3, "{}", clear.len());
        for b in clear {
            assert_eq!(b.dimension, b.motor_rank, "{b:?}");
        }
    }
}
