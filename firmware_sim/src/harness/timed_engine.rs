//! [`TimedEngine`]: an [`Engine`] decorator that times every stage and counts the allocations
//! made inside engine calls, into series reserved before the replay (recording never allocates).
//!
//! The native GKT gather-sum runs inside `SatMap::step` between the last `image_encoder` call
//! and the `bev_encoder` call, with nothing else in between (see `runtime/core/src/step.rs`), so its
//! latency is the gap between those two calls: the decorator records it as `gkt_gather` without
//! the runtime having to time itself.

use std::time::Instant;

use satmap_runtime::capacity::CAN_BUS_LEN;
use satmap_runtime::engine::{Engine, EngineError};
use satmap_runtime::features::{FeaturesMut, FeaturesRef};
use satmap_runtime::model_dims::ModelDims;

use super::stats::Series;
use crate::arena::ArenaAllocator;

/// Timed quantities, in report order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Timed {
    /// One camera's `image_encoder` run (six per step).
    ImageEncoder = 0,
    /// `bev_query`.
    BevQuery = 1,
    /// The native gather-sum (inferred from the gap, see the module doc).
    GktGather = 2,
    /// `bev_encoder`.
    BevEncoder = 3,
    /// The satellite crop from the route pack.
    SatelliteCrop = 4,
    /// `satellite_encoder`.
    SatelliteEncoder = 5,
    /// `map_decoder`.
    MapDecoder = 6,
    /// The whole step.
    Step = 7,
}

impl Timed {
    /// All quantities in report order.
    pub const ALL: [Self; 8] = [
        Self::ImageEncoder,
        Self::BevQuery,
        Self::GktGather,
        Self::BevEncoder,
        Self::SatelliteCrop,
        Self::SatelliteEncoder,
        Self::MapDecoder,
        Self::Step,
    ];

    /// Name, as in `memory_layout.toml` `[budgets.latency_us]`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ImageEncoder => "image_encoder",
            Self::BevQuery => "bev_query",
            Self::GktGather => "gkt_gather",
            Self::BevEncoder => "bev_encoder",
            Self::SatelliteCrop => "satellite_crop",
            Self::SatelliteEncoder => "satellite_encoder",
            Self::MapDecoder => "map_decoder",
            Self::Step => "step",
        }
    }
}

/// Latency series of every timed quantity plus the engine's allocation count.
#[derive(Debug)]
pub struct Timings {
    /// One series per [`Timed`], indexed by `Timed as usize`.
    pub series: [Series; 8],
    /// Allocations made inside engine calls since the last [`Timings::take_engine_allocations`].
    engine_allocations: usize,
}

impl Timings {
    /// Series with room for `steps` steps (six image samples per step).
    #[must_use]
    pub fn with_steps(steps: usize) -> Self {
        let series = Timed::ALL.map(|t| {
            Series::with_capacity(if t == Timed::ImageEncoder {
                steps * 6
            } else {
                steps
            })
        });
        Self {
            series,
            engine_allocations: 0,
        }
    }

    /// Record one sample of `what`.
    pub fn record(&mut self, what: Timed, us: u64) {
        self.series[what as usize].record(us);
    }

    /// Allocations inside engine calls since the previous call; resets the count.
    pub fn take_engine_allocations(&mut self) -> usize {
        core::mem::take(&mut self.engine_allocations)
    }
}

/// Microseconds since `t`.
#[must_use]
pub fn micros_since(t: Instant) -> u64 {
    u64::try_from(t.elapsed().as_micros()).unwrap_or(u64::MAX)
}

/// The timing decorator.
pub struct TimedEngine<E: Engine> {
    inner: E,
    timings: Timings,
    alloc: Option<&'static ArenaAllocator>,
    /// End of the last `image_encoder` call of the current step.
    images_done: Option<Instant>,
}

impl<E: Engine> TimedEngine<E> {
    /// Wrap `inner`; `alloc` (when the arena allocator is the global allocator) counts the
    /// allocations inside engine calls.
    pub fn new(inner: E, steps: usize, alloc: Option<&'static ArenaAllocator>) -> Self {
        Self {
            inner,
            timings: Timings::with_steps(steps),
            alloc,
            images_done: None,
        }
    }

    /// The timings so far.
    pub fn timings_mut(&mut self) -> &mut Timings {
        &mut self.timings
    }

    /// The timings so far.
    #[must_use]
    pub fn timings(&self) -> &Timings {
        &self.timings
    }

    fn allocations(&self) -> usize {
        self.alloc.map_or(0, |a| a.stats().all_allocations())
    }

    fn timed<T>(&mut self, what: Timed, f: impl FnOnce(&mut E) -> T) -> T {
        let before = self.allocations();
        let t = Instant::now();
        let out = f(&mut self.inner);
        let us = micros_since(t);
        self.timings.record(what, us);
        let allocations = self.allocations() - before;
        self.timings.engine_allocations += allocations;
        out
    }
}

impl<E: Engine> Engine for TimedEngine<E> {
    fn dims(&self) -> &ModelDims {
        self.inner.dims()
    }

    fn encode_image(
        &mut self,
        camera: usize,
        image_rgb: &[u8],
        value_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let r = self.timed(Timed::ImageEncoder, |e| {
            e.encode_image(camera, image_rgb, value_out)
        });
        self.images_done = Some(Instant::now());
        r
    }

    fn bev_query(
        &mut self,
        can_bus: &[f32; CAN_BUS_LEN],
        query_out: &mut [f32],
        gkt_weights_out: &mut [f32],
    ) -> Result<(), EngineError> {
        self.images_done = None;
        self.timed(Timed::BevQuery, |e| {
            e.bev_query(can_bus, query_out, gkt_weights_out)
        })
    }

    fn bev_encode(
        &mut self,
        query: &[f32],
        gathered: &[f32],
        camera_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError> {
        if let Some(t) = self.images_done.take() {
            self.timings.record(Timed::GktGather, micros_since(t));
        }
        self.timed(Timed::BevEncoder, |e| {
            e.bev_encode(query, gathered, camera_bev_out)
        })
    }

    fn encode_satellite(
        &mut self,
        crop_rgb: &[u8],
        satellite_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError> {
        self.timed(Timed::SatelliteEncoder, |e| {
            e.encode_satellite(crop_rgb, satellite_bev_out)
        })
    }

    fn decode_map(
        &mut self,
        camera_bev: FeaturesRef<'_>,
        satellite_bev: FeaturesRef<'_>,
        class_logits_out: &mut [f32],
        points_out: &mut [f32],
    ) -> Result<(), EngineError> {
        self.timed(Timed::MapDecoder, |e| {
            e.decode_map(camera_bev, satellite_bev, class_logits_out, points_out)
        })
    }
}
