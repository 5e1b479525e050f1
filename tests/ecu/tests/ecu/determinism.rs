//! Steps alternating the two golden frames over the compiled bundle: every even step repeats
//! step 0's digest and every odd step step 1's, and a second process computes the same digests.
//! `SATMAP_DETERMINISM_STEPS` sets the count (200 by default; the emulated aarch64 run in CI
//! takes a slice, see the Makefile's `test-aarch64`).
//!
//! Under user-mode emulation the child cannot be executed directly (no binfmt handler is
//! registered on a CI machine): `SATMAP_TEST_RUNNER` (set by `targets/cross.env`) names the
//! emulator to start it with, as cargo's runner started the parent.

use std::process::{Command, Stdio};

use satmap_ecu_tests::golden::compiled_engine;
use satmap_ecu_tests::parity::alternating_digests;

fn steps() -> usize {
    std::env::var("SATMAP_DETERMINISM_STEPS")
        .ok()
        .map(|s| s.parse().expect("SATMAP_DETERMINISM_STEPS is a count"))
        .unwrap_or(200)
}

/// This test binary as a child process, through the emulator where one is named.
fn this_binary() -> Command {
    let exe = std::env::current_exe().unwrap();
    match std::env::var("SATMAP_TEST_RUNNER") {
        Ok(runner) if !runner.trim().is_empty() => {
            let mut parts = runner.split_whitespace();
            let mut cmd = Command::new(parts.next().unwrap());
            cmd.args(parts).arg(exe);
            cmd
        }
        _ => Command::new(exe),
    }
}

#[test]
fn steps_are_bit_identical_within_and_across_processes() {
    let steps = steps();
    assert!(steps >= 2, "at least one step of each frame");
    // The child starts first so that its steps overlap the parent's on a second core.
    let child = this_binary()
        .args([
            "--exact",
            "determinism::child_process_digests",
            "--ignored",
            "--nocapture",
        ])
        .env("SATMAP_DIGEST_CHILD", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let d = alternating_digests(compiled_engine(), steps);
    assert_ne!(d[0], d[1], "the two frames differ");
    for (i, x) in d.iter().enumerate() {
        assert_eq!(*x, d[i % 2], "step {i}");
    }
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("DIGESTS "))
        .expect("child printed its digests");
    let child: Vec<u64> = line.split(',').map(|s| s.parse().unwrap()).collect();
    assert_eq!(child, d);
    println!(
        "{steps} steps bit-identical in two processes on {}: {:016x} {:016x}",
        satmap_runtime::engine_tract::kernel_family(),
        d[0],
        d[1]
    );
}

/// Run by the parent test in a second process.
#[test]
#[ignore = "spawned by steps_are_bit_identical_within_and_across_processes"]
fn child_process_digests() {
    assert!(
        std::env::var_os("SATMAP_DIGEST_CHILD").is_some(),
        "run only as the child of steps_are_bit_identical_within_and_across_processes"
    );
    let d = alternating_digests(compiled_engine(), steps());
    let line: Vec<String> = d.iter().map(u64::to_string).collect();
    println!("DIGESTS {}", line.join(","));
}
