//! The readers of user files never panic: experiment TOML, `--set` overrides,
//! environment JSON and `.npy` arrays, fed arbitrary and mutated input (seeded
//! proptest: the bounded run of every CI build; `fuzz/` has the `cargo fuzz` targets
//! for longer runs). Each input ends in a value or an error, and a valid experiment goes
//! on to `smspace_pipeline::check`, which validates every table before anything runs.

use proptest::prelude::*;
use smspace::agent::Environment;
use smspace_pipeline::config::load_experiment;

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
            let _ = smspace_pipeline::check(&loaded);
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
            let _ = smspace_pipeline::check(&loaded);
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

/// A valid `.npy` file of a small array, whose bytes the mutations below corrupt.
fn npy_bytes(rows: usize, columns: usize) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.npy");
    let array = ndarray::Array2::from_shape_fn((rows, columns), |(i, j)| (i * 10 + j) as f64);
    smspace::io::write_npy(&path, &array).unwrap();
    std::fs::read(&path).unwrap()
}

/// A byte edit: `(position, byte, how)`: overwrite, insert, delete, or truncate there.
fn edited(mut bytes: Vec<u8>, edits: &[(usize, u8, u8)]) -> Vec<u8> {
    for &(at, byte, how) in edits {
        let at = at % (bytes.len() + 1);
        match how {
            0 if at < bytes.len() => bytes[at] = byte,
            1 => bytes.insert(at, byte),
            2 if at < bytes.len() => {
                bytes.remove(at);
            }
            _ => bytes.truncate(at),
        }
    }
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: prop::test_runner::RngSeed::Fixed(19),
        ..ProptestConfig::default()
    })]

    /// Valid files with a few bytes overwritten, inserted, deleted or cut (most land
    /// in the header: its text, its length field, the shape), and arbitrary bytes.
    #[test]
    fn npy_files_give_an_array_or_an_error(
        rows in 0usize..5,
        columns in 1usize..4,
        edits in prop::collection::vec((0usize..200, any::<u8>(), 0u8..4), 0..4),
        arbitrary in prop::collection::vec(any::<u8>(), 0..300),
        mutate in any::<bool>(),
    ) {
        let bytes = if mutate { edited(npy_bytes(rows, columns), &edits) } else { arbitrary };
        let (_dir, path) = in_file("a.npy", "");
        std::fs::write(&path, &bytes).unwrap();
        if let Ok(array) = smspace::io::read_f64(&path) {
            prop_assert!(array.iter().all(|x| x.is_finite()));
            // Never more values than the file has bytes for.
            prop_assert!(array.len() * 8 <= bytes.len());
        }
        let _ = smspace::io::read_i64(&path);
        let _ = smspace::io::read_matrix(&path, Some(columns), "(M, C)");
        let _ = smspace::io::read_cube(&path, "(M, P, N)");
    }
}

#[test]
fn the_base_experiment_is_valid() {
    // So that the mutations start from a file that passes every check.
    let (_dir, path) = in_file("e.toml", BASE);
    let loaded = load_experiment(&path, &[]).unwrap();
    smspace_pipeline::check(&loaded).unwrap();
}
