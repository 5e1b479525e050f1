//! Linker scripts per bare-metal target: the memory map of the emulated board (`link/`), placed
//! where the linker finds it, and the startup crate's own script.

use std::path::PathBuf;

fn main() {
    let target = std::env::var("TARGET").unwrap_or_default();
    let out = PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let dir =
        PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default()).join("link");
    let copy = |from: &str, to: &str| {
        let src = dir.join(from);
        println!("cargo::rerun-if-changed={}", src.display());
        if let Err(e) = std::fs::copy(&src, out.join(to)) {
            println!("cargo::error=copying {}: {e}", src.display());
        }
    };
    match target.as_str() {
        "aarch64-unknown-none" => {
            // aarch64-rt's image.ld lays the sections into the `image` region named here.
            copy("virt.ld", "memory.ld");
            println!("cargo::rustc-link-search={}", out.display());
            println!("cargo::rustc-link-arg=-Timage.ld");
            println!("cargo::rustc-link-arg=-Tmemory.ld");
        }
        "thumbv7em-none-eabihf" => {
            // cortex-m-rt's link.x includes memory.x.
            copy("mps2_an386.x", "memory.x");
            println!("cargo::rustc-link-search={}", out.display());
            println!("cargo::rustc-link-arg=-Tlink.x");
        }
        _ => {}
    }
}
