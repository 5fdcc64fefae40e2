//! Kinematic chains (`kind = "chain"`, issue 14): forward kinematics against hand
//! computations, the paper's arm written as a chain, the analytic pose Jacobian against
//! finite differences, bad chains, and environments in a volume.

use std::f64::consts::{FRAC_1_SQRT_2, FRAC_PI_2, PI};

use approx::assert_abs_diff_eq;
use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::agent::{
    Agent, AgentConfig, Environment, EnvironmentConfig, LightSpace, Motor, Observer, PoseSpace,
};
use smspace::kernel::{trace_sets, StepControl, TraceMethod, TraceParams};
use smspace::progress::Silent;

fn build(text: &str) -> Result<Box<dyn Agent>, smspace::agent::AgentError> {
    toml::from_str::<AgentConfig>(text).unwrap().build()
}

fn chain(text: &str) -> Box<dyn Agent> {
    build(text).unwrap()
}

/// The paper's arm (3 unit links and the retina's hinge) as a chain.
const PAPER_ARM: &str = r#"
kind = "chain"
joints = [
    { axis = [0, 0, 1], link = [1.0, 0, 0] },
    { axis = [0, 0, 1], link = [1.0, 0, 0] },
    { axis = [0, 0, 1], link = [1.0, 0, 0] },
    { axis = [0, 0, 1], link = [0, 0, 0] },
]
[retina]
cells = 6
half_width = 1.0
focal_length = 1.0
"#;

/// A 7-joint arm in 3-D with a 4 × 4 retina (as `experiments/arm-3d.toml`).
const ARM_3D: &str = r#"
kind = "chain"
joints = [
    { axis = [0, 0, 1], link = [0, 0, 0.5] },
    { axis = [0, 1, 0], link = [1.0, 0, 0] },
    { axis = [1, 0, 0], link = [0, 0, 0] },
    { axis = [0, 1, 0], link = [1.0, 0, 0] },
    { axis = [1, 0, 0], link = [0, 0, 0] },
    { axis = [0, 1, 0], link = [0.5, 0, 0] },
    { axis = [0, 0, 1], link = [0, 0, 0] },
]
[retina]
cells = [4, 4]
"#;

fn pose(agent: &dyn Agent, motors: &[f64]) -> Vec<f64> {
    let observer = agent.ground_truth().unwrap();
    let mut pose = vec![0.0; observer.pose_space().dim()];
    observer.pose(motors, &mut pose);
    pose
}

fn random_motors(agent: &dyn Agent, rows: usize, seed: u64) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ranges: Vec<(f64, f64)> = agent
        .motor_space()
        .motors()
        .iter()
        .map(|m| m.range())
        .collect();
    Array2::from_shape_fn((rows, ranges.len()), |(_, j)| {
        rng.random_range(ranges[j].0..ranges[j].1)
    })
}

#[test]
fn planar_forward_kinematics_matches_hand_computed_poses() {
    // Two links of lengths 1 and 0.5, the second turning clockwise (axis −z), and a
    // sideways link [0, 0.5] after it.
    let agent = chain(
        r#"
        kind = "chain"
        joints = [
            { axis = [0, 0, 1], link = [1.0, 0, 0] },
            { axis = [0, 0, -2], link = [0.5, 0.5, 0] },
        ]
        "#,
    );
    assert_eq!(
        agent.ground_truth().unwrap().pose_space(),
        PoseSpace::planar()
    );
    assert_eq!(agent.light_space(), LightSpace::Plane);
    // m = (π/2, π/2): θ1 = π/2, θ2 = π/2 − π/2 = 0; p = (0, 1) + (0.5, 0.5).
    let p = pose(agent.as_ref(), &[FRAC_PI_2, FRAC_PI_2]);
    assert_abs_diff_eq!(p[0], 0.5, epsilon = 1e-12);
    assert_abs_diff_eq!(p[1], 1.5, epsilon = 1e-12);
    assert_abs_diff_eq!(p[2], 0.0, epsilon = 1e-12);
    // m = (0, π/2): θ2 = −π/2, the link [0.5, 0.5] turned clockwise is (0.5, −0.5).
    let p = pose(agent.as_ref(), &[0.0, FRAC_PI_2]);
    assert_abs_diff_eq!(p[0], 1.5, epsilon = 1e-12);
    assert_abs_diff_eq!(p[1], -0.5, epsilon = 1e-12);
    assert_abs_diff_eq!(p[2], -FRAC_PI_2, epsilon = 1e-12);
    let skeleton = agent.skeleton(&[FRAC_PI_2, FRAC_PI_2]);
    assert_eq!(skeleton.len(), 3);
    assert_abs_diff_eq!(skeleton[1][1], 1.0, epsilon = 1e-12);
}

