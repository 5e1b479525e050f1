//! The pack tiles the route corridor needs, counted exactly and checked against the pack
//! format's limits and the `route_pack` region of `memory_layout.toml` before any tile is
//! listed or any imagery read.
//!
//! The corridor is the set of points within half the corridor width of the route in each axis
//! (a square swept along every segment). Per segment and tile row, the points of the segment
//! whose square reaches the row form one interval of the segment, so the tiles the segment
//! needs in that row are one run of columns. The runs of all segments are merged per row and
//! counted; the work is one run per (segment, row), bounded by [`MAX_CORRIDOR_RUNS`] before
//! anything is allocated for them.

use glam::DVec2;
use satmap_runtime::capacity::layout::ROUTE_PACK_BYTES;
use satmap_runtime::route_pack::TileKey;
use satmap_runtime::route_pack::format::{
    CHANNELS, HEADER_LEN, INDEX_ENTRY_LEN, MAX_ROUTE_POINTS, MAX_TILES, ROUTE_POINT_LEN,
};

use super::compress::TileCompression;
use super::error::BuildError;
use super::options::BuildOptions;

/// Most (segment, tile row) runs the count may hold: 48 MB of runs. A route needs more only
/// with far more points than tiles (points much closer than a tile side); thin it.
pub const MAX_CORRIDOR_RUNS: u64 = 4_000_000;

/// The best compression ratio assumed of satellite tiles when sizing a compressed pack before
/// its imagery is read (JPEG of aerial imagery reaches 8-15:1 at the qualities crops need).
pub const MAX_COMPRESSION_RATIO: u64 = 32;

/// One run of tiles: row, first and last column.
type Run = (i32, i32, i32);

/// The corridor's tiles, sorted by `(tile_y, tile_x)` (the index order), after checking that
/// the route points, the tile count and the pack size fit the format and the `route_pack`
/// region. The size counts every corridor tile (tiles later skipped for missing imagery
/// included).
///
/// # Errors
/// [`BuildError::PackTooLarge`] naming the count and the limit.
pub fn corridor_tiles(route_m: &[DVec2], opts: &BuildOptions) -> Result<Vec<TileKey>, BuildError> {
    let too_large = |what, needed: u64, limit: u64, limit_name| BuildError::PackTooLarge {
        what,
        needed,
        limit,
        limit_name,
    };
    let points = route_m.len() as u64;
    if points > u64::from(MAX_ROUTE_POINTS) {
        return Err(too_large(
            "route points",
            points,
            MAX_ROUTE_POINTS.into(),
            "the pack format's limit",
        ));
    }
    let side_m = f64::from(opts.tile_size_px) * opts.gsd_m;
    let half_m = 0.5 * opts.corridor_width_m;
    let cell = |v_m: f64| (v_m / side_m).floor();
    // Tile rows and columns must be i32 (the index) with room for one more.
    let grid = f64::from(i32::MAX - 1);
    let mut runs_needed = 0u64;
    for w in route_m.windows(2) {
        let (y0, y1) = (w[0].y.min(w[1].y), w[0].y.max(w[1].y));
        let (x0, x1) = (w[0].x.min(w[1].x), w[0].x.max(w[1].x));
        let (r0, r1) = (cell(y0 - half_m), cell(y1 + half_m));
        let (c0, c1) = (cell(x0 - half_m), cell(x1 + half_m));
        if ![r0, r1, c0, c1].iter().all(|v| v.abs() < grid) {
            return Err(too_large(
                "tile rows or columns",
                u64::MAX,
                i32::MAX as u64,
                "the pack index's i32 grid",
            ));
        }
        runs_needed = runs_needed.saturating_add((r1 - r0) as u64 + 1);
    }
    if runs_needed > MAX_CORRIDOR_RUNS {
        return Err(too_large(
            "corridor runs (route segments x tile rows)",
            runs_needed,
            MAX_CORRIDOR_RUNS,
            "the builder's limit (thin the route: points much closer than a tile are not needed)",
        ));
    }
    let mut runs: Vec<Run> = Vec::with_capacity(runs_needed as usize);
    for w in route_m.windows(2) {
        segment_runs(w[0], w[1], side_m, half_m, &mut runs);
    }
    runs.sort_unstable();
    let merged = merge(&runs);
    let tiles: u64 = merged
        .iter()
        .map(|&(_, a, b)| (i64::from(b) - i64::from(a) + 1) as u64)
        .fold(0u64, u64::saturating_add);
    if tiles > u64::from(MAX_TILES) {
        return Err(too_large(
            "tiles",
            tiles,
            MAX_TILES.into(),
            "the pack format's limit",
        ));
    }
    let side_px = u64::from(opts.tile_size_px);
    let bytes = [
        HEADER_LEN as u64,
        points.saturating_mul(ROUTE_POINT_LEN as u64),
        tiles.saturating_mul(INDEX_ENTRY_LEN as u64),
        tiles.saturating_mul(side_px * side_px * CHANNELS as u64),
    ]
    .into_iter()
    .fold(0u64, u64::saturating_add);
    // A compressed pack's size is known once its tiles are encoded (checked then, in
    // `build_pack`); before reading imagery only a corridor that could not fit even at
    // MAX_COMPRESSION_RATIO is refused.
    let (limit, limit_name) = if opts.compression == TileCompression::Raw {
        (
            ROUTE_PACK_BYTES as u64,
            "the route_pack region of memory_layout.toml",
        )
    } else {
        (
            (ROUTE_PACK_BYTES as u64).saturating_mul(MAX_COMPRESSION_RATIO),
            "the route_pack region of memory_layout.toml at the best compression ratio assumed (32:1)",
        )
    };
    if bytes > limit {
        return Err(too_large("bytes", bytes, limit, limit_name));
    }
    Ok(merged
        .iter()
        .flat_map(|&(row, a, b)| (a..=b).map(move |col| TileKey::new(col, row)))
        .collect())
}

