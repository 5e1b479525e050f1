//! Unit-test fixtures: the nuScenes-like rig, a deterministic pure-Rust engine double, frames,
//! and a per-thread allocation counter installed as the test binary's global allocator.

use alloc::vec;
use alloc::vec::Vec;
use core::alloc::{GlobalAlloc, Layout};
use core::cell::Cell;
use std::alloc::System;

use glam::{DVec2, Vec3};

use crate::calibration::{Calibration, NUM_CAMERAS};
use crate::capacity::CAN_BUS_LEN;
use crate::engine::{BackendFault, Engine, EngineError, EngineErrorKind, Stage};
use crate::features::{FeaturesMut, FeaturesRef};
use crate::frame::{CameraImage, Frame};
use crate::model_dims::ModelDims;
use crate::pose::{EgoMotion, EgoPose};

/// The committed nuScenes-like rig.
pub(crate) fn nuscenes_like() -> Calibration {
    crate::calibration_rig::NUSCENES_LIKE
}

/// A deterministic stand-in for the graph engine: cheap functions of every input, so that any
/// change of an input (or a stage skipped) changes the outputs.
pub(crate) struct FakeEngine {
    pub dims: ModelDims,
    /// Fail this stage on the next call (then clear).
    pub fail_next: Option<Stage>,
    /// Make the decoder emit a NaN logit on the next call (then clear).
    pub nan_next: bool,
    /// Make the decoder emit a finite but huge point (1e37) on the next call (then clear).
    pub huge_point_next: bool,
    /// Factor on every camera BEV value (1; large to push it past f16's range).
    pub bev_gain: f32,
    /// Stages run, in order (bounded; for ordering checks).
    pub calls: heapless::Vec<Stage, 64>,
}

impl FakeEngine {
    pub(crate) fn new(dims: ModelDims) -> Self {
        Self {
            dims,
            fail_next: None,
            nan_next: false,
            huge_point_next: false,
            bev_gain: 1.0,
            calls: heapless::Vec::new(),
        }
    }

    fn enter(&mut self, stage: Stage) -> Result<(), EngineError> {
        if self.calls.is_full() {
            self.calls.clear();
        }
        let _ = self.calls.push(stage);
        if self.fail_next == Some(stage) {
            self.fail_next = None;
            return Err(EngineError {
                stage,
                kind: EngineErrorKind::Backend(BackendFault::RunFailed),
            });
        }
        Ok(())
    }
}

fn shape(stage: Stage, expected: usize, got: usize) -> Result<(), EngineError> {
    if expected == got {
        Ok(())
    } else {
        Err(EngineError {
            stage,
            kind: EngineErrorKind::ShapeMismatch { expected, got },
        })
    }
}

impl Engine for FakeEngine {
    fn dims(&self) -> &ModelDims {
        &self.dims
    }

    fn encode_image(
        &mut self,
        camera: usize,
        image_rgb: &[u8],
        value_out: &mut [f32],
    ) -> Result<(), EngineError> {
        self.enter(Stage::ImageEncoder)?;
        shape(
            Stage::ImageEncoder,
            self.dims.image_bytes(),
            image_rgb.len(),
        )?;
        shape(Stage::ImageEncoder, self.dims.value_len(), value_out.len())?;
        for (i, v) in value_out.iter_mut().enumerate() {
            let px = image_rgb[(i * 31) % image_rgb.len()];
            *v = f32::from(px) / 255.0 - 0.5 + camera as f32 * 0.125;
        }
        Ok(())
    }

    fn bev_query(
        &mut self,
        can_bus: &[f32; CAN_BUS_LEN],
        query_out: &mut [f32],
        gkt_weights_out: &mut [f32],
    ) -> Result<(), EngineError> {
        self.enter(Stage::BevQuery)?;
        shape(Stage::BevQuery, self.dims.bev_len(), query_out.len())?;
        shape(
            Stage::BevQuery,
            self.dims.weights_len(),
            gkt_weights_out.len(),
        )?;
        for (i, q) in query_out.iter_mut().enumerate() {
            *q = (i % 97) as f32 * 0.01 + can_bus[16] * 0.1 + can_bus[14] * 0.01;
        }
        let kp = self.dims.kernel_points();
        for (i, w) in gkt_weights_out.iter_mut().enumerate() {
            *w = ((i % kp) as f32 + 1.0 + can_bus[3]) / (kp * (kp + 1) / 2) as f32;
        }
        Ok(())
    }

