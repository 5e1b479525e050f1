//! The engine's modules import each other without a circle (issue 40): read from the sources,
//! outside test code and comments, a module's imports of its siblings (`super::x` from a
//! top-level file or folder, `super::super::x` from inside a folder, `crate::engine_tract::x`
//! anywhere), and a depth-first search for a cycle. Tests are left out on purpose: a pass's
//! tests stop the driver (`rewrite`) before their pass.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// `(module, imported siblings)` of every module under `root`.
fn sibling_imports(root: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("the engine's sources are readable") {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in files {
        let rel = path.strip_prefix(root).expect("under the root");
        let parts: Vec<String> = rel
            .iter()
            .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
            .collect();
        if parts == ["mod"] {
            continue;
        }
        let module = parts[0].clone();
        // A folder's own files (not its mod.rs) reach their siblings one `super` further up.
        let nested = parts.len() > 1 && parts[parts.len() - 1] != "mod";
        let sibling_prefixes: &[&str] = if nested {
            &["super::super::", "crate::engine_tract::"]
        } else {
            &["super::", "crate::engine_tract::"]
        };
        let text = std::fs::read_to_string(&path).expect("a source file is readable");
        let code = text.split("#[cfg(test)]").next().unwrap_or_default();
        let code: String = code
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let deps = graph.entry(module.clone()).or_default();
        for prefix in sibling_prefixes {
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
fn cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        graph: &BTreeMap<String, BTreeSet<String>>,
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

#[test]
fn the_engine_modules_import_each_other_without_a_circle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/engine_tract");
    let graph = sibling_imports(&root);
    // The reader sees what it should: the driver imports the passes, the passes the helpers.
    assert!(graph["rewrite"].contains("epilogue") && graph["rewrite"].contains("gemm"));
    assert!(graph["epilogue"].contains("graph_match") && graph["epilogue"].contains("finish"));
    assert!(
        graph["gemm"].contains("pool"),
        "gemm/blocks.rs imports pool"
    );
    assert_eq!(cycle(&graph), None, "{graph:#?}");
    // And a circle is found where there is one.
    let mut with_circle = graph.clone();
    with_circle
        .get_mut("graph_match")
        .expect("a module")
        .insert("rewrite".into());
    assert!(cycle(&with_circle).is_some());
}
