//! `satmap-sim synth-drive`: generate a seeded synthetic drive and write it as a scenario folder
//! (`synth/SCENARIO.md`): tiles, route GeoJSON, per-frame images, pose, CAN bus and ground truth;
//! optionally pictures of the ground truth over the satellite crop and camera contact sheets.

use std::path::PathBuf;

use anyhow::{Context, Result};
use satmap_runtime::calibration::from_toml_file;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::satellite::SatelliteSource;

use crate::render::{camera_sheet, contact_sheet, render_frame};
use crate::synth::drive::{DriveConfig, SyntheticDrive};
use crate::synth::lighting::LightingPreset;
use crate::synth::scenario::{ScenarioPlacement, frame_dir_name, write_scenario};

/// Arguments of `synth-drive`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output scenario folder.
    #[arg(long, short)]
    pub out: PathBuf,
    /// World and drive seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of frames.
    #[arg(long, default_value_t = 100)]
    pub frames: usize,
    /// Frame rate, Hz.
    #[arg(long, default_value_t = 10.0)]
    pub fps: f64,
    /// Mean speed, m/s.
    #[arg(long, default_value_t = 8.0)]
    pub speed_mps: f64,
    /// Camera image width, pixels.
    #[arg(long, default_value_t = 320)]
    pub image_width: usize,
    /// Camera image height, pixels.
    #[arg(long, default_value_t = 180)]
    pub image_height: usize,
    /// Lighting (default: chosen by the seed).
    #[arg(long, value_enum)]
    pub lighting: Option<LightingPreset>,
    /// Calibration TOML (default: the built-in nuScenes-like rig).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Latitude of the route-frame origin, degrees.
    #[arg(long, default_value_t = 42.3505, allow_hyphen_values = true)]
    pub anchor_lat: f64,
    /// Longitude of the route-frame origin, degrees.
    #[arg(long, default_value_t = -71.0454, allow_hyphen_values = true)]
    pub anchor_lon: f64,
    /// Slippy-map zoom of the tiles.
    #[arg(long, default_value_t = 19)]
    pub zoom: u8,
    /// Ground raster resolution, metres per pixel.
    #[arg(long, default_value_t = 0.2)]
    pub raster_gsd_m: f64,
    /// Also write `pictures/`: ground truth over the satellite crop per frame, camera sheets
    /// and a contact sheet.
    #[arg(long)]
    pub pictures: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Generate and write the drive.
///
/// # Errors
/// Bad settings, an unreadable calibration, or a file that cannot be written.
pub fn run(args: &Args) -> Result<()> {
    check_placement(args)?;
    let config = DriveConfig {
        image_width_px: args.image_width,
        image_height_px: args.image_height,
        num_frames: args.frames,
        frame_rate_hz: args.fps,
        mean_speed_mps: args.speed_mps,
        lighting: args.lighting,
        raster_gsd_m: args.raster_gsd_m,
        ..DriveConfig::default()
    };
    let drive = match &args.calibration {
        Some(path) => {
            let cal = from_toml_file(path)?;
            SyntheticDrive::with_calibration(args.seed, config, cal)?
        }
        None => SyntheticDrive::new(args.seed, config)?,
    };
    let placement = ScenarioPlacement {
        anchor: Geodetic::new(args.anchor_lat, args.anchor_lon, 0.0),
        tile_zoom: args.zoom,
    };
    let bar = progress_bar(args.frames as u64, args.quiet);
    write_scenario(&drive, &args.out, &placement, |_| bar.inc(1))
        .with_context(|| format!("writing scenario {}", args.out.display()))?;
    bar.finish_and_clear();
    if args.pictures {
        write_pictures(&drive, &args.out.join("pictures"))?;
    }
    println!(
        "wrote {} frames ({}x{}, {:?}) to {}",
        drive.len(),
        args.image_width,
        args.image_height,
        drive.lighting_preset(),
        args.out.display()
    );
    Ok(())
}

