//! Traces the same arm starts with the kinematic and the sensory method and compares
//! them set by set (largest point distance on the torus), per status.
//!
//! `cargo run --release -p smspace --example compare_methods -- [n] [env-seed] [lights]`
use smspace::agent::{AgentConfig, EnvironmentConfig, MotorSpace};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{trace_sets, TraceMethod, TraceParams};
use smspace::progress::Silent;

fn main() -> Result<(), smspace::Error> {
    let args: Vec<String> = std::env::args().collect();
    let n = args.get(1).map_or(500, |s| s.parse().expect("n"));
    let env_seed = args.get(2).map_or(1, |s| s.parse().expect("seed"));
    let lights = args.get(3).map(|s| s.parse().expect("lights"));
    let agent = AgentConfig::preset("planar-arm")?.build()?;
    let environment = EnvironmentConfig {
        seed: env_seed,
        lights,
        ..EnvironmentConfig::default()
    }
    .build(agent.as_ref())?;
    let e = explore(
        agent.as_ref(),
        &ExploreParams {
            n,
            ..ExploreParams::default()
        },
    )?;
    let run = |method| {
        let params = TraceParams {
            method,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        trace_sets(
            agent.as_ref(),
            Some(&environment),
            e.motors.view(),
            e.workspace.as_ref(),
            &params,
            &Silent,
        )
        .unwrap()
    };
    let k = run(TraceMethod::Kinematic);
    let s = run(TraceMethod::Sensory);
    println!(
        "kinematic {:?}\nsensory   {:?}",
        k.report.summary.by_status, s.report.summary.by_status
    );
    let mut worst: f64 = 0.0;
    let mut over = 0;
    for (si, &row) in s.kept.iter().enumerate() {
        let Ok(ki) = k.kept.binary_search(&row) else {
            continue;
        };
        let (a, b) = (
            k.sets.index_axis(ndarray::Axis(0), ki),
            s.sets.index_axis(ndarray::Axis(0), si),
        );
        let mut d: f64 = 0.0;
        for (pa, pb) in a.outer_iter().zip(b.outer_iter()) {
            d = d.max(
                MotorSpace::hinges(pa.len())
                    .distance(pa.as_slice().unwrap(), pb.as_slice().unwrap()),
            );
        }
        if d > 1e-3 {
            over += 1;
            let (kr, sr) = (&k.report.sets[row], &s.report.sets[row]);
            if over <= 5 {
                println!(
                    "row {row}: max distance {d:.3e}, lengths {:.4} vs {:.4}, pose {:?}",
                    kr.length,
                    sr.length,
                    e.planar_poses().map(|p| p.row(row).to_vec())
                );
            }
        }
        worst = worst.max(d);
    }
    println!("sets differing by more than 1e-3: {over}; largest pointwise distance {worst:.3e}");
    for r in s
        .report
        .sets
        .iter()
        .filter(|r| !r.status.is_traced())
        .take(8)
    {
        println!(
            "failed row {}: {:?} after {} steps, pose {:?}",
            r.index,
            r.status,
            r.steps,
            e.planar_poses().map(|p| p.row(r.index).to_vec())
        );
    }
    println!("lights {:?}", environment.lights);
    Ok(())
}
