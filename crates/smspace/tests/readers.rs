//! The readers of user files never panic: experiment TOML, `--set` overrides and
//! environment JSON, fed arbitrary and mutated text (seeded proptest). Each input ends
//! in a value or an error, and a valid experiment goes on to `pipeline::check`, which
//! validates every table before anything runs.

use proptest::prelude::*;
use smspace::agent::Environment;
use smspace::config::load_experiment;

/// A small valid experiment whose lines the mutations below rearrange and corrupt.
const BASE: &str = r#"name = "fuzz"

[agent]
kind = "planar-arm"
retina_cells = 6

[environment]
seed = 1
lights = 10

[exploration]
n = 20
probes = "grid"
probe_positions = 2
probe_orientations = 2

[kernel]
points = 30
method = "kinematic"

[metric]
metric = "curve"

[embedding]
method = "mds"
dim = 2

[analysis]
max_points = 50
"#;

/// Keys and values that the mutations splice in: real keys with wrong types, huge or
/// negative numbers, unknown names, broken syntax.
const PIECES: [&str; 16] = [
    "n = 1000000000000",
    "points = -3",
    "lights = 0",
    "dim = 1e308",
    "method = \"tsne\"",
    "kind = \"octopus\"",
    "[kernel",
    "= 3",
    "retina_cells = []",
    "probe_positions = 18446744073709551615",
    "metric = { a = 1 }",
    "seed = \"x\"",
    "name = \"../../etc\"",
    "\u{0}",
    "[[environment.compare]]",
    "period = \"3pi\"",
];

/// `text` in a new file `name` of a new temporary folder (kept alive by the guard).
fn in_file(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

fn mutated() -> impl Strategy<Value = String> {
    let lines: Vec<String> = BASE.lines().map(str::to_owned).collect();
    let count = lines.len();
    prop::collection::vec((0..count, 0..PIECES.len(), 0u8..4), 0..6).prop_map(move |edits| {
        let mut lines = lines.clone();
        for (at, piece, how) in edits {
            let at = at.min(lines.len().saturating_sub(1));
            match how {
                0 => lines.insert(at, PIECES[piece].to_owned()),
                1 if !lines.is_empty() => lines[at] = PIECES[piece].to_owned(),
                2 if !lines.is_empty() => {
                    lines.remove(at);
                }
                _ => {
                    let other = (at * 7 + piece) % count.min(lines.len()).max(1);
                    if other < lines.len() {
                        lines.swap(at, other);
                    }
                }
            }
        }
        lines.join("\n")
    })
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 192,
        rng_seed: prop::test_runner::RngSeed::Fixed(19),
        ..ProptestConfig::default()
    })]

    #[test]
    fn experiment_files_give_a_value_or_an_error(text in prop_oneof![mutated(), ".{0,300}"]) {
        let (_dir, path) = in_file("e.toml", &text);
        if let Ok(loaded) = load_experiment(&path, &[]) {
            let _ = smspace::pipeline::check(&loaded);
        }
    }

    #[test]
    fn overrides_give_a_value_or_an_error(
        set in prop_oneof![
            "(exploration|kernel|metric|agent|environment|embedding)\\.[a-z_]{1,12}=[-0-9a-z\"\\[\\].e]{0,20}",
            ".{0,40}",
        ]
    ) {
        let (_dir, path) = in_file("e.toml", BASE);
        if let Ok(loaded) = load_experiment(&path, &[set]) {
            let _ = smspace::pipeline::check(&loaded);
        }
    }

    #[test]
    fn environment_files_give_a_value_or_an_error(
        text in prop_oneof![
            "\\{\"lights\": \\[(\\[[-0-9.e]{1,8}, ?[-0-9.e]{1,8}\\],? ?){0,4}\\]( ?, ?\"seed\": [0-9]{1,3})?\\}",
            ".{0,120}",
        ]
    ) {
        let (_dir, path) = in_file("env.json", &text);
        if let Ok(env) = Environment::load(&path) {
            prop_assert!(!env.lights.is_empty());
            prop_assert!(env.lights.iter().all(|l| l[0].is_finite() && l[1].is_finite()));
        }
    }
}

#[test]
fn the_base_experiment_is_valid() {
    // So that the mutations start from a file that passes every check.
    let (_dir, path) = in_file("e.toml", BASE);
    let loaded = load_experiment(&path, &[]).unwrap();
    smspace::pipeline::check(&loaded).unwrap();
}
