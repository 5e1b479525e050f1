//! `satmap-sim sign-bundle`: sign bundles with a `keygen` secret key.
//!
//! Each bundle is opened and verified whole first (only a bundle that loads is worth a
//! signature), then its digest is signed and the signature written where the runtime looks for
//! it (`signature_path`: `x.satmap.sig`, or `manifest.sig` in a folder), and checked back with
//! the key's public half.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use ed25519_dalek::SigningKey;
use ed25519_dalek::ed25519::signature::Signer as _;
use satmap_runtime::bundle::signature::{KeyFileError, read_hex_file, signed_message};
use satmap_runtime::bundle::{Bundle, BundlePublicKey, BundleSignature, Trust, signature_path};

use crate::cli::drive::BadArgument;

/// Arguments of `sign-bundle`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The secret key (`<name>.key` from `keygen`).
    #[arg(long)]
    pub key: PathBuf,
    /// Bundles to sign: compiled `<name>.satmap` files or folders.
    #[arg(required = true)]
    pub bundles: Vec<PathBuf>,
}

/// The secret key of a `.key` file: 64 lowercase hex digits and an optional newline
/// (`read_hex_file`: a wrong file is refused without reading it whole, a pipe never blocks).
///
/// # Errors
/// The file unreadable ([`anyhow`]) or not a key ([`BadArgument`]).
pub fn read_secret_key(path: &Path) -> Result<SigningKey> {
    let mut seed = match read_hex_file::<32>(path) {
        Ok(seed) => seed,
        Err(KeyFileError::Text(_)) => {
            return Err(BadArgument(format!(
                "{}: a secret key is 64 lowercase hex digits and a newline",
                path.display()
            ))
            .into());
        }
        Err(KeyFileError::Io(e)) => {
            return Err(e).with_context(|| format!("reading {}", path.display()));
        }
    };
    let key = SigningKey::from_bytes(&seed);
    seed.fill(0);
    Ok(key)
}

/// Sign every bundle.
///
/// # Errors
/// The key unreadable, a bundle refused by its own checks, or a signature not writable.
pub fn run(args: &Args) -> Result<()> {
    let secret = read_secret_key(&args.key)?;
    let public = BundlePublicKey::from_bytes(&secret.verifying_key().to_bytes())?;
    for path in &args.bundles {
        let sig_path = sign(&secret, path)?;
        // What an ECU given the public key will do.
        Bundle::open_trusted(path, &Trust::Signed(public))?;
        println!("{}: signed, {}", path.display(), sig_path.display());
    }
    println!("public key {public}");
    Ok(())
}

/// Verify the bundle at `path`, sign its digest with `secret` and write the signature file;
/// returns its path.
///
/// # Errors
/// The bundle refused, or the signature not writable.
pub fn sign(secret: &SigningKey, path: &Path) -> Result<PathBuf> {
    let bundle = Bundle::open(path)?;
    let signature = secret.sign(&signed_message(&bundle.digest()));
    let signature = BundleSignature::from_bytes(&signature.to_bytes());
    let sig_path = signature_path(path);
    std::fs::write(&sig_path, format!("{signature}\n"))
        .with_context(|| format!("writing {}", sig_path.display()))?;
    Ok(sig_path)
}
