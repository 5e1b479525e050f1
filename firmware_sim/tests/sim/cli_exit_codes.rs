//! Issue 38, part 5: bad input exits 2 (the README's contract) in every tool, not 1. Each case
//! here exited 1 before: a layout file that is missing or invalid given to `compile` or
//! `memory-map`, a folder that is already compiled, predictions or ground truth that cannot be
//! read or scored, a bundle without its reference inputs for `bench-stages`, a calibration file
//! that is missing or invalid, overlapping seed splits and out-of-range frame counts for
//! `export-dataset`. And an `export-dataset` refused for its drive settings writes nothing (it
//! used to leave an `index.json` whose knobs then refused every corrected resume).

use std::path::Path;

use crate::common::run;
use satmap_sim::harness::EXIT_BAD_INPUT;

fn bundles() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/bundles"))
}

fn repo(rel: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(rel)
        .display()
        .to_string()
}

#[test]
fn bad_input_in_every_tool_exits_2_naming_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let file = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    let bad_toml = file("bad.toml", "x = [");
    let bad_json = file("bad.json", "not json");
    let empty_json = file("empty.json", "{}");
    let missing = dir.path().join("missing.toml").display().to_string();
    let out = dir.path().join("out").display().to_string();
    let folder = bundles().join("test").display().to_string();
    let compiled = bundles().join("test.satmap").display().to_string();
    // No reference inputs are committed beside the int8 form.
    let int8 = bundles().join("test-int8.satmap").display().to_string();
    let bad_bytes_layout = repo("tests/layouts/bad_bytes.toml");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "compile", "--bundle", &folder, "--out", &out, "--layout", &bad_toml,
            ],
            "does not parse",
        ),
        (
            vec![
                "compile", "--bundle", &folder, "--out", &out, "--layout", &missing,
            ],
            "missing.toml",
        ),
        (
            vec!["compile", "--bundle", &compiled, "--out", &out],
            "already a compiled bundle",
        ),
        (
            vec!["drive", "--frames", "1", "--bev-storage", "bf16"],
            "give f32 or f16",
        ),
        (vec!["memory-map", "--layout", &bad_toml], "does not parse"),
        (vec!["memory-map", "--layout", &missing], "missing.toml"),
        (
            vec!["memory-map", "--layout", &bad_bytes_layout],
            "region `value_features` declares",
        ),
        (
            vec!["evaluate", "--predictions", &bad_json, "--gt", &empty_json],
            "invalid results JSON",
        ),
        (
            vec![
                "evaluate",
                "--predictions",
                &empty_json,
                "--gt",
                &empty_json,
            ],
            "not a results file",
        ),
        (
            vec!["evaluate", "--predictions", &missing, "--gt", &empty_json],
            "missing.toml",
        ),
        (
            vec!["bench-stages", "--bundle", &int8, "--repeats", "1"],
            "reference.safetensors",
        ),
        (
            vec![
                "synth-drive",
                "--out",
                &out,
                "--frames",
                "2",
                "--calibration",
                &missing,
            ],
            "cannot read calibration file",
        ),
        (
            vec![
                "synth-drive",
                "--out",
                &out,
                "--frames",
                "2",
                "--calibration",
                &bad_toml,
            ],
            "calibration TOML",
        ),
        (
            vec![
                "export-dataset",
                "--out",
                &out,
                "--train-seeds",
                "1..3",
                "--val-seeds",
                "2..4",
                "--test-seeds",
                "5..6",
                "--frames",
                "2",
            ],
            "seed ranges overlap",
        ),
        (
            vec!["export-dataset", "--out", &out, "--frames", "0"],
            "--frames",
        ),
        (
            vec![
                "export-dataset",
                "--out",
                &out,
                "--frames",
                "2",
                "--drive-hz",
                "0",
            ],
            "frame_rate_hz",
        ),
    ];
    for (args, named) in &cases {
        let (code, _, stderr) = run(args);
        assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{args:?}: {stderr}");
        assert!(
            stderr.contains(named),
            "{args:?} should name {named}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    // None of the refusals wrote an output (export-dataset's index.json included).
    assert!(!Path::new(&out).exists(), "a refused command wrote {out}");
}
