//! Satellite tiles of a synthetic world in the layout real imagery comes in: Web Mercator
//! slippy-map `z/x/y.png` (256 x 256 RGB) around a WGS84 anchor, so the route-pack builder
//! ingests them like downloaded tiles.
//!
//! The world's route frame is the local ENU plane whose origin is the anchor
//! (`satmap_runtime::geo::EnuFrame`): a tile pixel centre is converted to WGS84, then to ENU,
//! and samples the satellite raster bilinearly.

use std::path::{Path, PathBuf};

use glam::DVec3;
use satmap_runtime::geo::web_mercator::{TILE_SIZE_PX, lat_lon_to_world_px, world_px_to_lat_lon};
use satmap_runtime::geo::{EnuFrame, Geodetic, TileId, WorldPixel};

use super::ground_raster::GroundRaster;

/// Errors writing tiles.
#[derive(Debug, thiserror::Error)]
pub enum TileWriteError {
    /// A tile or folder could not be written.
    #[error("{path}: {source}")]
    Io {
        /// Path concerned.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// PNG encoding failed.
    #[error("{path}: {source}")]
    Png {
        /// Path concerned.
        path: PathBuf,
        /// Underlying error.
        source: image::ImageError,
    },
    /// The anchor or zoom is outside Web Mercator.
    #[error("anchor ({lat_deg}, {lon_deg}) at zoom {zoom} is outside Web Mercator")]
    OffWorld {
        /// Anchor latitude, degrees.
        lat_deg: f64,
        /// Anchor longitude, degrees.
        lon_deg: f64,
        /// Zoom level.
        zoom: u8,
    },
}

/// Tiles covering the raster's extent at `zoom`, in (x, y) order.
pub fn covering_tiles(
    raster: &GroundRaster,
    anchor: Geodetic,
    zoom: u8,
) -> Result<Vec<TileId>, TileWriteError> {
    let enu = EnuFrame::new(anchor);
    let off = TileWriteError::OffWorld {
        lat_deg: anchor.lat_deg,
        lon_deg: anchor.lon_deg,
        zoom,
    };
    let x_max = raster.x_min_m + raster.width_px as f64 * raster.gsd_m;
    let y_min = raster.y_max_m - raster.height_px as f64 * raster.gsd_m;
    let mut lo = (u32::MAX, u32::MAX);
    let mut hi = (0u32, 0u32);
    for (x, y) in [
        (raster.x_min_m, raster.y_max_m),
        (x_max, raster.y_max_m),
        (raster.x_min_m, y_min),
        (x_max, y_min),
    ] {
        let g = enu.enu_to_geodetic(DVec3::new(x, y, 0.0));
        let t =
            TileId::from_lat_lon(g.lat_deg, g.lon_deg, zoom).ok_or(TileWriteError::OffWorld {
                lat_deg: anchor.lat_deg,
                lon_deg: anchor.lon_deg,
                zoom,
            })?;
        lo = (lo.0.min(t.x), lo.1.min(t.y));
        hi = (hi.0.max(t.x), hi.1.max(t.y));
    }
    if lo.0 > hi.0 {
        return Err(off);
    }
    let mut out = Vec::new();
    for x in lo.0..=hi.0 {
        for y in lo.1..=hi.1 {
            out.push(TileId { zoom, x, y });
        }
    }
    Ok(out)
}

/// Render one tile (256 x 256 RGB) from the raster.
#[must_use]
pub fn render_tile(raster: &GroundRaster, enu: &EnuFrame, tile: TileId) -> image::RgbImage {
    let size = TILE_SIZE_PX as u32;
    let origin = tile.origin_world_px();
    image::RgbImage::from_fn(size, size, |col, row| {
        let wp = WorldPixel {
            x_px: origin.x_px + f64::from(col) + 0.5,
            y_px: origin.y_px + f64::from(row) + 0.5,
        };
        let (lat, lon) = world_px_to_lat_lon(wp, tile.zoom);
        let p = enu.geodetic_to_enu(&Geodetic::new(lat, lon, 0.0));
        let c = raster.sample_bilinear(p.x as f32, p.y as f32);
        image::Rgb(c.map(|v| v.round().clamp(0.0, 255.0) as u8))
    })
}

/// Write every covering tile as `dir/z/x/y.png`; returns the tiles written.
pub fn write_tiles(
    raster: &GroundRaster,
    anchor: Geodetic,
    zoom: u8,
    dir: &Path,
) -> Result<Vec<TileId>, TileWriteError> {
    let enu = EnuFrame::new(anchor);
    let tiles = covering_tiles(raster, anchor, zoom)?;
    for t in &tiles {
        let folder = dir.join(t.zoom.to_string()).join(t.x.to_string());
        std::fs::create_dir_all(&folder).map_err(|source| TileWriteError::Io {
            path: folder.clone(),
            source,
        })?;
        let path = folder.join(format!("{}.png", t.y));
        render_tile(raster, &enu, *t)
            .save(&path)
            .map_err(|source| TileWriteError::Png {
                path: path.clone(),
                source,
            })?;
    }
    Ok(tiles)
}

/// World pixel of the anchor (useful to check tile placement in tests).
#[must_use]
pub fn anchor_world_px(anchor: Geodetic, zoom: u8) -> WorldPixel {
    lat_lon_to_world_px(anchor.lat_deg, anchor.lon_deg, zoom)
}
