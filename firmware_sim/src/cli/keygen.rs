//! `satmap-sim keygen`: a new Ed25519 key pair for signing bundles.
//!
//! Two files, each one line of lowercase hex: `<name>.key`, the 32-byte secret seed (mode 0600;
//! it stays with whoever publishes bundles), and `<name>.pub`, the public key the integrator
//! gives the runtime (`Trust::Signed`, `satmap_create_trusted`). An existing key is never
//! overwritten: a lost secret cannot be recovered, and a replaced one orphans every signature.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use ed25519_dalek::SigningKey;
use satmap_runtime::bundle::BundlePublicKey;

use crate::cli::drive::BadArgument;

/// Arguments of `keygen`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Folder the two files are written into (created if missing).
    #[arg(long)]
    pub out_dir: PathBuf,
    /// File stem of the pair: `<name>.key` and `<name>.pub`.
    #[arg(long, default_value = "bundle-signing")]
    pub name: String,
}

/// Make the pair from 32 bytes of the OS's randomness and write it.
///
/// # Errors
/// An existing file of either name, a name that is not a plain file stem, the OS's randomness
/// unavailable, or a file not writable.
pub fn run(args: &Args) -> Result<()> {
    if args.name.is_empty() || args.name.contains(['/', '\\', '\0']) || args.name.starts_with('.') {
        return Err(BadArgument(format!("--name `{}` is not a plain file stem", args.name)).into());
    }
    let mut seed = [0u8; 32];
    getrandom::fill(&mut seed).map_err(|e| anyhow::anyhow!("the OS's randomness: {e}"))?;
    let secret = SigningKey::from_bytes(&seed);
    seed.fill(0);
    let public = BundlePublicKey::from_bytes(&secret.verifying_key().to_bytes())?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating {}", args.out_dir.display()))?;
    let key_path = args.out_dir.join(format!("{}.key", args.name));
    let pub_path = args.out_dir.join(format!("{}.pub", args.name));
    for path in [&key_path, &pub_path] {
        if path.exists() {
            return Err(BadArgument(format!(
                "{} exists; a key is never overwritten",
                path.display()
            ))
            .into());
        }
    }
    write_new(&key_path, &hex_line(secret.as_bytes()), true)?;
    write_new(&pub_path, &format!("{public}\n"), false)?;
    println!("secret key {} (keep it private)", key_path.display());
    println!("public key {} = {public}", pub_path.display());
    Ok(())
}

fn hex_line(bytes: &[u8]) -> String {
    format!("{}\n", hex::encode(bytes))
}

/// Write `text` to a file that must not exist yet; `private` makes it owner-only (Unix).
fn write_new(path: &Path, text: &str, private: bool) -> Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(if private { 0o600 } else { 0o644 });
    }
    #[cfg(not(unix))]
    let _ = private;
    options
        .open(path)
        .and_then(|mut f| f.write_all(text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}
