//! Writing a scenario folder from a [`SyntheticDrive`]: frames, calibration, route, tiles and
//! ground truth, in the formats of `SCENARIO.md`.

use std::path::Path;

use glam::{DVec2, DVec3};
use satmap_runtime::calibration::{Calibration, from_toml_str};
use satmap_runtime::geo::{EnuFrame, Geodetic};

use crate::eval::SampleSet;
use crate::eval::maptr_json::ResultsFile;
use crate::synth::drive::{NUSCENES_LIKE_CALIBRATION_TOML, SyntheticDrive};
use crate::synth::slippy_tiles::write_tiles;

use super::{
    FrameRecord, SCENARIO_FORMAT, ScenarioError, ScenarioManifest, ScenarioPlacement,
    SyntheticSource, frame_dir_name, io,
};
fn write_text(path: &Path, text: &str) -> Result<(), ScenarioError> {
    std::fs::write(path, text).map_err(io(path))
}

/// Write the whole drive to `dir`; `on_frame(i)` is called after each frame (progress bars).
pub fn write_scenario(
    drive: &SyntheticDrive,
    dir: &Path,
    placement: &ScenarioPlacement,
    mut on_frame: impl FnMut(usize),
) -> Result<ScenarioManifest, ScenarioError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let cfg = drive.config();
    let manifest = ScenarioManifest {
        format: SCENARIO_FORMAT.to_owned(),
        num_frames: cfg.num_frames,
        frame_rate_hz: cfg.frame_rate_hz,
        image_width_px: cfg.image_width_px,
        image_height_px: cfg.image_height_px,
        calibration_file: "calibration.toml".to_owned(),
        route_geojson: "route.geojson".to_owned(),
        tiles_dir: "tiles".to_owned(),
        tile_zoom: placement.tile_zoom,
        anchor_lat_deg: placement.anchor.lat_deg,
        anchor_lon_deg: placement.anchor.lon_deg,
        anchor_height_m: placement.anchor.height_m,
        route_pack: None,
        ground_truth_json: "ground_truth.json".to_owned(),
        synthetic: Some(SyntheticSource {
            seed: drive.seed(),
            lighting: drive.lighting_preset(),
            drive: cfg.clone(),
        }),
    };
    let text = toml::to_string(&manifest).map_err(|e| ScenarioError::Toml {
        path: dir.join("scenario.toml"),
        message: e.to_string(),
    })?;
    write_text(&dir.join("scenario.toml"), &text)?;
    write_text(
        &dir.join(&manifest.calibration_file),
        &calibration_toml(drive.calibration()),
    )?;
    write_text(
        &dir.join(&manifest.route_geojson),
        &route_geojson(drive, placement.anchor),
    )?;
    write_tiles(
        drive.satellite(),
        placement.anchor,
        placement.tile_zoom,
        &dir.join(&manifest.tiles_dir),
    )?;

    let mut all_gt = SampleSet::new();
    let (w, h) = (cfg.image_width_px, cfg.image_height_px);
    for (i, frame) in drive.frames().enumerate() {
        let fdir = dir.join("frames").join(frame_dir_name(i));
        std::fs::create_dir_all(&fdir).map_err(io(&fdir))?;
        for c in 0..6 {
            let path = fdir.join(format!("cam{c}.png"));
            let bytes = frame.images[c * w * h * 3..(c + 1) * w * h * 3].to_vec();
            let img = image::RgbImage::from_raw(w as u32, h as u32, bytes).ok_or_else(|| {
                ScenarioError::Image {
                    path: path.clone(),
                    message: "image buffer size".to_owned(),
                }
            })?;
            img.save(&path).map_err(|e| ScenarioError::Image {
                path: path.clone(),
                message: e.to_string(),
            })?;
        }
        let record = FrameRecord {
            sequence: frame.sequence,
            timestamp_us: frame.timestamp_us,
            x_m: frame.pose.position_m.x,
            y_m: frame.pose.position_m.y,
            yaw_rad: frame.pose.yaw_rad,
            acceleration_mps2: frame.motion.acceleration_mps2.to_array(),
            rotation_rate_radps: frame.motion.rotation_rate_radps.to_array(),
            velocity_mps: frame.motion.velocity_mps.to_array(),
        };
        let path = fdir.join("frame.toml");
        let text = toml::to_string(&record).map_err(|e| ScenarioError::Toml {
            path: path.clone(),
            message: e.to_string(),
        })?;
        write_text(&path, &text)?;
        let one = SampleSet::from([(frame_dir_name(i), frame.ground_truth.clone())]);
        let gt = ResultsFile::from_samples(&one, serde_json::Value::Null, false);
        let record = gt.results.into_values().next().unwrap_or_default();
        let path = fdir.join("gt.json");
        let text = serde_json::to_string(&record)
            .map_err(|e| ScenarioError::Invalid(format!("{}: {e}", path.display())))?;
        write_text(&path, &text)?;
        all_gt.insert(frame_dir_name(i), frame.ground_truth);
        on_frame(i);
    }
    ResultsFile::from_samples(
        &all_gt,
        serde_json::json!({"source": "satmap-sim synth"}),
        false,
    )
    .write(&dir.join(&manifest.ground_truth_json))?;
    Ok(manifest)
}

