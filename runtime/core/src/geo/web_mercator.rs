//! Web Mercator (EPSG:3857) slippy-map math: tile indices `z/x/y` and global pixel positions.
//!
//! World pixels at zoom `z`: the whole world is `TILE_SIZE_PX * 2^z` pixels wide and high,
//! x east from longitude -180, y south from latitude +85.0511 (the usual slippy-map origin at
//! the top-left). Tile `(x, y)` covers world pixels `[x * 256, (x + 1) * 256)` on each axis.

use super::ellipsoid::WGS84_A_M;

/// Side of a slippy-map tile, pixels.
pub const TILE_SIZE_PX: f64 = 256.0;
/// Highest latitude Web Mercator covers (the world is square), degrees.
pub const MAX_LAT_DEG: f64 = 85.051_128_779_806_59;
/// Highest zoom level the tile math accepts (tile counts fit in `u32`).
pub const MAX_ZOOM: u8 = 30;

/// A position in world pixels at one zoom level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldPixel {
    /// Pixels east of longitude -180.
    pub x_px: f64,
    /// Pixels south of latitude `MAX_LAT_DEG`.
    pub y_px: f64,
}

/// A slippy-map tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileId {
    /// Zoom level.
    pub zoom: u8,
    /// Column, 0 at longitude -180.
    pub x: u32,
    /// Row, 0 at the north edge.
    pub y: u32,
}

/// World size at `zoom`, pixels per side.
#[must_use]
pub fn world_size_px(zoom: u8) -> f64 {
    TILE_SIZE_PX * libm::exp2(f64::from(zoom))
}

/// World pixel of a WGS84 latitude/longitude at `zoom` (latitude clamped to `MAX_LAT_DEG`).
#[must_use]
pub fn lat_lon_to_world_px(lat_deg: f64, lon_deg: f64, zoom: u8) -> WorldPixel {
    let size = world_size_px(zoom);
    let lat_rad = lat_deg.clamp(-MAX_LAT_DEG, MAX_LAT_DEG).to_radians();
    let x = (lon_deg + 180.0) / 360.0;
    // asinh(tan(lat)) is the Mercator northing ln(tan(lat) + sec(lat)).
    let y = 0.5 - libm::asinh(libm::tan(lat_rad)) / (2.0 * core::f64::consts::PI);
    WorldPixel {
        x_px: x * size,
        y_px: y * size,
    }
}

/// WGS84 latitude/longitude (degrees) of a world pixel at `zoom`.
#[must_use]
pub fn world_px_to_lat_lon(p: WorldPixel, zoom: u8) -> (f64, f64) {
    let size = world_size_px(zoom);
    let lon_deg = p.x_px / size * 360.0 - 180.0;
    let n = core::f64::consts::PI * (1.0 - 2.0 * p.y_px / size);
    let lat_deg = libm::atan(libm::sinh(n)).to_degrees();
    (lat_deg, lon_deg)
}

/// Ground distance of one pixel at latitude `lat_deg` and `zoom`, metres (on the sphere of
/// radius `WGS84_A_M` that Web Mercator uses).
#[must_use]
pub fn ground_resolution_m_per_px(lat_deg: f64, zoom: u8) -> f64 {
    libm::cos(lat_deg.to_radians()) * 2.0 * core::f64::consts::PI * WGS84_A_M / world_size_px(zoom)
}

impl TileId {
    /// The tile containing world pixel `p` at `zoom`, or `None` if `p` is off the world or
    /// `zoom > MAX_ZOOM`.
    #[must_use]
    pub fn containing(p: WorldPixel, zoom: u8) -> Option<Self> {
        if zoom > MAX_ZOOM || !p.x_px.is_finite() || !p.y_px.is_finite() {
            return None;
        }
        let tiles = 1u64 << zoom;
        let tx = libm::floor(p.x_px / TILE_SIZE_PX);
        let ty = libm::floor(p.y_px / TILE_SIZE_PX);
        if tx < 0.0 || ty < 0.0 || tx >= tiles as f64 || ty >= tiles as f64 {
            return None;
        }
        // In range [0, 2^30) so the casts are exact.
        Some(Self {
            zoom,
            x: tx as u32,
            y: ty as u32,
        })
    }

    /// The tile containing a WGS84 latitude/longitude at `zoom`.
    #[must_use]
    pub fn from_lat_lon(lat_deg: f64, lon_deg: f64, zoom: u8) -> Option<Self> {
        if zoom > MAX_ZOOM {
            return None;
        }
        Self::containing(lat_lon_to_world_px(lat_deg, lon_deg, zoom), zoom)
    }

    /// World pixel of the tile's top-left corner.
    #[must_use]
    pub fn origin_world_px(&self) -> WorldPixel {
        WorldPixel {
            x_px: f64::from(self.x) * TILE_SIZE_PX,
            y_px: f64::from(self.y) * TILE_SIZE_PX,
        }
    }

    /// (north-west, south-east) corners as (lat_deg, lon_deg).
    #[must_use]
    pub fn bounds_lat_lon(&self) -> ((f64, f64), (f64, f64)) {
        let nw = self.origin_world_px();
        let se = WorldPixel {
            x_px: nw.x_px + TILE_SIZE_PX,
            y_px: nw.y_px + TILE_SIZE_PX,
        };
        (
            world_px_to_lat_lon(nw, self.zoom),
            world_px_to_lat_lon(se, self.zoom),
        )
    }
}
