//! The deterministic step state machine: [`SatMap`] owns every buffer of the pipeline (reserved
//! once at init), checks each frame, drives the engine's stages and the native GKT kernel, and
//! publishes the decoded [`MapFrame`].
//!
//! Step order: frame checks -> CAN-bus vector -> `bev_query` -> one `image_encoder` run per
//! camera that takes part (see [`crate::frame::CameraState`]) -> gather-sum over those cameras -> `bev_encoder` -> satellite crop (source) -> `satellite_encoder`, or zeros when
//! the prior is missing or corrupt (degraded) -> `map_decoder` -> decode -> digest. Every
//! stage's output (and the gather-sum's) is checked finite as it is written, the decoder's
//! normalised points also within [`MAX_NORMALISED_POINT`]. Failure at any point returns a [`StepError`] and leaves the last published map, the
//! last sequence and timestamp untouched; intermediate buffers then hold the partial step.
//! `step` allocates nothing. The same step can be run slice by slice (`step/staged.rs`).
//!
//! The frame checks bound how far sequence and timestamp may jump ([`FrameLimits`]), so a frame
//! cannot lock the runtime out: one that jumps too far is refused and not adopted.
//! [`SatMap::reset`] is the explicit restart after which any first frame is accepted again.

mod buffers;
mod error;
mod slices;
mod staged;

pub use buffers::StepBuffers;
pub use error::{InitError, StepError};
pub use staged::{FramePart, SliceDone, StepSlice};
use staged::{ImageSeen, Pending, Slices, changed_part};

use crate::calibration::Calibration;
use crate::decode::decode;
use crate::engine::Engine;
use crate::features::FeatureStorage;
use crate::frame::{Frame, FrameLimits, LastStep, check_frame};
use crate::gkt::Lut;
use crate::map_frame::{self, Health, MapFrame, SatellitePrior};
use crate::model_dims::ModelDims;
use crate::placement::RuntimeRegions;
use crate::satellite::SatelliteSource;

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
    /// The staged step in progress.
    pending: Option<Pending>,
}

