//! The map frame's protected serialised form, for crossing a bus or a process boundary: an
//! AUTOSAR E2E Profile 4-style header (length, counter, data id, CRC-32/AUTOSAR) followed by the
//! frame, little-endian, documented to the byte in `ARCHITECTURE.md` ("Protected map frame").
//!
//! | bytes | field |
//! |---|---|
//! | 0..2 | `length`: u16, bytes of the whole serialised frame |
//! | 2..4 | `counter`: u16, [`MapFrame::e2e_counter`] (+1 per published map, wraps) |
//! | 4..8 | `data_id`: u32, the message id the receiver expects |
//! | 8..12 | `crc`: u32, CRC-32/AUTOSAR (poly 0xF4ACFB13) over bytes 0..8 then 12..length |
//! | 12..20 | `sequence`: u64 |
//! | 20..28 | `timestamp_us`: u64 |
//! | 28..36 | `digest`: u64 ([`super::digest`]) |
//! | 36..40 | health word: u32 ([`health_word`]) |
//! | 40..42 | `covered_permille`: u16 (0 unless the prior is partial) |
//! | 42 | element count: u8 (at most `MAX_TOP_K`) |
//! | 43 | reserved, 0 |
//! | 44.. | elements, [`ELEMENT_BYTES`] each: class u8, reserved u8 (0), instance u16, score f32 bits, then 20 x (x f32 bits, y f32 bits), ego metres |
//!
//! Health word: bits `2c..2c+2` camera `c`'s [`CameraState`] (c = 0..6); bits 12..15 the
//! satellite prior (0 present, 1 partial, 2 missing, 3 corrupt); bit 15 degraded; bit 16
//! deadline overrun; the rest 0.

use core::fmt;

mod receive;
pub use receive::{Checked, check, deserialise};

use crc::{CRC_32_AUTOSAR, Crc};

use super::{Health, MapFrame, SatellitePrior};
use crate::calibration::NUM_CAMERAS;
use crate::capacity::{MAX_TOP_K, NUM_POINTS};
use crate::frame::CameraState;

/// Header and frame fields before the elements, bytes.
pub const HEADER_BYTES: usize = 44;
/// One serialised element, bytes.
pub const ELEMENT_BYTES: usize = 8 + NUM_POINTS * 8;
/// The largest serialised frame (`MAX_TOP_K` elements), bytes: a buffer of this size always
/// suffices.
pub const MAX_WIRE_BYTES: usize = HEADER_BYTES + MAX_TOP_K * ELEMENT_BYTES;
/// The data id SatMap's map message carries unless the integrator assigns another ("SMAP").
pub const DEFAULT_DATA_ID: u32 = 0x534D_4150;

const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_AUTOSAR);

/// Why a serialised frame was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum WireError {
    /// The output buffer cannot hold the frame.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// Fewer bytes than a header, or not the length the header states.
    Length {
        /// Bytes the header states (0 when there is no header).
        stated: usize,
        /// Bytes received.
        got: usize,
    },
    /// The CRC does not match: the frame was corrupted.
    Crc {
        /// CRC in the frame.
        stated: u32,
        /// CRC of the bytes received.
        computed: u32,
    },
    /// Another message's data id.
    DataId {
        /// Data id expected.
        expected: u32,
        /// Data id received.
        got: u32,
    },
    /// A field outside its range: a sender bug or a forgery, since the CRC matched.
    Field {
        /// Byte offset of the field.
        offset: usize,
        /// Which rule it breaks.
        rule: FieldRule,
    },
}

/// The content rules a received frame must keep (module doc), beyond its length and CRC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldRule {
    /// The element count is above `MAX_TOP_K` or disagrees with the frame's length.
    ElementCount,
    /// A reserved byte or bit is not 0.
    Reserved,
    /// A camera state or satellite prior code that does not exist.
    Health,
    /// `covered_permille` above 1000, or not 0 while the prior is not partial.
    Coverage,
    /// An element class that does not exist.
    Class,
    /// A score that is not a finite value in [0, 1].
    Score,
    /// A point coordinate that is not finite.
    Point,
}

impl FieldRule {
    /// What the rule asks, for messages.
    #[must_use]
    pub const fn describe(self) -> &'static str {
        match self {
            Self::ElementCount => "element count above the maximum or not the frame's length",
            Self::Reserved => "reserved bits not 0",
            Self::Health => "no such camera state or satellite prior",
            Self::Coverage => "coverage above 1000 per mille, or set without a partial prior",
            Self::Class => "no such element class",
            Self::Score => "score not finite in [0, 1]",
            Self::Point => "point coordinate not finite",
        }
    }
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooSmall { needed, got } => {
                write!(f, "map frame needs {needed} bytes, buffer has {got}")
            }
            Self::Length { stated, got } => {
                write!(f, "map frame states {stated} bytes, {got} received")
            }
            Self::Crc { stated, computed } => write!(
                f,
                "map frame CRC {stated:#010x} does not match the bytes ({computed:#010x})"
            ),
            Self::DataId { expected, got } => {
                write!(
                    f,
                    "map frame data id {got:#010x}, expected {expected:#010x}"
                )
            }
            Self::Field { offset, rule } => {
                write!(f, "map frame field at byte {offset}: {}", rule.describe())
            }
        }
    }
}

