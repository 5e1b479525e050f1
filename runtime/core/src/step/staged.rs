//! A step split into slices an ECU scheduler can place in separate time slots:
//! [`SatMap::step_begin`] checks the frame, each [`SatMap::step_run_next`] runs one slice, and
//! [`SatMap::step_finish`] publishes. [`SatMap::step`] is exactly these three calls in a row, so
//! the staged and the one-call step compute the same bits.
//!
//! Slice order: `bev_query`, one `image_encoder` per camera that takes part (left-out cameras
//! have no slice), the native GKT gather-sum, `bev_encoder`, the satellite crop and
//! `satellite_encoder` (or zeros when degraded), `map_decoder` with the output checks. While a
//! staged step is in progress every new frame is refused ([`StepError::StepInProgress`]); a
//! failed slice ends the staged step (the published map is untouched) and
//! [`SatMap::step_abort`] drops one on purpose.
//!
//! [`SatMap::step_begin`]: super::SatMap::step_begin
//! [`SatMap::step_run_next`]: super::SatMap::step_run_next
//! [`SatMap::step_finish`]: super::SatMap::step_finish
//! [`SatMap::step`]: super::SatMap::step
//! [`SatMap::step_abort`]: super::SatMap::step_abort
//! [`StepError::StepInProgress`]: crate::StepError::StepInProgress

use crate::calibration::NUM_CAMERAS;
use crate::frame::{CameraImage, CameraUse, Frame};
use crate::map_frame::SatellitePrior;
use crate::pose::{EgoMotion, EgoPose};

/// One slice of a staged step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum StepSlice {
    /// CAN-bus vector and the `bev_query` stage.
    BevQuery,
    /// The `image_encoder` stage for one camera.
    ImageEncoder {
        /// Camera index (model order).
        camera: u8,
    },
    /// The native GKT gather-sum.
    GktGather,
    /// The `bev_encoder` stage.
    BevEncoder,
    /// The route-pack crop and the `satellite_encoder` stage (zeros when degraded).
    Satellite,
    /// The `map_decoder` stage and the output checks.
    MapDecoder,
}

/// Slots of the fixed slice sequence: bev_query, six cameras, gather, bev_encoder, satellite,
/// map_decoder.
const SLOTS: usize = NUM_CAMERAS + 5;

impl StepSlice {
    /// The slice in slot `slot` of the fixed sequence.
    const fn at(slot: usize) -> Option<Self> {
        match slot {
            0 => Some(Self::BevQuery),
            s if s <= NUM_CAMERAS => Some(Self::ImageEncoder {
                camera: (s - 1) as u8,
            }),
            s if s == NUM_CAMERAS + 1 => Some(Self::GktGather),
            s if s == NUM_CAMERAS + 2 => Some(Self::BevEncoder),
            s if s == NUM_CAMERAS + 3 => Some(Self::Satellite),
            s if s == NUM_CAMERAS + 4 => Some(Self::MapDecoder),
            _ => None,
        }
    }

    /// Stable numeric id (the C API's `SatmapSlice`): 0 bev_query, 1..=6 image_encoder of
    /// cameras 0..=5, 7 gather, 8 bev_encoder, 9 satellite, 10 map_decoder.
    #[must_use]
    pub const fn id(self) -> u8 {
        match self {
            Self::BevQuery => 0,
            Self::ImageEncoder { camera } => 1 + camera,
            Self::GktGather => NUM_CAMERAS as u8 + 1,
            Self::BevEncoder => NUM_CAMERAS as u8 + 2,
            Self::Satellite => NUM_CAMERAS as u8 + 3,
            Self::MapDecoder => NUM_CAMERAS as u8 + 4,
        }
    }
}

/// What one [`step_run_next`](super::SatMap::step_run_next) did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SliceDone {
    /// The slice that ran.
    pub slice: StepSlice,
    /// Slices still to run before [`step_finish`](super::SatMap::step_finish).
    pub remaining: u8,
}

impl SliceDone {
    /// True while slices remain.
    #[must_use]
    pub const fn more(&self) -> bool {
        self.remaining > 0
    }
}

/// The part of a frame a slice reads that differs from what `step_begin` checked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FramePart {
    /// Pose or motion (read by the `bev_query` slice's CAN-bus vector).
    Motion,
    /// A camera's image bytes, size or stamp (read by its `image_encoder` slice).
    Image {
        /// Camera index (model order).
        camera: u8,
    },
}

/// How a step's slices get their frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Slices {
    /// `step`: one borrowed frame for every slice.
    OneCall,
    /// `step_begin` / `step_run_next`: a frame per slice, checked against what began.
    Staged,
}

/// What `step_begin` saw of one camera's image: a slice that reads it again must find the same.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct ImageSeen {
    width_px: u32,
    height_px: u32,
    capture_us: u64,
    /// xxh3-64 of the RGB bytes.
    rgb_hash: u64,
}

impl ImageSeen {
    pub(super) fn of(image: &CameraImage<'_>) -> Self {
        Self {
            width_px: image.width_px,
            height_px: image.height_px,
            capture_us: image.capture_us,
            rgb_hash: xxhash_rust::xxh3::xxh3_64(image.rgb),
        }
    }
}

/// The staged step in progress: what `step_begin` checked and how far it got.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pending {
    pub(super) sequence: u64,
    pub(super) timestamp_us: u64,
    pub(super) pose: EgoPose,
    pub(super) motion: EgoMotion,
    /// What `step_begin` saw of each used camera's image, for a staged step; `None` in a
    /// one-call step, whose slices all read the one frame `step` borrows.
    pub(super) seen: Option<[Option<ImageSeen>; NUM_CAMERAS]>,
    pub(super) cameras: CameraUse,
    /// Next slot of the fixed sequence (skipping left-out cameras).
    pub(super) slot: usize,
    /// Set by the satellite slice.
    pub(super) prior: SatellitePrior,
    pub(super) degraded: bool,
}

impl Pending {
    /// The next slice to run and its slot, skipping cameras left out; `None` when done.
    pub(super) fn next(&self) -> Option<(usize, StepSlice)> {
        (self.slot..SLOTS)
            .filter_map(|s| StepSlice::at(s).map(|slice| (s, slice)))
            .find(|(_, slice)| match *slice {
                StepSlice::ImageEncoder { camera } => self.cameras.mask.contains(camera.into()),
                _ => true,
            })
    }

    /// Slices left after slot `slot` has run.
    pub(super) fn remaining_after(&self, slot: usize) -> u8 {
        let cameras_after = (slot.max(1)..NUM_CAMERAS + 1)
            .filter(|&s| s > slot && self.cameras.mask.contains(s - 1))
            .count();
        let fixed_after = (NUM_CAMERAS + 1..SLOTS).filter(|&s| s > slot).count();
        (cameras_after + fixed_after) as u8
    }
}

/// The part of `frame` that `slice` reads and that differs from what `step_begin` checked;
/// always `None` in a one-call step.
pub(super) fn changed_part(slice: StepSlice, frame: &Frame<'_>, p: &Pending) -> Option<FramePart> {
    let seen = p.seen.as_ref()?;
    match slice {
        StepSlice::BevQuery => {
            (frame.pose != p.pose || frame.motion != p.motion).then_some(FramePart::Motion)
        }
        StepSlice::ImageEncoder { camera } => {
            let c = usize::from(camera);
            let now = frame.images.get(c).copied().flatten();
            (now.as_ref().map(ImageSeen::of) != seen.get(c).copied().flatten())
                .then_some(FramePart::Image { camera })
        }
        _ => None,
    }
}
