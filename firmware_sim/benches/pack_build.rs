//! Pack build time per km of route: 1 km of route, 60 m corridor, 0.15 m/px, 256 px pack tiles,
//! from zoom-19 PNG slippy tiles (decoding included: the tile folder is reopened every
//! iteration).

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use image::RgbImage;
use satmap_runtime::geo::{EnuFrame, Geodetic, TileId};
use satmap_sim::route_pack_builder::{BuildOptions, SlippyTiles, build_pack};

const ZOOM: u8 = 19;
const ROUTE_M: f64 = 1000.0;

fn setup() -> (PathBuf, Vec<Geodetic>) {
    let dir = std::env::temp_dir().join(format!("satmap_pack_build_bench_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let origin = Geodetic::new(42.336, -71.057, 0.0);
    let frame = EnuFrame::new(origin);
    // A gently curving 1 km route heading east-north-east.
    let route: Vec<Geodetic> = (0..=20)
        .map(|k| {
            let x = ROUTE_M * f64::from(k) / 20.0;
            frame.enu_to_geodetic(DVec3::new(
                x * 0.95,
                0.3 * x + 20.0 * (x / 150.0).sin(),
                0.0,
            ))
        })
        .collect();
    let corner = |x: f64, y: f64| frame.enu_to_geodetic(DVec3::new(x, y, 0.0));
    let (sw, ne) = (
        corner(-80.0, -80.0),
        corner(ROUTE_M + 80.0, 0.35 * ROUTE_M + 80.0),
    );
    let t0 = TileId::from_lat_lon(ne.lat_deg, sw.lon_deg, ZOOM).unwrap();
    let t1 = TileId::from_lat_lon(sw.lat_deg, ne.lon_deg, ZOOM).unwrap();
    for tx in t0.x..=t1.x {
        let col = dir.join(ZOOM.to_string()).join(tx.to_string());
        std::fs::create_dir_all(&col).unwrap();
        for ty in t0.y..=t1.y {
            let img = RgbImage::from_fn(256, 256, |c, r| {
                image::Rgb([
                    (tx * 3 + c) as u8,
                    (ty * 5 + r) as u8,
                    ((c ^ r) & 0xff) as u8,
                ])
            });
            img.save(col.join(format!("{ty}.png"))).unwrap();
        }
    }
    (dir, route)
}

fn bench_build(c: &mut Criterion) {
    let (dir, route) = setup();
    let opts = BuildOptions {
        corridor_width_m: 60.0,
        gsd_m: 0.15,
        tile_size_px: 256,
        ..BuildOptions::default()
    };
    let mut group = c.benchmark_group("pack_build");
    group.sample_size(10);
    group.bench_function("per_km_60m_corridor_0.15m", |b| {
        b.iter(|| {
            let mut tiles = SlippyTiles::open(&dir, Some(ZOOM)).unwrap();
            build_pack(&mut tiles, &route, &opts).unwrap()
        })
    });
    group.finish();
    let mut tiles = SlippyTiles::open(&dir, Some(ZOOM)).unwrap();
    let built = build_pack(&mut tiles, &route, &opts).unwrap();
    eprintln!(
        "pack: {} tiles, {:.1} MB for a {:.0} m route",
        built.tiles,
        built.bytes.len() as f64 / 1e6,
        built.route_length_m
    );
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench_build);
criterion_main!(benches);
