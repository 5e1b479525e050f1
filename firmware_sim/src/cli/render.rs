//! `satmap-sim render`: pictures of a scenario: for each frame the satellite crop with ground
//! truth and (optionally) predictions, a contact sheet, camera sheets, and GeoJSON of the
//! predictions and ground truth in the route frame.
//!
//! Each frame's pose is checked before anything is drawn from it: the crop samples the world
//! raster at the pose, so a pose far outside any world (`x_m = 1e308`) is refused, naming its
//! `frame.toml`, instead of reaching pixel arithmetic.

use std::path::{Path, PathBuf};

use satmap_runtime::pose::EgoPose;
use satmap_runtime::satellite::{CropSpec, SatelliteSource};

use crate::eval::{SampleSet, read_samples};
use crate::render::{
    camera_sheet, contact_sheet, frame_features, render_frame, route_frame_geojson,
};
use crate::synth::scenario::{Scenario, frame_dir_name};

/// Arguments of `render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scenario folder.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Predictions: MapTR results JSON keyed by frame folder name (`000000`, ...).
    #[arg(long)]
    pub predictions: Option<PathBuf>,
    /// Output folder.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Render every n-th frame (at least 1).
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Also write the camera images of each rendered frame as a sheet.
    #[arg(long)]
    pub cameras: bool,
}

/// Farthest a frame's ego position may lie from the route frame's origin, metres: the route
/// frame is a local tangent plane of one drive, and 1000 km is far beyond any drive it serves.
pub const MAX_ROUTE_OFFSET_M: f64 = 1e6;

/// Why `render` stopped. Messages name the file; each cause is printed once (the underlying
/// error is flattened into the message, not chained).
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The scenario, one of its frames or the predictions could not be read.
    #[error("{0}")]
    Input(String),
    /// A frame's pose is not finite or lies too far from the route origin.
    #[error(
        "{path}: ego pose x_m {x_m:?}, y_m {y_m:?}, yaw_rad {yaw_rad:?} must be finite and \
         within {MAX_ROUTE_OFFSET_M:?} m of the route origin"
    )]
    BadPose {
        /// The frame's `frame.toml`.
        path: PathBuf,
        /// Ego east, metres.
        x_m: f64,
        /// Ego north, metres.
        y_m: f64,
        /// Heading, radians.
        yaw_rad: f64,
    },
    /// `--every 0`.
    #[error("--every {0} must be at least 1")]
    Every(usize),
    /// An output could not be written.
    #[error("writing {path}: {message}")]
    Write {
        /// The output file or folder.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

impl RenderError {
    /// True for errors in the input (exit code 2), false for output failures.
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        !matches!(self, Self::Write { .. })
    }
}

/// Refuse a pose the crop cannot sample: non-finite, or farther than
/// [`MAX_ROUTE_OFFSET_M`] from the origin on either axis.
///
/// # Errors
/// [`RenderError::BadPose`] naming `path`.
pub fn check_pose(pose: &EgoPose, path: &Path) -> Result<(), RenderError> {
    let p = pose.position_m;
    let near = |v: f64| v.abs() <= MAX_ROUTE_OFFSET_M;
    if near(p.x) && near(p.y) && pose.yaw_rad.is_finite() {
        Ok(())
    } else {
        Err(RenderError::BadPose {
            path: path.to_owned(),
            x_m: p.x,
            y_m: p.y,
            yaw_rad: pose.yaw_rad,
        })
    }
}

/// The SatMap crop: 100 x 200 px at 0.3 m over x in [-15, 15], y in [-30, 30].
#[must_use]
pub fn satmap_crop_spec() -> CropSpec {
    CropSpec {
        height_px: 200,
        width_px: 100,
        gsd_m: 0.3,
        x_min_m: -15.0,
        y_min_m: -30.0,
    }
}

/// Render the pictures (the subcommand's entry point; see [`render`]).
///
/// # Errors
/// A [`RenderError`].
pub fn run(args: &Args) -> anyhow::Result<()> {
    Ok(render(args)?)
}

/// Render the pictures.
///
/// # Errors
/// [`RenderError`]: unreadable scenario or predictions, a frame with an unusable pose, `--every
/// 0`, or an output that cannot be written.
pub fn render(args: &Args) -> Result<(), RenderError> {
    if args.every == 0 {
        return Err(RenderError::Every(args.every));
    }
    let input = |e: &dyn std::fmt::Display| RenderError::Input(e.to_string());
    let scenario = Scenario::open(&args.scenario).map_err(|e| input(&e))?;
    let predictions: SampleSet = match &args.predictions {
        Some(p) => read_samples(p).map_err(|e| input(&e))?,
        None => SampleSet::new(),
    };
    // Synthetic scenarios crop their own satellite raster; others are drawn on grey.
    let drive = scenario
        .regenerate()
        .transpose()
        .map_err(|e| input(&format!("{}: {e}", args.scenario.display())))?;
    std::fs::create_dir_all(&args.out).map_err(|e| write_error(&args.out, &e))?;
    let spec = satmap_crop_spec();
    let mut crop = vec![0u8; spec.height_px * spec.width_px * 3];
    let mut pictures = Vec::new();
    let mut pred_features = Vec::new();
    let mut gt_features = Vec::new();
    let m = &scenario.manifest;
    for i in (0..m.num_frames).step_by(args.every) {
        let frame = scenario.read_frame(i).map_err(|e| input(&e))?;
        let name = frame_dir_name(i);
        check_pose(
            &frame.pose,
            &scenario.dir.join("frames").join(&name).join("frame.toml"),
        )?;
        let preds = predictions.get(&name).cloned().unwrap_or_default();
        match &drive {
            Some(d) => {
                d.satellite_source().crop(&frame.pose, &spec, &mut crop);
            }
            None => crop.fill(110),
        }
        let pic = render_frame(&crop, &spec, &preds, &frame.ground_truth);
        save(&pic, &args.out.join(format!("frame_{name}.png")))?;
        if args.cameras {
            let sheet = camera_sheet(&frame.images, m.image_width_px, m.image_height_px);
            save(&sheet, &args.out.join(format!("cameras_{name}.png")))?;
        }
        pred_features.extend(frame_features(&frame.pose, &preds, frame.sequence));
        gt_features.extend(frame_features(
            &frame.pose,
            &frame.ground_truth,
            frame.sequence,
        ));
        pictures.push(pic);
    }
    let step = pictures.len().div_ceil(20).max(1);
    let chosen: Vec<_> = pictures.into_iter().step_by(step).collect();
    save(
        &contact_sheet(&chosen, 5, 6),
        &args.out.join("contact_sheet.png"),
    )?;
    for (name, features) in [
        ("predictions.geojson", pred_features),
        ("ground_truth.geojson", gt_features),
    ] {
        let path = args.out.join(name);
        std::fs::write(&path, route_frame_geojson(features).to_string())
            .map_err(|e| write_error(&path, &e))?;
    }
    println!("wrote {} pictures to {}", chosen.len(), args.out.display());
    Ok(())
}

fn write_error(path: &Path, e: &dyn std::fmt::Display) -> RenderError {
    RenderError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

fn save(img: &image::RgbImage, path: &Path) -> Result<(), RenderError> {
    img.save(path).map_err(|e| write_error(path, &e))
}
