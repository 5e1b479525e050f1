//! Who may publish a bundle: an Ed25519 signature over the bundle digest, or a pinned digest,
//! checked on the raw bytes before anything of the bundle is parsed.
//!
//! The integrator gives the runtime a public key at create time ([`Trust::Signed`]); the
//! publisher signs [`signed_message`] of the bundle digest with the matching secret key
//! (`satmap-sim sign-bundle`) and ships the 64-byte signature beside the bundle as 128 lowercase
//! hex digits and `\n`: `x.satmap.sig` for a compiled bundle `x.satmap`, `manifest.sig` inside a
//! bundle folder ([`signature_path`]). Verification is `verify_strict` (no small-order keys, no
//! malleable signatures).
//!
//! Why before any parse: the tar reader, the TOML parser and above all tract's NNEF parser are
//! large attack surfaces, and a forged bundle with self-consistent hashes reaches them (issue 38
//! found panics, aborts and hangs inside tract). So the digest is taken from the raw bytes: a
//! folder's is the SHA-256 of `manifest.toml`; a compiled bundle's covers every byte before its
//! last entry's header, which in the archive's one canonical form sits [`ARCHIVE_TRAILER_BYTES`]
//! before the end. Only a bundle whose digest is pinned or signed goes on to be parsed, and
//! [`super::archive`] then refuses any archive whose own digest entry says otherwise.

use std::fmt;

use ed25519_dalek::{Signature, VerifyingKey};

use super::Sha256Digest;

/// What an Ed25519 signature of a bundle signs: this context, then the 32 digest bytes. The
/// context keeps a bundle signature from being replayed as a signature of anything else made
/// with the same key (and the reverse).
pub const SIGNING_CONTEXT: &[u8; 27] = b"satmap-bundle-signature-v1\0";

/// Bytes after the digested prefix of a canonical compiled bundle: the `bundle.sha256` header
/// (512), its 65 data bytes padded to one block (512), and the two zero end blocks (1024).
pub const ARCHIVE_TRAILER_BYTES: usize = 2048;

/// File name of a bundle folder's signature.
pub const FOLDER_SIGNATURE_FILE: &str = "manifest.sig";

/// Which bundles the runtime accepts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Trust {
    /// Any bundle whose own hashes agree: development only, since anyone who can write the
    /// bundle file can re-seal an edited one.
    SelfConsistent,
    /// Exactly the bundle with this digest (what `check-bundle` prints).
    Pinned(Sha256Digest),
    /// Any bundle signed by the secret key of this public key.
    Signed(BundlePublicKey),
}

/// An Ed25519 public key that bundles are verified against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BundlePublicKey(VerifyingKey);

/// An Ed25519 signature of a bundle digest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BundleSignature(Signature);

/// Why a key or signature text (or its bytes) was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KeyTextError {
    /// Not the expected number of lowercase hex digits (then one optional `\n`).
    #[error("expected {expected_digits} lowercase hex digits and an optional newline")]
    NotHex {
        /// Hex digits a key (64) or signature (128) has.
        expected_digits: usize,
    },
    /// 32 bytes that are not a point of the curve (or a small-order one).
    #[error("not a valid Ed25519 public key")]
    NotAPublicKey,
}

impl BundlePublicKey {
    /// The key of 32 bytes.
    ///
    /// # Errors
    /// [`KeyTextError::NotAPublicKey`] for bytes that are no usable key.
    pub fn from_bytes(bytes: &[u8; 32]) -> Result<Self, KeyTextError> {
        let key = VerifyingKey::from_bytes(bytes).map_err(|_| KeyTextError::NotAPublicKey)?;
        if key.is_weak() {
            return Err(KeyTextError::NotAPublicKey);
        }
        Ok(Self(key))
    }

    /// The key of a `.pub` file's text: 64 lowercase hex digits and an optional `\n`.
    ///
    /// # Errors
    /// As [`BundlePublicKey::from_bytes`], or [`KeyTextError::NotHex`].
    pub fn parse(text: &[u8]) -> Result<Self, KeyTextError> {
        Self::from_bytes(&hex_bytes::<32>(text)?)
    }

    /// The 32 key bytes.
    #[must_use]
    pub fn to_bytes(&self) -> [u8; 32] {
        self.0.to_bytes()
    }

    /// Whether `signature` signs `digest` under this key.
    #[must_use]
    pub fn verifies(&self, digest: &Sha256Digest, signature: &BundleSignature) -> bool {
        self.0
            .verify_strict(&signed_message(digest), &signature.0)
            .is_ok()
    }
}

impl fmt::Display for BundlePublicKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&hex::encode(self.to_bytes()))
    }
}

impl BundleSignature {
    /// The signature of 64 bytes (whether it verifies is [`BundlePublicKey::verifies`]).
    #[must_use]
    pub fn from_bytes(bytes: &[u8; 64]) -> Self {
        Self(Signature::from_bytes(bytes))
    }

    /// The signature of a `.sig` file's text: 128 lowercase hex digits and an optional `\n`.
    ///
    /// # Errors
    /// [`KeyTextError::NotHex`].
    pub fn parse(text: &[u8]) -> Result<Self, KeyTextError> {
        Ok(Self::from_bytes(&hex_bytes::<64>(text)?))
    }

    /// The 64 signature bytes.
    #[must_use]
    pub fn to_bytes(&self) -> [u8; 64] {
        self.0.to_bytes()
    }
}

