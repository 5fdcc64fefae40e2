//! The pipeline crate's modules stand on floors too, and no module imports one on its
//! own floor or above (test code excepted): the run's records (`manifest`, `lock`) and
//! the `[data]` and `[scale]` tables below the report, the report below the experiment
//! files, those below the stage error and the stages, and the crate root (`check`,
//! `run`) on top.

#[path = "../../smspace/tests/common/layers.rs"]
mod layers;

use std::path::Path;

use layers::{violations, Floors};

const FLOORS: Floors<'static> = Floors {
    ground: &["manifest", "lock", "scale", "data"],
    floors: &[
        ("report", 1),
        ("config", 2),
        ("error", 3),
        ("stages", 4),
        ("plan", 5),
        ("memory", 6),
        ("runner", 7),
        ("front", 8),
    ],
    aliases: &[
        ("Error", "error"),
        ("Result", "error"),
        ("StageId", "manifest"),
        ("BusyFolder", "lock"),
        ("Plan", "plan"),
        ("RunObserver", "plan"),
        ("RunOptions", "plan"),
        ("RunSummary", "plan"),
        ("Recompute", "plan"),
        ("PipelineError", "plan"),
        ("DistanceBackend", "stages"),
        ("LocalDistances", "stages"),
    ],
    // Items of the crate root (lib.rs): the top floor.
    top: &["Registries", "check", "check_with", "run", "run_with"],
};

#[test]
fn no_module_imports_its_own_floor_or_above() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let found = violations(&root, &FLOORS);
    assert!(
        found.is_empty(),
        "imports that run up a floor (move the shared type down):\n{found:#?}"
    );
}
