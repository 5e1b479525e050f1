//! Reading the host's input files (std only): regular files only, up to a size cap.
//!
//! `std::fs::read` reads whatever the path names to its end: `/dev/zero` given as a calibration,
//! layout or pack ran to the memory cap, and opening a named pipe blocks until a writer appears
//! (issue 38 found 11 commands hanging so). Every input file of the runtime's host side and of
//! `satmap-sim` goes through [`read_capped`] instead: the path must name a regular file (checked
//! before it is opened, so a FIFO never blocks), and a file longer than the caller's cap is
//! refused after reading one byte past the cap.

use std::io::Read as _;
use std::path::Path;

/// Cap of a text configuration file (calibration, memory layout, manifest, scenario and frame
/// TOML): far beyond any real one.
pub const MAX_CONFIG_BYTES: u64 = 4 << 20;

/// Cap of a data file (results or ground-truth JSON, a route's GeoJSON, a reference tensor
/// file, a compiled bundle, a route pack).
pub const MAX_DATA_BYTES: u64 = 1 << 30;

/// The bytes of the regular file at `path`, at most `cap` of them.
///
/// # Errors
/// The OS error; [`std::io::ErrorKind::InvalidInput`] when `path` is not a regular file (a FIFO,
/// a device, a folder); [`std::io::ErrorKind::FileTooLarge`] beyond `cap`.
pub fn read_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a pipe, device or folder is never read)",
        ));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len().min(cap)).unwrap_or(0));
    std::fs::File::open(path)?
        .take(cap.saturating_add(1))
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!("longer than the {cap}-byte cap of this input"),
        ));
    }
    Ok(bytes)
}

/// [`read_capped`] as UTF-8 text.
///
/// # Errors
/// As [`read_capped`], and [`std::io::ErrorKind::InvalidData`] for text that is not UTF-8.
pub fn read_text_capped(path: &Path, cap: u64) -> std::io::Result<String> {
    String::from_utf8(read_capped(path, cap)?)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_folders_and_pipes_are_refused_unread_and_the_cap_holds() {
        for path in ["/dev/zero", "/dev/null", "/tmp"] {
            let e = read_capped(Path::new(path), MAX_CONFIG_BYTES).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput, "{path}");
        }
        let dir = std::env::temp_dir().join(format!("satmap-host-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A named pipe with no writer: opening it would block forever.
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success(), "mkfifo (coreutils)");
        let e = read_capped(&fifo, MAX_CONFIG_BYTES).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        let file = dir.join("ten");
        std::fs::write(&file, [7u8; 10]).unwrap();
        assert_eq!(read_capped(&file, 10).unwrap(), [7u8; 10]);
        assert_eq!(
            read_capped(&file, 9).unwrap_err().kind(),
            std::io::ErrorKind::FileTooLarge
        );
        std::fs::write(&file, [0xff, 0xfe]).unwrap();
        assert_eq!(
            read_text_capped(&file, 10).unwrap_err().kind(),
            std::io::ErrorKind::InvalidData
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
