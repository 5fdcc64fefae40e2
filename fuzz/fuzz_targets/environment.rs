//! Arbitrary bytes as an environment JSON file: a valid environment (at least one
//! light, finite positions) or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = dir.path().join("env.json");
    std::fs::write(&path, bytes).expect("the input is written");
    if let Ok(environment) = smspace::agent::Environment::load(&path) {
        assert!(!environment.lights.is_empty());
        assert!(environment
            .lights
            .iter()
            .all(|l| l[0].is_finite() && l[1].is_finite()));
    }
});
