//! Inputs that used to panic or pass silently, each turned into a clear refusal: `drive`'s
//! numeric arguments out of range (exit 2, the argument named), `render` over a frame at
//! `x_m = 1e308` (exit 2, the frame file named; it overflowed in the world raster), and a
//! `drive` whose every step runs without the satellite prior (exit 5, the reason named; it
//! exited 0 silently). The case was a pack of 8-64 px tiles (every crop `TooManyTiles`);
//! the route-pack builder now refuses such tiles, so the pack here is of another place (every
//! crop finds no coverage). The crop-fault reasons are covered by `harness::degraded`'s tests.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::common::run;
use satmap_runtime::geo::Geodetic;
use satmap_sim::harness::world_imagery::RasterImagery;
use satmap_sim::harness::{EXIT_BAD_INPUT, EXIT_DEGRADED};
use satmap_sim::route_pack_builder::{BuildOptions, build_pack, parse_route_geojson};
use satmap_sim::synth::scenario::{ScenarioPlacement, route_geojson};
use satmap_sim::synth::{DriveConfig, SyntheticDrive, write_scenario};

const FRAMES: usize = 3;

fn bundle() -> &'static str {
    concat!(env!("CARGO_MANIFEST_DIR"), "/../models/bundles/test")
}

/// The scenarios' drive: seed 7, [`FRAMES`] frames at 2 Hz.
fn seven() -> SyntheticDrive {
    SyntheticDrive::new(
        7,
        DriveConfig {
            num_frames: FRAMES,
            frame_rate_hz: 2.0,
            ..DriveConfig::default()
        },
    )
    .unwrap()
}

/// `drive` over the scenario folder `dir`, its 3 frames at 1 Hz, with one output flag.
fn drive_scenario(dir: &Path, output_flag: &str) -> (Option<i32>, String, String) {
    run(&[
        "drive",
        "--bundle",
        bundle(),
        "--scenario",
        dir.to_str().unwrap(),
        "--frames",
        "3",
        "--rate-hz",
        "1",
        output_flag,
    ])
}

/// A 3-frame synthetic scenario folder in Boston whose manifest names a route pack of the same
/// world placed one degree (111 km) further north: no crop of the drive touches its tiles.
/// Written once, shared by the tests.
fn scenario_with_a_pack_elsewhere() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("satmap_cli_refusals_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let drive = seven();
        let placement = ScenarioPlacement::default();
        write_scenario(&drive, &dir, &placement, |_| {}).unwrap();
        let a = placement.anchor;
        let elsewhere = Geodetic::new(a.lat_deg + 1.0, a.lon_deg, a.height_m);
        let route =
            parse_route_geojson(&route_geojson(&drive, elsewhere), Path::new("<drive>")).unwrap();
        let mut imagery = RasterImagery::new(drive.satellite(), elsewhere);
        let pack = build_pack(
            &mut imagery,
            &route,
            &BuildOptions {
                corridor_width_m: 80.0,
                ..BuildOptions::default()
            },
        )
        .unwrap();
        std::fs::write(dir.join("elsewhere.pack"), &pack.bytes).unwrap();
        let manifest_path = dir.join("scenario.toml");
        let mut manifest: toml::Table = std::fs::read_to_string(&manifest_path)
            .unwrap()
            .parse()
            .unwrap();
        manifest.insert("route_pack".into(), "elsewhere.pack".into());
        std::fs::write(&manifest_path, toml::to_string(&manifest).unwrap()).unwrap();
        dir
    })
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

