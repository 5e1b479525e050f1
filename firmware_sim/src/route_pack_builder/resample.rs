//! Choosing the pack tiles that cover the route corridor and filling them by resampling the
//! imagery once into the route frame.
//!
//! Route frame: local ENU at the route's first point, ellipsoid height 0 (or at
//! [`BuildOptions::origin`]). Pack pixel centre `(x, y)` is taken as the ground point with ENU
//! coordinates `(x, y, -h0 - (x^2 + y^2) / 2R)` (the tangent plane dropped back to the
//! ellipsoid; h0 the origin's height, R = 6 371 km), converted to WGS84, then
//! projected into the imagery. The exact chain runs on a grid of nodes every
//! [`NODE_STEP_PX`] pixels; pixels in between interpolate the node's source coordinates
//! bilinearly (the map is smooth: the interpolation error is far below 1e-3 source px).

use glam::DVec2;
use indicatif::{ProgressBar, ProgressStyle};
use satmap_runtime::capacity::layout::ROUTE_PACK_BYTES;
use satmap_runtime::geo::{EnuFrame, Geodetic};
use satmap_runtime::route_pack::{PackHeader, PackTile, TileKey, encode_pack};

use super::compress::{TileCompression, compress_tile, psnr_db};
use super::corridor::corridor_tiles;
use super::error::BuildError;
use super::frame::{check_route_radius, ground_point};
use super::imagery::{Gap, Imagery};
use super::options::BuildOptions;

/// Spacing of exactly projected nodes inside a pack tile, pixels.
pub const NODE_STEP_PX: usize = 16;

/// A built pack and what went into it.
#[derive(Clone, Debug)]
pub struct BuiltPack {
    /// The pack image.
    pub bytes: Vec<u8>,
    /// The pack's WGS84 origin (the route's first point).
    pub origin: Geodetic,
    /// Tiles written.
    pub tiles: usize,
    /// Tiles left out for missing imagery (only with `allow_missing`).
    pub skipped_tiles: usize,
    /// Route length in the route frame, metres.
    pub route_length_m: f64,
    /// Bytes the tiles would take raw (`tiles * S * S * 3`).
    pub raw_tile_bytes: u64,
    /// Bytes the tile payloads take as written.
    pub payload_bytes: u64,
    /// PSNR of the decoded tiles against the resampled raw ones, all tiles pooled, dB
    /// (infinite for raw and lossless packs).
    pub tile_psnr_db: f64,
    /// Lowest PSNR of any one tile, dB.
    pub worst_tile_psnr_db: f64,
}

