//! The wire form's offsets, round trip and corruption checks.

use super::*;
use crate::frame::CameraState;
use crate::map_frame::{MapClass, MapElement, digest};
use glam::Vec2;

pub(crate) fn sample() -> MapFrame {
    let mut f = MapFrame {
        sequence: 0x0102_0304_0506_0708,
        timestamp_us: 42_000_000,
        e2e_counter: 65535,
        health: Health {
            satellite: SatellitePrior::Partial {
                covered_permille: 731,
            },
            degraded: false,
            deadline_overrun: true,
            cameras: [
                CameraState::Used,
                CameraState::Missing,
                CameraState::Used,
                CameraState::Stale,
                CameraState::Invalid,
                CameraState::Used,
            ],
        },
        ..MapFrame::default()
    };
    for k in 0..3u16 {
        let _ = f.elements.push(MapElement {
            class: MapClass::from_label(usize::from(k)).unwrap_or(MapClass::Divider),
            score: 0.9 - f32::from(k) * 0.1,
            instance: 7 * k,
            points_m: core::array::from_fn(|i| Vec2::new(i as f32 * 0.5, -(k as f32))),
        });
    }
    f.digest = digest(&f.elements);
    f
}

#[test]
fn round_trip_and_documented_offsets() {
    let f = sample();
    let mut buf = [0u8; MAX_WIRE_BYTES];
    let n = serialise(&f, DEFAULT_DATA_ID, &mut buf).unwrap();
    assert_eq!(n, HEADER_BYTES + 3 * ELEMENT_BYTES);
    let bytes = &buf[..n];
    assert_eq!(u16::from_le_bytes([bytes[0], bytes[1]]) as usize, n);
    assert_eq!(u16::from_le_bytes([bytes[2], bytes[3]]), 65535);
    assert_eq!(&bytes[4..8], &DEFAULT_DATA_ID.to_le_bytes());
    assert_eq!(&bytes[12..20], &f.sequence.to_le_bytes());
    // Camera states 0,1,0,2,3,0 -> bits; partial prior (1 << 12); overrun (1 << 16).
    let word = 1 << 2 | 2 << 6 | 3 << 8 | 1 << 12 | 1 << 16;
    assert_eq!(&bytes[36..40], &(word as u32).to_le_bytes());
    assert_eq!(&bytes[40..42], &731u16.to_le_bytes());
    assert_eq!(bytes[42], 3);
    // The CRC is CRC-32/AUTOSAR of everything but itself (check value of the catalogue).
    assert_eq!(CRC32.checksum(b"123456789"), 0x1697_D06A);
    assert_eq!(deserialise(bytes, DEFAULT_DATA_ID), Ok(f));
    assert!(matches!(
        deserialise(bytes, DEFAULT_DATA_ID + 1),
        Err(WireError::DataId { .. })
    ));
    assert!(matches!(
        serialise(&sample(), DEFAULT_DATA_ID, &mut buf[..n - 1]),
        Err(WireError::BufferTooSmall { .. })
    ));
}

#[test]
fn every_single_bit_flip_fails_the_check() {
    let mut buf = [0u8; MAX_WIRE_BYTES];
    let n = serialise(&sample(), DEFAULT_DATA_ID, &mut buf).unwrap();
    let good = buf;
    let mut flips = 0;
    for bit in 0..n * 8 {
        let mut bad = good;
        bad[bit / 8] ^= 1 << (bit % 8);
        assert!(
            check(&bad[..n], DEFAULT_DATA_ID).is_err(),
            "flip of bit {bit} passed the check"
        );
        flips += 1;
    }
    assert_eq!(flips, n * 8);
    // Truncated and extended frames fail on the length.
    assert!(matches!(
        check(&good[..n - 1], DEFAULT_DATA_ID),
        Err(WireError::Length { .. })
    ));
    assert!(matches!(
        check(&good[..n + 1], DEFAULT_DATA_ID),
        Err(WireError::Length { .. })
    ));
    assert!(matches!(
        check(&[], DEFAULT_DATA_ID),
        Err(WireError::Length { .. })
    ));
}