impl<E: Engine, S: SatelliteSource> SatMap<E, S> {
    /// Check the engine's dimensions and the calibration, build the look-up table and reserve
    /// every buffer; frames are checked against [`FrameLimits::DEFAULT`].
    ///
    /// # Errors
    /// [`InitError::Dims`], [`InitError::Memory`] (a region of `memory_layout.toml` cannot
    /// hold the model's buffers, or a buffer cannot be reserved) or
    /// [`InitError::InvalidCalibration`] (see [`Calibration::validate`]).
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
        Self::with_bev_storage(
            engine,
            calibration,
            satellite,
            limits,
            FeatureStorage::LAYOUT,
        )
    }

    /// As [`SatMap::with_limits`], with the two BEV feature maps reserved in `bev` storage
    /// instead of the layout's ([`FeatureStorage::LAYOUT`]): to compare both storages in one
    /// build. They must fit the layout's regions in that storage (f32 BEVs of the size a layout
    /// gives f16 do not: nano's in `layouts/nano-f16-bev.toml`).
    ///
    /// # Errors
    /// As [`SatMap::with_limits`].
    pub fn with_bev_storage(
        engine: E,
        calibration: &Calibration,
        satellite: S,
        limits: FrameLimits,
        bev: FeatureStorage,
    ) -> Result<Self, InitError> {
        let dims = checked_dims(&engine, &limits, bev)?;
        let lut = Lut::new(&dims, calibration)?;
        let buffers = StepBuffers::new(&dims, bev)?;
        Ok(Self::assemble(
            engine, satellite, dims, lut, buffers, limits,
        ))
    }

    /// As [`SatMap::with_limits`], with every model-sized buffer in memory the caller placed
    /// ([`RuntimeRegions`]: one region per runtime region of `memory_layout.toml`, each at least
    /// its layout size and [`REGION_ALIGN`](crate::placement::REGION_ALIGN)-aligned). Nothing
    /// of the step's own state is allocated (the engine keeps its own memory).
    ///
    /// # Errors
    /// [`InitError::Memory`] naming the region (too small or misaligned),
    /// else as [`SatMap::with_limits`].
    pub fn in_regions(
        engine: E,
        calibration: &Calibration,
        satellite: S,
        limits: FrameLimits,
        regions: RuntimeRegions,
    ) -> Result<Self, InitError> {
        let dims = checked_dims(&engine, &limits, FeatureStorage::LAYOUT)?;
        let (step, lut) = regions.split(&dims)?;
        let lut = Lut::placed(&dims, calibration, lut.queries, lut.indices, lut.count)?;
        let buffers = StepBuffers::placed(step);
        Ok(Self::assemble(
            engine, satellite, dims, lut, buffers, limits,
        ))
    }

    fn assemble(
        engine: E,
        satellite: S,
        dims: ModelDims,
        lut: Lut,
        buffers: StepBuffers,
        limits: FrameLimits,
    ) -> Self {
        Self {
            buffers,
            limits,
            output: MapFrame::default(),
            last: None,
            pending: None,
            engine,
            satellite,
            dims,
            lut,
        }
    }

    /// Run one step on `frame` and return the new map: [`SatMap::step_begin`], every
    /// [`SatMap::step_run_next`], then [`SatMap::step_finish`] (the same bits), without the
    /// staged step's content check, which one borrowed frame cannot fail.
    ///
    /// # Errors
    /// An input check, an engine stage or a non-finite decoder output; see [`StepError`].
    /// The runtime stays usable: the next good frame steps normally.
    /// [`StepError::StepInProgress`] while a staged step is in progress.
    pub fn step(&mut self, frame: &Frame<'_>) -> Result<&MapFrame, StepError> {
        // One borrowed frame serves every slice: nothing of it can change between them, so its
        // images are not hashed for the slices to compare.
        self.begin(frame, Slices::OneCall)?;
        while self.step_run_next(frame)?.more() {}
        self.step_finish()
    }

    /// Start a staged step: check `frame` (as [`SatMap::step`] does) and run nothing yet.
    ///
    /// # Errors
    /// [`StepError::StepInProgress`] while another staged step is in progress (that step
    /// continues); else the frame checks' errors (no step is started then).
    pub fn step_begin(&mut self, frame: &Frame<'_>) -> Result<(), StepError> {
        self.begin(frame, Slices::Staged)
    }

    /// [`SatMap::step_begin`], remembering what the slices must find again where they may be
    /// given another frame (`Slices::Staged`).
    fn begin(&mut self, frame: &Frame<'_>, slices: Slices) -> Result<(), StepError> {
        if let Some(p) = &self.pending {
            return Err(StepError::StepInProgress {
                sequence: p.sequence,
            });
        }
        let cameras = check_frame(frame, &self.dims, &self.limits, self.last)?;
        let seen = match slices {
            Slices::OneCall => None,
            Slices::Staged => Some(core::array::from_fn(|c| {
                frame.images[c]
                    .as_ref()
                    .filter(|_| cameras.mask.contains(c))
                    .map(ImageSeen::of)
            })),
        };
        self.pending = Some(Pending {
            sequence: frame.sequence,
            timestamp_us: frame.timestamp_us,
            pose: frame.pose,
            motion: frame.motion,
            seen,
            cameras,
            slot: 0,
            prior: SatellitePrior::Missing,
            degraded: true,
        });
        Ok(())
    }

    /// Run the next slice of the staged step. `frame` must be the frame given to
    /// [`SatMap::step_begin`]: the same sequence and timestamp, and what the slice reads the
    /// same as what `step_begin` checked (pose and motion for `bev_query`, the camera's image
    /// bytes, size and stamp for its `image_encoder`: hashed at begin, hashed again here).
    ///
    /// # Errors
    /// [`StepError::NoStepInProgress`], [`StepError::FrameMismatch`] or
    /// [`StepError::FrameChanged`] (the staged step goes on), or the slice's own error, which
    /// ends the staged step.
    pub fn step_run_next(&mut self, frame: &Frame<'_>) -> Result<SliceDone, StepError> {
        let Some(mut p) = self.pending else {
            return Err(StepError::NoStepInProgress);
        };
        if (frame.sequence, frame.timestamp_us) != (p.sequence, p.timestamp_us) {
            return Err(StepError::FrameMismatch {
                expected_sequence: p.sequence,
                got_sequence: frame.sequence,
            });
        }
        let Some((slot, slice)) = p.next() else {
            // Every slice ran; only step_finish is left.
            return Ok(SliceDone {
                slice: StepSlice::MapDecoder,
                remaining: 0,
            });
        };
        if let Some(part) = changed_part(slice, frame, &p) {
            return Err(StepError::FrameChanged {
                sequence: p.sequence,
                part,
            });
        }
        match self.run_slice(slice, frame, &mut p) {
            Ok(()) => {
                p.slot = slot + 1;
                self.pending = Some(p);
                Ok(SliceDone {
                    slice,
                    remaining: p.remaining_after(slot),
                })
            }
            Err(e) => {
                self.pending = None;
                Err(e)
            }
        }
    }

    /// Publish the staged step's map: decode, health and digest.
    ///
    /// # Errors
    /// [`StepError::NoStepInProgress`], or [`StepError::StepIncomplete`] while slices remain
    /// (the staged step goes on).
    pub fn step_finish(&mut self) -> Result<&MapFrame, StepError> {
        let Some(p) = self.pending else {
            return Err(StepError::NoStepInProgress);
        };
        if let Some((_, next)) = p.next() {
            return Err(StepError::StepIncomplete { next });
        }
        self.pending = None;
        let b = &self.buffers;
        decode(&self.dims, &b.logits, &b.points, &mut self.output.elements);
        self.output.sequence = p.sequence;
        self.output.timestamp_us = p.timestamp_us;
        self.output.health = Health {
            satellite: p.prior,
            degraded: p.degraded,
            deadline_overrun: false,
            cameras: p.cameras.states,
        };
        self.output.digest = map_frame::digest(&self.output.elements);
        self.output.e2e_counter = self.output.e2e_counter.wrapping_add(1);
        self.last = Some(LastStep {
            sequence: p.sequence,
            timestamp_us: p.timestamp_us,
        });
        Ok(&self.output)
    }

    /// Drop the staged step in progress, if any (the published map is untouched). For a
    /// scheduler that gives up on a frame, e.g. at its deadline.
    pub fn step_abort(&mut self) {
        self.pending = None;
    }

    /// The next slice of the staged step in progress; `None` when no step is in progress or
    /// only [`SatMap::step_finish`] is left.
    #[must_use]
    pub fn next_slice(&self) -> Option<StepSlice> {
        self.pending.and_then(|p| p.next()).map(|(_, s)| s)
    }

    /// Rebuild the GKT look-up table for a new calibration (or the same one, to repair a table
    /// a step found corrupt: [`StepError::LutCorrupt`]); the model stays loaded and nothing is
    /// allocated.
    ///
    /// # Errors
    /// [`InitError::InvalidCalibration`] (see [`Calibration::validate`]); the previous table
    /// stays in use then.
    pub fn recalibrate(&mut self, calibration: &Calibration) -> Result<(), InitError> {
        Ok(self.lut.rebuild(calibration)?)
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
        self.pending = None;
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
}

/// The checks both constructors make before any buffer exists: the limits, the engine's
/// dimensions and whether they fit the layout's regions with the BEVs in `bev` storage.
fn checked_dims<E: Engine>(
    engine: &E,
    limits: &FrameLimits,
    bev: FeatureStorage,
) -> Result<ModelDims, InitError> {
    limits.validate()?;
    let dims = engine.dims().clone();
    dims.validate()?;
    crate::regions::check_regions_with(&dims, bev, crate::regions::built_in_capacity)?;
    Ok(dims)
}

#[cfg(test)]
mod bev_storage_tests;
#[cfg(test)]
mod changed_frame_tests;
#[cfg(test)]
mod hardening_tests;
#[cfg(test)]
mod lut_integrity_tests;
#[cfg(test)]
mod tests;