    fn bev_encode(
        &mut self,
        query: &[f32],
        gathered: &[f32],
        mut camera_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError> {
        self.enter(Stage::BevEncoder)?;
        shape(Stage::BevEncoder, self.dims.bev_len(), camera_bev_out.len())?;
        shape(Stage::BevEncoder, query.len(), gathered.len())?;
        shape(Stage::BevEncoder, query.len(), camera_bev_out.len())?;
        let gain = self.bev_gain;
        camera_bev_out.fill_with(|i| (query[i] + gathered[i]) * gain);
        Ok(())
    }

    fn encode_satellite(
        &mut self,
        crop_rgb: &[u8],
        mut satellite_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError> {
        self.enter(Stage::SatelliteEncoder)?;
        shape(
            Stage::SatelliteEncoder,
            self.dims.crop_bytes(),
            crop_rgb.len(),
        )?;
        satellite_bev_out.fill_with(|i| f32::from(crop_rgb[(i * 13) % crop_rgb.len()]) / 255.0);
        Ok(())
    }

    fn decode_map(
        &mut self,
        camera_bev: FeaturesRef<'_>,
        satellite_bev: FeaturesRef<'_>,
        class_logits_out: &mut [f32],
        points_out: &mut [f32],
    ) -> Result<(), EngineError> {
        self.enter(Stage::MapDecoder)?;
        shape(
            Stage::MapDecoder,
            self.dims.logits_len(),
            class_logits_out.len(),
        )?;
        shape(Stage::MapDecoder, self.dims.points_len(), points_out.len())?;
        let n = camera_bev.len() / class_logits_out.len();
        for (j, l) in class_logits_out.iter_mut().enumerate() {
            let cam: f32 = camera_bev.iter().skip(j * n).take(n).sum();
            let sat: f32 = satellite_bev.iter().skip(j * n).take(n).sum();
            *l = (cam + 2.0 * sat) / n as f32 - 1.0;
        }
        if self.nan_next {
            self.nan_next = false;
            class_logits_out[0] = f32::NAN;
        }
        for (i, p) in points_out.iter_mut().enumerate() {
            let n = camera_bev.len();
            let at = |bev: FeaturesRef<'_>, k: usize| bev.get(k % n).unwrap_or(f32::NAN);
            let x = at(camera_bev, i * 7) + at(satellite_bev, i * 5);
            *p = x.abs().fract();
        }
        if self.huge_point_next {
            self.huge_point_next = false;
            points_out[1] = 1e37;
        }
        Ok(())
    }
}

/// Owned pixels for frames built by [`frame`].
pub(crate) struct Images {
    pub rgb: Vec<u8>,
    pub dims: ModelDims,
}

impl Images {
    /// Six images whose pixels depend on `seed`.
    pub(crate) fn new(dims: &ModelDims, seed: u8) -> Self {
        let n = NUM_CAMERAS * dims.image_bytes();
        let rgb = (0..n)
            .map(|i| (i as u8).wrapping_mul(7).wrapping_add(seed))
            .collect();
        Self {
            rgb,
            dims: dims.clone(),
        }
    }

    /// A valid frame over these images.
    pub(crate) fn frame(&self, sequence: u64) -> Frame<'_> {
        let len = self.dims.image_bytes();
        let images = core::array::from_fn(|c| {
            Some(CameraImage {
                width_px: self.dims.image_w as u32,
                height_px: self.dims.image_h as u32,
                rgb: &self.rgb[c * len..(c + 1) * len],
                capture_us: 1_000_000 + sequence * 100_000,
                valid: true,
            })
        });
        Frame {
            sequence,
            timestamp_us: 1_000_000 + sequence * 100_000,
            pose: EgoPose::new(DVec2::new(10.0, 20.0), 0.3 + sequence as f64 * 0.01),
            motion: EgoMotion {
                acceleration_mps2: Vec3::new(0.1, 0.2, 0.0),
                rotation_rate_radps: Vec3::new(0.0, 0.0, 0.05),
                velocity_mps: Vec3::new(0.0, 8.0 + sequence as f32 * 0.1, 0.0),
            },
            images,
        }
    }
}

/// A satellite crop of the test size.
pub(crate) fn crop(dims: &ModelDims) -> Vec<u8> {
    let mut v = vec![0u8; dims.crop_bytes()];
    for (i, b) in v.iter_mut().enumerate() {
        *b = (i % 251) as u8;
    }
    v
}

std::thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

/// System allocator that counts allocations made on the current thread while counting is on.
pub(crate) struct CountingAlloc;

// SAFETY: forwards to the system allocator unchanged; the counters are thread-local `Cell`s with
// const initialisers (no allocation, no destructor).
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

fn note_allocation() {
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        }
    });
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// Run `f` and return how many allocations it made on this thread.
pub(crate) fn count_allocations<R>(f: impl FnOnce() -> R) -> (R, usize) {
    ALLOCATIONS.with(|n| n.set(0));
    COUNTING.with(|on| on.set(true));
    let r = f();
    COUNTING.with(|on| on.set(false));
    (r, ALLOCATIONS.with(Cell::get))
}

/// Move `frame` to `timestamp_us` with its cameras (captured at the same instant, so none is
/// stale).
pub(crate) fn retime(frame: &mut Frame<'_>, timestamp_us: u64) {
    frame.timestamp_us = timestamp_us;
    for image in frame.images.iter_mut().flatten() {
        image.capture_us = timestamp_us;
    }
}

/// A runtime over a [`FakeEngine`] of the `test` dims, the nuScenes-like rig and a fixed
/// satellite crop: what the step tests drive.
pub fn fake_runtime(
    crop: &[u8],
) -> crate::step::SatMap<FakeEngine, crate::satellite::FixedCrop<'_>> {
    crate::step::SatMap::new(
        FakeEngine::new(crate::model_dims::ModelDims::test_config()),
        &nuscenes_like(),
        crate::satellite::FixedCrop(crop),
    )
    .unwrap()
}
