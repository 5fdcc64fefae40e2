//! `smspace env|explore|trace|sense --agent FILE` with kinematic chains (issue 14),
//! bad chain files and environments of the wrong dimension included.

mod common;

use std::path::PathBuf;

use ndarray::{Array2, Array3};
use ndarray_npy::read_npy;

use common::{fails, ok};

const ARM_3D: &str = r#"
[agent]
kind = "chain"
joints = [
    { axis = [0, 0, 1], link = [0, 0, 0.5] },
    { axis = [0, 1, 0], link = [1.0, 0, 0] },
    { axis = [1, 0, 0], link = [0, 0, 0] },
    { axis = [0, 1, 0], link = [1.0, 0, 0] },
    { axis = [1, 0, 0], link = [0, 0, 0] },
    { axis = [0, 1, 0], link = [0.5, 0, 0], range = [-2.5, 2.5] },
    { axis = [0, 0, 1], link = [0, 0, 0] },
]
[agent.retina]
cells = [4, 4]
half_width = 1.0
focal_length = 1.0

[environment]
lights = 12
seed = 2
"#;

fn temp() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().to_owned();
    (dir, path)
}

#[test]
fn a_3d_chain_file_explores_traces_and_senses() {
    let (_guard, dir) = temp();
    std::fs::write(dir.join("arm3d.toml"), ARM_3D).unwrap();
    ok(&dir, &["env", "--agent", "arm3d.toml", "--out", "e.json"]);
    let env: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("e.json")).unwrap()).unwrap();
    let lights = env["lights"].as_array().unwrap();
    assert_eq!(lights.len(), 12);
    assert!(lights.iter().all(|l| l.as_array().unwrap().len() == 3));
    ok(
        &dir,
        &[
            "explore",
            "--agent",
            "arm3d.toml",
            "--n",
            "6",
            "--out-dir",
            "run",
        ],
    );
    let motors: Array2<f64> = read_npy(dir.join("run/motors.npy")).unwrap();
    let poses: Array2<f64> = read_npy(dir.join("run/poses.npy")).unwrap();
    assert_eq!((motors.dim(), poses.dim()), ((6, 7), (6, 7)));
    assert!(motors.column(5).iter().all(|m| m.abs() <= 2.5));
    ok(
        &dir,
        &[
            "trace",
            "--agent",
            "arm3d.toml",
            "--motors",
            "run/motors.npy",
            "--method",
            "kinematic",
            "--points",
            "12",
            "--out",
            "run/sets.npy",
        ],
    );
    let sets: Array3<f64> = read_npy(dir.join("run/sets.npy")).unwrap();
    assert_eq!((sets.dim().1, sets.dim().2), (12, 7));
    assert!(sets.dim().0 >= 1);
    ok(
        &dir,
        &[
            "sense",
            "--agent",
            "arm3d.toml",
            "--motors",
            "run/motors.npy",
            "--env",
            "e.json",
            "--out",
            "s.npy",
        ],
    );
    let s: Array2<f64> = read_npy(dir.join("s.npy")).unwrap();
    assert_eq!(s.dim(), (6, 16));
    assert!(s.iter().all(|v| v.is_finite() && *v >= 0.0));
    // Lights in a volume are not for a planar agent, and planar lights not for a 3-D
    // chain.
    let err = fails(
        &dir,
        &[
            "sense",
            "--agent",
            "planar-arm",
            "--motors",
            "run/motors.npy",
            "--env",
            "e.json",
            "--out",
            "t.npy",
        ],
    );
    assert!(err.contains("e.json") && err.contains("[x, y]"), "{err}");
    std::fs::write(dir.join("flat.json"), r#"{"lights": [[1.0, 2.0]]}"#).unwrap();
    let err = fails(
        &dir,
        &[
            "sense",
            "--agent",
            "arm3d.toml",
            "--motors",
            "run/motors.npy",
            "--env",
            "flat.json",
            "--out",
            "t.npy",
        ],
    );
    assert!(
        err.contains("flat.json") && err.contains("[x, y, z]"),
        "{err}"
    );
}

