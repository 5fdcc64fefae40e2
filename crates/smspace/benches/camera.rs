//! How fast a camera renders: frames per second of [`Agent::sense_batch`] for a 3-D
//! camera of 32 × 24 pixels (grey and rgb) and a strip of 32 pixels in a textured room
//! (one box, 6 waves; and with 1 wave, the cost of the geometry) and in the same room
//! with a sphere and a disc in it, on the
//! default rayon pool (set `RAYON_NUM_THREADS` to change it).
//!
//! ```text
//! cargo bench -p smspace --bench camera
//! SMSPACE_BENCH_FRAMES=100000 cargo bench -p smspace --bench camera
//! ```
//!
//! `SMSPACE_BENCH_FRAMES` sets the frames per batch (default 20000); each case runs
//! three batches and reports the best.

use std::time::Instant;

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::agent::{
    Agent, AgentConfig, Disc, Environment, Primitive, Scene, Sphere, Texture, Wave,
};

fn camera(body: &str) -> Box<dyn Agent> {
    let config: AgentConfig =
        toml::from_str(&format!("kind = \"chain\"\n{body}")).expect("a valid camera table");
    config.build().expect("a valid camera")
}

fn main() {
    let frames: usize = std::env::var("SMSPACE_BENCH_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000);
    let arm = "joints = [{ axis = [0, 0, 1], link = [0.5, 0, 0] }, { axis = [0, 1, 0], link = [0.5, 0, 0], range = [-1.0, 1.0] }]";
    let cases = [
        ("32 × 24 grey", format!("{arm}\n[camera]\nwidth = 32\nheight = 24\nfov = 1.2")),
        (
            "32 × 24 rgb",
            format!("{arm}\n[camera]\nwidth = 32\nheight = 24\nfov = 1.2\ncolor = \"rgb\""),
        ),
        (
            "32 strip grey",
            "joints = [{ axis = [0, 0, 1], link = [0.5, 0, 0] }, { axis = [0, 0, 1], link = [0.5, 0, 0] }]\n[camera]\nwidth = 32".to_owned(),
        ),
    ];
    let room = Scene::textured_room([6.0, 6.0, 4.0], 7);
    let mut furnished = room.clone();
    furnished.primitives.push(Primitive::Sphere(Sphere {
        center: [2.0, 1.0, 0.2],
        radius: 0.6,
        color: [0.9, 0.3, 0.1],
        texture: Some(Texture::Waves(vec![Wave {
            direction: [1.0, 1.0, 0.0],
            wavelength: 0.4,
            amplitude: smspace::agent::Amplitude::Grey(0.1),
            phase: 0.0,
        }])),
    }));
    furnished.primitives.push(Primitive::Disc(Disc {
        center: [-2.0, -1.5, 0.0],
        normal: [1.0, 0.5, 0.0],
        radius: 0.8,
        color: [0.1, 0.4, 0.8],
        texture: None,
    }));
    let mut plain = room.clone();
    if let Primitive::Box(walls) = &mut plain.primitives[0] {
        // Not uniform: a camera must see something; one wave is the least texture.
        walls.texture = Some(Texture::Waves(vec![Wave {
            direction: [1.0, 0.3, 0.2],
            wavelength: 2.0,
            amplitude: smspace::agent::Amplitude::Grey(0.1),
            phase: 0.0,
        }]));
    }
    let threads = rayon::current_num_threads();
    println!("{frames} frames per batch, {threads} threads");
    let scenes = [
        ("room, 1 wave", plain),
        ("room", room),
        ("room + sphere + disc", furnished),
    ];
    for (scene_name, scene) in scenes {
        let environment = Environment::from_scene(scene);
        for (name, body) in &cases {
            let agent = camera(body);
            environment
                .check_for(agent.as_ref())
                .expect("the camera sees the room");
            let mut rng = ChaCha8Rng::seed_from_u64(1);
            let motors =
                Array2::from_shape_fn((frames, agent.motor_dim()), |_| rng.random_range(-1.0..1.0));
            let mut sensors = Array2::zeros((frames, agent.sensor_dim()));
            let mut best = f64::INFINITY;
            for _ in 0..3 {
                let start = Instant::now();
                agent.sense_batch(&environment, motors.view(), sensors.view_mut());
                best = best.min(start.elapsed().as_secs_f64());
            }
            let checksum: f64 = sensors.iter().sum();
            println!(
                "{scene_name:>22} | {name:>14}: {:>10.0} frames/s ({:.2} µs/frame, {:.1} ns/pixel; checksum {checksum:.6e})",
                frames as f64 / best,
                1e6 * best / frames as f64,
                1e9 * best * threads as f64 / (frames * agent.sensor_dim()) as f64,
            );
        }
    }
}
