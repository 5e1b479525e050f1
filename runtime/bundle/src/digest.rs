//! The bundle digest: the SHA-256 of `manifest.toml`, kept beside it in `manifest.sha256`.
//!
//! The manifest names every stage file with its SHA-256, so this one digest covers the whole
//! bundle: the numbers that place the map in the world (`pc_range_m`, heights, scales) as well
//! as the graphs. An integrator who pins it (see [`super::Bundle::open_pinned`]) accepts exactly
//! one bundle; without a pin it still catches every accidental change of the manifest.
//!
//! The file format is strict so that every single-bit change of it is refused as well: exactly
//! 64 lowercase hex digits, optionally followed by one `\n`.

use core::fmt;

use sha2::{Digest, Sha256};

/// A SHA-256 digest (of a manifest or a stage file).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Sha256Digest([u8; 32]);

/// Why a digest text was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DigestParseError {
    /// Not 64 characters (after at most one trailing newline).
    #[error("a digest is 64 hex digits, found {0} characters")]
    Length(usize),
    /// A character other than `0-9a-f` (upper case is refused too: one spelling per digest).
    #[error("character {0} is not a lowercase hex digit")]
    NotLowerHex(usize),
}

impl Sha256Digest {
    /// The SHA-256 of `bytes`.
    #[must_use]
    pub fn of(bytes: &[u8]) -> Self {
        Self(Sha256::digest(bytes).into())
    }

    /// Parse the strict text form: 64 lowercase hex digits, optionally one trailing `\n`.
    ///
    /// # Errors
    /// [`DigestParseError`] saying what is wrong.
    pub fn parse(text: &str) -> Result<Self, DigestParseError> {
        let hex_text = text.strip_suffix('\n').unwrap_or(text);
        if hex_text.len() != 64 {
            return Err(DigestParseError::Length(hex_text.len()));
        }
        if let Some(ix) = hex_text
            .bytes()
            .position(|b| !matches!(b, b'0'..=b'9' | b'a'..=b'f'))
        {
            return Err(DigestParseError::NotLowerHex(ix));
        }
        let mut out = [0u8; 32];
        hex::decode_to_slice(hex_text, &mut out).map_err(|_| DigestParseError::NotLowerHex(0))?;
        Ok(Self(out))
    }

    /// The digest of 32 raw bytes (a pin handed over C).
    #[must_use]
    pub const fn from_bytes(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// The raw 32 bytes.
    #[must_use]
    pub const fn as_bytes(&self) -> &[u8; 32] {
        &self.0
    }
}

impl fmt::Display for Sha256Digest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&hex::encode(self.0))
    }
}

impl fmt::Debug for Sha256Digest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Sha256Digest({self})")
    }
}

impl core::str::FromStr for Sha256Digest {
    type Err = DigestParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EMPTY: &str = "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855";

    #[test]
    fn digest_of_empty_input_is_the_published_value() {
        assert_eq!(Sha256Digest::of(b"").to_string(), EMPTY);
        assert_eq!(Sha256Digest::parse(EMPTY), Ok(Sha256Digest::of(b"")));
        assert_eq!(
            Sha256Digest::parse(&format!("{EMPTY}\n")),
            Ok(Sha256Digest::of(b""))
        );
    }

    #[test]
    fn one_spelling_only() {
        let upper = EMPTY.to_ascii_uppercase();
        assert_eq!(
            Sha256Digest::parse(&upper),
            Err(DigestParseError::NotLowerHex(0))
        );
        assert_eq!(
            Sha256Digest::parse(&format!("{EMPTY}\n\n")),
            Err(DigestParseError::Length(65))
        );
        assert_eq!(
            Sha256Digest::parse(&format!("{EMPTY} ")),
            Err(DigestParseError::Length(65))
        );
        assert_eq!(
            Sha256Digest::parse(&EMPTY[..63]),
            Err(DigestParseError::Length(63))
        );
    }
}
