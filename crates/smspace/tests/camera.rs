//! The camera body and its scene: analytic images, shifts, smoothness, bad input and
//! determinism across thread counts.

use std::f64::consts::PI;

use approx::assert_abs_diff_eq;
use smspace::agent::{
    sense_rows, Agent, AgentConfig, Amplitude, Environment, Primitive, Scene, Sphere, Texture,
    Wall, Wave,
};

/// A chain from its TOML body (`kind = "chain"` added).
fn chain(body: &str) -> Box<dyn Agent> {
    let config: AgentConfig = toml::from_str(&format!("kind = \"chain\"\n{body}")).unwrap();
    config.build().unwrap()
}

/// A planar strip camera on one `z` hinge with a unit link: at `m = 0` it sits at
/// `(1, 0, 0)` and looks along `+x`.
fn strip(width: usize, fov: f64) -> Box<dyn Agent> {
    chain(&format!(
        "joints = [{{ axis = [0, 0, 1], link = [1.0, 0, 0] }}]\n[camera]\nwidth = {width}\nfov = {fov}"
    ))
}

/// A 3-D camera (a `z` hinge, then a `y` hinge with a range) of `width × height` pixels.
fn camera_3d(width: usize, height: usize, color: &str) -> Box<dyn Agent> {
    chain(&format!(
        "joints = [{{ axis = [0, 0, 1], link = [0.5, 0, 0] }}, {{ axis = [0, 1, 0], link = [0.5, 0, 0], range = [-1.0, 1.0] }}]\n\
         [camera]\nwidth = {width}\nheight = {height}\nfov = 1.2\ncolor = \"{color}\""
    ))
}

/// A wall `x = 5` of colour `color`, with `waves`.
fn wall_scene(color: [f64; 3], waves: Vec<Wave>) -> Scene {
    Scene {
        primitives: vec![Primitive::Wall(Wall {
            point: [5.0, 0.0, 0.0],
            normal: [1.0, 0.0, 0.0],
            color,
            texture: (!waves.is_empty()).then_some(Texture::Waves(waves)),
        })],
        background: [0.0; 3],
    }
}

fn room() -> Environment {
    Environment::from_scene(Scene::textured_room([6.0, 6.0, 4.0], 7))
}

#[test]
fn a_camera_facing_a_uniform_wall_sees_a_uniform_image() {
    let color = [0.2, 0.4, 0.6];
    let environment = Environment::from_scene(wall_scene(color, Vec::new()));
    let grey = 0.2126 * 0.2 + 0.7152 * 0.4 + 0.0722 * 0.6;
    let camera = strip(16, 1.0);
    let mut image = vec![0.0; camera.sensor_dim()];
    camera.sense(&environment, &[0.3], &mut image);
    for v in &image {
        assert_abs_diff_eq!(*v, grey, epsilon = 1e-12);
    }
    let rgb = camera_3d(4, 3, "rgb");
    let mut image = vec![0.0; rgb.sensor_dim()];
    rgb.sense(&environment, &[0.0, 0.2], &mut image);
    for pixel in image.chunks_exact(3) {
        for (v, c) in pixel.iter().zip(color) {
            assert_abs_diff_eq!(*v, c, epsilon = 1e-12);
        }
    }
    // A camera that sees a uniform image sees nothing it could learn from.
    let err = environment
        .check_for(camera.as_ref())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("sees nothing") && err.contains("chain"),
        "{err}"
    );
}