/// Build a pack from `imagery` along `route`.
///
/// # Errors
/// Bad options ([`BuildOptions::validate`]), a pack too large for the format or the
/// `route_pack` region (checked before any imagery is read), a route vertex outside the imagery, missing imagery under the corridor (unless
/// `allow_missing`), unreadable images, or nothing to write.
pub fn build_pack(
    imagery: &mut dyn Imagery,
    route: &[Geodetic],
    opts: &BuildOptions,
) -> Result<BuiltPack, BuildError> {
    opts.validate()?;
    let origin = match (route.first(), opts.origin) {
        (Some(_), Some(origin)) if route.len() >= 2 => origin,
        (Some(p), None) if route.len() >= 2 => Geodetic::new(p.lat_deg, p.lon_deg, 0.0),
        _ => {
            return Err(BuildError::Option(
                "the route needs at least two points".into(),
            ));
        }
    };
    let frame = EnuFrame::new(origin);
    let route_m: Vec<DVec2> = route
        .iter()
        .map(|p| frame.geodetic_to_enu(p).truncate())
        .collect();
    // Beyond its tested radius the one route frame's distortion is not bounded (frame.rs).
    check_route_radius(&route_m)?;
    // Sizes first: nothing is read from the imagery for a pack that cannot be written.
    let keys = corridor_tiles(&route_m, opts)?;
    for (index, p) in route.iter().enumerate() {
        if let Err(gap) = imagery.sample(imagery.project(p.lat_deg, p.lon_deg))? {
            let detail = imagery.gap_error(&gap, p.lat_deg, p.lon_deg).to_string();
            return Err(BuildError::RouteOutsideImagery {
                index,
                lat_deg: p.lat_deg,
                lon_deg: p.lon_deg,
                detail,
            });
        }
    }
    let progress = if opts.show_progress {
        ProgressBar::new(keys.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    progress.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} tiles, {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    progress.set_message("resampling");
    let mut payloads: Vec<(TileKey, Vec<u8>)> = Vec::with_capacity(keys.len());
    let mut skipped_tiles = 0;
    let (mut squared_error, mut worst_tile_psnr_db) = (0u64, f64::INFINITY);
    let tile_samples = (usize::from(opts.tile_size_px).pow(2) * 3) as u64;
    for key in keys {
        match fill_tile(imagery, &frame, key, opts)? {
            Ok(rgb) if opts.compression == TileCompression::Raw => payloads.push((key, rgb)),
            Ok(rgb) => {
                let tile =
                    compress_tile(opts.compression, &rgb, opts.tile_size_px).map_err(|detail| {
                        BuildError::TileEncode {
                            tile_x: key.tile_x,
                            tile_y: key.tile_y,
                            detail,
                        }
                    })?;
                squared_error += tile.squared_error;
                worst_tile_psnr_db =
                    worst_tile_psnr_db.min(psnr_db(tile.squared_error, tile_samples));
                payloads.push((key, tile.payload));
            }
            Err((gap, at)) if !opts.allow_missing => {
                progress.abandon();
                return Err(imagery.gap_error(&gap, at.lat_deg, at.lon_deg));
            }
            Err(_) => skipped_tiles += 1,
        }
        progress.inc(1);
    }
    progress.finish_and_clear();
    if payloads.is_empty() {
        return Err(BuildError::Empty);
    }
    let tiles: Vec<PackTile<'_>> = payloads
        .iter()
        .map(|(key, rgb)| PackTile {
            key: *key,
            payload: rgb,
        })
        .collect();
    let header = PackHeader {
        tile_size_px: opts.tile_size_px,
        origin,
        gsd_m: opts.gsd_m,
        corridor_width_m: opts.corridor_width_m,
        tile_count: 0,
        route_point_count: 0,
        codec: opts.compression.codec(),
    };
    let bytes = encode_pack(&header, &route_m, &tiles)?;
    if bytes.len() > ROUTE_PACK_BYTES {
        return Err(BuildError::PackTooLarge {
            what: "bytes",
            needed: bytes.len() as u64,
            limit: ROUTE_PACK_BYTES as u64,
            limit_name: "the route_pack region of memory_layout.toml",
        });
    }
    let payload_bytes = tiles.iter().map(|t| t.payload.len() as u64).sum();
    let route_length_m = route_m.windows(2).map(|w| w[0].distance(w[1])).sum();
    Ok(BuiltPack {
        bytes,
        origin,
        tiles: tiles.len(),
        skipped_tiles,
        route_length_m,
        raw_tile_bytes: tiles.len() as u64 * tile_samples,
        payload_bytes,
        tile_psnr_db: psnr_db(squared_error, tiles.len() as u64 * tile_samples),
        worst_tile_psnr_db,
    })
}

type TileFill = Result<Vec<u8>, (Gap, Geodetic)>;

/// Resample one pack tile; a gap (with where it was) if any pixel lacks imagery.
fn fill_tile(
    imagery: &mut dyn Imagery,
    frame: &EnuFrame,
    key: TileKey,
    opts: &BuildOptions,
) -> Result<TileFill, BuildError> {
    let s = usize::from(opts.tile_size_px);
    let step = NODE_STEP_PX.min(s);
    let nodes = s / step + 1;
    let gsd = opts.gsd_m;
    let pixel_centre = |c: usize, r: usize| {
        DVec2::new(
            (f64::from(key.tile_x) * s as f64 + c as f64 + 0.5) * gsd,
            (f64::from(key.tile_y) * s as f64 + r as f64 + 0.5) * gsd,
        )
    };
    let ground = |p: DVec2| ground_point(frame, p);
    let mut grid = Vec::with_capacity(nodes * nodes);
    for nr in 0..nodes {
        for nc in 0..nodes {
            let g = ground(pixel_centre(nc * step, nr * step));
            grid.push(imagery.project(g.lat_deg, g.lon_deg));
        }
    }
    let mut rgb = Vec::with_capacity(s * s * 3);
    for r in 0..s {
        let (nr, fr) = (r / step, (r % step) as f64 / step as f64);
        for c in 0..s {
            let (nc, fc) = (c / step, (c % step) as f64 / step as f64);
            let at = |i: usize, j: usize| grid[(nr + i) * nodes + nc + j];
            let south = at(0, 0).lerp(at(0, 1), fc);
            let north = at(1, 0).lerp(at(1, 1), fc);
            match imagery.sample(south.lerp(north, fr))? {
                Ok(px) => rgb.extend_from_slice(&px),
                Err(gap) => return Ok(Err((gap, ground(pixel_centre(c, r))))),
            }
        }
    }
    Ok(Ok(rgb))
}
