//! Test packs drawn in code: tiles painted per global pack pixel, encoded with the runtime's
//! writer.

use glam::DVec2;
use satmap_core::geo::Geodetic;
use satmap_core::pose::EgoPose;
use satmap_core::route_pack::{PackHeader, PackSource, PackTile, TileCodec, TileKey, encode_pack};
use satmap_core::satellite::CropSpec;

/// Encode a pack whose tile `(tx, ty)` pixel `(row r, col c)` is `paint(tx * S + c, ty * S + r)`.
pub fn draw_pack(
    tile_size_px: u16,
    gsd_m: f64,
    tiles: impl IntoIterator<Item = (i32, i32)>,
    route: &[DVec2],
    paint: impl Fn(i64, i64) -> [u8; 3],
) -> Vec<u8> {
    let s = i64::from(tile_size_px);
    let payloads: Vec<(TileKey, Vec<u8>)> = tiles
        .into_iter()
        .map(|(tx, ty)| {
            let mut rgb = Vec::with_capacity((s * s * 3) as usize);
            for r in 0..s {
                for c in 0..s {
                    rgb.extend_from_slice(&paint(i64::from(tx) * s + c, i64::from(ty) * s + r));
                }
            }
            (TileKey::new(tx, ty), rgb)
        })
        .collect();
    let tiles: Vec<PackTile<'_>> = payloads
        .iter()
        .map(|(key, rgb)| PackTile {
            key: *key,
            payload: rgb,
        })
        .collect();
    let header = PackHeader {
        tile_size_px,
        origin: Geodetic::new(42.336, -71.057, 12.0),
        gsd_m,
        corridor_width_m: 20.0,
        tile_count: 0,
        route_point_count: 0,
        codec: TileCodec::Raw,
    };
    encode_pack(&header, route, &tiles).unwrap()
}

/// Every tile in `x0..x1` x `y0..y1`.
pub fn grid(x0: i32, x1: i32, y0: i32, y1: i32) -> Vec<(i32, i32)> {
    (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .collect()
}

/// A crop spec centred on the ego origin: `h` rows, `w` cols at `gsd_m`.
pub fn centred_spec(h: usize, w: usize, gsd_m: f64) -> CropSpec {
    CropSpec {
        height_px: h,
        width_px: w,
        gsd_m,
        x_min_m: -(w as f64) * gsd_m / 2.0,
        y_min_m: -(h as f64) * gsd_m / 2.0,
    }
}

/// Crop and return (pixels, report).
pub fn crop(
    source: &mut PackSource<'_>,
    pose: EgoPose,
    spec: &CropSpec,
) -> (Vec<u8>, satmap_core::route_pack::CropReport) {
    let mut out = vec![7u8; spec.height_px * spec.width_px * 3];
    let report = source.crop_with_report(&pose, spec, &mut out);
    (out, report)
}

/// Pixel `(r, c)` of a crop of width `w`.
pub fn px(out: &[u8], w: usize, r: usize, c: usize) -> [u8; 3] {
    let i = (r * w + c) * 3;
    [out[i], out[i + 1], out[i + 2]]
}
