//! Shared by the command-line tests: run the `satmap-sim` binary of this build.

use std::process::Command;

/// Run `satmap-sim` with `args`: its exit code (`None` if killed), stdout and stderr.
pub fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_satmap-sim"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
