//! The deterministic step state machine: [`SatMap`] owns every buffer of the pipeline (reserved
//! once at init), checks each frame, drives the engine's stages and the native GKT kernel, and
//! publishes the decoded [`MapFrame`].
//!
//! Step order: frame checks -> CAN-bus vector -> `bev_query` -> six `image_encoder` runs ->
//! gather-sum -> `bev_encoder` -> satellite crop (source) -> `satellite_encoder`, or zeros when
//! the prior is missing or corrupt (degraded) -> `map_decoder` -> finiteness check (normalised
//! points also within [`MAX_NORMALISED_POINT`]) -> decode ->
//! digest. Failure at any point returns a [`StepError`] and leaves the last published map, the
//! last sequence and timestamp untouched; intermediate buffers then hold the partial step.
//! `step` allocates nothing.
//!
//! The frame checks bound how far sequence and timestamp may jump ([`FrameLimits`]), so a frame
//! cannot lock the runtime out: one that jumps too far is refused and not adopted.
//! [`SatMap::reset`] is the explicit restart after which any first frame is accepted again.

mod buffers;

pub use buffers::StepBuffers;

use crate::calibration::Calibration;
use crate::can_bus::can_bus;
use crate::capacity::CAN_BUS_LEN;
use crate::decode::decode;
use crate::engine::{Engine, Stage};
use crate::error::{InitError, StepError};
use crate::frame::{Frame, FrameLimits, LastStep, check_frame};
use crate::gkt::{Lut, gather_sum};
use crate::map_frame::{self, Health, MapFrame, SatellitePrior};
use crate::model_dims::ModelDims;
use crate::satellite::{Coverage, SatelliteSource};

/// Largest magnitude of a normalised decoder point the step publishes (the model's points are
/// sigmoid outputs in [0, 1]): anything beyond, or NaN, is [`StepError::NonFiniteOutput`].
pub const MAX_NORMALISED_POINT: f32 = 1e6;

/// The SatMap runtime: one instance per vehicle, one [`SatMap::step`] per cycle.
pub struct SatMap<E: Engine, S: SatelliteSource> {
    engine: E,
    satellite: S,
    dims: ModelDims,
    lut: Lut,
    buffers: StepBuffers,
    limits: FrameLimits,
    output: MapFrame,
    /// `None` until the first successful step, and again after [`SatMap::reset`].
    last: Option<LastStep>,
}

impl<E: Engine, S: SatelliteSource> SatMap<E, S> {
    /// Check the engine's dimensions and the calibration, build the look-up table and reserve
    /// every buffer; frames are checked against [`FrameLimits::DEFAULT`].
    ///
    /// # Errors
    /// [`InitError::Dims`], [`InitError::RegionTooSmall`] (a region of `memory_layout.toml`
    /// cannot hold the model's buffers), [`InitError::InvalidCalibration`] (see
    /// [`Calibration::validate`]) or [`InitError::OutOfMemory`].
    pub fn new(engine: E, calibration: &Calibration, satellite: S) -> Result<Self, InitError> {
        Self::with_limits(engine, calibration, satellite, FrameLimits::DEFAULT)
    }

    /// As [`SatMap::new`], with frames checked against `limits`.
    ///
    /// # Errors
    /// [`InitError::InvalidLimits`] (see [`FrameLimits::validate`]), else as [`SatMap::new`].
    pub fn with_limits(
        engine: E,
        calibration: &Calibration,
        satellite: S,
        limits: FrameLimits,
    ) -> Result<Self, InitError> {
        limits.validate()?;
        let dims = engine.dims().clone();
        dims.validate()?;
        crate::regions::check_regions(&dims)?;
        let lut = Lut::new(&dims, calibration)?;
        Ok(Self {
            buffers: StepBuffers::new(&dims)?,
            limits,
            output: MapFrame::default(),
            last: None,
            engine,
            satellite,
            dims,
            lut,
        })
    }