impl core::error::Error for WireError {}

/// The health word of the serialised frame (layout in the module doc).
#[must_use]
pub fn health_word(h: &Health) -> u32 {
    let cameras = h
        .cameras
        .iter()
        .enumerate()
        .fold(0u32, |w, (c, s)| w | (u32::from(*s as u8) << (2 * c)));
    let prior = match h.satellite {
        SatellitePrior::Present => 0u32,
        SatellitePrior::Partial { .. } => 1,
        SatellitePrior::Missing => 2,
        SatellitePrior::Corrupt => 3,
    };
    cameras | prior << 12 | u32::from(h.degraded) << 15 | u32::from(h.deadline_overrun) << 16
}

/// The health of a received frame from its word and `covered_permille`, under the content
/// rules: no reserved bit set (bits 17 and up), a satellite prior code that exists, coverage at
/// most 1000 and only with a partial prior.
fn health_from_word(word: u32, covered_permille: u16) -> Result<Health, WireError> {
    let field = |offset, rule| Err(WireError::Field { offset, rule });
    if word >> 17 != 0 {
        return field(36, FieldRule::Reserved);
    }
    let satellite = match (word >> 12) & 0b111 {
        0 => SatellitePrior::Present,
        1 => SatellitePrior::Partial { covered_permille },
        2 => SatellitePrior::Missing,
        3 => SatellitePrior::Corrupt,
        _ => return field(36, FieldRule::Health),
    };
    let partial = matches!(satellite, SatellitePrior::Partial { .. });
    if covered_permille > 1000 || (!partial && covered_permille != 0) {
        return field(40, FieldRule::Coverage);
    }
    let camera = |c: usize| match (word >> (2 * c)) & 0b11 {
        0 => CameraState::Used,
        1 => CameraState::Missing,
        2 => CameraState::Stale,
        _ => CameraState::Invalid,
    };
    Ok(Health {
        satellite,
        degraded: word & (1 << 15) != 0,
        deadline_overrun: word & (1 << 16) != 0,
        cameras: core::array::from_fn(camera),
    })
}

/// Bytes `frame` serialises to.
#[must_use]
pub fn wire_len(frame: &MapFrame) -> usize {
    HEADER_BYTES + frame.elements.len() * ELEMENT_BYTES
}

/// Serialise `frame` with its E2E header into the start of `out`; returns the bytes written.
///
/// # Errors
/// [`WireError::BufferTooSmall`] (nothing written).
pub fn serialise(frame: &MapFrame, data_id: u32, out: &mut [u8]) -> Result<usize, WireError> {
    let len = wire_len(frame);
    let Some(out) = out.get_mut(..len) else {
        return Err(WireError::BufferTooSmall {
            needed: len,
            got: out.len(),
        });
    };
    // len <= MAX_WIRE_BYTES < 65536.
    out[0..2].copy_from_slice(&(len as u16).to_le_bytes());
    out[2..4].copy_from_slice(&frame.e2e_counter.to_le_bytes());
    out[4..8].copy_from_slice(&data_id.to_le_bytes());
    out[12..20].copy_from_slice(&frame.sequence.to_le_bytes());
    out[20..28].copy_from_slice(&frame.timestamp_us.to_le_bytes());
    out[28..36].copy_from_slice(&frame.digest.to_le_bytes());
    out[36..40].copy_from_slice(&health_word(&frame.health).to_le_bytes());
    let covered = match frame.health.satellite {
        SatellitePrior::Partial { covered_permille } => covered_permille,
        _ => 0,
    };
    out[40..42].copy_from_slice(&covered.to_le_bytes());
    out[42] = frame.elements.len() as u8;
    out[43] = 0;
    for (e, b) in frame
        .elements
        .iter()
        .zip(out[HEADER_BYTES..].chunks_exact_mut(ELEMENT_BYTES))
    {
        b[0] = e.class as u8;
        b[1] = 0;
        b[2..4].copy_from_slice(&e.instance.to_le_bytes());
        b[4..8].copy_from_slice(&e.score.to_bits().to_le_bytes());
        for (p, pb) in e.points_m.iter().zip(b[8..].chunks_exact_mut(8)) {
            pb[0..4].copy_from_slice(&p.x.to_bits().to_le_bytes());
            pb[4..8].copy_from_slice(&p.y.to_bits().to_le_bytes());
        }
    }
    let crc = crc_of(out);
    out[8..12].copy_from_slice(&crc.to_le_bytes());
    Ok(len)
}

/// CRC-32/AUTOSAR over bytes 0..8 and 12..end (everything but the CRC field).
fn crc_of(frame: &[u8]) -> u32 {
    let mut digest = CRC32.digest();
    digest.update(&frame[..8]);
    digest.update(&frame[12..]);
    digest.finalize()
}

fn le4(b: &[u8]) -> [u8; 4] {
    let mut a = [0; 4];
    a.copy_from_slice(&b[..4]);
    a
}

fn le8(b: &[u8]) -> [u8; 8] {
    let mut a = [0; 8];
    a.copy_from_slice(&b[..8]);
    a
}

const _: () = assert!(MAX_WIRE_BYTES <= u16::MAX as usize);
const _: () = assert!(NUM_CAMERAS * 2 <= 12);

#[cfg(test)]
mod tests;
