//! The core crate's modules stand on floors that follow the pipeline, and no module
//! imports one on its own floor or above (test code excepted): shared types (checked
//! parameters, closure records, set views, distance matrices, registries) live in leaf
//! modules on the ground floor, so that no import runs back up and none loops.
//!
//! The test reads the sources: every `crate::MODULE` outside comments and outside
//! `#[cfg(test)]` modules is an import of `MODULE`.

#[path = "common/layers.rs"]
mod layers;

use std::path::Path;

use layers::{code, imports, imports_from, violations, Floors};

/// The floors (docs/ARCHITECTURE.md draws them).
const FLOORS: Floors<'static> = Floors {
    ground: &[
        "params",
        "io",
        "progress",
        "threads",
        "linalg",
        "sets",
        "matrix",
        "registry",
        "neighbours",
    ],
    floors: &[
        ("agent", 1),
        ("explore", 2),
        ("kernel", 3),
        ("metric", 4),
        ("embed", 5),
        ("learn", 5),
        ("analysis", 6),
        ("invariance", 7),
        ("error", 8),
    ],
    aliases: &[("Error", "error"), ("Result", "error")],
    top: &[],
};

#[test]
fn no_module_imports_its_own_floor_or_above() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let found = violations(&root, &FLOORS);
    assert!(
        found.is_empty(),
        "imports that run up a floor (move the shared type to a ground-floor module):\n{found:#?}"
    );
}

#[test]
fn the_reader_finds_imports_and_skips_comments_and_tests() {
    let text = "use crate::{metric::X, io};\n// crate::agent\nfn f() { crate::kernel::g() }\n#[cfg(test)]\nmod tests {\n    use crate::analysis::Y;\n}\n";
    assert_eq!(imports(&code(text)), ["metric", "io", "kernel"]);
}

#[test]
fn the_reader_resolves_super_paths_from_the_modules_own_path() {
    let text =
        "use super::World;\nuse super::{kernel, io::X};\nfn f() { super::super::metric::g() }\n";
    let top = vec!["data".to_owned()];
    assert_eq!(imports_from(text, &top), ["World", "kernel", "io"]);
    let nested = vec!["stages".to_owned(), "trace".to_owned()];
    assert_eq!(
        imports_from(text, &nested),
        ["stages", "stages", "stages", "metric"]
    );
}