    /// Run one step on `frame` and return the new map.
    ///
    /// # Errors
    /// An input check, an engine stage or a non-finite decoder output; see [`StepError`].
    /// The runtime stays usable: the next good frame steps normally.
    pub fn step(&mut self, frame: &Frame<'_>) -> Result<&MapFrame, StepError> {
        check_frame(frame, &self.dims, &self.limits, self.last)?;
        let b = &mut self.buffers;
        b.can_bus = can_bus(&frame.pose, &frame.motion);
        self.engine
            .bev_query(&b.can_bus, &mut b.query, &mut b.weights)?;
        let value_len = self.dims.value_len();
        for (camera, (image, value)) in frame
            .images
            .iter()
            .zip(b.value.chunks_exact_mut(value_len))
            .enumerate()
        {
            // check_frame guarantees every image is present.
            let Some(image) = image else {
                return Err(StepError::MissingCamera { camera });
            };
            self.engine.encode_image(camera, image.rgb, value)?;
        }
        gather_sum(&self.lut, &b.value, &b.weights, &mut b.gathered)?;
        self.engine
            .bev_encode(&b.query, &b.gathered, &mut b.camera_bev)?;

        let spec = self.dims.crop_spec();
        let coverage = self.satellite.crop(&frame.pose, &spec, &mut b.crop);
        let (prior, degraded) = match coverage {
            Coverage::Full => (SatellitePrior::Present, false),
            Coverage::Partial { covered_permille } => {
                (SatellitePrior::Partial { covered_permille }, false)
            }
            Coverage::None => (SatellitePrior::Missing, true),
            Coverage::Corrupt => (SatellitePrior::Corrupt, true),
        };
        if degraded {
            b.satellite_bev.fill(0.0);
        } else {
            self.engine
                .encode_satellite(&b.crop, &mut b.satellite_bev)?;
        }
        self.engine.decode_map(
            &b.camera_bev,
            &b.satellite_bev,
            &mut b.logits,
            &mut b.points,
        )?;
        // Points are normalised to the BEV range (sigmoid outputs in [0, 1]); a finite but huge
        // value would still decode to an infinite coordinate in metres, so bound them too.
        if !(b.logits.iter().all(|v| v.is_finite())
            && b.points.iter().all(|v| v.abs() <= MAX_NORMALISED_POINT))
        {
            return Err(StepError::NonFiniteOutput {
                stage: Stage::MapDecoder,
            });
        }

        // Every stage succeeded: publish.
        decode(&self.dims, &b.logits, &b.points, &mut self.output.elements);
        self.output.sequence = frame.sequence;
        self.output.timestamp_us = frame.timestamp_us;
        self.output.health = Health {
            satellite: prior,
            degraded,
            deadline_overrun: false,
        };
        self.output.digest = map_frame::digest(&self.output.elements);
        self.last = Some(LastStep {
            sequence: frame.sequence,
            timestamp_us: frame.timestamp_us,
        });
        Ok(&self.output)
    }

    /// Rebuild the GKT look-up table for a new calibration; the model stays loaded and nothing
    /// is allocated.
    ///
    /// # Errors
    /// [`InitError::InvalidCalibration`] (see [`Calibration::validate`]); the previous table
    /// stays in use then.
    pub fn recalibrate(&mut self, calibration: &Calibration) -> Result<(), InitError> {
        self.lut.rebuild(calibration)
    }

    /// Restart the frame counters: forget the last successful step, so that the next frame is
    /// accepted whatever its sequence and timestamp, as after [`SatMap::new`]. For a genuine
    /// restart of the caller's counters (a reboot of the camera rig, a pause longer than
    /// [`FrameLimits::max_timestamp_gap_us`]), which the gap checks otherwise refuse; also the
    /// way out if the first frame after init carried corrupt counters, since a first frame is
    /// never refused for its counters.
    ///
    /// The satellite source is reset too ([`SatelliteSource::reset`]: a route pack's cursor
    /// searches for the vehicle again). [`SatMap::last_map`] is `None` until the next successful
    /// step. Calibration, limits, engine, satellite source and buffers are kept; nothing is
    /// allocated.
    pub fn reset(&mut self) {
        self.last = None;
        self.satellite.reset();
    }

