//! Options of a build and their up-front checks: every number finite and in range, and pack
//! tiles large enough for the model's crop.

use satmap_runtime::capacity::layout::TILE_PIXELS_BYTES;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::route_pack::{
    MAX_CROP_TILES, PREFETCH_TILES_PER_STEP, TILE_CACHE_TILES, crop_tile_bound,
};
use satmap_runtime::satellite::CropSpec;

use super::compress::TileCompression;
use super::error::BuildError;

/// Largest corridor width, metres.
pub const MAX_CORRIDOR_WIDTH_M: f64 = 10_000.0;
/// Largest crop side, pixels.
pub const MAX_CROP_SIDE_PX: usize = 4096;

/// The crop of the paper's configuration (and of `nano` and `test`, which share its 60 m x 30
/// m footprint): 400 x 200 px at 0.15 m/px, 15 m either side, 30 m behind and ahead.
pub const PAPER_CROP: CropSpec = CropSpec {
    height_px: 400,
    width_px: 200,
    gsd_m: 0.15,
    x_min_m: -15.0,
    y_min_m: -30.0,
};

/// Options of a build.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Width of the corridor around the route that must be covered, metres.
    pub corridor_width_m: f64,
    /// Ground sampling distance of the pack, metres per pixel.
    pub gsd_m: f64,
    /// Pack tile side, pixels (a power of two, 8..=1024).
    pub tile_size_px: u16,
    /// Leave out pack tiles that lack imagery instead of failing.
    pub allow_missing: bool,
    /// Draw a progress bar on stderr.
    pub show_progress: bool,
    /// Origin of the route frame; `None`: the route's first point at ellipsoid height 0. Give
    /// the frame the poses are expressed in (e.g. a synthetic world's anchor) to use it as is.
    pub origin: Option<Geodetic>,
    /// The crop the runtime will take from the pack (the model's `sat_h`, `sat_w`,
    /// `sat_gsd_m`): tiles must be large enough that one crop spans at most the runtime's
    /// `MAX_CROP_TILES`.
    pub crop: CropSpec,
    /// How tiles are stored: raw (version 1, read in place) or compressed (version 2).
    pub compression: TileCompression,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            corridor_width_m: 60.0,
            gsd_m: 0.15,
            tile_size_px: 256,
            allow_missing: false,
            show_progress: false,
            origin: None,
            crop: PAPER_CROP,
            compression: TileCompression::Raw,
        }
    }
}

impl BuildOptions {
    /// Check every option: finite and in range, a power-of-two tile side, and tiles large
    /// enough for [`Self::crop`] at every pose (`crop_tile_bound`).
    ///
    /// # Errors
    /// [`BuildError::OptionRange`] naming the flag and its range, or
    /// [`BuildError::TilesTooSmallForCrop`].
    pub fn validate(&self) -> Result<(), BuildError> {
        let range = |option, value: String, range| {
            Err(BuildError::OptionRange {
                option,
                value,
                range,
            })
        };
        // The pack format's `gsd_m` rule.
        if !(self.gsd_m.is_finite() && self.gsd_m > 0.001 && self.gsd_m <= 100.0) {
            return range("--gsd-m", self.gsd_m.to_string(), "(0.001, 100] m/px");
        }
        if !(self.corridor_width_m.is_finite()
            && (0.0..=MAX_CORRIDOR_WIDTH_M).contains(&self.corridor_width_m))
        {
            return range(
                "--corridor-m",
                self.corridor_width_m.to_string(),
                "[0, 10000] m",
            );
        }
        if !(8..=1024).contains(&self.tile_size_px) || !self.tile_size_px.is_power_of_two() {
            return range(
                "--tile-px",
                self.tile_size_px.to_string(),
                "the powers of two 8..=1024 px",
            );
        }
        let crop = &self.crop;
        for (option, side) in [
            ("--crop-h-px", crop.height_px),
            ("--crop-w-px", crop.width_px),
        ] {
            if !(1..=MAX_CROP_SIDE_PX).contains(&side) {
                return range(option, side.to_string(), "1..=4096 px");
            }
        }
        if !(crop.gsd_m.is_finite() && crop.gsd_m > 0.001 && crop.gsd_m <= 100.0) {
            return range("--crop-gsd-m", crop.gsd_m.to_string(), "(0.001, 100] m/px");
        }
        if let TileCompression::Jpeg { quality } = self.compression
            && !(1..=100).contains(&quality)
        {
            return range("--jpeg-quality", quality.to_string(), "1..=100");
        }
        let tiles_for = |size: u16| crop_tile_bound(crop, self.gsd_m, size).unwrap_or(usize::MAX);
        let tiles = tiles_for(self.tile_size_px);
        if tiles > MAX_CROP_TILES {
            let min_tile_px = (3..=10)
                .map(|k| 1u16 << k)
                .find(|&size| tiles_for(size) <= MAX_CROP_TILES);
            return Err(BuildError::TilesTooSmallForCrop {
                tile_size_px: self.tile_size_px,
                gsd_m: self.gsd_m,
                crop_h_px: crop.height_px,
                crop_w_px: crop.width_px,
                crop_gsd_m: crop.gsd_m,
                tiles,
                max_tiles: MAX_CROP_TILES,
                min_tile_px,
            });
        }
        // A compressed pack is decoded into the vehicle's tile buffer: one crop's tiles and a
        // step's prefetch must fit it at once.
        let side = usize::from(self.tile_size_px);
        let slots = (TILE_PIXELS_BYTES / (side * side * 3)).min(TILE_CACHE_TILES);
        let needed = tiles + PREFETCH_TILES_PER_STEP;
        if self.compression != TileCompression::Raw && slots < needed {
            return Err(BuildError::Option(format!(
                "compressed tiles of {side} px: the tile_pixels region of memory_layout.toml \
                 ({TILE_PIXELS_BYTES} bytes) holds {slots}, one crop and its prefetch need \
                 {needed}; use smaller tiles or raw"
            )));
        }
        Ok(())
    }
}