#[test]
fn drive_numeric_arguments_out_of_range_are_refused_naming_the_argument() {
    for (flag, value) in [
        ("--frames", "0"),
        ("--frames", "100001"),
        ("--speed-mps", "NaN"),
        ("--speed-mps", "-1"),
        ("--speed-mps", "60"),
        ("--drive-hz", "0"),
        ("--drive-hz", "inf"),
        ("--drive-hz", "1e-300"),
        ("--rate-hz", "1e-300"),
        ("--rate-hz", "NaN"),
        ("--arena-bytes", "0"),
        ("--max-degraded-share", "-0.1"),
        ("--max-degraded-share", "1.5"),
        ("--max-degraded-share", "NaN"),
    ] {
        let arg = format!("{flag}={value}");
        let (code, _, stderr) = run(&["drive", "--bundle", bundle(), "--quiet", &arg]);
        assert_eq!(
            code,
            Some(i32::from(EXIT_BAD_INPUT)),
            "{flag} {value}: {stderr}"
        );
        assert!(
            stderr.contains(&format!("error: {flag} ")) && stderr.contains(" must be in "),
            "{flag} {value}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn render_refuses_a_frame_at_1e308_naming_its_file() {
    let dir = std::env::temp_dir().join(format!("satmap_cli_render_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    copy_dir(scenario_with_a_pack_elsewhere(), &dir);
    let frame = dir.join("frames/000001/frame.toml");
    let mut record: toml::Table = std::fs::read_to_string(&frame).unwrap().parse().unwrap();
    record.insert("x_m".into(), 1e308.into());
    std::fs::write(&frame, toml::to_string(&record).unwrap()).unwrap();
    let out = dir.join("pictures");
    let (code, _, stderr) = run(&[
        "render",
        "--scenario",
        dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains(&format!("{}: ego pose x_m 1e308", frame.display())),
        "{stderr}"
    );
    // Frame 0 was fine and was drawn before frame 1 was refused.
    assert!(out.join("frame_000000.png").is_file());
    assert!(!out.join("frame_000001.png").exists());

    let (code, _, stderr) = run(&[
        "render",
        "--scenario",
        dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--every",
        "0",
    ]);
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{stderr}");
    assert!(stderr.contains("--every 0 must be at least 1"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn drive_over_a_pack_of_another_place_exits_degraded_naming_the_reason() {
    let dir = scenario_with_a_pack_elsewhere();
    let (code, stdout, stderr) = drive_scenario(dir, "--json");
    assert_eq!(code, Some(i32::from(EXIT_DEGRADED)), "{stderr}");
    assert!(
        stderr.contains(
            "degraded run: 3 of 3 steps (100.0%) ran without the satellite prior, more than the \
             stated 5.0% (--max-degraded-share 0.05): no coverage (no imagery in the route pack \
             under the crop) 3 (100.0%)"
        ),
        "{stderr}"
    );
    let report: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let d = &report["degraded"];
    assert_eq!(d["steps"], 3);
    assert_eq!(d["share"], 1.0);
    assert_eq!(d["max_share"], 0.05);
    assert_eq!(d["over_limit"], true);
    assert_eq!(
        d["by_reason"],
        serde_json::json!([{ "reason": "no_coverage", "steps": 3, "share": 1.0 }])
    );
    for step in report["steps"].as_array().unwrap() {
        assert_eq!(step["degraded"], true);
        assert_eq!(step["degraded_reason"], "no_coverage");
    }
}

/// The case: a pack of tiles too small for the model's crop (the builder accepts 16 px
/// tiles for a 40 x 20 px crop it was told of, but the `test` model crops 200 x 100 px at 0.3 m)
/// made every crop `TooManyTiles` and the drive ran degraded. `drive` now refuses it at load.
#[test]
fn drive_refuses_a_pack_whose_tiles_cannot_serve_the_models_crop() {
    let dir = std::env::temp_dir().join(format!("satmap_cli_tiles_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    copy_dir(scenario_with_a_pack_elsewhere(), &dir);
    let drive = seven();
    let anchor = ScenarioPlacement::default().anchor;
    let route = parse_route_geojson(&route_geojson(&drive, anchor), Path::new("<drive>")).unwrap();
    let mut imagery = RasterImagery::new(drive.satellite(), anchor);
    let small_crop = satmap_runtime::CropSpec {
        height_px: 40,
        width_px: 20,
        gsd_m: 0.15,
        x_min_m: -1.5,
        y_min_m: -3.0,
    };
    let pack = build_pack(
        &mut imagery,
        &route,
        &BuildOptions {
            corridor_width_m: 20.0,
            tile_size_px: 16,
            crop: small_crop,
            ..BuildOptions::default()
        },
    )
    .unwrap();
    std::fs::write(dir.join("elsewhere.pack"), &pack.bytes).unwrap();
    let (code, _, stderr) = drive_scenario(&dir, "--quiet");
    assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{stderr}");
    assert!(
        stderr.contains("its tiles cannot serve the model's satellite crop (TooManyTiles"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Drive settings that hung (`--image-width 100000`: six 100000 x 180 renders a frame;
/// `--fps 1e-300`: a road of 1e301 m generated up front) or wrote an empty drive (`--frames 0`)
/// are refused before any work, as bad input.
#[test]
fn synth_drive_settings_that_hung_are_refused_before_any_work() {
    let out = std::env::temp_dir().join(format!("satmap_cli_synth_{}", std::process::id()));
    for (flag, value, why) in [
        (
            "--image-width",
            "100000",
            "image width and height must be in 8..=4096 px",
        ),
        (
            "--image-height",
            "4",
            "image width and height must be in 8..=4096 px",
        ),
        ("--frames", "0", "num_frames must be in 1..=100000"),
        ("--fps", "1e-300", "frame_rate_hz must be in [0.01, 100]"),
        ("--fps", "1e300", "frame_rate_hz must be in [0.01, 100]"),
        ("--fps", "NaN", "frame_rate_hz must be in [0.01, 100]"),
        (
            "--fps",
            "0.01",
            "the drive needs a road longer than 100 km (frames / rate x speed)",
        ),
    ] {
        let arg = format!("{flag}={value}");
        let frames = if flag == "--frames" {
            &arg
        } else {
            "--frames=200"
        };
        let mut args = vec![
            "synth-drive",
            "--out",
            out.to_str().unwrap(),
            "--quiet",
            frames,
        ];
        if flag != "--frames" {
            args.push(&arg);
        }
        let (code, _, stderr) = run(&args);
        assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{arg}: {stderr}");
        assert_eq!(stderr, format!("error: drive config: {why}\n"), "{arg}");
    }
    assert!(!out.join("scenario.toml").exists());
}

/// `bench-stages --threads 1000000` aborted the process and `--repeats 1000000` ran unbounded:
/// both are refused as bad input before the bundle is loaded.
#[test]
fn bench_stages_bounds_threads_and_repeats() {
    for (flag, value) in [
        ("--threads", "1000000"),
        ("--threads", "65"),
        ("--repeats", "1000000"),
        ("--repeats", "0"),
    ] {
        let (code, _, err) = run(&["bench-stages", "--bundle", bundle(), flag, value]);
        assert_eq!(
            code,
            Some(i32::from(EXIT_BAD_INPUT)),
            "{flag} {value}: {err}"
        );
        assert!(err.contains(flag), "{flag} {value}: {err}");
    }
}

/// `scenario.toml` paths that leave the scenario folder (`..`, absolute) are refused by name
/// before anything they point at is read; a calibration given as `/dev/zero` or a results file
/// given as a named pipe is refused unread (it ran to the memory cap, or blocked).
#[test]
fn scenario_paths_stay_inside_and_devices_and_pipes_are_never_read() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("s");
    write_scenario(&seven(), &scenario, &ScenarioPlacement::default(), |_| {}).unwrap();
    let manifest = std::fs::read_to_string(scenario.join("scenario.toml")).unwrap();
    for (field, bad) in [
        ("calibration_file", "../../../etc/passwd"),
        ("ground_truth_json", "/etc/passwd"),
        ("tiles_dir", "tiles/../../x"),
    ] {
        let line = manifest
            .lines()
            .find(|l| l.starts_with(&format!("{field} = ")))
            .unwrap();
        let edited = manifest.replace(line, &format!("{field} = {bad:?}"));
        std::fs::write(scenario.join("scenario.toml"), edited).unwrap();
        let (code, _, err) = drive_scenario(&scenario, "--json");
        assert_eq!(code, Some(i32::from(EXIT_BAD_INPUT)), "{field}: {err}");
        assert!(
            err.contains(&format!("`{field}` is not a path inside")),
            "{err}"
        );
    }
    std::fs::write(scenario.join("scenario.toml"), &manifest).unwrap();

    let fifo = dir.path().join("results.fifo");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    for (args, what) in [
        (
            vec!["memory-map", "--layout", "/dev/zero"],
            "not a regular file",
        ),
        (
            vec![
                "evaluate",
                "--predictions",
                fifo.to_str().unwrap(),
                "--gt",
                fifo.to_str().unwrap(),
            ],
            "not a regular file",
        ),
    ] {
        let (code, _, err) = run(&args);
        assert_ne!(code, Some(0), "{args:?}: {err}");
        assert!(err.contains(what), "{args:?}: {err}");
    }
}
