//! The documentation holds together: every relative link and image of the README, ARCHITECTURE.md,
//! `docs/` and the other READMEs points at a file or folder that exists (anchors aside), and the
//! README stays a front door of at most 200 lines (issue 41: the records live in `docs/`).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Markdown files of the repository that people read (generated and vendored trees aside).
fn documents() -> Vec<PathBuf> {
    let r = root();
    let mut out = vec![
        r.join("README.md"),
        r.join("ARCHITECTURE.md"),
        r.join("models/README.md"),
        r.join("targets/README.md"),
    ];
    let mut dirs = vec![r.join("docs")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// `(line, target)` of every Markdown link or image outside code fences and inline code.
fn links(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Inline code spans never hold links.
        let visible: String = line
            .split('`')
            .enumerate()
            .filter(|(i, _)| i % 2 == 0)
            .map(|(_, s)| s)
            .collect::<Vec<_>>()
            .join(" ");
        let mut rest = visible.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            out.push((n + 1, after[..end].trim().to_owned()));
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_of_the_docs_resolves() {
    let docs = documents();
    assert!(docs.len() >= 14, "{docs:?}");
    let mut broken = Vec::new();
    let mut checked = 0;
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap();
        for (line, target) in links(&text) {
            if target.contains("://") || target.starts_with('#') || target.starts_with("mailto:") {
                continue;
            }
            let path = target.split('#').next().unwrap_or_default();
            let resolved = doc.parent().unwrap_or(Path::new(".")).join(path);
            checked += 1;
            if !resolved.exists() {
                broken.push(format!("{}:{line}: {target}", doc.display()));
            }
        }
    }
    assert!(
        checked >= 30,
        "only {checked} links found: is the parser blind?"
    );
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_readme_is_a_front_door() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= 200,
        "README.md has {lines} lines: move records to docs/"
    );
    for section in [
        "## The two commands",
        "## What it does",
        "## Integrate it (C)",
    ] {
        assert!(readme.contains(section), "README.md lacks {section:?}");
    }
    // Every doc of docs/ is reachable from the README's table or another doc.
    let all: String = documents()
        .iter()
        .map(|d| std::fs::read_to_string(d).unwrap())
        .collect();
    for doc in documents()
        .iter()
        .filter(|d| d.starts_with(root().join("docs")))
    {
        let name = doc.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            all.contains(&format!("{name})")),
            "nothing links to docs/.../{name}"
        );
    }
}

#[test]
fn the_link_parser_sees_links_and_skips_code() {
    let text = "a [x](docs/a.md) `[y](no.md)` ![i](img/p.png)\n```\n[z](no.md)\n```\n[w](b.md#s)";
    let got: Vec<String> = links(text).into_iter().map(|(_, t)| t).collect();
    assert_eq!(got, ["docs/a.md", "img/p.png", "b.md#s"]);
}
