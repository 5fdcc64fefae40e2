#![allow(dead_code)]
//! Reads a crate's sources and checks that no module imports one on its own floor or
//! above (test code excepted): the layers test of each library crate.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A crate's floors: the ground-floor modules in the order in which they may import
/// each other (a module only those before it), and every other module's floor (the
/// ground is floor 0). Names in `aliases` are items the crate root re-exports from a
/// module (`crate::Result` from `error`); those in `top`, the crate root's own items,
/// count as the top floor.
pub struct Floors<'a> {
    pub ground: &'a [&'a str],
    pub floors: &'a [(&'a str, u32)],
    pub aliases: &'a [(&'a str, &'a str)],
    pub top: &'a [&'a str],
}

impl Floors<'_> {
    /// A module's position: floor, then order within the ground floor.
    fn rank(&self, module: &str) -> Option<(u32, usize)> {
        if let Some(&(_, to)) = self.aliases.iter().find(|(alias, _)| *alias == module) {
            return self.rank(to);
        }
        if let Some(i) = self.ground.iter().position(|&g| g == module) {
            return Some((0, i));
        }
        if self.top.contains(&module) {
            return Some((u32::MAX, 0));
        }
        self.floors
            .iter()
            .find(|(m, _)| *m == module)
            .map(|&(_, floor)| (floor, 0))
    }
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
pub fn code(text: &str) -> String {
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

/// The first names after a path prefix: `m` of `m::…`, or each `m` of `{m, …}`.
fn names_after(rest: &str) -> Vec<String> {
    let ident = |text: &str| -> String {
        text.trim()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    match rest.strip_prefix('{') {
        Some(group) => {
            let end = group.find('}').unwrap_or(group.len());
            group[..end].split(',').map(ident).collect()
        }
        None => vec![ident(rest)],
    }
}

/// The modules of the crate `code` imports: `crate::m` and the `m` of `use crate::{m, …}`.
pub fn imports(code: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        rest = &rest[at + "crate::".len()..];
        found.extend(names_after(rest));
    }
    found
}

/// The top-level modules (or crate-root items) that the code of the module at
/// `module_path` (`["stages", "trace"]` for `src/stages/trace.rs`, `["data"]` for
/// `src/data.rs`) imports by every path form: `crate::m`, and `super::…` chains
/// resolved from the module's own path (`super::World` in `src/data.rs` is the crate
/// root's `World`; `super::x` in `src/stages/trace.rs` is the module's own `stages`).
pub fn imports_from(code: &str, module_path: &[String]) -> Vec<String> {
    let mut found = imports(code);
    let mut rest = code;
    while let Some(at) = rest.find("super::") {
        let mut depth = 0;
        let mut tail = &rest[at..];
        while let Some(after) = tail.strip_prefix("super::") {
            depth += 1;
            tail = after;
        }
        rest = tail;
        if depth > module_path.len() {
            continue;
        }
        let base = &module_path[..module_path.len() - depth];
        for name in names_after(tail) {
            match base.first() {
                Some(top) => found.push(top.clone()),
                None => found.push(name),
            }
        }
    }
    found
}

/// The module path of a source file relative to `src` (`stages/mod.rs`: `["stages"]`).
fn module_path(relative: &Path) -> Vec<String> {
    let mut path: Vec<String> = relative
        .components()
        .map(|c| {
            c.as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_owned()
        })
        .collect();
    if path.last().is_some_and(|last| last == "mod") {
        path.pop();
    }
    path
}

/// The imports under `root` (a crate's `src`) that run up a floor, by file.
pub fn violations(root: &Path, floors: &Floors<'_>) -> BTreeMap<String, Vec<String>> {
    let mut files = Vec::new();
    sources(root, &mut files);
    assert!(
        files.len() > 10,
        "only {} source files under {}",
        files.len(),
        root.display()
    );
    let mut found = BTreeMap::new();
    for file in &files {
        let relative = file.strip_prefix(root).unwrap();
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
        let own = floors.rank(&module).unwrap_or_else(|| {
            panic!(
                "src/{} has no floor: add `{module}` to the floors of this test",
                relative.display()
            )
        });
        let path = module_path(relative);
        let text = code(&std::fs::read_to_string(file).unwrap());
        for imported in imports_from(&text, &path) {
            if imported == module {
                continue;
            }
            let Some(theirs) = floors.rank(&imported) else {
                continue;
            };
            if theirs >= own {
                found
                    .entry(relative.display().to_string())
                    .or_insert_with(Vec::new)
                    .push(format!("crate::{imported}"));
            }
        }
    }
    found
}
