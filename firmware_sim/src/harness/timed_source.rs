//! [`TimedSource`]: a [`SatelliteSource`] decorator that times each crop into a series reserved
//! before the replay, and counts the allocations made inside it: the only ones a crop makes
//! are the JPEG decoder's scratch while it decodes a tile of a compressed pack (taken and
//! returned within the decode; `route_pack::codec`), which the report shows apart from the
//! runtime's own (which must be none).

use std::time::Instant;

use satmap_runtime::pose::EgoPose;
use satmap_runtime::satellite::{Coverage, CropSpec, SatelliteSource};

use super::stats::Series;
use super::timed_engine::micros_since;
use crate::arena::ArenaAllocator;

/// The timing decorator.
pub struct TimedSource<S: SatelliteSource> {
    inner: S,
    /// Crop latencies, microseconds.
    pub crop_us: Series,
    alloc: Option<&'static ArenaAllocator>,
    decoder_allocations: usize,
}

impl<S: SatelliteSource> TimedSource<S> {
    /// Wrap `inner` with room for `steps` samples; `alloc` counts allocations inside crops.
    pub fn new(inner: S, steps: usize, alloc: Option<&'static ArenaAllocator>) -> Self {
        Self {
            inner,
            crop_us: Series::with_capacity(steps),
            alloc,
            decoder_allocations: 0,
        }
    }

    /// Allocations made inside crops since the last call (tile decoder scratch).
    pub fn take_decoder_allocations(&mut self) -> usize {
        core::mem::take(&mut self.decoder_allocations)
    }

    /// The wrapped source (e.g. to read its crop report).
    pub const fn inner(&self) -> &S {
        &self.inner
    }
}

impl<S: SatelliteSource> SatelliteSource for TimedSource<S> {
    fn crop(&mut self, pose: &EgoPose, spec: &CropSpec, out: &mut [u8]) -> Coverage {
        let count =
            |a: Option<&'static ArenaAllocator>| a.map_or(0, |a| a.stats().all_allocations());
        let before = count(self.alloc);
        let t = Instant::now();
        let c = self.inner.crop(pose, spec, out);
        self.crop_us.record(micros_since(t));
        self.decoder_allocations += count(self.alloc) - before;
        c
    }

    /// Passed through, so `SatMap::reset` reaches the wrapped source (a pack's route cursor).
    fn reset(&mut self) {
        self.inner.reset();
    }
}
