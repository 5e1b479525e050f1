//! The receiving side of the protected map frame: a received byte string checked (length, CRC,
//! data id) and parsed back into a [`MapFrame`].

use glam::Vec2;

use super::{
    ELEMENT_BYTES, FieldRule, HEADER_BYTES, WireError, crc_of, health_from_word, le4, le8,
};
use crate::capacity::{MAX_TOP_K, NUM_POINTS};
use crate::map_frame::{Health, MapClass, MapElement, MapFrame};

/// What a checked frame's header says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Checked {
    /// The E2E counter.
    pub counter: u16,
    /// The frame's sequence counter.
    pub sequence: u64,
}

/// Check a received serialised frame: length, CRC, data id, then every field's content (the
/// element count against the length, reserved bytes and bits, health codes, coverage, classes,
/// finite scores in [0, 1] and finite points), so that a receiver may trust what it reads: a
/// frame whose CRC a sender computed over a wrong count passes no further.
///
/// # Errors
/// [`WireError::Length`], [`WireError::Crc`], [`WireError::DataId`] or [`WireError::Field`]
/// with the first field (by offset) that breaks its rule.
pub fn check(bytes: &[u8], data_id: u32) -> Result<Checked, WireError> {
    let stated = bytes
        .get(0..2)
        .map_or(0, |b| usize::from(u16::from_le_bytes([b[0], b[1]])));
    if bytes.len() < HEADER_BYTES || stated != bytes.len() {
        return Err(WireError::Length {
            stated,
            got: bytes.len(),
        });
    }
    let stated_crc = u32::from_le_bytes(le4(&bytes[8..12]));
    let computed = crc_of(bytes);
    if stated_crc != computed {
        return Err(WireError::Crc {
            stated: stated_crc,
            computed,
        });
    }
    let got = u32::from_le_bytes(le4(&bytes[4..8]));
    if got != data_id {
        return Err(WireError::DataId {
            expected: data_id,
            got,
        });
    }
    check_fields(bytes)?;
    Ok(Checked {
        counter: u16::from_le_bytes([bytes[2], bytes[3]]),
        sequence: u64::from_le_bytes(le8(&bytes[12..20])),
    })
}

/// [`check`], then parse the frame back.
///
/// # Errors
/// As [`check`].
pub fn deserialise(bytes: &[u8], data_id: u32) -> Result<MapFrame, WireError> {
    let checked = check(bytes, data_id)?;
    let health = health_of(bytes)?;
    let mut frame = MapFrame {
        sequence: checked.sequence,
        timestamp_us: u64::from_le_bytes(le8(&bytes[20..28])),
        elements: heapless::Vec::new(),
        health,
        digest: u64::from_le_bytes(le8(&bytes[28..36])),
        e2e_counter: checked.counter,
    };
    for (k, b) in bytes[HEADER_BYTES..]
        .chunks_exact(ELEMENT_BYTES)
        .enumerate()
    {
        let class = MapClass::from_label(usize::from(b[0])).ok_or(WireError::Field {
            offset: HEADER_BYTES + k * ELEMENT_BYTES,
            rule: FieldRule::Class,
        })?;
        let mut points_m = [Vec2::ZERO; NUM_POINTS];
        for (p, pb) in points_m.iter_mut().zip(b[8..].chunks_exact(8)) {
            *p = Vec2::new(
                f32::from_bits(u32::from_le_bytes(le4(&pb[0..4]))),
                f32::from_bits(u32::from_le_bytes(le4(&pb[4..8]))),
            );
        }
        let element = MapElement {
            class,
            score: f32::from_bits(u32::from_le_bytes(le4(&b[4..8]))),
            instance: u16::from_le_bytes([b[2], b[3]]),
            points_m,
        };
        // At most MAX_TOP_K elements: `check` compared the count and the length.
        let _ = frame.elements.push(element);
    }
    Ok(frame)
}

/// The content rules of [`check`], on a frame whose length and CRC are already checked.
fn check_fields(bytes: &[u8]) -> Result<(), WireError> {
    let field = |offset, rule| Err(WireError::Field { offset, rule });
    health_of(bytes)?;
    let n = usize::from(bytes[42]);
    if n > MAX_TOP_K || bytes.len() != HEADER_BYTES + n * ELEMENT_BYTES {
        return field(42, FieldRule::ElementCount);
    }
    if bytes[43] != 0 {
        return field(43, FieldRule::Reserved);
    }
    for (k, b) in bytes[HEADER_BYTES..]
        .chunks_exact(ELEMENT_BYTES)
        .enumerate()
    {
        let at = HEADER_BYTES + k * ELEMENT_BYTES;
        if MapClass::from_label(usize::from(b[0])).is_none() {
            return field(at, FieldRule::Class);
        }
        if b[1] != 0 {
            return field(at + 1, FieldRule::Reserved);
        }
        let score = f32::from_bits(u32::from_le_bytes(le4(&b[4..8])));
        if !(0.0..=1.0).contains(&score) {
            return field(at + 4, FieldRule::Score);
        }
        if let Some(i) = b[8..]
            .chunks_exact(4)
            .position(|c| !f32::from_bits(u32::from_le_bytes(le4(c))).is_finite())
        {
            return field(at + 8 + 4 * i, FieldRule::Point);
        }
    }
    Ok(())
}

/// The health word (bytes 36..40) and coverage (40..42) read under their rules.
fn health_of(bytes: &[u8]) -> Result<Health, WireError> {
    let covered = u16::from_le_bytes([bytes[40], bytes[41]]);
    health_from_word(u32::from_le_bytes(le4(&bytes[36..40])), covered)
}