/// Runs of tiles within `half_m` (per axis) of segment `a`-`b`, one per tile row.
fn segment_runs(a: DVec2, b: DVec2, side_m: f64, half_m: f64, runs: &mut Vec<Run>) {
    let d = b - a;
    let (r0, r1) = (
        ((a.y.min(b.y) - half_m) / side_m).floor() as i32,
        ((a.y.max(b.y) + half_m) / side_m).floor() as i32,
    );
    for row in r0..=r1 {
        // Segment points whose square reaches the row: y in [row * side - h, (row + 1) * side + h].
        let (lo_m, hi_m) = (
            f64::from(row) * side_m - half_m,
            f64::from(row + 1) * side_m + half_m,
        );
        let (t0, t1) = if d.y == 0.0 {
            (0.0, 1.0)
        } else {
            let (u, v) = ((lo_m - a.y) / d.y, (hi_m - a.y) / d.y);
            (u.min(v).max(0.0), u.max(v).min(1.0))
        };
        if t0 > t1 {
            continue;
        }
        let (xa, xb) = (a.x + d.x * t0, a.x + d.x * t1);
        let c0 = ((xa.min(xb) - half_m) / side_m).floor() as i32;
        let c1 = ((xa.max(xb) + half_m) / side_m).floor() as i32;
        runs.push((row, c0, c1));
    }
}

/// Merge sorted runs that overlap or touch within a row.
fn merge(sorted: &[Run]) -> Vec<Run> {
    let mut out: Vec<Run> = Vec::with_capacity(sorted.len());
    for &(row, a, b) in sorted {
        match out.last_mut() {
            Some(last) if last.0 == row && a <= last.2.saturating_add(1) => {
                last.2 = last.2.max(b);
            }
            _ => out.push((row, a, b)),
        }
    }
    out
}