#[test]
fn spatial_forward_kinematics_matches_hand_computed_poses() {
    // A turn about z then a link along x, a turn about y then a link along x.
    let agent = chain(
        r#"
        kind = "chain"
        joints = [
            { axis = [0, 0, 1], link = [1.0, 0, 0] },
            { axis = [0, 1, 0], link = [1.0, 0, 0], range = [-1.5, 1.5] },
        ]
        [retina]
        cells = [2, 3]
        "#,
    );
    assert_eq!(agent.light_space(), LightSpace::Volume);
    assert_eq!(agent.sensor_dim(), 6);
    // m = (π/2, π/2): the first link points along y; turning about the (rotated) y
    // axis by π/2 sends the second link's x to −z: p = (0, 1, −1).
    let p = pose(agent.as_ref(), &[FRAC_PI_2, FRAC_PI_2]);
    let expected_position = [0.0, 1.0, -1.0];
    for (a, b) in p[..3].iter().zip(expected_position) {
        assert_abs_diff_eq!(*a, b, epsilon = 1e-12);
    }
    // q = q_z(π/2) q_y(π/2) = (1/2, −1/2, 1/2, 1/2) (w, x, y, z).
    for (a, b) in p[3..].iter().zip([0.5, -0.5, 0.5, 0.5]) {
        assert_abs_diff_eq!(*a, b, epsilon = 1e-12);
    }
    // A quarter turn about z alone: q = (cos π/4, 0, 0, sin π/4), position (0, 1, 0)
    // + (0, 1, 0); a turn of −3π/2 is the same orientation, written with qw ≥ 0.
    for m1 in [FRAC_PI_2, -1.5 * PI] {
        let p = pose(agent.as_ref(), &[m1, 0.0]);
        assert_abs_diff_eq!(p[1], 2.0, epsilon = 1e-12);
        for (a, b) in p[3..].iter().zip([FRAC_1_SQRT_2, 0.0, 0.0, FRAC_1_SQRT_2]) {
            assert_abs_diff_eq!(*a, b, epsilon = 1e-12);
        }
    }
    // The range makes the second motor bounded, the first stays a hinge.
    let motors = agent.motor_space();
    assert_eq!(motors.motors()[0], Motor::HINGE);
    assert_eq!(
        motors.motors()[1],
        Motor::Bounded {
            low: -1.5,
            high: 1.5
        }
    );
    let babbled = random_motors(agent.as_ref(), 200, 1);
    assert!(babbled.column(1).iter().all(|m| (-1.5..1.5).contains(m)));
}

#[test]
fn the_retina_sees_a_light_ahead_in_the_middle_of_its_grid() {
    let agent = chain(
        r#"
        kind = "chain"
        joints = [{ axis = [0, 1, 0], link = [1.0, 0, 0] }]
        [retina]
        cells = [3, 3]
        "#,
    );
    // The lens at (1, 0, 0) looking along +x: a light at (3, 0, 0) projects on the
    // centre cell, a light above (+z) projects below (the image is inverted).
    let ahead = Environment::from_lights_3d(vec![[3.0, 0.0, 0.0]]);
    let mut s = vec![0.0; 9];
    agent.sense(&ahead, &[0.0], &mut s);
    assert_abs_diff_eq!(s[4], 0.5, epsilon = 1e-12);
    assert_abs_diff_eq!(s[0], (-2.0f64).exp() * 0.5, epsilon = 1e-12);
    let above = Environment::from_lights_3d(vec![[3.0, 0.0, 1.0]]);
    agent.sense(&above, &[0.0], &mut s);
    let (bottom, top): (f64, f64) = (s[..3].iter().sum(), s[6..].iter().sum());
    assert!(bottom > top, "{s:?}");
    let behind = Environment::from_lights_3d(vec![[0.0, 0.0, 0.0]]);
    agent.sense(&behind, &[0.0], &mut s);
    assert!(s.iter().all(|&v| v == 0.0));
}