#[test]
fn a_sinusoidal_texture_matches_its_filtered_formula() {
    let (wavelength, amplitude, phase) = (2.0, 0.1, 0.3);
    let wave = Wave {
        direction: [0.0, 1.0, 0.0],
        wavelength,
        amplitude: Amplitude::Grey(amplitude),
        phase,
    };
    let environment = Environment::from_scene(wall_scene([0.5; 3], vec![wave]));
    let (width, fov) = (24, 1.0);
    let camera = strip(width, fov);
    environment.check_for(camera.as_ref()).unwrap();
    let mut image = vec![0.0; width];
    camera.sense(&environment, &[0.0], &mut image);
    let pitch = 2.0 * (fov / 2.0_f64).tan() / width as f64;
    let k = 2.0 * PI / wavelength;
    for (c, v) in image.iter().enumerate() {
        let a = (c as f64 + 0.5 - width as f64 / 2.0) * pitch;
        // The ray (1, −a, 0) reaches the wall x = 5 at forward depth 4.
        let y = -4.0 * a;
        let sigma = 0.5 * pitch * 4.0;
        let expected =
            0.5 + amplitude * (-0.5 * k * k * sigma * sigma).exp() * (k * y + phase).sin();
        assert_abs_diff_eq!(*v, expected, epsilon = 1e-12);
    }
}

#[test]
fn rotating_the_last_hinge_shifts_a_strip_image() {
    let camera = chain(
        "joints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }, { axis = [0, 0, 1], link = [0, 0, 0] }]\n\
         [camera]\nwidth = 64\nfov = 0.4",
    );
    let environment = room();
    environment.check_for(camera.as_ref()).unwrap();
    let (width, fov, shift) = (64, 0.4_f64, 5);
    let pitch = 2.0 * (fov / 2.0).tan() / width as f64;
    let a = |c: usize| (c as f64 + 0.5 - width as f64 / 2.0) * pitch;
    // The angle between the rays of the two pixels around the centre `shift` apart.
    let centre = width / 2;
    let angle = a(centre).atan() - a(centre - shift).atan();
    let mut before = vec![0.0; width];
    let mut after = vec![0.0; width];
    camera.sense(&environment, &[0.4, 0.0], &mut before);
    camera.sense(&environment, &[0.4, angle], &mut after);
    let range = before.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - before.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(range > 1e-3, "a textured room has contrast: {range}");
    let (mut shifted, mut unshifted) = (0.0_f64, 0.0_f64);
    for c in shift + 4..width - 4 {
        shifted = shifted.max((after[c] - before[c - shift]).abs());
        unshifted = unshifted.max((after[c] - before[c]).abs());
    }
    // The pinhole's rays are not equally spaced in angle (tan), so the shift is exact
    // at the centre only: allow a small part of the image's range elsewhere.
    assert!(shifted < 0.05 * range, "{shifted} vs range {range}");
    assert!(unshifted > 4.0 * shifted, "{unshifted} vs {shifted}");
    let c = centre;
    assert_abs_diff_eq!(after[c], before[c - shift], epsilon = 1e-3 * range);
}

#[test]
fn finite_differences_of_a_pixel_converge() {
    let camera = camera_3d(16, 12, "grey");
    let mut scene = Scene::textured_room([6.0, 6.0, 4.0], 7);
    // A textured sphere in the room, away from the camera's path.
    scene.primitives.push(Primitive::Sphere(Sphere {
        center: [2.0, 1.0, 0.2],
        radius: 0.6,
        color: [0.9, 0.3, 0.1],
        texture: Some(Texture::Waves(vec![Wave {
            direction: [1.0, 1.0, 0.0],
            wavelength: 0.4,
            amplitude: Amplitude::Rgb([0.05, 0.1, 0.0]),
            phase: 0.0,
        }])),
    }));
    let environment = Environment::from_scene(scene);
    environment.check_for(camera.as_ref()).unwrap();
    let m0 = [0.35, 0.15];
    let k = camera.sensor_dim();
    let sense = |m: &[f64]| {
        let mut s = vec![0.0; k];
        camera.sense(&environment, m, &mut s);
        s
    };
    let derivative = |motor: usize, h: f64| {
        let (mut plus, mut minus) = (m0, m0);
        plus[motor] += h;
        minus[motor] -= h;
        let (a, b) = (sense(&plus), sense(&minus));
        a.iter()
            .zip(&b)
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect::<Vec<_>>()
    };
    let mut checked = 0;
    for motor in 0..2 {
        let d = [1e-2, 1e-3, 1e-4].map(|h| derivative(motor, h));
        for pixel in 0..k {
            let (coarse, fine) = (
                (d[0][pixel] - d[1][pixel]).abs(),
                (d[1][pixel] - d[2][pixel]).abs(),
            );
            // Central differences converge as h²: each tenfold step cuts the change a
            // hundredfold where the image is smooth. A pixel whose footprint crosses a
            // corner of the room within 1e-2 rad may not: count the others.
            if fine <= 0.05 * coarse + 1e-8 {
                checked += 1;
            }
            assert!(d[2][pixel].is_finite());
        }
    }
    assert!(
        checked as f64 >= 0.9 * (2 * k) as f64,
        "{checked} of {} converge",
        2 * k
    );
}