/// The calibration as the TOML of `ARCHITECTURE.md` (the built-in file verbatim when it is the
/// built-in rig, so comments survive).
#[must_use]
pub fn calibration_toml(c: &Calibration) -> String {
    if from_toml_str(NUSCENES_LIKE_CALIBRATION_TOML).is_ok_and(|b| b == *c) {
        return NUSCENES_LIKE_CALIBRATION_TOML.to_owned();
    }
    let mut s = format!(
        "raw_width_px = {}\nraw_height_px = {}\n",
        c.raw_width_px, c.raw_height_px
    );
    for (name, cam) in satmap_runtime::calibration::CAMERA_NAMES
        .iter()
        .zip(&c.cameras)
    {
        let q = cam.rotation;
        let t = cam.translation_m;
        s += &format!(
            "\n[[camera]]\nname = \"{name}\"\nfx_px = {}\nfy_px = {}\ncx_px = {}\ncy_px = {}\ntranslation_m = [{}, {}, {}]\nrotation_wxyz = [{}, {}, {}, {}]\n",
            cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px, t.x, t.y, t.z, q.w, q.x, q.y, q.z
        );
    }
    s
}

/// The ego path of the drive (every 2 m, plus both ends) as a GeoJSON Feature with a WGS84
/// LineString (`[lon, lat]`).
#[must_use]
pub fn route_geojson(drive: &SyntheticDrive, anchor: Geodetic) -> String {
    let enu = EnuFrame::new(anchor);
    let n = drive.len().max(1);
    let t_end = (n - 1) as f64 / drive.config().frame_rate_hz;
    let mut coords: Vec<[f64; 2]> = Vec::new();
    let mut last: Option<DVec2> = None;
    let steps = ((t_end * drive.config().mean_speed_mps * 1.2) / 2.0)
        .ceil()
        .max(1.0) as usize;
    for k in 0..=steps {
        let p = drive
            .pose_at_time(t_end * k as f64 / steps as f64)
            .position_m;
        if last.is_some_and(|q| (q - p).length() < 1.0) && k != steps {
            continue;
        }
        last = Some(p);
        let g = enu.enu_to_geodetic(DVec3::new(p.x, p.y, 0.0));
        coords.push([g.lon_deg, g.lat_deg]);
    }
    let mut feature = geojson::Feature::from(geojson::Geometry::new_line_string(coords));
    feature.set_property("name", format!("synthetic drive, seed {}", drive.seed()));
    feature.set_property("frames", drive.len());
    geojson::FeatureCollection::new([feature]).to_string()
}