impl fmt::Display for BundleSignature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&hex::encode(self.to_bytes()))
    }
}

/// The bytes a bundle signature signs: [`SIGNING_CONTEXT`] and the digest.
#[must_use]
pub fn signed_message(digest: &Sha256Digest) -> [u8; SIGNING_CONTEXT.len() + 32] {
    let mut message = [0; SIGNING_CONTEXT.len() + 32];
    message[..SIGNING_CONTEXT.len()].copy_from_slice(SIGNING_CONTEXT);
    message[SIGNING_CONTEXT.len()..].copy_from_slice(digest.as_bytes());
    message
}

/// Where the signature of the bundle at `bundle` lives: `<file>.sig` beside a compiled bundle,
/// [`FOLDER_SIGNATURE_FILE`] inside a folder.
#[must_use]
pub fn signature_path(bundle: &std::path::Path) -> std::path::PathBuf {
    if bundle.is_dir() {
        bundle.join(FOLDER_SIGNATURE_FILE)
    } else {
        let mut name = bundle.as_os_str().to_owned();
        name.push(".sig");
        name.into()
    }
}

/// The digest of a compiled bundle's raw bytes, as its canonical form defines it, without
/// parsing them; `None` for bytes too short or not whole 512-byte blocks (no compiled bundle).
#[must_use]
pub fn archive_digest_unparsed(bytes: &[u8]) -> Option<Sha256Digest> {
    let prefix = bytes.len().checked_sub(ARCHIVE_TRAILER_BYTES)?;
    bytes
        .len()
        .is_multiple_of(512)
        .then(|| Sha256Digest::of(&bytes[..prefix]))
}

/// Why a key or signature file gave no bytes.
#[derive(Debug, thiserror::Error)]
pub enum KeyFileError {
    /// Unreadable, not a regular file (a pipe is never opened), or the OS error.
    #[error("{0}")]
    Io(std::io::Error),
    /// Not the strict hex text (a file longer than it is refused unread past one byte).
    #[error("{0}")]
    Text(KeyTextError),
}

/// The `N` bytes of a key or signature file (`.pub`, `.key`, `.sig`): exactly `2 N` lowercase
/// hex digits and an optional `\n`, read through [`crate::host_files::read_capped`].
///
/// # Errors
/// [`KeyFileError`].
pub fn read_hex_file<const N: usize>(path: &std::path::Path) -> Result<[u8; N], KeyFileError> {
    let text = match crate::host_files::read_capped(path, 2 * N as u64 + 1) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::FileTooLarge => {
            return Err(KeyFileError::Text(KeyTextError::NotHex {
                expected_digits: 2 * N,
            }));
        }
        Err(e) => return Err(KeyFileError::Io(e)),
    };
    hex_bytes(&text).map_err(KeyFileError::Text)
}

/// `N` bytes from exactly `2 N` lowercase hex digits and an optional `\n`.
fn hex_bytes<const N: usize>(text: &[u8]) -> Result<[u8; N], KeyTextError> {
    let digits = text.strip_suffix(b"\n").unwrap_or(text);
    let lower = digits
        .iter()
        .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(b));
    let mut out = [0; N];
    match hex::decode_to_slice(digits, &mut out) {
        Ok(()) if lower => Ok(out),
        _ => Err(KeyTextError::NotHex {
            expected_digits: 2 * N,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // RFC 8032, section 7.1, TEST 1: its public key.
    const RFC_KEY: &[u8] = b"d75a980182b10ab7d54bfed3c964073a0ee172f3daa62325af021a68f707511a";

    #[test]
    fn key_and_signature_texts_are_strict() {
        let key = BundlePublicKey::parse(RFC_KEY).unwrap();
        assert_eq!(key.to_string().as_bytes(), RFC_KEY);
        let mut line = RFC_KEY.to_vec();
        line.push(b'\n');
        assert_eq!(BundlePublicKey::parse(&line), Ok(key));
        let upper = RFC_KEY.to_ascii_uppercase();
        let short = &RFC_KEY[..62];
        for bad in [&upper[..], short, b"", &[RFC_KEY, b"\n\n"].concat()] {
            assert_eq!(
                BundlePublicKey::parse(bad),
                Err(KeyTextError::NotHex {
                    expected_digits: 64
                })
            );
        }
        // The identity point: small order, refused.
        let mut identity = [0u8; 32];
        identity[0] = 1;
        assert_eq!(
            BundlePublicKey::from_bytes(&identity),
            Err(KeyTextError::NotAPublicKey)
        );
        assert!(BundleSignature::parse(&[b'0'; 127]).is_err());
        assert!(BundleSignature::parse(&[b'0'; 128]).is_ok());
    }

    #[test]
    fn the_digest_of_a_non_archive_is_none() {
        assert_eq!(archive_digest_unparsed(&[0; 2047]), None);
        assert_eq!(archive_digest_unparsed(&[0; 2049]), None);
        assert_eq!(
            archive_digest_unparsed(&[0; 2560]),
            Some(Sha256Digest::of(&[0; 512]))
        );
    }

    #[test]
    fn the_message_is_the_context_then_the_digest() {
        let digest = Sha256Digest::of(b"x");
        let message = signed_message(&digest);
        assert_eq!(&message[..27], SIGNING_CONTEXT);
        assert_eq!(&message[27..], digest.as_bytes());
    }
}
