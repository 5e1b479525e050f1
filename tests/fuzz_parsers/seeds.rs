//! Seeds and fixtures shared by several harnesses: the committed bundle manifest, digest file,
//! calibration and memory layouts (the default and `layouts/paper.toml`); the synthetic drive
//! the product's writers turn into seeds (and its GeoJSON route); the model dims and
//! calibration the later steps use; and the one-colour `BoxImagery`, crop and build options the
//! route packs are built with.

use std::sync::OnceLock;

use glam::DVec2;
use satmap_runtime::bundle::Manifest;
use satmap_runtime::calibration::{Calibration, from_toml_str};
use satmap_runtime::geo::Geodetic;
use satmap_runtime::model_dims::ModelDims;
use satmap_runtime::satellite::CropSpec;
use satmap_sim::route_pack_builder::imagery::{Gap, Imagery};
use satmap_sim::route_pack_builder::{BuildError, BuildOptions};
use satmap_sim::synth::scenario::route_geojson;
use satmap_sim::synth::{DriveConfig, LightingPreset, ScenarioPlacement, SyntheticDrive};

pub const MANIFEST_TOML: &str = include_str!("../../models/bundles/test/manifest.toml");
pub const MANIFEST_SHA256: &str = include_str!("../../models/bundles/test/manifest.sha256");
pub const CALIBRATION_TOML: &str = include_str!("../../models/calibration/nuscenes_like.toml");
pub const MEMORY_LAYOUT_TOML: &str = include_str!("../../memory_layout.toml");
pub const PAPER_LAYOUT_TOML: &str = include_str!("../../layouts/paper.toml");

/// A 20-frame synthetic drive with tiny images, made once per test binary.
pub fn seed_drive() -> &'static SyntheticDrive {
    static DRIVE: OnceLock<SyntheticDrive> = OnceLock::new();
    DRIVE.get_or_init(|| {
        let config = DriveConfig {
            image_width_px: 16,
            image_height_px: 8,
            num_frames: 20,
            lighting: Some(LightingPreset::Day),
            ..DriveConfig::default()
        };
        SyntheticDrive::new(7, config).unwrap()
    })
}

pub fn seed_route_geojson() -> String {
    route_geojson(seed_drive(), ScenarioPlacement::default().anchor)
}

pub fn test_dims() -> ModelDims {
    Manifest::parse(MANIFEST_TOML.as_bytes()).unwrap().model
}

pub fn seed_calibration() -> Calibration {
    from_toml_str(CALIBRATION_TOML).unwrap()
}

/// Imagery of one colour over a small WGS84 box around the seed route, gaps outside: a route
/// that leaves the box is refused like one that leaves real imagery, and one inside it has a
/// bounded corridor, so a case's cost stays bounded.
pub struct BoxImagery {
    lat: (f64, f64),
    lon: (f64, f64),
}

impl BoxImagery {
    pub fn around(anchor: Geodetic) -> Self {
        let half = 0.002;
        Self {
            lat: (anchor.lat_deg - half, anchor.lat_deg + half),
            lon: (anchor.lon_deg - half, anchor.lon_deg + half),
        }
    }
}

impl Imagery for BoxImagery {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        DVec2::new(lon_deg, lat_deg)
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        let inside =
            (self.lon.0..=self.lon.1).contains(&p.x) && (self.lat.0..=self.lat.1).contains(&p.y);
        Ok(if inside {
            Ok([90, 120, 60])
        } else {
            Err(Gap::OutsideImage)
        })
    }

    fn gap_error(&self, _gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        BuildError::Option(format!("no imagery at {lat_deg}, {lon_deg}"))
    }
}

/// The crop the packs are built for and cropped with: small, so a case stays cheap.
pub const CROP: CropSpec = CropSpec {
    height_px: 20,
    width_px: 12,
    gsd_m: 0.4,
    x_min_m: -2.4,
    y_min_m: -4.0,
};

/// Small tiles and a narrow corridor: a pack of a few dozen tiles, cheap to verify per case.
pub fn pack_options() -> BuildOptions {
    BuildOptions {
        corridor_width_m: 10.0,
        gsd_m: 0.5,
        tile_size_px: 16,
        crop: CROP,
        ..BuildOptions::default()
    }
}
