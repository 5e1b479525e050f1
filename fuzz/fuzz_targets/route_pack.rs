//! `PackSource::from_bytes` on route packs: header, route, tile index and their checksums; a
//! pack that loads lists only tiles inside its bytes, and crops around its route. The first
//! input byte picks the mode: odd recomputes both checksums after the mutation (offsets from
//! `runtime/core/src/route_pack/FORMAT.md`), so edits of the header, route or index reach the field
//! rules behind them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use satmap_runtime::glam::DVec2;
use satmap_runtime::pose::EgoPose;
use satmap_runtime::route_pack::PackSource;
use satmap_runtime::route_pack::format::HEADER_LEN;
use satmap_runtime::satellite::{CropSpec, SatelliteSource};

fn reseal(bytes: &mut [u8]) {
    if bytes.len() < HEADER_LEN {
        return;
    }
    let count =
        |b: &[u8], at: usize| u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]) as usize;
    let meta_end = HEADER_LEN
        .saturating_add(count(bytes, 56).saturating_mul(16))
        .saturating_add(count(bytes, 60).saturating_mul(16));
    if meta_end <= bytes.len() {
        let index = xxhash_rust::xxh3::xxh3_64(&bytes[HEADER_LEN..meta_end]);
        bytes[64..72].copy_from_slice(&index.to_le_bytes());
    }
    let header = xxhash_rust::xxh3::xxh3_64(&bytes[..72]);
    bytes[72..80].copy_from_slice(&header.to_le_bytes());
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let mut bytes = rest.to_vec();
    if mode & 1 == 1 {
        reseal(&mut bytes);
    }
    let Ok(mut source) = PackSource::from_bytes(&bytes) else {
        return;
    };
    let pack = source.pack();
    let n = pack.tile_count();
    for i in 0..n {
        let key = pack.tile_key(i).expect("a listed tile has a key");
        assert_eq!(pack.find_tile(key), Some(i));
        let _ = pack.verified_tile(i);
    }
    assert!(pack.tile_key(n).is_none());
    let start = (pack.route_point_count() > 0)
        .then(|| pack.route_point(0))
        .flatten()
        .unwrap_or(DVec2::ZERO);
    // The seed pack's crop (`tests/fuzz_parsers/seeds.rs`, `CROP`).
    let spec = CropSpec {
        height_px: 20,
        width_px: 12,
        gsd_m: 0.4,
        x_min_m: -2.4,
        y_min_m: -4.0,
    };
    let mut out = [0u8; 20 * 12 * 3];
    source.crop(&EgoPose::new(start, 0.3), &spec, &mut out);
    let report = source.last_report();
    assert!(report.covered_px <= report.total_px);
});
