//! The runtime's crates depend on each other as the crate map says (ARCHITECTURE.md), and inside
//! each crate the top-level modules import each other without a circle (issue 40): `crate::x`
//! anywhere, `super::x` from a top-level file, `super::super::x` from inside a folder. Read from
//! the sources, outside test code and comments, then a depth-first search for a cycle. Tests are left out on purpose: a pass's
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

/// The `src` folder of the runtime crate in `runtime/<folder>`.
fn src(folder: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(folder)
        .join("src")
}

/// The top-level module graph of the crate in `runtime/<folder>`.
fn crate_graph(folder: &str) -> Graph {
    sibling_imports(
        &src(folder),
        &["crate::", "super::"],
        &["crate::", "super::super::"],
    )
}

#[test]
fn no_crate_of_the_runtime_has_an_import_circle() {
    for folder in ["core", "bundle", "engine_tract", "translate", "kernels"] {
        let graph = crate_graph(folder);
        assert!(graph.len() > 1, "{folder}: modules found");
        assert_eq!(cycle(&graph), None, "{folder}: {graph:#?}");
    }
    // The reader sees what it should. Core: the step wraps the errors of the modules below it,
    // and nothing imports the step back.
    let core = crate_graph("core");
    assert!(core["step"].contains("frame") && core["step"].contains("gkt"));
    assert!(
        core.values().all(|deps| !deps.contains("step")),
        "{core:#?}"
    );
    // Engine: the passes import the ops, the ops the product driver, the pool and the graph
    // helpers; only the runner imports the passes (the driver, at load), and the graph helpers
    // import nothing of the engine.
    let engine = crate_graph("engine_tract");
    assert!(engine["passes"].contains("ops") && engine["passes"].contains("graph"));
    assert!(engine["ops"].contains("gemm") && engine["ops"].contains("graph"));
    assert!(
        engine["gemm"].contains("pool"),
        "gemm/blocks.rs imports pool"
    );
    let importers: Vec<&String> = engine
        .iter()
        .filter(|(_, deps)| deps.contains("passes"))
        .map(|(module, _)| module)
        .collect();
    assert_eq!(importers, ["runner"], "{engine:#?}");
    assert!(engine["graph"].is_empty(), "{engine:#?}");
    // Inside the engine's folders: the ops among themselves, the passes among themselves.
    for folder in ["ops", "passes"] {
        let path = format!("crate::{folder}::");
        let graph = sibling_imports(
            &src("engine_tract").join(folder),
            &["super::", &path],
            &["super::super::", &path],
        );
        assert!(graph.len() > 4, "{folder}: modules found");
        assert_eq!(cycle(&graph), None, "engine {folder}: {graph:#?}");
        if folder == "passes" {
            assert!(graph["rewrite"].contains("epilogue"), "{graph:#?}");
        }
    }
    // And a circle is found where there is one (the one issue 40 found in the core: a shared
    // error module that imported the modules whose errors it defined).
    let mut with_circle = core.clone();
    with_circle
        .get_mut("frame")
        .expect("a module")
        .insert("step".into());
    assert!(cycle(&with_circle).is_some());
}

/// The SatMap crates a runtime crate's manifest names under `[dependencies]`.
fn satmap_dependencies(folder: &str) -> BTreeSet<String> {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(folder)
        .join("Cargo.toml");
    let text = std::fs::read_to_string(&manifest).expect("a crate manifest is readable");
    let mut in_dependencies = false;
    let mut found = BTreeSet::new();
    for line in text.lines() {
        if line.starts_with('[') {
            in_dependencies = line == "[dependencies]";
        } else if in_dependencies && line.starts_with("satmap-") {
            let name = line.split([' ', '=']).next().unwrap_or_default();
            found.insert(name.to_string());
        }
    }
    found
}

#[test]
fn each_crate_imports_only_what_the_crate_map_allows() {
    let allowed: [(&str, &[&str]); 6] = [
        ("core", &[]),
        ("kernels", &[]),
        ("bundle", &["satmap-core"]),
        (
            "engine_tract",
            &["satmap-core", "satmap-bundle", "satmap-kernels"],
        ),
        (
            "translate",
            &["satmap-core", "satmap-bundle", "satmap-engine-tract"],
        ),
        (
            ".",
            &[
                "satmap-core",
                "satmap-bundle",
                "satmap-engine-tract",
                "satmap-translate",
            ],
        ),
    ];
    for (folder, allowed) in allowed {
        let found = satmap_dependencies(folder);
        let allowed: BTreeSet<String> = allowed.iter().map(|s| s.to_string()).collect();
        assert!(
            found.is_subset(&allowed),
            "{folder}: {found:?} beyond {allowed:?}"
        );
    }
    assert!(satmap_dependencies("engine_tract").contains("satmap-kernels"));
}

#[test]
fn test_code_is_told_apart_from_product_code() {
    let text = "use crate::a::X;\n#[cfg(test)]\nmod tests;\n// use crate::c;\nuse crate::b;\n\
                #[cfg(test)]\nmod inline {\n    use crate::d;\n}\n";
    let code = non_test_code(text);
    assert_eq!(code, "use crate::a::X;\nuse crate::b;");
    assert_eq!(imported_names("{a, b::{c, d}, e}"), ["a", "b", "e"]);
}

/// `satmap-core` builds without tract and without the host crates: its normal dependency tree
/// (`cargo tree -p satmap-core -e normal`) names no tract crate, no other SatMap crate and none
/// of the std-only crates of the bundle side. (That it links without std is `make nostd`.)
#[test]
fn the_core_names_no_tract_and_no_host_crate() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(&cargo)
        .args(["tree", "--offline", "-p", "satmap-core", "-e", "normal"])
        .args(["--prefix", "none", "--format", "{p}"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let tree = String::from_utf8(out.stdout).expect("cargo tree prints UTF-8");
    let crates: BTreeSet<&str> = tree.lines().filter_map(|l| l.split(' ').next()).collect();
    assert!(
        crates.contains("satmap-core") && crates.contains("glam"),
        "{tree}"
    );
    for banned in ["thiserror", "serde", "toml", "tar", "sha2", "rayon"] {
        assert!(
            !crates.contains(banned),
            "satmap-core pulls {banned}:\n{tree}"
        );
    }
    for krate in &crates {
        assert!(
            !krate.starts_with("tract-"),
            "satmap-core pulls {krate}:\n{tree}"
        );
        assert!(
            !krate.starts_with("satmap-") || *krate == "satmap-core",
            "satmap-core pulls {krate}:\n{tree}"
        );
    }
}
