//! Arbitrary text as an experiment file, and as `--set` overrides of a valid one:
//! loading gives a value or an error, and a loaded experiment is checked
//! (`pipeline::check`, which validates every table and size) without panicking.
#![no_main]

use libfuzzer_sys::fuzz_target;

/// A valid experiment for the overrides.
const BASE: &str = "name = \"fuzz\"\n[agent]\nkind = \"planar-arm\"\n[exploration]\nn = 20\n[kernel]\npoints = 30\n";

fuzz_target!(|text: &str| {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let file = dir.path().join("experiment.toml");
    std::fs::write(&file, text).expect("the input is written");
    if let Ok(loaded) = smspace_pipeline::config::load_experiment(&file, &[]) {
        let _ = smspace_pipeline::check(&loaded);
    }
    std::fs::write(&file, BASE).expect("the base is written");
    let overrides: Vec<String> = text.lines().map(str::to_owned).collect();
    if let Ok(loaded) = smspace_pipeline::config::load_experiment(&file, &overrides) {
        let _ = smspace_pipeline::check(&loaded);
    }
});
