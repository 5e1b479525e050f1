//! [`RasterImagery`]: a synthetic world's satellite raster seen as WGS84 imagery, so that the
//! route-pack builder can pack it exactly as it packs real slippy tiles (no files in between).
//!
//! Source pixel coordinates are the world's route-frame metres (ENU at the scenario anchor):
//! `project` maps WGS84 to those metres and `sample` reads the raster bilinearly there.

use glam::{DVec2, DVec3};
use satmap_runtime::geo::{EnuFrame, Geodetic};

use crate::route_pack_builder::BuildError;
use crate::route_pack_builder::imagery::{Gap, Imagery};
use crate::synth::ground_raster::GroundRaster;

/// The raster of a synthetic world, anchored at a WGS84 point.
pub struct RasterImagery<'a> {
    raster: &'a GroundRaster,
    frame: EnuFrame,
}

impl<'a> RasterImagery<'a> {
    /// `raster` (route-frame metres) with its route frame's origin at `anchor`.
    #[must_use]
    pub fn new(raster: &'a GroundRaster, anchor: Geodetic) -> Self {
        Self {
            raster,
            frame: EnuFrame::new(anchor),
        }
    }

    /// WGS84 of a route-frame point.
    #[must_use]
    pub fn to_geodetic(&self, p_m: DVec2) -> Geodetic {
        self.frame.enu_to_geodetic(DVec3::new(p_m.x, p_m.y, 0.0))
    }
}

impl Imagery for RasterImagery<'_> {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        self.frame
            .geodetic_to_enu(&Geodetic::new(lat_deg, lon_deg, 0.0))
            .truncate()
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        let rgb = self.raster.sample_bilinear(p.x as f32, p.y as f32);
        Ok(Ok(rgb.map(|v| v.round().clamp(0.0, 255.0) as u8)))
    }

    fn gap_error(&self, _gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        BuildError::Option(format!("no synthetic imagery at {lat_deg}, {lon_deg}"))
    }
}
