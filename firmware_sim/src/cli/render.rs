//! `satmap-sim render`: pictures of a scenario: for each frame the satellite crop with ground
//! truth and (optionally) predictions, a contact sheet, camera sheets, and GeoJSON of the
//! predictions and ground truth in the route frame.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
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
    /// Render every n-th frame.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Also write the camera images of each rendered frame as a sheet.
    #[arg(long)]
    pub cameras: bool,
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

/// Render the pictures.
///
/// # Errors
/// Unreadable scenario or predictions, or an output that cannot be written.
pub fn run(args: &Args) -> Result<()> {
    let scenario = Scenario::open(&args.scenario)?;
    let predictions: SampleSet = match &args.predictions {
        Some(p) => read_samples(p)?,
        None => SampleSet::new(),
    };
    // Synthetic scenarios crop their own satellite raster; others are drawn on grey.
    let drive = scenario.regenerate().transpose()?;
    std::fs::create_dir_all(&args.out).with_context(|| args.out.display().to_string())?;
    let spec = satmap_crop_spec();
    let mut crop = vec![0u8; spec.height_px * spec.width_px * 3];
    let mut pictures = Vec::new();
    let mut pred_features = Vec::new();
    let mut gt_features = Vec::new();
    let m = &scenario.manifest;
    for i in (0..m.num_frames).step_by(args.every.max(1)) {
        let frame = scenario.read_frame(i)?;
        let name = frame_dir_name(i);
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
            .with_context(|| path.display().to_string())?;
    }
    println!("wrote {} pictures to {}", chosen.len(), args.out.display());
    Ok(())
}

fn save(img: &image::RgbImage, path: &Path) -> Result<()> {
    img.save(path).with_context(|| path.display().to_string())
}