#[test]
fn bad_scenes_are_named_with_their_key_and_value() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("environment.json");
    let load = |text: &str| {
        std::fs::write(&path, text).unwrap();
        Environment::load(&path).map_err(|e| e.to_string())
    };
    let err =
        load(r#"{"scene": {"primitives": [{"kind": "cone", "color": [1, 1, 1]}]}}"#).unwrap_err();
    assert!(
        err.contains("kind = \"cone\"") && err.contains("wall, box, sphere, disc"),
        "{err}"
    );
    let err = load(
        r#"{"scene": {"primitives": [{"kind": "sphere", "center": [1, 0, 0], "radius": -0.5, "color": [1, 1, 1]}]}}"#,
    )
    .unwrap_err();
    assert!(
        err.contains("scene.primitives") && err.contains("radius = -0.5"),
        "{err}"
    );
    let err = load(
        r#"{"scene": {"primitives": [{"kind": "disc", "center": [1, 0, 0], "normal": [0, 0, 0], "radius": 1, "color": [1, 1, 1]}]}}"#,
    )
    .unwrap_err();
    assert!(
        err.contains("normal = [0.0, 0.0, 0.0]") && err.contains("disc"),
        "{err}"
    );
    let err = load(
        r#"{"scene": {"primitives": [{"kind": "wall", "point": [1, 0, 0], "normal": [1, 0, 0], "color": [1, 1, 1], "colour": 2}]}}"#,
    )
    .unwrap_err();
    assert!(err.contains("colour"), "{err}");
    let err = load(r#"{"lights": []}"#).unwrap_err();
    assert!(err.contains("no lights"), "{err}");
    // A scene without lights is an environment, and it round-trips.
    let environment = room();
    environment.save(&path).unwrap();
    assert_eq!(Environment::load(&path).unwrap(), environment);
    // Old files without a scene keep working.
    let lights = load(r#"{"lights": [[1.0, 2.0]]}"#).unwrap();
    assert!(lights.scene.is_none());
}

#[test]
fn a_camera_needs_a_scene_and_a_valid_body() {
    let camera = camera_3d(8, 6, "grey");
    let lights = Environment::from_lights_3d(vec![[1.0, 2.0, 3.0]]);
    let err = lights.check_for(camera.as_ref()).unwrap_err().to_string();
    assert!(err.contains("camera") && err.contains("has none"), "{err}");
    let build = |body: &str| {
        toml::from_str::<AgentConfig>(&format!("kind = \"chain\"\n{body}"))
            .unwrap()
            .build()
            .unwrap_err()
            .to_string()
    };
    let planar = "joints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }]\n";
    let err = build(&format!("{planar}[camera]\nfov = 3.5"));
    assert!(err.contains("camera.fov = 3.5"), "{err}");
    let err = build(&format!("{planar}[camera]\nwidth = 1000000000"));
    assert!(err.contains("width = 1000000000"), "{err}");
    let err = build(&format!("{planar}[camera]\ncolor = \"infrared\""));
    assert!(err.contains("infrared"), "{err}");
    let err = build(&format!("{planar}[camera]\nwidth = 8\n[retina]\ncells = 4"));
    assert!(err.contains("not both"), "{err}");
}

#[test]
fn the_ground_truth_is_the_chains_pose_and_the_resolved_table_has_no_retina() {
    let config: AgentConfig = toml::from_str(
        "kind = \"chain\"\njoints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }, { axis = [0, 1, 0], link = [0.5, 0, 0] }]\n[camera]\nwidth = 8\nheight = 4",
    )
    .unwrap();
    let built = smspace::agent::AgentRegistry::builtin()
        .build(&config)
        .unwrap();
    assert!(built.config.params.contains_key("camera"));
    assert!(!built.config.params.contains_key("retina"));
    let retina: AgentConfig = toml::from_str(
        "kind = \"chain\"\njoints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }, { axis = [0, 1, 0], link = [0.5, 0, 0] }]\n[retina]\ncells = [2, 2]",
    )
    .unwrap();
    let retina = retina.build().unwrap();
    let m = [0.3, -0.4];
    let (mut a, mut b) = ([0.0; 7], [0.0; 7]);
    built.agent.ground_truth().unwrap().pose(&m, &mut a);
    retina.ground_truth().unwrap().pose(&m, &mut b);
    assert_eq!(a, b);
}

#[test]
fn images_are_identical_for_any_number_of_threads() {
    let camera = camera_3d(32, 24, "rgb");
    let environment = room();
    let motors = ndarray::Array2::from_shape_fn((40, 2), |(i, j)| {
        0.05 * i as f64 * if j == 0 { 1.0 } else { -0.3 }
    });
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| sense_rows(camera.as_ref(), &environment, motors.view()).unwrap());
    let many = sense_rows(camera.as_ref(), &environment, motors.view()).unwrap();
    assert_eq!(one, many);
    // The batch is the frames one by one, also from a transposed (strided) array.
    let mut single = vec![0.0; camera.sensor_dim()];
    for (m, row) in motors.outer_iter().zip(many.outer_iter()) {
        camera.sense(&environment, m.as_slice().unwrap(), &mut single);
        assert_eq!(row.as_slice().unwrap(), &single[..]);
    }
    let transposed = motors.t().to_owned();
    assert_eq!(
        sense_rows(camera.as_ref(), &environment, transposed.t()).unwrap(),
        many
    );
}

#[test]
fn an_environment_table_gives_a_camera_its_textured_room_and_a_retina_its_lights() {
    use smspace::agent::EnvironmentConfig;
    let camera = strip(32, 1.2);
    // By default: a room around the agent's light region, seeded, that the camera sees.
    let built = EnvironmentConfig::default().build(camera.as_ref()).unwrap();
    assert!(built.scene.is_some() && built.lights.is_empty());
    built.check_for(camera.as_ref()).unwrap();
    let again = EnvironmentConfig::default().build(camera.as_ref()).unwrap();
    assert_eq!(built, again);
    let other = EnvironmentConfig {
        seed: 2,
        ..EnvironmentConfig::default()
    }
    .build(camera.as_ref())
    .unwrap();
    assert_ne!(built.scene, other.scene);
    // A room of the size given; a size that is not positive is named.
    let sized = EnvironmentConfig {
        room: Some([6.0, 6.0, 4.0]),
        ..EnvironmentConfig::default()
    }
    .build(camera.as_ref())
    .unwrap();
    assert_eq!(sized.scene, Some(Scene::textured_room([6.0, 6.0, 4.0], 1)));
    let error = EnvironmentConfig {
        room: Some([6.0, -1.0, 4.0]),
        ..EnvironmentConfig::default()
    }
    .build(camera.as_ref())
    .unwrap_err()
    .to_string();
    assert!(error.contains("room") && error.contains("-1"), "{error}");
    // A retina's environment is lights; a room there is refused.
    let retina = chain("joints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }]\n[retina]\ncells = 4");
    let lights = EnvironmentConfig::default().build(retina.as_ref()).unwrap();
    assert!(lights.scene.is_none() && !lights.lights.is_empty());
    let error = EnvironmentConfig {
        room: Some([6.0, 6.0, 4.0]),
        ..EnvironmentConfig::default()
    }
    .build(retina.as_ref())
    .unwrap_err()
    .to_string();
    assert!(error.contains("room"), "{error}");
}

#[test]
fn a_planar_arms_image_has_rows_and_depends_on_the_cameras_pose_in_the_plane_only() {
    // The paper's arm as a chain (3 unit links on z hinges, the camera's hinge) with a
    // 32 × 24 image: its rows look above and below the arm's plane.
    let arm = chain(
        "joints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }, { axis = [0, 0, 1], link = [1.0, 0, 0] }, \
         { axis = [0, 0, 1], link = [1.0, 0, 0] }, { axis = [0, 0, 1], link = [0, 0, 0] }]\n\
         [camera]\nwidth = 32\nheight = 24\nfov = 1.2",
    );
    assert_eq!(arm.sensor_dim(), 32 * 24);
    let environment = Environment::from_scene(Scene::textured_room([8.0, 8.0, 4.0], 3));
    environment.check_for(arm.as_ref()).unwrap();
    let image = |m: &[f64]| {
        let mut s = vec![0.0; arm.sensor_dim()];
        arm.sense(&environment, m, &mut s);
        s
    };
    let m = [0.4, 0.9, -0.7, 0.3];
    let seen = image(&m);
    let row = |r: usize| &seen[r * 32..(r + 1) * 32];
    let change: f64 = row(0).iter().zip(row(23)).map(|(a, b)| (a - b).abs()).sum();
    assert!(change > 0.1, "the top and bottom rows differ: {change}");
    // The other elbow of the first two links reaches the same wrist; the third link
    // keeps its direction: the same pose, the same image.
    let (l1, l2) = (1.0_f64, 1.0_f64);
    let flipped1 = m[0] + 2.0 * (l2 * m[1].sin()).atan2(l1 + l2 * m[1].cos());
    let flipped = [flipped1, -m[1], m[0] + m[1] + m[2] - flipped1 + m[1], m[3]];
    let pose = |m: &[f64]| {
        let mut p = [0.0; 3];
        arm.ground_truth().unwrap().pose(m, &mut p);
        p
    };
    let (a, b) = (pose(&m), pose(&flipped));
    for (x, y) in a.iter().zip(&b) {
        assert_abs_diff_eq!(x, y, epsilon = 1e-12);
    }
    let other = image(&flipped);
    for (x, y) in seen.iter().zip(&other) {
        assert_abs_diff_eq!(x, y, epsilon = 1e-9);
    }
    // A different pose, a different image.
    let moved = image(&[0.5, 0.9, -0.7, 0.3]);
    assert!(seen.iter().zip(&moved).any(|(x, y)| (x - y).abs() > 1e-3));
}

#[test]
fn a_camera_that_keeps_its_direction_sees_its_position_only() {
    // Two links and the camera's hinge (no link): turning the last hinge turns a camera
    // carried by the chain, and leaves one that keeps its world direction as it was.
    let joints = "joints = [{ axis = [0, 0, 1], link = [1.0, 0, 0] }, { axis = [0, 0, 1], link = [1.0, 0, 0] }, \
                  { axis = [0, 0, 1], link = [0, 0, 0] }]\n";
    let camera = "[camera]\nwidth = 16\nheight = 16\nfov = 0.785\ncolor = \"rgb\"\n";
    let fixed = chain(&format!("{joints}{camera}direction = [0.8139, 0, -0.5810]"));
    let carried = chain(&format!("{joints}{camera}"));
    let environment =
        Environment::from_scene(Scene::furnished_room([7.0, 7.0, 3.2], 16, 1).unwrap());
    environment.check_for(fixed.as_ref()).unwrap();
    let image = |agent: &dyn Agent, m: &[f64]| {
        let mut s = vec![0.0; agent.sensor_dim()];
        agent.sense(&environment, m, &mut s);
        s
    };
    let (m, turned) = ([0.3, 0.8, -0.2], [0.3, 0.8, 1.1]);
    assert_eq!(image(fixed.as_ref(), &m), image(fixed.as_ref(), &turned));
    let (a, b) = (
        image(carried.as_ref(), &m),
        image(carried.as_ref(), &turned),
    );
    assert!(a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 1e-2));
    let moved = image(fixed.as_ref(), &[0.4, 0.8, -0.2]);
    assert!(image(fixed.as_ref(), &m)
        .iter()
        .zip(&moved)
        .any(|(x, y)| (x - y).abs() > 1e-2));
    // Looking along +x with the image upright is the carried camera at orientation 0.
    let level = chain(&format!("{joints}{camera}direction = [2, 0, 0]"));
    let home = [0.5, -1.0, 0.5];
    for (x, y) in image(level.as_ref(), &home)
        .iter()
        .zip(&image(carried.as_ref(), &home))
    {
        assert_abs_diff_eq!(x, y, epsilon = 1e-9);
    }
    // The pose is the position (x, y); its Jacobian the chain's first two rows.
    let truth = fixed.ground_truth().unwrap();
    let names: Vec<_> = truth
        .pose_space()
        .coordinates()
        .iter()
        .map(|c| c.name.clone())
        .collect();
    assert_eq!(names, ["x", "y"]);
    assert_eq!(truth.configuration_dim(), 2);
    let (mut jacobian, mut pose) = (vec![0.0; 2 * 3], [0.0; 2]);
    truth.pose_jacobian(&m, &mut jacobian, &mut pose);
    let (x, y) = (0.3_f64.cos() + 1.1_f64.cos(), 0.3_f64.sin() + 1.1_f64.sin());
    assert_abs_diff_eq!(pose[0], x, epsilon = 1e-12);
    assert_abs_diff_eq!(pose[1], y, epsilon = 1e-12);
    let expected = [-y, -(1.1_f64.sin()), 0.0, x, 1.1_f64.cos(), 0.0];
    for (j, e) in jacobian.iter().zip(expected) {
        assert_abs_diff_eq!(*j, e, epsilon = 1e-12);
    }
    // A vertical or zero direction has no upright image.
    for bad in ["[0, 0, -1]", "[0, 0, 0]"] {
        let config: AgentConfig = toml::from_str(&format!(
            "kind = \"chain\"\n{joints}{camera}direction = {bad}"
        ))
        .unwrap();
        let err = config.build().unwrap_err().to_string();
        assert!(
            err.contains("camera.direction") && err.contains("vertical"),
            "{err}"
        );
    }
}