#[test]
fn the_paper_arm_as_a_chain_senses_as_the_planar_arm() {
    let arm = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let chain = chain(PAPER_ARM);
    let environment = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let chain_environment = EnvironmentConfig::default().build(chain.as_ref()).unwrap();
    assert_eq!(environment, chain_environment, "the same default lights");
    assert_eq!(chain.default_workspace(), arm.default_workspace());
    let motors = random_motors(arm.as_ref(), 2000, 7);
    let (mut a, mut b) = (vec![0.0; 6], vec![0.0; 6]);
    let mut largest: f64 = 0.0;
    for m in motors.outer_iter() {
        let m = m.as_slice().unwrap();
        arm.sense(&environment, m, &mut a);
        chain.sense(&environment, m, &mut b);
        for (x, y) in a.iter().zip(&b) {
            largest = largest.max((x - y).abs());
        }
        let (pa, pc) = (pose(arm.as_ref(), m), pose(chain.as_ref(), m));
        for (x, y) in pa.iter().zip(&pc) {
            assert_abs_diff_eq!(*x, *y, epsilon = 1e-12);
        }
    }
    assert!(largest <= 1e-12, "sensations differ by {largest}");
}

#[test]
fn the_paper_arm_as_a_chain_traces_the_same_sets() {
    let arm = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let chain = chain(PAPER_ARM);
    let environment = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let starts = random_motors(arm.as_ref(), 6, 3);
    for method in [TraceMethod::Kinematic, TraceMethod::Sensory] {
        let params = TraceParams {
            method,
            step_control: StepControl::Adaptive,
            points: 50,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        let trace = |agent: &dyn Agent| {
            trace_sets(
                agent,
                Some(&environment),
                starts.view(),
                None,
                &params,
                &Silent,
            )
            .unwrap()
        };
        let (a, b) = (trace(arm.as_ref()), trace(chain.as_ref()));
        assert_eq!(a.kept, b.kept, "{method:?}");
        assert!(!a.kept.is_empty());
        let largest = (&a.sets - &b.sets)
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(largest <= 1e-9, "{method:?}: sets differ by {largest}");
    }
}

/// An observer with the chain's poses and the default (finite-difference) Jacobian.
struct Numeric<'a>(&'a dyn Observer);
impl Observer for Numeric<'_> {
    fn pose_space(&self) -> PoseSpace {
        self.0.pose_space()
    }
    fn pose(&self, m: &[f64], pose: &mut [f64]) {
        self.0.pose(m, pose)
    }
}

#[test]
fn the_analytic_pose_jacobian_matches_finite_differences() {
    for text in [PAPER_ARM, ARM_3D] {
        let agent = chain(text);
        let observer = agent.ground_truth().unwrap();
        let (n, space) = (agent.motor_dim(), observer.pose_space());
        let rows = space.tangent_dim();
        assert_eq!(observer.configuration_dim(), rows);
        let motors = random_motors(agent.as_ref(), 20, 11);
        for m in motors.outer_iter() {
            let m = m.as_slice().unwrap();
            let (mut analytic, mut numeric) = (vec![0.0; rows * n], vec![0.0; rows * n]);
            let (mut pose_a, mut pose_n) = (vec![0.0; space.dim()], vec![0.0; space.dim()]);
            observer.pose_jacobian(m, &mut analytic, &mut pose_a);
            Numeric(observer).pose_jacobian(m, &mut numeric, &mut pose_n);
            for (a, b) in analytic.iter().zip(&numeric) {
                assert_abs_diff_eq!(a, b, epsilon = 1e-7);
            }
            for (a, b) in pose_a.iter().zip(&pose_n) {
                assert_abs_diff_eq!(a, b, epsilon = 1e-12);
            }
            assert!(space.is_planar() || pose_a[3] >= 0.0);
        }
    }
}

