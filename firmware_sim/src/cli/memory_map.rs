//! `satmap-sim memory-map`: print `memory_layout.toml` like a linker map: every region with its
//! offset, bytes, owner, dtype and shape, the totals and the arena headroom; with `--bundle`,
//! also what that bundle needs in each region.

use std::path::PathBuf;

use anyhow::{Context, Result};
use satmap_layout::MemoryLayout;
use satmap_runtime::bundle::Bundle;
use satmap_runtime::regions::check_regions;

/// The layout this binary was built with.
pub const BUILT_IN_LAYOUT: &str = include_str!("../../../memory_layout.toml");

/// Arguments of `memory-map`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Layout file (default: the one this binary was built with).
    #[arg(long)]
    pub layout: Option<PathBuf>,
    /// Also check that this bundle's buffers fit the built-in layout's regions.
    #[arg(long)]
    pub bundle: Option<PathBuf>,
}

/// Print the map.
///
/// # Errors
/// An unreadable or invalid layout, or a bundle that does not fit.
pub fn run(args: &Args) -> Result<()> {
    let text = match &args.layout {
        Some(p) => std::fs::read_to_string(p).with_context(|| p.display().to_string())?,
        None => BUILT_IN_LAYOUT.to_owned(),
    };
    let layout = MemoryLayout::parse(&text).with_context(|| match &args.layout {
        Some(p) => p.display().to_string(),
        None => "built-in memory_layout.toml".to_owned(),
    })?;
    print!("{}", layout.render_map());
    if let Some(dir) = &args.bundle {
        // Bundle errors name the file that failed; a context would print the folder twice.
        let bundle = Bundle::open(dir)?;
        check_regions(bundle.dims())
            .map_err(crate::harness::HarnessError::from)
            .with_context(|| format!("bundle {}", dir.display()))?;
        println!("bundle {}: every region fits", dir.display());
    }
    Ok(())
}
