//! Turns `memory_layout.toml` (the repository root) into Rust constants in
//! `$OUT_DIR/memory_layout.rs`, included by `src/capacity.rs`. A bad layout fails the build with
//! the layout crate's message.

use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let path = manifest_dir.join("../memory_layout.toml");
    println!("cargo::rerun-if-changed={}", path.display());
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("ERROR(layout): cannot read {}: {e}", path.display());
            std::process::exit(1);
        }
    };
    let layout = match satmap_layout::MemoryLayout::parse(&text) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("{e} ({})", path.display());
            std::process::exit(1);
        }
    };
    let out =
        PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default()).join("memory_layout.rs");
    if let Err(e) = std::fs::write(&out, layout.to_rust_consts()) {
        eprintln!("ERROR(layout): cannot write {}: {e}", out.display());
        std::process::exit(1);
    }
}