    /// The limits frames are checked against.
    #[must_use]
    pub const fn limits(&self) -> &FrameLimits {
        &self.limits
    }

    /// Flag the last published map as late (the caller measures the deadline).
    pub fn mark_deadline_overrun(&mut self) {
        self.output.health.deadline_overrun = true;
    }

    /// The last published map; `None` before the first successful step.
    #[must_use]
    pub fn last_map(&self) -> Option<&MapFrame> {
        self.last.map(|_| &self.output)
    }

    /// Model dimensions (from the engine).
    #[must_use]
    pub const fn dims(&self) -> &ModelDims {
        &self.dims
    }

    /// The GKT look-up table in use.
    #[must_use]
    pub const fn lut(&self) -> &Lut {
        &self.lut
    }

    /// The engine.
    #[must_use]
    pub const fn engine(&self) -> &E {
        &self.engine
    }

    /// The engine, mutably (e.g. to read its timings).
    pub const fn engine_mut(&mut self) -> &mut E {
        &mut self.engine
    }

    /// The satellite source, mutably (e.g. to swap route packs).
    pub const fn satellite_mut(&mut self) -> &mut S {
        &mut self.satellite
    }

    /// The intermediate buffers of the last attempted step (the partial step after a failure).
    #[must_use]
    pub const fn buffers(&self) -> &StepBuffers {
        &self.buffers
    }

    // Shorthands for the most used views of [`StepBuffers`], kept so that existing callers
    // (`tests/golden_step.rs`, the sim harness) need not change.

    /// CAN-bus vector of the last attempted step; see [`StepBuffers::can_bus`].
    #[must_use]
    pub const fn can_bus(&self) -> &[f32; CAN_BUS_LEN] {
        self.buffers.can_bus()
    }

    /// Value features `[6, F, D]`; see [`StepBuffers::value`].
    #[must_use]
    pub fn value(&self) -> &[f32] {
        self.buffers.value()
    }

    /// BEV queries `[Q, D]`; see [`StepBuffers::query`].
    #[must_use]
    pub fn query(&self) -> &[f32] {
        self.buffers.query()
    }

    /// GKT weights `[Q, 4, kp]`; see [`StepBuffers::weights`].
    #[must_use]
    pub fn weights(&self) -> &[f32] {
        self.buffers.weights()
    }

    /// Gather-sum output `[Q, D]`; see [`StepBuffers::gathered`].
    #[must_use]
    pub fn gathered(&self) -> &[f32] {
        self.buffers.gathered()
    }

    /// Camera BEV `[bev_h, bev_w, D]`; see [`StepBuffers::camera_bev`].
    #[must_use]
    pub fn camera_bev(&self) -> &[f32] {
        self.buffers.camera_bev()
    }

    /// Satellite crop `[sat_h, sat_w, 3]`; see [`StepBuffers::crop`].
    #[must_use]
    pub fn crop(&self) -> &[u8] {
        self.buffers.crop()
    }

    /// Satellite BEV `[bev_h, bev_w, D]` (zeros when degraded); see
    /// [`StepBuffers::satellite_bev`].
    #[must_use]
    pub fn satellite_bev(&self) -> &[f32] {
        self.buffers.satellite_bev()
    }

    /// Class logits `[num_vec, 3]`; see [`StepBuffers::logits`].
    #[must_use]
    pub fn logits(&self) -> &[f32] {
        self.buffers.logits()
    }

    /// Normalised points `[num_vec, num_pts, 2]`; see [`StepBuffers::points`].
    #[must_use]
    pub fn points(&self) -> &[f32] {
        self.buffers.points()
    }
}

#[cfg(test)]
mod hardening_tests;
#[cfg(test)]
mod tests;
