//! The core crate's modules stand on floors that follow the pipeline, and no module
//! imports one on its own floor or above (test code excepted): shared types (checked
//! parameters, closure records, set views, distance matrices, registries) live in leaf
//! modules on the ground floor, so that no import runs back up and none loops.
//!
//! The test reads the sources: every `crate::MODULE` outside comments and outside
//! `#[cfg(test)]` modules is an import of `MODULE`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Ground-floor modules, in the order in which they may import each other (a module
/// may import only those before it), then the pipeline's floors.
const GROUND: [&str; 8] = [
    "params",
    "io",
    "progress",
    "threads",
    "sets",
    "matrix",
    "registry",
    "neighbours",
];

/// The floor of every module above the ground (the ground is floor 0).
const FLOORS: [(&str, u32); 9] = [
    ("agent", 1),
    ("explore", 2),
    ("kernel", 3),
    ("metric", 4),
    ("embed", 5),
    ("learn", 5),
    ("analysis", 6),
    ("invariance", 7),
    ("error", 8),
];

/// A module's position: floor, then order within the ground floor.
fn rank(module: &str) -> Option<(u32, usize)> {
    if let Some(i) = GROUND.iter().position(|&g| g == module) {
        return Some((0, i));
    }
    FLOORS
        .iter()
        .find(|(m, _)| *m == module)
        .map(|&(_, floor)| (floor, 0))
}

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The code of a source file: comments and `#[cfg(test)]` modules removed.
fn code(text: &str) -> String {
    let mut kept = String::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("#[cfg(test)]")
            && lines
                .peek()
                .is_some_and(|next| next.trim_start().starts_with("mod "))
        {
            // A test module: skip to its closing brace at the same indentation.
            let indent = line.len() - trimmed.len();
            let close = format!("{}}}", " ".repeat(indent));
            for inner in lines.by_ref() {
                if inner == close {
                    break;
                }
            }
            continue;
        }
        if trimmed.starts_with("//") {
            continue;
        }
        kept.push_str(line.split(" //").next().unwrap_or(line));
        kept.push('\n');
    }
    kept
}

/// The modules of the crate `code` imports: `crate::m` and the `m` of `use crate::{m, …}`.
fn imports(code: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        rest = &rest[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            for part in group[..end].split(',') {
                let name: String = part
                    .trim()
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                found.push(name);
            }
        } else {
            found.push(
                rest.chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect(),
            );
        }
    }
    found
}

#[test]
fn no_module_imports_its_own_floor_or_above() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&root, &mut files);
    let mut violations = BTreeMap::new();
    let mut seen = 0;
    for file in &files {
        let relative = file.strip_prefix(&root).unwrap();
        let module = relative
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_owned();
        if module == "lib" {
            continue;
        }
        let own = rank(&module).unwrap_or_else(|| {
            panic!(
                "src/{} has no floor: add `{module}` to this test's floors",
                relative.display()
            )
        });
        seen += 1;
        for imported in imports(&code(&std::fs::read_to_string(file).unwrap())) {
            if imported == module || matches!(imported.as_str(), "Error" | "Result") {
                // `crate::Result` is the error module's alias, on the top floor.
                if imported != module {
                    violations
                        .entry(relative.display().to_string())
                        .or_insert_with(Vec::new)
                        .push(format!("crate::{imported} (the error module, top floor)"));
                }
                continue;
            }
            let Some(theirs) = rank(&imported) else {
                continue;
            };
            if theirs >= own {
                violations
                    .entry(relative.display().to_string())
                    .or_insert_with(Vec::new)
                    .push(format!(
                        "crate::{imported} (floor {:?} ≥ own {:?})",
                        theirs, own
                    ));
            }
        }
    }
    assert!(
        seen > 50,
        "only {seen} source files read under {}",
        root.display()
    );
    assert!(
        violations.is_empty(),
        "imports that run up a floor (move the shared type to a ground-floor module):\n{violations:#?}"
    );
}

#[test]
fn the_reader_finds_imports_and_skips_comments_and_tests() {
    let text = "use crate::{metric::X, io};\n// crate::agent\nfn f() { crate::kernel::g() }\n#[cfg(test)]\nmod tests {\n    use crate::analysis::Y;\n}\n";
    assert_eq!(imports(&code(text)), ["metric", "io", "kernel"]);
}