#[test]
fn a_furnished_room_is_seeded_with_objects_apart_on_its_floor() {
    let size = [7.0, 7.0, 3.2];
    let scene = Scene::furnished_room(size, 16, 4).unwrap();
    assert_eq!(scene, Scene::furnished_room(size, 16, 4).unwrap());
    assert_ne!(scene, Scene::furnished_room(size, 16, 5).unwrap());
    assert_eq!(scene.primitives.len(), 17);
    scene.check().unwrap();
    assert_eq!(
        Scene::furnished_room(size, 0, 4).unwrap(),
        Scene::textured_room(size, 4)
    );
    // Each object's footprint on the floor: centre and half side.
    let footprints: Vec<([f64; 2], f64)> = scene.primitives[1..]
        .iter()
        .map(|p| match p {
            Primitive::Box(b) => {
                assert_abs_diff_eq!(b.center[2] - 0.5 * b.size[2], -1.6, epsilon = 1e-12);
                ([b.center[0], b.center[1]], 0.5 * b.size[0])
            }
            Primitive::Sphere(s) => {
                assert_abs_diff_eq!(s.center[2] - s.radius, -1.6, epsilon = 1e-12);
                ([s.center[0], s.center[1]], s.radius)
            }
            other => panic!("unexpected {}", other.kind()),
        })
        .collect();
    for (i, (c, r)) in footprints.iter().enumerate() {
        assert!(c[0].abs() + r < 3.5 && c[1].abs() + r < 3.5);
        assert_abs_diff_eq!(*r, 0.5 * 0.51 * 2.0 * 0.356 * 7.0 / 3.0, epsilon = 1e-12);
        for (d, s) in &footprints[i + 1..] {
            let gap = (c[0] - d[0]).abs().max((c[1] - d[1]).abs()) - r - s;
            assert!(gap > 0.1, "objects {c:?} and {d:?} {gap} apart");
        }
    }
    let err = Scene::furnished_room(size, 1000, 1)
        .unwrap_err()
        .to_string();
    assert!(err.contains("objects = 1000"), "{err}");
    // Objects stand in a camera's room only.
    let lights: smspace::agent::EnvironmentConfig = toml::from_str("objects = 3").unwrap();
    let arm = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let err = lights.build(arm.as_ref()).unwrap_err().to_string();
    assert!(
        err.contains("objects = 3") && err.contains("lights"),
        "{err}"
    );
}

