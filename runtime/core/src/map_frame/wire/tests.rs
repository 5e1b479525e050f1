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

/// `bytes` with its CRC recomputed: what a faulty sender or a forger who knows the profile
/// sends, so only the content rules can refuse it.
fn resealed(mut bytes: Vec<u8>) -> Vec<u8> {
    let crc = crc_of(&bytes);
    bytes[8..12].copy_from_slice(&crc.to_le_bytes());
    bytes
}

fn good_bytes() -> Vec<u8> {
    let mut buf = [0u8; MAX_WIRE_BYTES];
    let n = serialise(&sample(), DEFAULT_DATA_ID, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// Each content rule refuses a frame whose CRC is right (the cases of issue 38: a count of 255,
/// class 7, reserved bits set, 44 bytes claiming 50 elements), naming the field.
#[test]
fn a_resealed_frame_with_bad_content_is_refused_by_the_field() {
    let edit = |f: &dyn Fn(&mut Vec<u8>)| {
        let mut b = good_bytes();
        f(&mut b);
        check(&resealed(b), DEFAULT_DATA_ID)
    };
    let refused = |offset, rule| Err(WireError::Field { offset, rule });
    let e0 = HEADER_BYTES;
    assert_eq!(edit(&|b| b[42] = 255), refused(42, FieldRule::ElementCount));
    assert_eq!(edit(&|b| b[42] = 2), refused(42, FieldRule::ElementCount));
    assert_eq!(
        edit(&|b| {
            b.truncate(HEADER_BYTES);
            b[0..2].copy_from_slice(&(HEADER_BYTES as u16).to_le_bytes());
            b[42] = 50;
        }),
        refused(42, FieldRule::ElementCount)
    );
    assert_eq!(edit(&|b| b[43] = 1), refused(43, FieldRule::Reserved));
    assert_eq!(edit(&|b| b[38] |= 0x80), refused(36, FieldRule::Reserved));
    assert_eq!(edit(&|b| b[37] |= 0x70), refused(36, FieldRule::Health));
    assert_eq!(
        edit(&|b| b[40..42].copy_from_slice(&1001u16.to_le_bytes())),
        refused(40, FieldRule::Coverage)
    );
    // Coverage without a partial prior (prior 0 = present).
    assert_eq!(edit(&|b| b[37] &= !0x70), refused(40, FieldRule::Coverage));
    assert_eq!(edit(&|b| b[e0] = 7), refused(e0, FieldRule::Class));
    assert_eq!(
        edit(&|b| b[e0 + 1] = 1),
        refused(e0 + 1, FieldRule::Reserved)
    );
    for score in [f32::NAN, -0.1, 1.5, f32::INFINITY] {
        assert_eq!(
            edit(&|b| b[e0 + 4..e0 + 8].copy_from_slice(&score.to_bits().to_le_bytes())),
            refused(e0 + 4, FieldRule::Score)
        );
    }
    let third_point_y = e0 + ELEMENT_BYTES + 8 + 2 * 8 + 4;
    assert_eq!(
        edit(&|b| b[third_point_y..third_point_y + 4]
            .copy_from_slice(&f32::NEG_INFINITY.to_bits().to_le_bytes())),
        refused(third_point_y, FieldRule::Point)
    );
    // The untouched frame passes, resealed or not.
    assert!(check(&resealed(good_bytes()), DEFAULT_DATA_ID).is_ok());
}

proptest::proptest! {
    /// Any frame of a consistent length and CRC, whatever its content: `check` never panics,
    /// and a frame it accepts parses back and serialises to the same bytes (nothing it lets
    /// through is unreadable or ambiguous).
    #[test]
    fn a_resealed_frame_is_refused_or_round_trips(
        n in 0usize..=MAX_TOP_K + 1,
        seed in proptest::collection::vec(proptest::num::u8::ANY, MAX_WIRE_BYTES + ELEMENT_BYTES),
        keep_good in proptest::bool::ANY,
        flips in proptest::collection::vec((0usize..MAX_WIRE_BYTES, 0u8..8), 0..4),
    ) {
        let len = HEADER_BYTES + n * ELEMENT_BYTES;
        let mut bytes = if keep_good {
            let mut b = good_bytes();
            b.resize(len, 0);
            b
        } else {
            seed[..len].to_vec()
        };
        for (at, bit) in flips {
            if at < len {
                bytes[at] ^= 1 << bit;
            }
        }
        bytes[0..2].copy_from_slice(&(len as u16).to_le_bytes());
        bytes[4..8].copy_from_slice(&DEFAULT_DATA_ID.to_le_bytes());
        let bytes = resealed(bytes);
        if check(&bytes, DEFAULT_DATA_ID).is_ok() {
            let frame = deserialise(&bytes, DEFAULT_DATA_ID).unwrap();
            let mut again = [0u8; MAX_WIRE_BYTES];
            let m = serialise(&frame, DEFAULT_DATA_ID, &mut again).unwrap();
            proptest::prop_assert_eq!(&again[..m], &bytes[..]);
        }
    }
}