/// Largest |latitude| of the anchor, degrees: Web Mercator tiles shrink by cos(latitude), so
/// near the poles a world needs thousands of times more tiles (at 90 deg, infinitely many).
pub const MAX_ANCHOR_LAT_DEG: f64 = 80.0;
/// Tile zooms accepted: 15 (4.8 m/px at the equator) to 21 (0.075 m/px); beyond 21 one world
/// is tens of thousands of tiles.
pub const TILE_ZOOMS: std::ops::RangeInclusive<u8> = 15..=21;

/// Refuse an anchor or zoom whose tile set would not be finite or reasonable, before any work.
fn check_placement(args: &Args) -> Result<()> {
    let bad = |m: String| Err(crate::cli::drive::BadArgument(m).into());
    if !(-MAX_ANCHOR_LAT_DEG..=MAX_ANCHOR_LAT_DEG).contains(&args.anchor_lat) {
        return bad(format!(
            "--anchor-lat {} must be within +-{MAX_ANCHOR_LAT_DEG} degrees",
            args.anchor_lat
        ));
    }
    if !(-180.0..=180.0).contains(&args.anchor_lon) {
        return bad(format!(
            "--anchor-lon {} must be within +-180 degrees",
            args.anchor_lon
        ));
    }
    if !TILE_ZOOMS.contains(&args.zoom) {
        return bad(format!(
            "--zoom {} must be in {}..={}",
            args.zoom,
            TILE_ZOOMS.start(),
            TILE_ZOOMS.end()
        ));
    }
    Ok(())
}

/// Ground truth over the satellite crop for every frame, camera sheets every 10th frame, and a
/// contact sheet of every 10th picture.
fn write_pictures(drive: &SyntheticDrive, dir: &std::path::Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    let spec = crate::cli::render::satmap_crop_spec();
    let mut crop = vec![0u8; spec.height_px * spec.width_px * 3];
    let mut sheet = Vec::new();
    for (i, frame) in drive.frames().enumerate() {
        drive.satellite_source().crop(&frame.pose, &spec, &mut crop);
        let pic = render_frame(&crop, &spec, &[], &frame.ground_truth);
        let name = frame_dir_name(i);
        let path = dir.join(format!("gt_{name}.png"));
        pic.save(&path)
            .with_context(|| path.display().to_string())?;
        if i % 10 == 0 {
            let cams = camera_sheet(
                &frame.images,
                drive.config().image_width_px,
                drive.config().image_height_px,
            );
            let path = dir.join(format!("cameras_{name}.png"));
            cams.save(&path)
                .with_context(|| path.display().to_string())?;
            sheet.push(pic);
        }
    }
    let path = dir.join("contact_sheet.png");
    contact_sheet(&sheet, 5, 6)
        .save(&path)
        .with_context(|| path.display().to_string())?;
    Ok(())
}

fn progress_bar(len: u64, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames {elapsed}")
    {
        bar.set_style(style);
    }
    bar
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn args(extra: &[&str]) -> Args {
        let mut argv = vec!["synth-drive", "--out", "/nonexistent/never-written"];
        argv.extend_from_slice(extra);
        Cli::parse_from(argv).args
    }

    #[test]
    fn poles_bad_longitudes_and_huge_zooms_are_refused_before_any_work() {
        for extra in [
            &["--anchor-lat", "90"][..],
            &["--anchor-lat", "-85"],
            &["--anchor-lat", "NaN"],
            &["--anchor-lon", "181"],
            &["--zoom", "30"],
            &["--zoom", "3"],
        ] {
            let e = run(&args(extra)).unwrap_err();
            assert!(
                e.downcast_ref::<crate::cli::drive::BadArgument>().is_some(),
                "{extra:?}: {e:#}"
            );
        }
        assert!(check_placement(&args(&["--anchor-lat", "69.6", "--zoom", "21"])).is_ok());
    }
}