#[test]
fn the_piece_search_through_images_is_seen_to_miss_pieces() {
    // Three segments of 0.5 and a camera that keeps its direction: within 0.5 of the
    // base the arm reaches a position in two loops (elbow up and down). From images the
    // projections of the search rarely land on the second: the landings on the pieces
    // found estimate how often it is missed, and the summary says so.
    use smspace::kernel::{trace_sets, Components, TraceMethod, TraceParams};
    let arm = chain(
        "joints = [{ axis = [0, 0, 1], link = [0.5, 0, 0] }, { axis = [0, 0, 1], link = [0.5, 0, 0] }, \
         { axis = [0, 0, 1], link = [0.5, 0, 0] }]\n\
         [camera]\nwidth = 12\nheight = 12\nfov = 0.7854\ndirection = [0.8139, 0.0, -0.5810]",
    );
    let environment =
        Environment::from_scene(Scene::furnished_room([7.0, 7.0, 3.2], 16, 1).unwrap());
    let count = 40;
    let motors = ndarray::Array2::from_shape_fn((count, 3), |(i, j)| {
        // The end at distance r and bearing b, the first segment at angle a.
        let (r, b, a) = (
            0.1 + 0.3 * i as f64 / count as f64,
            0.9 * i as f64,
            2.1 * i as f64,
        );
        let (px, py) = (r * b.cos() - 0.5 * a.cos(), r * b.sin() - 0.5 * a.sin());
        let d = (px * px + py * py).sqrt();
        let elbow = ((d * d - 0.5) / 0.5).clamp(-1.0, 1.0).acos();
        let second = py.atan2(px) - (0.5 * elbow.sin()).atan2(0.5 + 0.5 * elbow.cos());
        [a, second - a, elbow][j]
    });
    let params = TraceParams {
        method: TraceMethod::Sensory,
        components: Components::All,
        piece_starts: 24,
        points: 20,
        ..TraceParams::default()
    };
    let traced = trace_sets(
        arm.as_ref(),
        Some(&environment),
        motors.view(),
        None,
        &params.check().unwrap(),
        &smspace::progress::Silent,
    )
    .unwrap();
    let summary = &traced.report.summary;
    let missed = 1.0 - summary.with_several_pieces as f64 / summary.traced as f64;
    let search = summary.piece_search.unwrap();
    eprintln!(
        "{} traced, missed {missed}, estimated {search:?}",
        summary.traced
    );
    assert!(summary.traced >= count - 2);
    assert!(missed > 0.3, "{missed}");
    assert!(
        search.miss_probability >= missed - 0.15,
        "estimated {search:?} against {missed}"
    );
    let warnings = summary.warnings();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("piece_starts") && w.contains("break into parts")),
        "{warnings:?}"
    );
}
