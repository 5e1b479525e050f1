//! Why a pack image was rejected at load, or could not be written.

use core::fmt;

use super::format::{HEADER_LEN, VERSION, VERSION_1};

/// Why a pack image was rejected at load (or could not be written).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum PackError {
    /// The image is shorter than the header.
    TooShort {
        /// Bytes given.
        len: usize,
    },
    /// The first 8 bytes are not [`super::format::MAGIC`].
    BadMagic,
    /// A version this runtime does not read.
    UnsupportedVersion {
        /// Version in the header.
        version: u16,
    },
    /// `header_len` is not [`HEADER_LEN`].
    BadHeaderLen {
        /// Value in the header.
        header_len: u16,
    },
    /// The header checksum does not match: the header is damaged.
    HeaderChecksum,
    /// A header field breaks its rule in `FORMAT.md`.
    BadField {
        /// Field name as in `FORMAT.md`.
        field: &'static str,
    },
    /// The image length is not what the header's counts imply.
    LengthMismatch {
        /// Bytes given.
        len: usize,
        /// Bytes the header implies (saturated at `usize::MAX`).
        expected: usize,
    },
    /// The route + index checksum does not match: route or index damaged.
    IndexChecksum,
    /// A route point is not finite.
    RouteNotFinite {
        /// Point number.
        point: u32,
    },
    /// Index entries are not strictly increasing in (tile_y, tile_x).
    IndexNotSorted {
        /// Entry number of the first entry out of order.
        entry: u32,
    },
    /// A tile codec this runtime does not decode (version 2 `codec` byte).
    UnsupportedCodec {
        /// Value in the header.
        codec: u8,
    },
    /// Version 2: a tile's payload offset or length breaks the layout rule (payloads packed
    /// back to back in index order, each 1..=[`PackHeader::max_payload_len`](super::PackHeader::max_payload_len) bytes, ending
    /// exactly at the end of the image; raw payloads exactly `tile_size_px^2 * 3`).
    PayloadLayout {
        /// Entry number of the first offending entry.
        entry: u32,
    },
    /// Writer: a tile payload does not hold `tile_size_px^2 * 3` bytes (raw), or is empty or
    /// longer than [`PackHeader::max_payload_len`](super::PackHeader::max_payload_len) (compressed).
    TilePayloadSize {
        /// Entry number (after sorting).
        entry: u32,
    },
}

impl fmt::Display for PackError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooShort { len } => {
                write!(
                    f,
                    "route pack of {len} bytes is shorter than its {HEADER_LEN}-byte header"
                )
            }
            Self::BadMagic => f.write_str("not a route pack (bad magic)"),
            Self::UnsupportedVersion { version } => {
                write!(
                    f,
                    "route pack version {version} is not supported (expected {VERSION_1} or {VERSION})"
                )
            }
            Self::BadHeaderLen { header_len } => {
                write!(
                    f,
                    "route pack header_len {header_len} (expected {HEADER_LEN})"
                )
            }
            Self::HeaderChecksum => f.write_str("route pack header checksum mismatch"),
            Self::BadField { field } => write!(f, "route pack header field `{field}` is invalid"),
            Self::LengthMismatch { len, expected } => {
                write!(
                    f,
                    "route pack is {len} bytes, its header implies {expected}"
                )
            }
            Self::IndexChecksum => f.write_str("route pack route/index checksum mismatch"),
            Self::RouteNotFinite { point } => {
                write!(f, "route pack route point {point} is not finite")
            }
            Self::IndexNotSorted { entry } => {
                write!(
                    f,
                    "route pack tile index entry {entry} is out of order or duplicated"
                )
            }
            Self::UnsupportedCodec { codec } => {
                write!(f, "route pack tile codec {codec} is not supported")
            }
            Self::PayloadLayout { entry } => {
                write!(
                    f,
                    "route pack tile {entry} payload offset or length breaks the layout"
                )
            }
            Self::TilePayloadSize { entry } => {
                write!(f, "route pack tile {entry} payload has the wrong size")
            }
        }
    }
}

impl core::error::Error for PackError {}