#[test]
fn bad_chain_files_name_the_joint_and_the_key() {
    let (_guard, dir) = temp();
    let cases = [
        (
            ARM_3D.replace(
                "axis = [1, 0, 0], link = [0, 0, 0] },\n    { axis = [0, 1, 0], link = [0.5",
                "axis = [0, 0, 0], link = [0, 0, 0] },\n    { axis = [0, 1, 0], link = [0.5",
            ),
            vec!["joint 4", "axis"],
        ),
        (
            ARM_3D.replace("range = [-2.5, 2.5]", "range = [2.5, -2.5]"),
            vec!["joint 5", "range"],
        ),
        (
            ARM_3D.replace("range = [-2.5, 2.5]", "rnage = [2.5, -2.5]"),
            vec!["joint 5", "rnage"],
        ),
        (
            ARM_3D.replace("link = [0.5, 0, 0]", "link = [nan, 0, 0]"),
            vec!["joint 5", "link"],
        ),
        (
            ARM_3D.replace("cells = [4, 4]", "cells = 0"),
            vec!["retina.cells"],
        ),
        (
            ARM_3D.replace("half_width = 1.0", "half_width = 0.0"),
            vec!["retina.half_width"],
        ),
    ];
    for (i, (text, needles)) in cases.iter().enumerate() {
        let file = format!("bad{i}.toml");
        std::fs::write(dir.join(&file), text).unwrap();
        let err = fails(
            &dir,
            &["explore", "--agent", &file, "--n", "2", "--out-dir", "x"],
        );
        for needle in needles {
            assert!(err.contains(needle), "case {i}: {err}");
        }
    }
}

#[test]
fn a_3d_chain_with_a_bounded_joint_runs_end_to_end() {
    let (_guard, dir) = temp();
    let experiment = format!(
        "name = \"arm3d\"\n{ARM_3D}\n[exploration]\nn = 40\nseed = 1\n\n[kernel]\nmethod = \"kinematic\"\npoints = 20\n\n[metric]\nmetric = \"curve\"\nperiod = \"motors\"\n\n[embedding]\nmethod = \"mds\"\ndim = 3\n\n[report]\nformats = \"png\"\nsample_configurations = 4\nsample_sets = 3\n"
    );
    std::fs::write(dir.join("arm3d.toml"), &experiment).unwrap();
    // A uniform period cannot describe the bounded wrist: refused, naming the fix.
    std::fs::write(
        dir.join("uniform.toml"),
        experiment.replace("period = \"motors\"", "period = \"2pi\""),
    )
    .unwrap();
    let text = fails(&dir, &["run", "uniform.toml", "--out", "u"]);
    assert!(text.contains("period = \"motors\""), "{text}");
    ok(&dir, &["run", "arm3d.toml", "--out", "run"]);
    let run = dir.join("run");
    // The wrist's joint is not wrapped, the hinges are.
    let resolved: String = std::fs::read_to_string(run.join("config.resolved.toml"))
        .unwrap()
        .split_whitespace()
        .collect();
    assert!(
        resolved.contains(r#"period=["2pi","2pi","2pi","2pi","2pi","none","2pi",]"#)
            || resolved.contains(r#"period=["2pi","2pi","2pi","2pi","2pi","none","2pi"]"#),
        "{resolved}"
    );
    // The pose figures are drawn from above, and say so.
    let report = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(report.contains("seen from above"), "{report}");
    assert!(run.join("figures/fig5a-configurations.png").is_file());
    assert!(run.join("figures/embedding-pose.png").is_file());
    // `analyze --poses` reads the 3-D poses (M, 7) of the kept sets.
    let poses: Array2<f64> = read_npy(run.join("poses.npy")).unwrap();
    let kept: ndarray::Array1<i64> = read_npy(run.join("sets.kept.npy")).unwrap();
    let rows: Vec<usize> = kept.iter().map(|&k| k as usize).collect();
    let kept_poses = poses.select(ndarray::Axis(0), &rows);
    assert_eq!(kept_poses.ncols(), 7);
    ndarray_npy::write_npy(dir.join("p7.npy"), &kept_poses).unwrap();
    ok(
        &dir,
        &[
            "analyze",
            "--distances",
            "run/D.npy",
            "--poses",
            "p7.npy",
            "--out",
            "a.json",
        ],
    );
    let analysis: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("a.json")).unwrap()).unwrap();
    assert!(
        analysis["agreement"]["trustworthiness"].is_number(),
        "{analysis}"
    );
    let five = kept_poses.select(ndarray::Axis(1), &[0, 1, 2, 3, 4]);
    ndarray_npy::write_npy(dir.join("p5.npy"), &five).unwrap();
    let text = fails(
        &dir,
        &["analyze", "--distances", "run/D.npy", "--poses", "p5.npy"],
    );
    assert!(
        text.contains("5 columns") && text.contains("(M, 7)"),
        "{text}"
    );
}
