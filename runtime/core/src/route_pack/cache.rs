//! Fixed-capacity cache of verified (and decoded) tiles.
//!
//! Raw tiles (version 1) stay in the pack image (zero copy), so what the cache keeps is the
//! outcome of verifying a tile's checksum: a tile is hashed before its first use and again only
//! after it was evicted. Compressed tiles (version 2) are hashed, then decoded into one slot of
//! the caller's tile buffer (`memory_layout.toml`, `region.tile_pixels`); entry `k` of the
//! cache owns slot `k`, so the cache holds as many compressed tiles as the buffer has slots (at
//! most [`TILE_CACHE_TILES`]). Least recently used goes first.
//!
//! Work bound: a step verifies (and decodes) at most [`super::MAX_CROP_TILES`] tiles for its
//! crop plus [`PREFETCH_TILES_PER_STEP`] tiles ahead on the route.

use super::codec::decode_tile;
use super::crop::MAX_CROP_TILES;
use super::parse::RoutePack;

/// Tile cache capacity, entries (one per tile; each entry is 16 bytes of state, the pixels stay
/// in the pack image). `memory_layout.toml` (`region.tile_cache`) records the same 64 x 16 B.
pub const TILE_CACHE_TILES: usize = 64;
/// Most tiles a step verifies ahead of the vehicle, on top of the ones its crop needs.
pub const PREFETCH_TILES_PER_STEP: usize = 2;

// A step's crop and prefetch tiles must fit together, or the cache would evict tiles the same
// step still needs and verify them twice.
const _: () = assert!(TILE_CACHE_TILES >= MAX_CROP_TILES + PREFETCH_TILES_PER_STEP);

/// Which entry a lookup may replace when the cache is full.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Evict {
    /// The least recently used (a crop's own tiles).
    LeastRecent,
    /// The least recently used of those not used this step (prefetch).
    OlderThanStep,
}

/// Outcome of verifying a tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileState {
    /// Checksum matched: the payload may be sampled.
    Verified,
    /// Checksum mismatch: never sample this tile.
    Corrupt,
    /// Checksum matched but the payload did not decode to the tile (a payload forged with a
    /// matching checksum, or a builder bug): never sample this tile.
    Undecodable,
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
    decoded_this_step: usize,
    decoded_total: u64,
    /// The clock when the step began: entries used after it are this step's.
    step_clock: u64,
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
            decoded_this_step: 0,
            decoded_total: 0,
            step_clock: 0,
        }
    }

    /// Start a step: resets the per-step verification and decode counters.
    pub fn begin_step(&mut self) {
        self.verified_this_step = 0;
        self.decoded_this_step = 0;
        self.step_clock = self.clock;
    }

    /// Mark cached tile `tile` as used now (prefetch keeps the tiles ahead it already holds
    /// from being evicted before the crop reaches them); its state, or `None` if not cached.
    pub fn touch(&mut self, tile: usize) -> Option<TileState> {
        self.clock += 1;
        let clock = self.clock;
        let e = self
            .entries
            .iter_mut()
            .flatten()
            .find(|e| e.tile as usize == tile)?;
        e.last_used = clock;
        Some(e.state)
    }

    /// Tiles decoded since [`Self::begin_step`] (compressed packs only).
    #[must_use]
    pub const fn decoded_this_step(&self) -> usize {
        self.decoded_this_step
    }

    /// Tiles decoded since the cache was made.
    #[must_use]
    pub const fn decoded_total(&self) -> u64 {
        self.decoded_total
    }

    /// Entries usable with `pack` and a tile buffer of `pixels_len` bytes: all of them for raw
    /// packs, one per whole tile slot of the buffer for compressed ones.
    #[must_use]
    pub fn capacity(pack: &RoutePack<'_>, pixels_len: usize) -> usize {
        if pack.codec().needs_decode() {
            (pixels_len / pack.header().tile_bytes()).min(TILE_CACHE_TILES)
        } else {
            TILE_CACHE_TILES
        }
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

    /// State of tile `tile` of `pack` and the entry holding it, verifying (hashing) and, for a
    /// compressed pack, decoding it into that entry's slot of `pixels` if it is not cached.
    /// `None` when the cache has no entry to give (a compressed pack with a tile buffer smaller
    /// than one tile, see [`Self::capacity`]).
    pub fn get_or_verify(
        &mut self,
        pack: &RoutePack<'_>,
        tile: usize,
        pixels: &mut [u8],
    ) -> Option<(TileState, usize)> {
        self.lookup(pack, tile, pixels, Evict::LeastRecent)
    }

    /// Like [`Self::get_or_verify`], for a tile wanted ahead of need: it never evicts a tile
    /// used since [`Self::begin_step`] (this step's crop and the tiles ahead already held), so
    /// when those fill the cache prefetch stops (`None`) instead of evicting what it fetched a
    /// moment ago and fetching it again every step.
    pub fn prefetch(
        &mut self,
        pack: &RoutePack<'_>,
        tile: usize,
        pixels: &mut [u8],
    ) -> Option<(TileState, usize)> {
        self.lookup(pack, tile, pixels, Evict::OlderThanStep)
    }

    fn lookup(
        &mut self,
        pack: &RoutePack<'_>,
        tile: usize,
        pixels: &mut [u8],
        evict: Evict,
    ) -> Option<(TileState, usize)> {
        let capacity = Self::capacity(pack, pixels.len());
        let entries = self.entries.get_mut(..capacity)?;
        self.clock += 1;
        let clock = self.clock;
        if let Some((k, e)) = entries.iter_mut().enumerate().find_map(|(k, e)| {
            e.as_mut()
                .filter(|e| e.tile as usize == tile)
                .map(|e| (k, e))
        }) {
            e.last_used = clock;
            return Some((e.state, k));
        }
        let step_clock = self.step_clock;
        let slot = match entries.iter().position(Option::is_none) {
            Some(free) => free,
            None => entries
                .iter()
                .enumerate()
                .filter(|(_, e)| {
                    evict == Evict::LeastRecent || e.is_some_and(|e| e.last_used <= step_clock)
                })
                .min_by_key(|(_, e)| e.map_or(0, |e| e.last_used))
                .map(|(i, _)| i)?,
        };
        let payload = pack.verified_tile(tile);
        self.verified_this_step += 1;
        self.verified_total += 1;
        let state = match payload {
            None => TileState::Corrupt,
            Some(_) if !pack.codec().needs_decode() => TileState::Verified,
            Some(payload) => {
                self.decoded_this_step += 1;
                self.decoded_total += 1;
                let bytes = pack.header().tile_bytes();
                let out = pixels.get_mut(slot * bytes..(slot + 1) * bytes);
                match out
                    .map(|out| decode_tile(pack.codec(), payload, pack.header().tile_size_px, out))
                {
                    Some(Ok(())) => TileState::Verified,
                    _ => TileState::Undecodable,
                }
            }
        };
        let tile = u32::try_from(tile).ok()?;
        if let Some(dst) = self.entries.get_mut(slot) {
            *dst = Some(Entry {
                tile,
                state,
                last_used: clock,
            });
        }
        Some((state, slot))
    }
}
