//! Decode time of one route-pack tile on the vehicle's path (`decode_tile`, the scalar no_std
//! decoders), for 256 px tiles of the procedural route imagery at 0.15 and 0.3 m/px: JPEG at
//! the builder's default quality and zlib. Tiles are cut from a real build so their content
//! (road, markings, fields) is what packs hold.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use satmap_runtime::geo::Geodetic;
use satmap_runtime::route_pack::{RoutePack, TileCodec, decode_tile};
use satmap_runtime::satellite::CropSpec;
use satmap_sim::route_pack_builder::{
    BuildOptions, DEFAULT_JPEG_QUALITY, SyntheticRoute, TileCompression, build_pack,
};

fn pack(gsd_m: f64, compression: TileCompression) -> Vec<u8> {
    let road = SyntheticRoute::new(3, 0.5, Geodetic::new(48.137, 11.575, 0.0)).unwrap();
    let opts = BuildOptions {
        gsd_m,
        origin: Some(road.anchor()),
        compression,
        crop: CropSpec {
            height_px: 200,
            width_px: 100,
            gsd_m: 0.3,
            x_min_m: -15.0,
            y_min_m: -30.0,
        },
        ..BuildOptions::default()
    };
    build_pack(&mut road.imagery_at(gsd_m), &road.route_wgs84(), &opts)
        .unwrap()
        .bytes
}

fn bench(c: &mut Criterion) {
    for gsd_m in [0.15, 0.3] {
        for (name, compression) in [
            (
                "jpeg",
                TileCompression::Jpeg {
                    quality: DEFAULT_JPEG_QUALITY,
                },
            ),
            ("deflate", TileCompression::Deflate),
        ] {
            let bytes = pack(gsd_m, compression);
            let pack = RoutePack::parse(&bytes).unwrap();
            let codec: TileCodec = pack.codec();
            let payloads: Vec<&[u8]> = (0..pack.tile_count())
                .filter_map(|i| pack.tile_payload_unverified(i))
                .collect();
            let mut out = vec![0u8; pack.header().tile_bytes()];
            let mut k = 0;
            c.bench_function(&format!("decode 256 px tile {name} {gsd_m} m/px"), |b| {
                b.iter(|| {
                    k = (k + 1) % payloads.len();
                    decode_tile(codec, black_box(payloads[k]), 256, &mut out).unwrap();
                    black_box(&out);
                });
            });
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
