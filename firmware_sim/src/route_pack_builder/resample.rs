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

use std::collections::BTreeSet;

use glam::{DVec2, DVec3};
use indicatif::{ProgressBar, ProgressStyle};
use satmap_runtime::geo::{EnuFrame, Geodetic};
use satmap_runtime::route_pack::{PackHeader, PackTile, TileKey, encode_pack};

use super::error::BuildError;
use super::imagery::{Gap, Imagery};

/// Spacing of exactly projected nodes inside a pack tile, pixels.
pub const NODE_STEP_PX: usize = 16;
/// Mean Earth radius for the tangent-plane drop, metres.
const EARTH_RADIUS_M: f64 = 6_371_000.0;

/// Options of a build.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Width of the corridor around the route that must be covered, metres.
    pub corridor_width_m: f64,
    /// Ground sampling distance of the pack, metres per pixel.
    pub gsd_m: f64,
    /// Pack tile side, pixels (a power of two, 8..=1024).
    pub tile_size_px: u16,
    /// Leave out pack tiles that lack imagery instead of failing.
    pub allow_missing: bool,
    /// Draw a progress bar on stderr.
    pub show_progress: bool,
    /// Origin of the route frame; `None`: the route's first point at ellipsoid height 0. Give
    /// the frame the poses are expressed in (e.g. a synthetic world's anchor) to use it as is.
    pub origin: Option<Geodetic>,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            corridor_width_m: 60.0,
            gsd_m: 0.15,
            tile_size_px: 256,
            allow_missing: false,
            show_progress: false,
            origin: None,
        }
    }
}

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
}

/// Build a pack from `imagery` along `route`.
///
/// # Errors
/// Bad options, a route vertex outside the imagery, missing imagery under the corridor (unless
/// `allow_missing`), unreadable images, or nothing to write.
pub fn build_pack(
    imagery: &mut dyn Imagery,
    route: &[Geodetic],
    opts: &BuildOptions,
) -> Result<BuiltPack, BuildError> {
    check_options(opts)?;
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
    let keys = corridor_tiles(&route_m, opts);
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
    for key in keys {
        match fill_tile(imagery, &frame, key, opts)? {
            Ok(rgb) => payloads.push((key, rgb)),
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
        .map(|(key, rgb)| PackTile { key: *key, rgb })
        .collect();
    let header = PackHeader {
        tile_size_px: opts.tile_size_px,
        origin,
        gsd_m: opts.gsd_m,
        corridor_width_m: opts.corridor_width_m,
        tile_count: 0,
        route_point_count: 0,
    };
    let bytes = encode_pack(&header, &route_m, &tiles)?;
    let route_length_m = route_m.windows(2).map(|w| w[0].distance(w[1])).sum();
    Ok(BuiltPack {
        bytes,
        origin,
        tiles: tiles.len(),
        skipped_tiles,
        route_length_m,
    })
}

fn check_options(opts: &BuildOptions) -> Result<(), BuildError> {
    if !(opts.gsd_m.is_finite() && opts.gsd_m > 0.001 && opts.gsd_m <= 100.0) {
        return Err(BuildError::Option(format!(
            "gsd {} m/px is outside (0.001, 100]",
            opts.gsd_m
        )));
    }
    if !(opts.corridor_width_m.is_finite()
        && opts.corridor_width_m >= 0.0
        && opts.corridor_width_m <= 10_000.0)
    {
        return Err(BuildError::Option(format!(
            "corridor width {} m is outside [0, 10000]",
            opts.corridor_width_m
        )));
    }
    if !(8..=1024).contains(&opts.tile_size_px) || !opts.tile_size_px.is_power_of_two() {
        return Err(BuildError::Option(format!(
            "tile size {} px is not a power of two in 8..=1024",
            opts.tile_size_px
        )));
    }
    Ok(())
}

/// Pack tiles within half the corridor width of the route (a square around points sampled at
/// most a quarter tile apart, so no tile the corridor touches is missed).
#[must_use]
pub fn corridor_tiles(route_m: &[DVec2], opts: &BuildOptions) -> BTreeSet<TileKey> {
    let side_m = f64::from(opts.tile_size_px) * opts.gsd_m;
    let half_m = 0.5 * opts.corridor_width_m;
    let step_m = (0.25 * side_m).min(half_m.max(opts.gsd_m));
    let mut keys = BTreeSet::new();
    let mut add = |p: DVec2| {
        let lo = ((p - DVec2::splat(half_m)) / side_m).floor();
        let hi = ((p + DVec2::splat(half_m)) / side_m).floor();
        for ty in lo.y as i32..=hi.y as i32 {
            for tx in lo.x as i32..=hi.x as i32 {
                keys.insert(TileKey::new(tx, ty));
            }
        }
    };
    for w in route_m.windows(2) {
        let (a, b) = (w[0], w[1]);
        let n = ((a.distance(b) / step_m).ceil() as usize).max(1);
        for k in 0..=n {
            add(a.lerp(b, k as f64 / n as f64));
        }
    }
    keys
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
    let drop_m = frame.origin().height_m;
    let ground = |p: DVec2| {
        let z_m = -drop_m - p.length_squared() / (2.0 * EARTH_RADIUS_M);
        frame.enu_to_geodetic(DVec3::new(p.x, p.y, z_m))
    };
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
