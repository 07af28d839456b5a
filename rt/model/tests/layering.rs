//! `coop-model`'s modules import one another in one direction only: no import circle between the
//! crate's top-level modules, and inside `method/` no method imports another method (what they
//! share lives beside them). Read from the sources, so a new `use` that closes a circle fails here.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const METHODS: [&str; 4] = ["naive", "paper", "timewarp", "coupled"];

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable source folder") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs")
            // A `tests.rs` is a test module (`#[cfg(test)] mod tests;`): tests may import anything.
            && path.file_name().is_some_and(|n| n != "tests.rs")
        {
            out.push(path);
        }
    }
}

/// The module path of `file` below `src` (`method/timewarp/mod.rs` → `["method", "timewarp"]`).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("below src");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// The code of `text` a build without tests compiles: comments and everything from the first
/// `#[cfg(test)]` on are left out (test modules sit at the end of their files).
fn code(text: &str) -> String {
    let end = text.find("#[cfg(test)]").unwrap_or(text.len());
    text[..end]
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Each `prefix<ident>` in `code`, as the identifier.
fn after<'a>(code: &'a str, prefix: &str) -> Vec<&'a str> {
    code.match_indices(prefix)
        .map(|(i, _)| {
            let rest = &code[i + prefix.len()..];
            let end = rest
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(rest.len());
            &rest[..end]
        })
        .filter(|s| !s.is_empty())
        .collect()
}

#[test]
fn the_models_modules_import_one_another_in_one_direction() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let mut top: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut crossing = Vec::new();
    for file in &files {
        let module = module_of(&src, file);
        let Some(first) = module.first() else {
            continue; // lib.rs declares the modules
        };
        let text = code(&std::fs::read_to_string(file).expect("readable source"));
        let deps = top.entry(first.clone()).or_default();
        for dep in after(&text, "crate::") {
            if dep != first {
                deps.insert(dep.to_owned());
            }
        }
        // A method's files import no other method.
        if module.len() >= 2 && module[0] == "method" && METHODS.contains(&module[1].as_str()) {
            let own = &module[1];
            for prefix in ["crate::method::", "super::", "super::super::"] {
                for dep in after(&text, prefix) {
                    if METHODS.contains(&dep) && dep != own {
                        crossing.push(format!("{}: {prefix}{dep}", file.display()));
                    }
                }
            }
        }
    }
    assert!(top.len() >= 15, "read {} modules: {top:?}", top.len());
    assert!(
        crossing.is_empty(),
        "a method imports another: {crossing:?}"
    );
    // Depth-first search for a back edge: a circle.
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == m) {
            let mut circle = path[at..].to_vec();
            circle.push(m.to_owned());
            return Some(circle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_owned());
        for dep in graph.get(m).into_iter().flatten() {
            if let Some(c) = visit(dep, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    for m in top.keys() {
        if let Some(circle) = visit(m, &top, &mut Vec::new(), &mut done) {
            panic!("an import circle: {}", circle.join(" -> "));
        }
    }
}
