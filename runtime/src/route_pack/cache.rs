//! Fixed-capacity cache of verified tiles.
//!
//! Tiles stay in the pack image (zero copy, raw RGB), so what the cache keeps is the outcome of
//! verifying a tile's checksum: a tile is hashed before its first use and again only after it
//! was evicted. Capacity is [`TILE_CACHE_TILES`] entries (least recently used goes first); it
//! moves to `memory_layout.toml` once that file defines a tile-cache entry.
//!
//! Work bound: a step verifies at most [`super::MAX_CROP_TILES`] tiles for its crop plus
//! [`PREFETCH_TILES_PER_STEP`] tiles ahead on the route.

use super::crop::MAX_CROP_TILES;
use super::format::RoutePack;

/// Tile cache capacity, entries (one per tile; each entry is 16 bytes of state, the pixels stay
/// in the pack image). `memory_layout.toml` (`region.tile_cache`) records the same 64 x 16 B.
pub const TILE_CACHE_TILES: usize = 64;
/// Most tiles a step verifies ahead of the vehicle, on top of the ones its crop needs.
pub const PREFETCH_TILES_PER_STEP: usize = 2;

// A step's crop and prefetch tiles must fit together, or the cache would evict tiles the same
// step still needs and verify them twice.
const _: () = assert!(TILE_CACHE_TILES >= MAX_CROP_TILES + PREFETCH_TILES_PER_STEP);

/// Outcome of verifying a tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileState {
    /// Checksum matched: the payload may be sampled.
    Verified,
    /// Checksum mismatch: never sample this tile.
    Corrupt,
}

// `memory_layout.toml` budgets 16 bytes per tile-cache entry.
const _: () = assert!(core::mem::size_of::<Option<Entry>>() == 16);

#[derive(Clone, Copy, Debug)]
struct Entry {
    tile: u32,
    state: TileState,
    last_used: u64,
}

/// LRU cache of tile verification outcomes, `TILE_CACHE_TILES` entries, no allocation.
#[derive(Clone, Debug)]
pub struct TileCache {
    entries: [Option<Entry>; TILE_CACHE_TILES],
    clock: u64,
    verified_this_step: usize,
    verified_total: u64,
}

impl Default for TileCache {
    fn default() -> Self {
        Self::new()
    }
}

impl TileCache {
    /// An empty cache.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            entries: [None; TILE_CACHE_TILES],
            clock: 0,
            verified_this_step: 0,
            verified_total: 0,
        }
    }

    /// Start a step: resets the per-step verification counter.
    pub fn begin_step(&mut self) {
        self.verified_this_step = 0;
    }

    /// Tiles hashed since [`Self::begin_step`].
    #[must_use]
    pub const fn verified_this_step(&self) -> usize {
        self.verified_this_step
    }

    /// Tiles hashed since the cache was made.
    #[must_use]
    pub const fn verified_total(&self) -> u64 {
        self.verified_total
    }

    /// Cached state of tile `tile`, without touching it.
    #[must_use]
    pub fn peek(&self, tile: usize) -> Option<TileState> {
        self.entries
            .iter()
            .flatten()
            .find(|e| e.tile as usize == tile)
            .map(|e| e.state)
    }

    /// State of tile `tile` of `pack`, verifying (hashing) it if it is not cached.
    pub fn get_or_verify(&mut self, pack: &RoutePack<'_>, tile: usize) -> TileState {
        self.clock += 1;
        let clock = self.clock;
        if let Some(e) = self
            .entries
            .iter_mut()
            .flatten()
            .find(|e| e.tile as usize == tile)
        {
            e.last_used = clock;
            return e.state;
        }
        let state = if pack.verified_tile(tile).is_some() {
            TileState::Verified
        } else {
            TileState::Corrupt
        };
        self.verified_this_step += 1;
        self.verified_total += 1;
        let Ok(tile) = u32::try_from(tile) else {
            return state;
        };
        let entry = Some(Entry {
            tile,
            state,
            last_used: clock,
        });
        let slot = match self.entries.iter().position(Option::is_none) {
            Some(free) => free,
            None => self
                .entries
                .iter()
                .enumerate()
                .min_by_key(|(_, e)| e.map_or(0, |e| e.last_used))
                .map_or(0, |(i, _)| i),
        };
        if let Some(dst) = self.entries.get_mut(slot) {
            *dst = entry;
        }
        state
    }
}
