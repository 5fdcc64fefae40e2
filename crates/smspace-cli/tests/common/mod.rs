//! Running the `smspace` binary from the CLI tests: one harness for every test file.
#![allow(
    dead_code,
    reason = "each test binary uses a different subset of the helpers"
)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs `smspace ARGS` in `dir`.
pub fn smspace(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_smspace"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("the binary runs")
}

/// The standard error of a run, as text.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Runs and expects success; returns the output.
pub fn ok(dir: &Path, args: &[&str]) -> Output {
    let out = smspace(dir, args);
    assert!(
        out.status.success(),
        "smspace {args:?} failed: {}",
        stderr(&out)
    );
    out
}

/// Runs and expects a clean failure: a non-zero exit and an `error: ` message, never a
/// panic or a backtrace. Returns the standard error.
pub fn fails(dir: &Path, args: &[&str]) -> String {
    let out = smspace(dir, args);
    let text = stderr(&out);
    assert!(!out.status.success(), "smspace {args:?} should fail");
    assert!(
        !text.contains("panicked"),
        "smspace {args:?} panicked: {text}"
    );
    assert!(!text.contains("RUST_BACKTRACE"), "{text}");
    // Progress notes (the kernel dimension, the estimated time) may come first.
    assert!(
        text.lines().any(|l| l.starts_with("error: ")),
        "smspace {args:?}: {text}"
    );
    text
}

/// Like [`fails`], and the message must contain `needle`.
pub fn fails_with(dir: &Path, args: &[&str], needle: &str) -> String {
    let text = fails(dir, args);
    assert!(
        text.contains(needle),
        "smspace {args:?}: expected {needle:?} in: {text}"
    );
    text
}
