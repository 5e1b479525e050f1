//! With the arena set below what is needed, `satmap-sim drive` names the region that does not
//! fit and exits with the arena-exhausted code, without a panic; with a model that does not fit
//! the memory map, it names the region and exits with the bad-input code; with a step scratch
//! too small for the bundle's step, the load-time rehearsal stops it before the first step.

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
    assert!(stderr.contains("its 1000000 bytes"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn arena_too_large_for_the_static_storage_is_bad_input() {
    let (code, stderr) = drive(&["--arena-bytes", "999999999999"]);
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{stderr}");
    assert!(stderr.contains("--arena-bytes"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Issue 38, part 1: a graph whose step needs more than the layout's step scratch is refused at
/// load (the rehearsal), with the region named, not at some later step.
#[test]
fn small_step_scratch_is_refused_at_load_naming_the_region() {
    let (code, stderr) = drive(&["--step-scratch-bytes", "1000000"]);
    assert_eq!(code, Some(EXIT_ARENA_EXHAUSTED), "{stderr}");
    assert!(
        stderr.contains("region `step_scratch` does not fit"),
        "{stderr}"
    );
    assert!(stderr.contains("--step-scratch-bytes"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn step_scratch_larger_than_the_static_region_is_bad_input() {
    for bytes in ["0", "999999999999"] {
        let (code, stderr) = drive(&["--step-scratch-bytes", bytes]);
        assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{bytes}: {stderr}");
        assert!(stderr.contains("--step-scratch-bytes"), "{stderr}");
    }
}
