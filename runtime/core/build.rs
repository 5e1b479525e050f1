//! Turns the memory layout into Rust constants in `$OUT_DIR/memory_layout.rs`, included by
//! `src/capacity.rs`. The layout is `memory_layout.toml` at the workspace root unless
//! `SATMAP_LAYOUT` names another file (one per product variant, e.g. `layouts/paper.toml`); a
//! relative `SATMAP_LAYOUT` is relative to the workspace root, and an empty one means the
//! default. A layout that cannot be read or does not pass the layout crate's checks fails the
//! build with a message naming the file.

use std::path::PathBuf;

/// The layout file when `SATMAP_LAYOUT` is unset, relative to the workspace root.
const DEFAULT_LAYOUT: &str = "memory_layout.toml";

fn fail(message: &str) -> ! {
    // `cargo::error` makes cargo fail the build and show the message as its error.
    for line in message.lines() {
        println!("cargo::error={line}");
    }
    std::process::exit(0);
}

fn main() {
    println!("cargo::rerun-if-env-changed=SATMAP_LAYOUT");
    let manifest_dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    // The workspace root (the directory of the default memory_layout.toml), two levels above
    // this crate's folder, `runtime/core`.
    let root = manifest_dir
        .parent()
        .and_then(std::path::Path::parent)
        .unwrap_or(&manifest_dir)
        .to_path_buf();
    let chosen = std::env::var_os("SATMAP_LAYOUT").filter(|v| !v.is_empty());
    let (given, from_env) = match &chosen {
        Some(v) => (PathBuf::from(v), true),
        None => (PathBuf::from(DEFAULT_LAYOUT), false),
    };
    let path = if given.is_absolute() {
        given.clone()
    } else {
        root.join(&given)
    };
    println!("cargo::rerun-if-changed={}", path.display());
    let origin = if !from_env {
        String::from(" (the default layout; set SATMAP_LAYOUT to build another)")
    } else if given.is_absolute() {
        format!(" (SATMAP_LAYOUT={})", given.display())
    } else {
        format!(
            " (SATMAP_LAYOUT={}, taken from the workspace root {})",
            given.display(),
            root.display()
        )
    };
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => fail(&format!(
            "ERROR(layout): cannot read memory layout {}: {e}{origin}",
            path.display()
        )),
    };
    let layout = match satmap_layout::MemoryLayout::parse(&text) {
        Ok(l) => l,
        Err(e) => fail(&format!("{e} (in {}){origin}", path.display())),
    };
    let mut consts = layout.to_rust_consts();
    // Which file this build carries, as it was given (workspace-relative unless absolute), and
    // its text, so host tools print the layout that is in the binary.
    consts.push_str(
        "/// The layout file this build was generated from (`SATMAP_LAYOUT`, else \
         `memory_layout.toml`), as given: relative to the workspace root unless absolute.\n",
    );
    consts.push_str(&format!(
        "pub const SOURCE_PATH: &str = {:?};\n",
        given.to_string_lossy()
    ));
    consts.push_str("/// The text of that layout file.\n");
    consts.push_str(&format!("pub const SOURCE_TOML: &str = {text:?};\n"));
    let out =
        PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default()).join("memory_layout.rs");
    if let Err(e) = std::fs::write(&out, consts) {
        fail(&format!(
            "ERROR(layout): cannot write {}: {e}",
            out.display()
        ));
    }
}
