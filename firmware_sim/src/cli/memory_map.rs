//! `satmap-sim memory-map`: print the memory layout this binary was built with
//! (`memory_layout.toml`, or the build's `SATMAP_LAYOUT` file) like a linker map: every region
//! with its offset, bytes, owner, dtype and shape, the totals and the arena headroom; with
//! `--bundle`, also whether that bundle's buffers fit the layout's regions.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use satmap_layout::MemoryLayout;
use satmap_runtime::bundle::Bundle;
use satmap_runtime::capacity::layout;
use satmap_runtime::regions::check_regions_with;
use satmap_runtime::{FeatureStorage, MemoryError};

use crate::cli::drive::BadArgument;

/// The layout this binary was built with (the text of [`layout::SOURCE_PATH`]).
pub const BUILT_IN_LAYOUT: &str = layout::SOURCE_TOML;

/// One line naming the layout built into this binary: its file and the config it is sized for.
#[must_use]
pub fn built_in_layout_line() -> String {
    format!(
        "built-in layout {} (sized for `{}`)",
        layout::SOURCE_PATH,
        layout::SIZED_FOR
    )
}

/// The layout file at `path`, or the one this binary was built with; errors name which.
///
/// # Errors
/// An unreadable file or an invalid layout.
pub fn read_layout(path: Option<&Path>) -> Result<MemoryLayout> {
    // A layout given on the command line is input: unreadable or invalid, it is bad input
    // (exit 2); the built-in one was checked when this binary was built.
    let text = match path {
        Some(p) => satmap_runtime::host_files::read_text_capped(
            p,
            satmap_runtime::host_files::MAX_CONFIG_BYTES,
        )
        .map_err(|e| BadArgument(format!("{}: {e}", p.display())))?,
        None => BUILT_IN_LAYOUT.to_owned(),
    };
    MemoryLayout::parse(&text).map_err(|e| {
        BadArgument(match path {
            Some(p) => format!("{}: {e}", p.display()),
            None => format!("built-in layout {}: {e}", layout::SOURCE_PATH),
        })
        .into()
    })
}

/// The storage `map` gives the BEV feature maps (`satmap-layout` checked that both BEV regions
/// are f32 or both f16).
#[must_use]
pub fn bev_storage(map: &MemoryLayout) -> FeatureStorage {
    map.region("camera_bev")
        .and_then(|r| FeatureStorage::from_name(r.dtype.name()))
        .unwrap_or(FeatureStorage::F32)
}

/// Arguments of `memory-map`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Layout file (default: the one this binary was built with).
    #[arg(long)]
    pub layout: Option<PathBuf>,
    /// Also check that this bundle's buffers fit the printed layout's regions.
    #[arg(long)]
    pub bundle: Option<PathBuf>,
}

/// Print the map.
///
/// # Errors
/// An unreadable or invalid layout, or a bundle that does not fit.
pub fn run(args: &Args) -> Result<()> {
    let map = read_layout(args.layout.as_deref())?;
    match &args.layout {
        Some(p) => println!("layout {} ({})", p.display(), built_in_layout_line()),
        None => println!("{}", built_in_layout_line()),
    }
    print!("{}", map.render_map());
    if let Some(dir) = &args.bundle {
        // Bundle errors name the file that failed; a context would print the folder twice.
        let bundle = Bundle::open(dir)?;
        let fits = check_regions_with(bundle.dims(), bev_storage(&map), |name| {
            map.region(name).map(|r| r.bytes)
        });
        match (fits, &args.layout) {
            (Ok(()), _) => {}
            // The built-in layout: the harness's message, which names it.
            (Err(e), None) => {
                return Err(crate::harness::HarnessError::from(e))
                    .with_context(|| format!("bundle {}", dir.display()));
            }
            (
                Err(MemoryError::RegionTooSmall {
                    region,
                    needed_bytes,
                    capacity_bytes,
                }),
                Some(p),
            ) => {
                // Bad input (exit 2), as the harness's region error is.
                return Err(BadArgument(format!(
                    "bundle {}: region `{region}` does not fit: needs {needed_bytes} bytes, \
                     layout {} gives {capacity_bytes}",
                    dir.display(),
                    p.display()
                ))
                .into());
            }
            (Err(e), Some(p)) => {
                return Err(BadArgument(format!(
                    "bundle {}: {e} ({})",
                    dir.display(),
                    p.display()
                ))
                .into());
            }
        }
        println!("bundle {}: every region fits", dir.display());
    }
    Ok(())
}
