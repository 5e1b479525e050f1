//! The compiled bundle: one file the ECU loads, a tar archive in one canonical form.
//!
//! Entries, in this order and no others:
//! 1. `manifest.toml`: the folder manifest's schema; each stage's `file` names an entry of the
//!    archive and its `sha256` is the SHA-256 of that entry's bytes (an NNEF tar);
//! 2. the five stage entries, in [`Stage::ALL`] order;
//! 3. `bundle.sha256`: 64 lowercase hex digits and `\n`, the SHA-256 of every archive byte before
//!    this entry's header. That is the bundle digest an integrator pins.
//!
//! Every header is written the same way (ustar, mode 0644, uid and gid 0, a fixed mtime), so one
//! archive has one byte form: after the stage and whole-file hashes are checked, the reader
//! writes the archive again from what it parsed and refuses any difference. Without that, a byte
//! flipped in the padding after the last entry or in the end-of-archive blocks would be ignored
//! by a tar reader and load.

use std::ops::Range;
use std::path::Path;

use satmap_core::engine::Stage;

use super::{
    BundleError, MANIFEST_FILE, Manifest, Sha256Digest, checked_manifest, checked_stage_entry,
    parse_digest_file, verify,
};

/// Entry name of the whole-file digest, the archive's last entry.
pub const ARCHIVE_DIGEST_ENTRY: &str = "bundle.sha256";

/// File name ending of a compiled bundle (tools use it to tell an archive from a folder).
pub const ARCHIVE_EXTENSION: &str = "satmap";

/// The mtime of every header: 1980-01-01, the MS-DOS epoch (a zero mtime upsets some tools).
const ENTRY_MTIME_S: u64 = 315_532_800;

/// A verified compiled bundle, held in memory: the engine parses the stage bytes kept here, so
/// nothing is read from a path again after hashing.
#[derive(Clone, Debug)]
pub(super) struct Archive {
    pub bytes: Vec<u8>,
    /// Byte range of `manifest.toml` in `bytes`.
    pub manifest_at: Range<usize>,
    pub digest: Sha256Digest,
    /// Byte range of each stage entry in `bytes`, in [`Stage::ALL`] order.
    pub stages: [Range<usize>; Stage::ALL.len()],
    /// The verified SHA-256 of each stage entry, in [`Stage::ALL`] order.
    pub stage_digests: [Sha256Digest; Stage::ALL.len()],
}

/// One entry as the reader found it.
struct RawEntry {
    name: String,
    header_at: usize,
    data: Range<usize>,
}

fn archive_error(message: impl Into<String>) -> BundleError {
    BundleError::Archive {
        message: message.into(),
    }
}

/// The entries of a tar archive: names, header offsets and data ranges; any entry that is not a
/// regular file, or whose data range lies outside `bytes`, is refused.
fn entries(bytes: &[u8]) -> Result<Vec<RawEntry>, BundleError> {
    let mut archive = tar::Archive::new(bytes);
    let iter = archive
        .entries()
        .map_err(|e| archive_error(format!("not a tar archive: {e}")))?;
    let mut out = Vec::new();
    for entry in iter {
        let entry = entry.map_err(|e| archive_error(format!("unreadable entry: {e}")))?;
        if entry.header().entry_type() != tar::EntryType::Regular {
            return Err(archive_error(format!(
                "entry {} is not a regular file",
                out.len()
            )));
        }
        let name = entry
            .path()
            .ok()
            .and_then(|p| p.to_str().map(str::to_owned))
            .ok_or_else(|| archive_error(format!("entry {} has no UTF-8 name", out.len())))?;
        let header_at = usize::try_from(entry.raw_header_position())
            .map_err(|_| archive_error("entry offset out of range"))?;
        let start = usize::try_from(entry.raw_file_position())
            .map_err(|_| archive_error("entry offset out of range"))?;
        let end = usize::try_from(entry.size())
            .ok()
            .and_then(|n| start.checked_add(n))
            .filter(|&end| end <= bytes.len())
            .ok_or_else(|| archive_error(format!("entry `{name}` runs past the end")))?;
        out.push(RawEntry {
            name,
            header_at,
            data: start..end,
        });
    }
    Ok(out)
}

