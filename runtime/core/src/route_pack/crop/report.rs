//! What a crop reports: why it could not be attempted ([`CropFault`]) and, when it ran, how
//! much of it the verified tiles covered ([`CropReport`]).

use crate::route_pack::format::TileKey;
use crate::route_pack::route::RouteState;
use crate::satellite::Coverage;

/// Why a crop could not be attempted (the output is all fill and coverage is `None`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CropFault {
    /// `out` is not `height_px * width_px * 3` bytes.
    OutputSize,
    /// The pose has a non-finite field.
    PoseNotFinite,
    /// The crop spec has a zero size or a non-finite or non-positive resolution or origin.
    BadSpec,
    /// The crop spans more than [`MAX_CROP_TILES`](super::MAX_CROP_TILES) tiles.
    TooManyTiles {
        /// Tiles in the crop's bounding box.
        tiles: usize,
    },
    /// A compressed pack's tile buffer has fewer tile slots than a crop (plus the step's
    /// prefetch) needs.
    TileBuffer {
        /// Whole tile slots in the buffer.
        slots: usize,
        /// Slots needed.
        needed: usize,
    },
}

/// What one crop delivered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CropReport {
    /// Coverage verdict returned through [`SatelliteSource::crop`](crate::satellite::SatelliteSource::crop).
    pub coverage: Coverage,
    /// Pixels sampled from verified imagery.
    pub covered_px: u32,
    /// Pixels in the crop.
    pub total_px: u32,
    /// Corrupt tiles the crop would have sampled (not used).
    pub corrupt_tiles: u8,
    /// One of those corrupt tiles, for the log.
    pub first_corrupt: Option<TileKey>,
    /// Tiles hashed this step (crop and prefetch); at most
    /// `MAX_CROP_TILES + PREFETCH_TILES_PER_STEP`.
    pub verified_tiles: u8,
    /// Of those, hashed ahead on the route.
    pub prefetched_tiles: u8,
    /// Tiles decoded this step (compressed packs: every tile hashed is then decoded).
    pub decoded_tiles: u8,
    /// Set when the crop could not be attempted.
    pub fault: Option<CropFault>,
    /// Where the route cursor stands after this step (not moved on a fault).
    pub route: RouteState,
    /// Route segments the cursor examined this step; at most
    /// [`MAX_ROUTE_SEGMENTS_PER_STEP`](crate::route_pack::route::MAX_ROUTE_SEGMENTS_PER_STEP) whatever the route's length.
    pub route_segments_examined: u32,
}

impl CropReport {
    pub(super) const EMPTY: Self = Self {
        coverage: Coverage::None,
        covered_px: 0,
        total_px: 0,
        corrupt_tiles: 0,
        first_corrupt: None,
        verified_tiles: 0,
        prefetched_tiles: 0,
        decoded_tiles: 0,
        fault: None,
        route: RouteState::Searching,
        route_segments_examined: 0,
    };

    /// Covered fraction, thousandths (0..=1000).
    #[must_use]
    pub fn covered_permille(&self) -> u16 {
        if self.total_px == 0 {
            return 0;
        }
        (u64::from(self.covered_px) * 1000 / u64::from(self.total_px)) as u16
    }
}
