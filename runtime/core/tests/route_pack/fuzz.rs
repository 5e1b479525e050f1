//! Property-based fuzzing of the pack parser and the crop behind it: arbitrary bytes,
//! truncations and mutations of valid packs never panic or read out of bounds.

use crate::common::{draw_pack, grid};
use glam::DVec2;
use proptest::prelude::*;
use satmap_core::pose::EgoPose;
use satmap_core::route_pack::format::HEADER_LEN;
use satmap_core::route_pack::{
    MAX_CROP_TILES, PREFETCH_TILES_PER_STEP, PackError, PackSource, RoutePack,
};
use satmap_core::satellite::{CropSpec, SatelliteSource};
use xxhash_rust::xxh3::xxh3_64;

/// Recompute both checksums (offsets from `FORMAT.md`) so a mutation reaches the field rules
/// behind them. Only when the header's counts fit the image.
fn reseal(bytes: &mut [u8]) {
    if bytes.len() < HEADER_LEN {
        return;
    }
    let count = |off: usize| u32::from_le_bytes(bytes[off..off + 4].try_into().unwrap()) as usize;
    let meta_end = HEADER_LEN
        .saturating_add(count(60).saturating_mul(16))
        .saturating_add(count(56).saturating_mul(16));
    if meta_end <= bytes.len() {
        let index = xxh3_64(&bytes[HEADER_LEN..meta_end]);
        bytes[64..72].copy_from_slice(&index.to_le_bytes());
    }
    let header = xxh3_64(&bytes[..72]);
    bytes[72..80].copy_from_slice(&header.to_le_bytes());
}

fn valid_pack() -> Vec<u8> {
    let route = [DVec2::new(0.5, 0.5), DVec2::new(6.0, 3.0)];
    draw_pack(8, 0.5, grid(-1, 2, -1, 1), &route, |x, y| {
        [(x * 9) as u8, (y * 7) as u8, 1]
    })
}

/// Parse, and if the pack loads, crop through it at a few poses.
fn exercise(bytes: &[u8]) {
    if let Ok(mut source) = PackSource::from_bytes(bytes) {
        let spec = CropSpec {
            height_px: 12,
            width_px: 10,
            gsd_m: 0.4,
            x_min_m: -2.0,
            y_min_m: -2.4,
        };
        let mut out = [0u8; 12 * 10 * 3];
        for (x, y, yaw) in [(0.0, 0.0, 0.0), (3.0, -1.0, 2.0), (-4.0, 2.0, -3.0)] {
            let _ = source.crop(&EgoPose::new(DVec2::new(x, y), yaw), &spec, &mut out);
        }
        let pack = source.pack();
        for i in 0..pack.tile_count() + 2 {
            let _ = pack.verified_tile(i);
            let _ = pack.tile_key(i);
        }
    }
}

#[test]
fn every_truncation_of_a_valid_pack_is_a_load_error() {
    let bytes = valid_pack();
    for len in 0..bytes.len() {
        let err = RoutePack::parse(&bytes[..len]).unwrap_err();
        if len < HEADER_LEN {
            assert_eq!(err, PackError::TooShort { len });
        } else {
            assert!(
                matches!(err, PackError::LengthMismatch { .. }),
                "{len}: {err}"
            );
        }
    }
    assert!(RoutePack::parse(&bytes).is_ok());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        exercise(&bytes);
    }

    #[test]
    fn arbitrary_bytes_behind_a_valid_header_never_panic(
        tail in proptest::collection::vec(any::<u8>(), 0..800),
        cut in 0usize..2000,
    ) {
        // A real header (so parsing gets past the checksum) over random sections.
        let mut bytes = valid_pack()[..HEADER_LEN].to_vec();
        bytes.extend_from_slice(&tail);
        bytes.truncate(cut.max(1));
        exercise(&bytes);
    }

    #[test]
    fn mutated_valid_packs_never_panic(
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..8),
        cut in any::<usize>(),
    ) {
        let mut bytes = valid_pack();
        for (pos, value) in edits {
            let n = bytes.len();
            bytes[pos % n] = value;
        }
        let len = bytes.len();
        bytes.truncate(len - cut % 4.min(len));
        exercise(&bytes);
    }

    #[test]
    fn resealed_mutations_reach_the_field_rules_without_panic(
        edits in proptest::collection::vec((0usize..400, any::<u8>()), 1..6),
        extra in 0usize..3,
    ) {
        // Mutations confined to header, route and index, checksums recomputed: every field rule
        // (counts, sizes, NaN, ordering) is hit, and anything that loads must crop safely.
        let mut bytes = valid_pack();
        for (pos, value) in edits {
            let n = (HEADER_LEN + 2 * 16 + 6 * 16).min(bytes.len());
            let pos = pos % n;
            if !(64..80).contains(&pos) {
                bytes[pos] = value;
            }
        }
        bytes.extend(std::iter::repeat_n(0u8, extra));
        reseal(&mut bytes);
        exercise(&bytes);
    }

    #[test]
    fn arbitrary_poses_and_specs_never_panic(
        x in prop_oneof![-50.0f64..50.0, any::<f64>()],
        y in prop_oneof![-50.0f64..50.0, any::<f64>()],
        yaw in prop_oneof![-10.0f64..10.0, any::<f64>()],
        h in 0usize..40,
        w in 0usize..40,
        gsd in prop_oneof![0.01f64..2.0, any::<f64>()],
        x_min in prop_oneof![-20.0f64..0.0, any::<f64>()],
        y_min in prop_oneof![-20.0f64..0.0, any::<f64>()],
        far_route in any::<bool>(),
    ) {
        // Including a finite but astronomically distant route vertex (prefetch must not loop).
        let route = if far_route {
            vec![DVec2::new(0.0, 0.0), DVec2::new(1e300, -1e300), DVec2::new(-1e300, 5.0)]
        } else {
            vec![DVec2::new(0.5, 0.5), DVec2::new(6.0, 3.0)]
        };
        let bytes = draw_pack(8, 0.5, grid(-1, 2, -1, 1), &route, |x, y| [x as u8, y as u8, 3]);
        let mut source = PackSource::from_bytes(&bytes).unwrap();
        let spec = CropSpec { height_px: h, width_px: w, gsd_m: gsd, x_min_m: x_min, y_min_m: y_min };
        let mut out = vec![1u8; h * w * 3];
        let pose = EgoPose::new(DVec2::new(x, y), yaw);
        let coverage = source.crop(&pose, &spec, &mut out);
        let report = *source.last_report();
        prop_assert_eq!(report.coverage, coverage);
        prop_assert!(report.covered_px <= report.total_px);
        prop_assert!(usize::from(report.verified_tiles) <= MAX_CROP_TILES + PREFETCH_TILES_PER_STEP);
        if report.covered_px == 0 {
            prop_assert!(out.iter().all(|v| *v == 0));
        }
    }
}