impl Archive {
    /// Verify `bytes` as a compiled bundle (see the module doc) and return it with its parsed
    /// manifest; errors name entries as `path/<entry>`. `canonical_prefix_digest` is the SHA-256
    /// of the bytes before the canonical trailer ([`super::archive_digest_unparsed`], already
    /// taken to decide trust): the whole-file digest is that one whenever the digest entry sits
    /// where the canonical form puts it, so the archive is not hashed a second time.
    pub fn parse(
        path: &Path,
        bytes: Vec<u8>,
        canonical_prefix_digest: Sha256Digest,
    ) -> Result<(Self, Manifest), BundleError> {
        let entries = entries(&bytes)?;
        let expected_count = Stage::ALL.len() + 2;
        if entries.len() != expected_count {
            return Err(archive_error(format!(
                "{} entries, a compiled bundle has {expected_count}",
                entries.len()
            )));
        }
        let (first, rest) = entries.split_at(1);
        let (stage_entries, last) = rest.split_at(Stage::ALL.len());
        if first[0].name != MANIFEST_FILE {
            return Err(archive_error(format!(
                "first entry is `{}`, not `{MANIFEST_FILE}`",
                first[0].name
            )));
        }
        let manifest_bytes = &bytes[first[0].data.clone()];
        let manifest = checked_manifest(&path.join(MANIFEST_FILE), manifest_bytes)?;
        if manifest.compiled.is_none() {
            return Err(archive_error(format!(
                "{MANIFEST_FILE} has no [compiled] table (a folder's manifest)"
            )));
        }
        let mut stages: [Range<usize>; Stage::ALL.len()] = Default::default();
        let mut stage_digests = [Sha256Digest::of(&[]); Stage::ALL.len()];
        for (((range, digest), stage), raw) in stages
            .iter_mut()
            .zip(&mut stage_digests)
            .zip(Stage::ALL)
            .zip(stage_entries)
        {
            let (entry, expected) = checked_stage_entry(&manifest, stage)?;
            if raw.name != entry.file {
                return Err(BundleError::StagePath {
                    stage: stage.name(),
                    file: raw.name.clone(),
                });
            }
            verify(
                stage,
                &path.join(&raw.name),
                &bytes[raw.data.clone()],
                expected,
            )?;
            *range = raw.data.clone();
            *digest = expected;
        }
        let last = &last[0];
        if last.name != ARCHIVE_DIGEST_ENTRY {
            return Err(archive_error(format!(
                "last entry is `{}`, not `{ARCHIVE_DIGEST_ENTRY}`",
                last.name
            )));
        }
        let recorded =
            parse_digest_file(path.join(ARCHIVE_DIGEST_ENTRY), &bytes[last.data.clone()])?;
        let digest = if last.header_at + super::signature::ARCHIVE_TRAILER_BYTES == bytes.len() {
            canonical_prefix_digest
        } else {
            Sha256Digest::of(&bytes[..last.header_at])
        };
        if digest != recorded {
            return Err(BundleError::ArchiveDigest {
                path: path.to_path_buf(),
                recorded,
                actual: digest,
            });
        }
        let stage_bytes: Vec<(&str, &[u8])> = stage_entries
            .iter()
            .map(|e| (e.name.as_str(), &bytes[e.data.clone()]))
            .collect();
        let canonical = write_archive(manifest_bytes, &stage_bytes)?;
        if canonical != bytes {
            let at = canonical
                .iter()
                .zip(&bytes)
                .position(|(a, b)| a != b)
                .unwrap_or(canonical.len().min(bytes.len()));
            return Err(archive_error(format!(
                "not in canonical form from byte {at} (of {})",
                bytes.len()
            )));
        }
        let manifest_at = first[0].data.clone();
        Ok((
            Self {
                bytes,
                manifest_at,
                digest,
                stages,
                stage_digests,
            },
            manifest,
        ))
    }
}

/// Write a compiled bundle: `manifest` (TOML bytes), the `(entry name, bytes)` of each stage in
/// [`Stage::ALL`] order, and the whole-file digest. Deterministic: the same inputs give the same
/// bytes. It does not check what it writes; [`super::Bundle::from_archive_bytes`] does.
///
/// # Errors
/// [`BundleError::Archive`] when an entry name does not fit a ustar header.
pub fn write_archive(manifest: &[u8], stages: &[(&str, &[u8])]) -> Result<Vec<u8>, BundleError> {
    let mut builder = tar::Builder::new(Vec::new());
    append(&mut builder, MANIFEST_FILE, manifest)?;
    for (name, bytes) in stages {
        append(&mut builder, name, bytes)?;
    }
    let digest = Sha256Digest::of(builder.get_ref());
    append(
        &mut builder,
        ARCHIVE_DIGEST_ENTRY,
        format!("{digest}\n").as_bytes(),
    )?;
    builder
        .into_inner()
        .map_err(|e| archive_error(format!("finishing the archive: {e}")))
}

fn append(
    builder: &mut tar::Builder<Vec<u8>>,
    name: &str,
    bytes: &[u8],
) -> Result<(), BundleError> {
    let mut header = tar::Header::new_ustar();
    header
        .set_path(name)
        .map_err(|e| archive_error(format!("entry name `{name}`: {e}")))?;
    header.set_size(bytes.len() as u64);
    header.set_mode(0o644);
    header.set_uid(0);
    header.set_gid(0);
    header.set_mtime(ENTRY_MTIME_S);
    header.set_entry_type(tar::EntryType::Regular);
    header.set_cksum();
    builder
        .append(&header, bytes)
        .map_err(|e| archive_error(format!("writing entry `{name}`: {e}")))
}