#[test]
fn bad_chains_name_the_joint_and_the_key() {
    let joint = |body: &str| {
        format!("kind = \"chain\"\njoints = [{{ axis = [0, 0, 1], link = [1.0, 0, 0] }}, {body}]")
    };
    let cases = [
        (
            "kind = \"chain\"".to_owned(),
            vec!["joints", "at least one joint"],
        ),
        (
            "kind = \"chain\"\njoints = []".to_owned(),
            vec!["joints", "at least one joint"],
        ),
        (
            joint("{ axis = [0, 0, 0], link = [1.0, 0, 0] }"),
            vec!["joint 1", "axis"],
        ),
        (
            joint("{ axis = [0, 0, nan], link = [1.0, 0, 0] }"),
            vec!["joint 1", "axis"],
        ),
        (
            joint("{ axis = [0, 0, 1], link = [inf, 0, 0] }"),
            vec!["joint 1", "link"],
        ),
        (
            joint("{ axis = [0, 0, 1], link = [1.0, 0, 0], range = [1.0, -1.0] }"),
            vec!["joint 1", "range", "low < high"],
        ),
        (
            joint("{ axis = [0, 0, 1], link = [1.0, 0, 0], range = [0.0, 0.0] }"),
            vec!["joint 1", "range"],
        ),
        (
            joint("{ axis = [0, 0, 1], lnk = [1.0, 0, 0] }"),
            vec!["joint 1", "lnk"],
        ),
        (
            joint("{ axis = [0, 1], link = [1.0, 0, 0] }"),
            vec!["joint 1", "axis"],
        ),
        (
            "kind = \"chain\"\njoints = [{ axis = [0, 0, 1], link = [0, 0, 0] }]".to_owned(),
            vec!["never moves"],
        ),
        (
            format!(
                "{}\n[retina]\ncells = 0",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["retina.cells", "0"],
        ),
        (
            format!(
                "{}\n[retina]\ncells = [4, 0]",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["retina.cells"],
        ),
        (
            format!(
                "{}\n[retina]\ncells = \"six\"",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["cells", "rows, cols"],
        ),
        (
            format!(
                "{}\n[retina]\nfocal_length = -1.0",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["retina.focal_length"],
        ),
        (
            format!(
                "{}\n[retina]\nsize = 3",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["size"],
        ),
        (
            format!(
                "{}\nelbow = 1",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["elbow"],
        ),
        (
            format!(
                "{}\n[workspace]\ncenter = [1.0, 0, 0]\nsize = [1.0, 1.0, 1.0]",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["workspace", "planar chain"],
        ),
        (
            format!(
                "{}\n[workspace]\ncenter = [1.0, 0]\nsize = [1.0, 0.0]",
                joint("{ axis = [0, 0, 1], link = [1.0, 0, 0] }")
            ),
            vec!["workspace", "positive"],
        ),
    ];
    for (text, needles) in cases {
        let err = build(&text).unwrap_err().to_string();
        for needle in needles {
            assert!(err.contains(needle), "{text}\n→ {err}\n(no '{needle}')");
        }
    }
}

#[test]
fn the_default_working_space_follows_the_reach() {
    // A 3-D chain stretched along x: the box sits at 7/12 of the reach along x, half
    // the reach deep, two thirds wide and high, and babbling reaches it.
    let agent = chain(ARM_3D);
    let w = agent.default_workspace().unwrap();
    let reach = 0.5 + 1.0 + 1.0 + 0.5;
    // Home: the first link points up, the rest along x: p = (2.5, 0, 0.5).
    let home = (2.5f64.powi(2) + 0.25).sqrt();
    assert_abs_diff_eq!(
        w.center[0],
        reach * 7.0 / 12.0 * 2.5 / home,
        epsilon = 1e-12
    );
    assert_abs_diff_eq!(w.size[0], reach / 2.0, epsilon = 1e-12);
    assert_abs_diff_eq!(w.size[1], 2.0 * reach / 3.0, epsilon = 1e-12);
    let [low, high] = w.z_range.unwrap();
    assert_abs_diff_eq!(high - low, 2.0 * reach / 3.0, epsilon = 1e-12);
    let params = smspace::explore::ExploreParams {
        n: 20,
        ..Default::default()
    };
    let found = smspace::explore::explore(agent.as_ref(), &params).unwrap();
    let poses = found.ground_truth.as_ref().unwrap().poses();
    assert_eq!(poses.dim(), (20, 7));
    for p in poses.outer_iter() {
        assert!(w.contains(p.as_slice().unwrap()));
        let q = &p.as_slice().unwrap()[3..];
        assert!(q[0] >= 0.0);
        assert_abs_diff_eq!(q.iter().map(|v| v * v).sum::<f64>(), 1.0, epsilon = 1e-12);
    }
    // A working space from the file.
    let given = chain(&format!(
        "{ARM_3D}\n[workspace]\ncenter = [1.5, 0.0, 0.5]\nsize = [1.0, 2.0, 0.4]"
    ));
    let w = given.default_workspace().unwrap();
    assert_eq!(w.z_range, Some([0.3, 0.7]));
    assert_eq!((w.center, w.size), ([1.5, 0.0], [1.0, 2.0]));
}

#[test]
fn environments_in_a_volume_are_read_drawn_and_matched_to_the_agent() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("env.json");
    let spatial = chain(ARM_3D);
    let planar = chain(PAPER_ARM);
    // Drawn: lights in a volume for a 3-D chain, seeded, outside the working space.
    let drawn = EnvironmentConfig::default()
        .build(spatial.as_ref())
        .unwrap();
    assert_eq!(drawn.space, LightSpace::Volume);
    assert_eq!(
        drawn,
        EnvironmentConfig::default()
            .build(spatial.as_ref())
            .unwrap()
    );
    let [low, high] = spatial.default_light_heights();
    assert!(drawn.lights.iter().all(|l| (low..high).contains(&l[2])));
    assert!(drawn.lights.iter().any(|l| l[2] != 0.0));
    let w = spatial.default_workspace().unwrap();
    assert!(drawn.lights.iter().all(|l| !w.contains(l)));
    drawn.check_for(spatial.as_ref()).unwrap();
    // Written and read back with three coordinates.
    drawn.save(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(Environment::load(&path).unwrap(), drawn, "{text}");
    // A planar file stays planar, with two coordinates.
    std::fs::write(&path, r#"{"lights": [[1.0, 2.0], [3.0, -1.0]]}"#).unwrap();
    let flat = Environment::load(&path).unwrap();
    assert_eq!(flat.space, LightSpace::Plane);
    assert_eq!(flat.lights[1], [3.0, -1.0, 0.0]);
    flat.check_for(planar.as_ref()).unwrap();
    flat.save(&path).unwrap();
    assert!(!std::fs::read_to_string(&path).unwrap().contains("0.0]"));
    // Mismatches are clear errors.
    let err = flat.check_for(spatial.as_ref()).unwrap_err().to_string();
    assert!(err.contains("[x, y, z]") && err.contains("chain"), "{err}");
    let err = drawn.check_for(planar.as_ref()).unwrap_err().to_string();
    assert!(
        err.contains("in the plane") && err.contains("[x, y]"),
        "{err}"
    );
    // Mixed and wrong-length lights name the light.
    for (body, needle) in [
        (
            r#"{"lights": [[1.0, 2.0, 0.5], [3.0, -1.0]]}"#,
            "light 1 has 2",
        ),
        (r#"{"lights": [[1.0]]}"#, "light 0 has 1"),
        (r#"{"lights": [[1.0, 2.0, 3.0, 4.0]]}"#, "light 0 has 4"),
    ] {
        std::fs::write(&path, body).unwrap();
        let err = Environment::load(&path).unwrap_err().to_string();
        assert!(err.contains(needle) && err.contains("env.json"), "{err}");
    }
}

#[test]
fn the_paper_arm_as_a_chain_explores_and_probes_as_the_planar_arm() {
    let arm = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let as_chain = chain(PAPER_ARM);
    let params = smspace::explore::ExploreParams {
        n: 50,
        probes: smspace::explore::Probes::Grid,
        probe_positions: 3,
        probe_orientations: 4,
        ..Default::default()
    };
    let a = smspace::explore::explore(arm.as_ref(), &params).unwrap();
    let b = smspace::explore::explore(as_chain.as_ref(), &params).unwrap();
    assert_eq!(a.motors, b.motors);
    assert_eq!(a.probes, b.probes);
    assert_eq!(a.ground_truth, b.ground_truth);
    // A chain of another shape has no inverse kinematics: no probe grid.
    let bent = chain(
        "kind = \"chain\"\njoints = [{ axis = [0, 0, 1], link = [1.0, 0.5, 0] }, { axis = [0, 0, 1], link = [0, 0, 0] }]",
    );
    assert!(bent
        .ground_truth()
        .unwrap()
        .inverse_kinematics(&[1.0, 0.0, 0.0])
        .is_none());
}
