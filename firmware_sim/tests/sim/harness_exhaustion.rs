//! With the arena set below what is needed, `satmap-sim drive` names the region that does not
//! fit and exits with the arena-exhausted code, without a panic; with a model that does not fit
//! the memory map, it names the region and exits with the bad-input code.

use std::process::Command;

use satmap_sim::arena::EXIT_ARENA_EXHAUSTED;
use satmap_sim::harness::EXIT_BAD_INPUT;

fn drive(extra: &[&str]) -> (Option<i32>, String) {
    let bundle = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/bundles/test");
    let out = Command::new(env!("CARGO_BIN_EXE_satmap-sim"))
        .args([
            "drive",
            "--bundle",
            bundle,
            "--frames",
            "2",
            "--quiet",
            "--rate-hz",
            "1",
        ])
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn small_arena_names_the_graph_engine_region_and_exits_3() {
    let (code, stderr) = drive(&["--arena-bytes", "1000000"]);
    assert_eq!(code, Some(EXIT_ARENA_EXHAUSTED), "{stderr}");
    assert!(
        stderr.contains("region `graph_engine` does not fit"),
        "{stderr}"
    );
    assert!(stderr.contains("the arena of 1000000 bytes"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn arena_too_large_for_the_static_storage_is_bad_input() {
    let (code, stderr) = drive(&["--arena-bytes", "999999999999"]);
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{stderr}");
    assert!(stderr.contains("--arena-bytes"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
