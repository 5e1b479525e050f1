//! The long-route path from the command line: `build-pack --synthetic-km` writes a compressed
//! pack of a procedural road, `drive --satellite-only` replays the satellite path along all of
//! it and reports the worst step against the `satellite_crop` budget (exit 0 within it), and
//! bad settings are refused as bad input (exit 2) before any work.

use crate::common::run;
use satmap_sim::harness::EXIT_BAD_INPUT;

const BUNDLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/bundles/test");
const CROP_03: [&str; 8] = [
    "--gsd-m",
    "0.3",
    "--crop-h-px",
    "200",
    "--crop-w-px",
    "100",
    "--crop-gsd-m",
    "0.3",
];

#[test]
fn a_synthetic_jpeg_pack_is_built_and_replayed_along_its_whole_route() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("r2.smrp");
    let pack = pack.to_str().unwrap();
    let mut args = vec![
        "build-pack",
        "--synthetic-km",
        "2",
        "--seed",
        "4",
        "--quiet",
    ];
    args.extend(CROP_03);
    args.extend(["--codec", "jpeg", "-o", pack]);
    let (code, out, err) = run(&args);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains("route 2.00 km") && out.contains("PSNR"),
        "{out}"
    );
    let (code, out, err) = run(&[
        "drive",
        "--bundle",
        BUNDLE,
        "--satellite-only",
        pack,
        "--speed-mps",
        "20",
        "--drive-hz",
        "10",
        "--json",
    ]);
    assert_eq!(code, Some(0), "{out}{err}");
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    // 2 km at 2 m a step.
    assert_eq!(report["steps"], 1001, "{report}");
    // 1e-308 m/s panicked (the step count overflowed); every speed below 0.1 m/s is refused.
    for speed in ["1e-308", "0.05", "0", "nan", "100"] {
        let (code, _, err) = run(&[
            "drive",
            "--bundle",
            BUNDLE,
            "--satellite-only",
            pack,
            "--speed-mps",
            speed,
        ]);
        assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{speed}: {err}");
        // The CLI's own range ([0, 60)) or the replay's floor (0.1 m/s) names the speed.
        assert!(err.contains("speed"), "{speed}: {err}");
    }
    assert_eq!(report["codec"], "jpeg");
    assert_eq!(report["not_full_steps"], 0, "{report}");
    assert!(report["decoded_tiles"].as_u64().unwrap() > 0);
    assert!(report["max_route_segments_per_step"].as_u64().unwrap() <= 4369);
    assert_eq!(report["budget_us"], 20_000);
}

#[test]
fn bad_long_route_settings_are_refused_as_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("x.smrp");
    let out_path = out_path.to_str().unwrap();
    for km in ["0", "-3", "250", "nan"] {
        let (code, _, err) = run(&[
            "build-pack",
            "--synthetic-km",
            km,
            "--quiet",
            "-o",
            out_path,
        ]);
        assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{km}: {err}");
    }
    let (code, _, err) = run(&[
        "build-pack",
        "--synthetic-km",
        "1",
        "--codec",
        "jpeg",
        "--jpeg-quality",
        "0",
        "-o",
        out_path,
    ]);
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{err}");
    assert!(err.contains("--jpeg-quality"), "{err}");
    // A drive over a file that is not a pack.
    std::fs::write(dir.path().join("junk"), b"not a pack").unwrap();
    let junk = dir.path().join("junk");
    let (code, _, err) = run(&[
        "drive",
        "--bundle",
        BUNDLE,
        "--satellite-only",
        junk.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{err}");
    assert!(err.contains("route pack"), "{err}");
}
