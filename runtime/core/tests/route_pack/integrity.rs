//! Integrity: every single-bit flip of a small pack is caught (header or index: load error;
//! tile: that tile reported corrupt and never sampled), and 10 000 random flips of a larger one.

use crate::common::{crop, draw_pack, grid};
use glam::DVec2;
use satmap_core::pose::EgoPose;
use satmap_core::route_pack::format::{HEADER_LEN, INDEX_ENTRY_LEN, ROUTE_POINT_LEN};
use satmap_core::route_pack::{FILL_RGB, PackError, PackSource, RoutePack, TileKey};
use satmap_core::satellite::{Coverage, CropSpec};

const GSD_M: f64 = 0.5;

fn paint(x: i64, y: i64) -> [u8; 3] {
    [(50 + x * 3) as u8, (60 + y * 5) as u8, 200]
}

/// Check one flipped image; returns true if it failed to load.
fn check_flip(
    bytes: &[u8],
    good: &[u8],
    bit: usize,
    tile_px: usize,
    spec: &CropSpec,
    pose: EgoPose,
) -> bool {
    let mut damaged = bytes.to_vec();
    damaged[bit / 8] ^= 1 << (bit % 8);
    let pack = RoutePack::parse(bytes).unwrap();
    let meta_end = HEADER_LEN
        + pack.route_point_count() * ROUTE_POINT_LEN
        + pack.tile_count() * INDEX_ENTRY_LEN;
    let byte = bit / 8;
    match PackSource::from_bytes(&damaged) {
        Err(e) => {
            assert!(
                byte < meta_end,
                "bit {bit} in a tile payload rejected the pack: {e}"
            );
            true
        }
        Ok(mut source) => {
            assert!(byte >= meta_end, "bit {bit} in header/index not detected");
            let tile = (byte - meta_end) / (tile_px * tile_px * 3);
            let key = pack.tile_key(tile).unwrap();
            let (out, report) = crop(&mut source, pose, spec);
            assert_eq!(report.coverage, Coverage::Corrupt, "bit {bit}");
            assert_eq!(report.corrupt_tiles, 1, "bit {bit}");
            assert_eq!(report.first_corrupt, Some(key), "bit {bit}");
            // Never used: every crop pixel that would have read the damaged tile is fill.
            let side_m = tile_px as f64 * GSD_M;
            let (sin, cos) = pose.yaw_rad.sin_cos();
            for r in 0..spec.height_px {
                for c in 0..spec.width_px {
                    let x_e = spec.x_min_m + (c as f64 + 0.5) * spec.gsd_m;
                    let y_e = spec.y_min_m + (r as f64 + 0.5) * spec.gsd_m;
                    let p =
                        pose.position_m + DVec2::new(sin, -cos) * x_e + DVec2::new(cos, sin) * y_e;
                    let at =
                        TileKey::new((p.x / side_m).floor() as i32, (p.y / side_m).floor() as i32);
                    let i = (r * spec.width_px + c) * 3;
                    if at == key {
                        assert_eq!(
                            out[i..i + 3],
                            FILL_RGB,
                            "bit {bit} pixel ({r},{c}) used a corrupt tile"
                        );
                    } else if out[i..i + 3] != FILL_RGB {
                        assert_eq!(out[i..i + 3], good[i..i + 3]);
                    }
                }
            }
            false
        }
    }
}

#[test]
fn every_single_bit_flip_of_a_small_pack_is_detected() {
    let tile_px = 8usize;
    let route = [
        DVec2::new(1.0, 1.0),
        DVec2::new(4.0, 5.0),
        DVec2::new(7.5, 7.0),
    ];
    let bytes = draw_pack(tile_px as u16, GSD_M, grid(0, 2, 0, 2), &route, paint);
    // The whole 2x2-tile pack (8 m square) inside a 12 m crop at yaw 0.3.
    let spec = CropSpec {
        height_px: 24,
        width_px: 24,
        gsd_m: GSD_M,
        x_min_m: -6.0,
        y_min_m: -6.0,
    };
    let pose = EgoPose::new(DVec2::new(4.0, 4.0), 0.3);
    let (good, _) = crop(&mut PackSource::from_bytes(&bytes).unwrap(), pose, &spec);
    let mut load_errors = 0;
    for bit in 0..bytes.len() * 8 {
        load_errors += usize::from(check_flip(&bytes, &good, bit, tile_px, &spec, pose));
    }
    assert_eq!(load_errors, (HEADER_LEN + 3 * 16 + 4 * 16) * 8);
}

