//! The image's program on the host (x86-64 with std): every digest equal to the expected ones
//! and exit status 0, as the bare-metal images must print under emulation
//! (`targets/baremetal.sh`, which also prints this program's lines beside theirs).

use std::process::Command;

#[test]
fn the_host_program_reports_every_digest_equal() {
    let out = Command::new(env!("CARGO_BIN_EXE_satmap-baremetal"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    print!("{stdout}");
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("core check: 8 of 8 digests equal to the host's"),
        "{stdout}"
    );
}
