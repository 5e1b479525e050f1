//! [`TimedSource`]: a [`SatelliteSource`] decorator that times each crop into a series reserved
//! before the replay.

use std::time::Instant;

use satmap_runtime::pose::EgoPose;
use satmap_runtime::satellite::{Coverage, CropSpec, SatelliteSource};

use super::stats::Series;
use super::timed_engine::micros_since;

/// The timing decorator.
pub struct TimedSource<S: SatelliteSource> {
    inner: S,
    /// Crop latencies, microseconds.
    pub crop_us: Series,
}

impl<S: SatelliteSource> TimedSource<S> {
    /// Wrap `inner` with room for `steps` samples.
    pub fn new(inner: S, steps: usize) -> Self {
        Self {
            inner,
            crop_us: Series::with_capacity(steps),
        }
    }

    /// The wrapped source (e.g. to read its crop report).
    pub const fn inner(&self) -> &S {
        &self.inner
    }
}

impl<S: SatelliteSource> SatelliteSource for TimedSource<S> {
    fn crop(&mut self, pose: &EgoPose, spec: &CropSpec, out: &mut [u8]) -> Coverage {
        let t = Instant::now();
        let c = self.inner.crop(pose, spec, out);
        self.crop_us.record(micros_since(t));
        c
    }

    /// Passed through, so `SatMap::reset` reaches the wrapped source (a pack's route cursor).
    fn reset(&mut self) {
        self.inner.reset();
    }
}
