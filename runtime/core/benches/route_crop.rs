//! Crop time per step: 400 x 200 (0.15 m/px, the paper's 60 m x 30 m) and 200 x 100 (0.3 m/px,
//! the `test` bundle), at an oblique yaw, tile verdicts cached (steady state) and cold (every
//! tile under the crop hashed first).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec2;
use satmap_core::geo::Geodetic;
use satmap_core::pose::EgoPose;
use satmap_core::route_pack::{PackHeader, PackSource, PackTile, TileCodec, TileKey, encode_pack};
use satmap_core::satellite::CropSpec;

const TILE_PX: u16 = 256;

fn pack(gsd_m: f64) -> Vec<u8> {
    let s = usize::from(TILE_PX);
    let payloads: Vec<(TileKey, Vec<u8>)> = (-2..3)
        .flat_map(|ty| (-2..3).map(move |tx| (tx, ty)))
        .map(|(tx, ty): (i32, i32)| {
            let rgb = (0..s * s * 3)
                .map(|i| (i as i32 * 31 + tx * 7 + ty * 13) as u8)
                .collect();
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
        tile_size_px: TILE_PX,
        origin: Geodetic::new(42.336, -71.057, 0.0),
        gsd_m,
        corridor_width_m: 60.0,
        tile_count: 0,
        route_point_count: 0,
        codec: TileCodec::Raw,
    };
    encode_pack(
        &header,
        &[DVec2::new(0.0, 0.0), DVec2::new(10.0, 30.0)],
        &tiles,
    )
    .unwrap()
}

fn bench_crop(c: &mut Criterion) {
    for (h, w, gsd_m) in [(400usize, 200usize, 0.15), (200, 100, 0.3)] {
        let bytes = pack(gsd_m);
        let spec = CropSpec {
            height_px: h,
            width_px: w,
            gsd_m,
            x_min_m: -15.0,
            y_min_m: -30.0,
        };
        let pose = EgoPose::new(DVec2::new(3.1, 7.7), 0.6);
        let mut out = vec![0u8; h * w * 3];
        let mut source = PackSource::from_bytes(&bytes).unwrap();
        c.bench_function(&format!("crop_{h}x{w}_cached"), |b| {
            b.iter(|| source.crop_with_report(black_box(&pose), &spec, &mut out))
        });
        c.bench_function(&format!("crop_{h}x{w}_cold"), |b| {
            b.iter(|| {
                let mut source = PackSource::from_bytes(&bytes).unwrap();
                source.crop_with_report(black_box(&pose), &spec, &mut out)
            })
        });
    }
}

criterion_group!(benches, bench_crop);
criterion_main!(benches);