#[test]
fn ten_thousand_random_bit_flips_of_a_larger_pack_are_detected() {
    let tile_px = 64usize;
    let route: Vec<DVec2> = (0..50)
        .map(|k| DVec2::new(f64::from(k), 40.0 + f64::from(k) * 0.3))
        .collect();
    let bytes = draw_pack(tile_px as u16, GSD_M, grid(0, 3, 0, 3), &route, paint);
    let spec = CropSpec {
        height_px: 100,
        width_px: 100,
        gsd_m: 1.0,
        x_min_m: -50.0,
        y_min_m: -50.0,
    };
    let pose = EgoPose::new(DVec2::new(48.0, 48.0), -2.0);
    // xorshift64*: a fixed, dependency-free sequence of positions.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    };
    let (good, _) = crop(&mut PackSource::from_bytes(&bytes).unwrap(), pose, &spec);
    let bits = bytes.len() as u64 * 8;
    // Every header/index bit plus random ones across the payloads.
    let meta_bits = (HEADER_LEN + route.len() * 16 + 9 * 16) * 8;
    for bit in 0..meta_bits {
        assert!(check_flip(&bytes, &good, bit, tile_px, &spec, pose));
    }
    for _ in 0..10_000 {
        check_flip(
            &bytes,
            &good,
            (next() % bits) as usize,
            tile_px,
            &spec,
            pose,
        );
    }
}

#[test]
fn load_errors_name_the_broken_rule() {
    let bytes = draw_pack(8, GSD_M, grid(0, 2, 0, 1), &[], paint);
    assert_eq!(
        RoutePack::parse(&bytes[..40]).unwrap_err(),
        PackError::TooShort { len: 40 }
    );
    let expected = bytes.len();
    assert_eq!(
        RoutePack::parse(&bytes[..expected - 1]).unwrap_err(),
        PackError::LengthMismatch {
            len: expected - 1,
            expected
        }
    );
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(
        RoutePack::parse(&longer),
        Err(PackError::LengthMismatch { .. })
    ));
    let mut magic = bytes.clone();
    magic[0] = b'X';
    assert_eq!(RoutePack::parse(&magic).unwrap_err(), PackError::BadMagic);
    let mut version = bytes.clone();
    version[8] = 3;
    assert_eq!(
        RoutePack::parse(&version).unwrap_err(),
        PackError::UnsupportedVersion { version: 3 }
    );
    let mut header = bytes.clone();
    header[20] ^= 4;
    assert_eq!(
        RoutePack::parse(&header).unwrap_err(),
        PackError::HeaderChecksum
    );
    let mut index = bytes.clone();
    index[HEADER_LEN + 3] ^= 1;
    assert_eq!(
        RoutePack::parse(&index).unwrap_err(),
        PackError::IndexChecksum
    );
}

#[test]
fn a_corrupt_tile_stays_corrupt_and_the_others_stay_usable() {
    let bytes = draw_pack(16, GSD_M, grid(0, 4, 0, 1), &[], paint);
    let pack = RoutePack::parse(&bytes).unwrap();
    let payload_start = bytes.len() - 4 * 16 * 16 * 3;
    let mut damaged = bytes.clone();
    damaged[payload_start + 16 * 16 * 3 + 5] ^= 0x10; // tile 1
    let mut source = PackSource::from_bytes(&damaged).unwrap();
    assert!(source.pack().verified_tile(1).is_none());
    assert!(pack.verified_tile(1).is_some());
    let spec = CropSpec {
        height_px: 8,
        width_px: 8,
        gsd_m: GSD_M,
        x_min_m: -2.0,
        y_min_m: -2.0,
    };
    // Over tile 0 (x in [0, 8) m): fine. Over tile 1 (x in [8, 16) m): corrupt, repeatedly.
    let (_, report) = crop(&mut source, EgoPose::new(DVec2::new(3.0, 4.0), 0.0), &spec);
    assert_eq!(report.coverage, Coverage::Full);
    for _ in 0..3 {
        let (out, report) = crop(&mut source, EgoPose::new(DVec2::new(12.0, 4.0), 0.0), &spec);
        assert_eq!(report.coverage, Coverage::Corrupt);
        assert!(out.chunks(3).all(|p| p == FILL_RGB));
    }
    // The verdict is cached: tile 1 was hashed once.
    assert_eq!(source.cache().verified_total(), 2);
}
