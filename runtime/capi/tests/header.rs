//! `include/satmap.h` is what cbindgen makes of this crate today: a stale committed header
//! fails here (`SATMAP_BLESS=1` rewrites it).

use std::path::PathBuf;

#[test]
fn the_committed_header_is_current() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    let bindings = cbindgen::Builder::new()
        .with_crate(&dir)
        .with_config(config)
        .generate()
        .unwrap();
    let mut fresh = Vec::new();
    bindings.write(&mut fresh);
    let path = dir.join("include/satmap.h");
    if std::env::var_os("SATMAP_BLESS").is_some() {
        std::fs::write(&path, &fresh).unwrap();
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "runtime/capi/include/satmap.h is stale: rerun with SATMAP_BLESS=1"
    );
}
