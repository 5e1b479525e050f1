//! The runtime's modules import each other without a circle (issue 40), at two levels: the
//! crate's top-level modules (`crate::x` anywhere), and the engine's modules inside
//! `engine_tract` (`super::x` from a top-level file or folder of it, `super::super::x` from
//! inside a folder, `crate::engine_tract::x` anywhere). Read from the sources, outside test code
//! and comments, then a depth-first search for a cycle. Tests are left out on purpose: a pass's
//! tests stop the driver (`rewrite`) before their pass, and a module's tests may use any helper.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Imports of one module level: module name -> the sibling modules it imports.
type Graph = BTreeMap<String, BTreeSet<String>>;

/// Every `.rs` file under `root`, test-only files (`tests.rs`, `*_tests.rs`, `test_support.rs`,
/// `test_graphs.rs`, anything under a `tests/` folder) left out.
fn source_files(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("the runtime's sources are readable") {
            let path = entry.expect("a directory entry").path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            let name = name.unwrap_or_default();
            if path.is_dir() {
                if name != "tests" {
                    stack.push(path);
                }
            } else if name.ends_with(".rs")
                && name != "tests.rs"
                && !name.ends_with("_tests.rs")
                && !name.starts_with("test_")
            {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// `text` without comment lines and without what `#[cfg(test)]` guards: a guarded one-line item
/// (`mod tests;`, a `use`) is dropped alone, a guarded block (the inline `mod tests { .. }` that
/// closes a file) to the end of the file.
fn non_test_code(text: &str) -> String {
    let mut kept = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("//") {
            continue;
        }
        if trimmed.starts_with("#[cfg(test)]") {
            match lines.next() {
                Some(item) if item.trim_end().ends_with('{') => break,
                _ => continue,
            }
        }
        kept.push(line);
    }
    kept.join("\n")
}

/// The import graph of the modules directly under `root` (files and folders), from the
/// prefixes through which a module names a sibling: `top` for a top-level file or a folder's
/// `mod.rs`, `nested` for a file deeper in a folder.
fn sibling_imports(root: &Path, top: &[&str], nested: &[&str]) -> Graph {
    let mut graph = Graph::new();
    for path in source_files(root) {
        let rel = path.strip_prefix(root).expect("under the root");
        let parts: Vec<String> = rel
            .iter()
            .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
            .collect();
        if parts.len() == 1 && (parts[0] == "mod" || parts[0] == "lib") {
            continue;
        }
        let module = parts[0].clone();
        let is_nested = parts.len() > 1 && parts[parts.len() - 1] != "mod";
        let prefixes = if is_nested { nested } else { top };
        let text = std::fs::read_to_string(&path).expect("a source file is readable");
        let code = non_test_code(&text);
        let deps = graph.entry(module.clone()).or_default();
        for prefix in prefixes {
            for (at, _) in code.match_indices(prefix) {
                // `super::super::x` also contains `super::x`: only whole prefixes count.
                if code[..at].ends_with("super::") {
                    continue;
                }
                for name in imported_names(&code[at + prefix.len()..]) {
                    if name != "super" && name != module {
                        deps.insert(name);
                    }
                }
            }
        }
    }
    let modules: BTreeSet<String> = graph.keys().cloned().collect();
    for deps in graph.values_mut() {
        deps.retain(|d| modules.contains(d));
    }
    graph
}

/// The first path segment of each name a `use` (or a path) takes from where `rest` starts:
/// `x::y` gives `x`, `{x, y::{z}, w}` gives `x`, `y`, `w`.
fn imported_names(rest: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')
            .collect()
    };
    let Some(group) = rest.strip_prefix('{') else {
        return vec![ident(rest)]
            .into_iter()
            .filter(|n| !n.is_empty())
            .collect();
    };
    let mut names = Vec::new();
    let (mut depth, mut item_start) = (0usize, 0usize);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                names.push(ident(&group[item_start..i]));
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                names.push(ident(&group[item_start..i]));
                item_start = i + 1;
            }
            _ => {}
        }
    }
    names.retain(|n| !n.is_empty());
    names
}

/// A cycle of `graph`, if it has one (the modules along it, the first repeated at the end).
fn cycle(graph: &Graph) -> Option<Vec<String>> {
    fn visit(
        graph: &Graph,
        node: &str,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            let mut c = path[at..].to_vec();
            c.push(node.to_string());
            return Some(c);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(c) = visit(graph, next, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|start| visit(graph, start, &mut Vec::new(), &mut done))
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

#[test]
fn the_crate_modules_import_each_other_without_a_circle() {
    let graph = sibling_imports(&src(), &["crate::"], &["crate::"]);
    // The reader sees what it should: the step wraps the errors of the modules below it, the
    // compiler imports the loader and the engine, and nothing imports the step back.
    assert!(graph["step"].contains("frame") && graph["step"].contains("gkt"));
    assert!(graph["translate"].contains("bundle") && graph["translate"].contains("engine_tract"));
    assert!(graph["engine_tract"].contains("bundle"));
    assert!(
        graph.values().all(|deps| !deps.contains("step")),
        "{graph:#?}"
    );
    assert_eq!(cycle(&graph), None, "{graph:#?}");
    // A circle is found where there is one (the one issue 40 found: a shared error module that
    // imported the modules whose errors it defined).
    let mut with_circle = graph.clone();
    with_circle
        .get_mut("frame")
        .expect("a module")
        .insert("step".into());
    assert!(cycle(&with_circle).is_some());
}

#[test]
fn the_engine_modules_import_each_other_without_a_circle() {
    let graph = sibling_imports(
        &src().join("engine_tract"),
        &["super::", "crate::engine_tract::"],
        &["super::super::", "crate::engine_tract::"],
    );
    // The reader sees what it should: the driver imports the passes, the passes the helpers.
    assert!(graph["rewrite"].contains("epilogue") && graph["rewrite"].contains("gemm"));
    assert!(graph["epilogue"].contains("graph_match") && graph["epilogue"].contains("finish"));
    assert!(
        graph["gemm"].contains("pool"),
        "gemm/blocks.rs imports pool"
    );
    assert_eq!(cycle(&graph), None, "{graph:#?}");
    let mut with_circle = graph.clone();
    with_circle
        .get_mut("graph_match")
        .expect("a module")
        .insert("rewrite".into());
    assert!(cycle(&with_circle).is_some());
}

#[test]
fn test_code_is_told_apart_from_product_code() {
    let text = "use crate::a::X;\n#[cfg(test)]\nmod tests;\n// use crate::c;\nuse crate::b;\n\
                #[cfg(test)]\nmod inline {\n    use crate::d;\n}\n";
    let code = non_test_code(text);
    assert_eq!(code, "use crate::a::X;\nuse crate::b;");
    assert_eq!(imported_names("{a, b::{c, d}, e}"), ["a", "b", "e"]);
}
