//! The load-time rehearsal that sizes the per-step scratch region before the first step.
//!
//! Every tensor shape of a checked bundle is static (the graph check refuses symbolic ones), so
//! what a step allocates inside the graph engine does not depend on the frame's values: one run
//! of every stage, in the step's order, on zero inputs, allocates exactly what a real step does.
//! The rehearsal runs the stages on the arena first (the engine's lasting per-thread caches
//! settle there, counted as the graph engine's), then once inside the step scratch, whose peak
//! it measures.
//! A scratch too small for that run stops the process at load with the region named (the
//! allocator's exhaustion report, exit 3); a block the engine keeps after a stage ends is found
//! here, not at step 1000.

use satmap_runtime::calibration::NUM_CAMERAS;
use satmap_runtime::capacity::CAN_BUS_LEN;
use satmap_runtime::engine::{Engine, EngineError};
use satmap_runtime::features::{FeaturesMut, FeaturesRef};

use super::HarnessError;
use crate::arena::{ArenaAllocator, ArenaRegion};

/// Warm runs in a row that must leave the arena's use unchanged before the measured run.
const SETTLED_RUNS: usize = 2;
/// Most warm runs.
const MAX_WARM_RUNS: usize = 12;

/// What the rehearsal measured in the step scratch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Rehearsal {
    /// Peak bytes of the step scratch during one rehearsed step (the size a step needs).
    pub step_scratch_peak_bytes: usize,
    /// Allocations the rehearsed step made (all in the step scratch).
    pub allocations: usize,
}

/// One step's engine calls on zero inputs, in `SatMap::step`'s order.
fn run_stages<E: Engine>(engine: &mut E, b: &mut Buffers) -> Result<(), EngineError> {
    engine.bev_query(&[0.0; CAN_BUS_LEN], &mut b.query, &mut b.weights)?;
    for camera in 0..NUM_CAMERAS {
        engine.encode_image(camera, &b.image, &mut b.value)?;
    }
    engine.bev_encode(&b.query, &b.gathered, FeaturesMut::F32(&mut b.camera_bev))?;
    engine.encode_satellite(&b.crop, FeaturesMut::F32(&mut b.satellite_bev))?;
    engine.decode_map(
        FeaturesRef::F32(&b.camera_bev),
        FeaturesRef::F32(&b.satellite_bev),
        &mut b.logits,
        &mut b.points,
    )
}

/// Host-side inputs and outputs of the rehearsal (the runtime's regions are not reserved yet).
struct Buffers {
    image: Vec<u8>,
    value: Vec<f32>,
    query: Vec<f32>,
    weights: Vec<f32>,
    gathered: Vec<f32>,
    camera_bev: Vec<f32>,
    crop: Vec<u8>,
    satellite_bev: Vec<f32>,
    logits: Vec<f32>,
    points: Vec<f32>,
}

/// Run every stage until [`SETTLED_RUNS`] runs in a row leave the arena's use unchanged (at
/// most [`MAX_WARM_RUNS`]).
fn warm_up<E: Engine>(
    engine: &mut E,
    b: &mut Buffers,
    alloc: &ArenaAllocator,
) -> Result<(), EngineError> {
    let mut settled = 0;
    for _ in 0..MAX_WARM_RUNS {
        let before = alloc.stats().current_bytes;
        run_stages(engine, b)?;
        settled = if alloc.stats().current_bytes == before {
            settled + 1
        } else {
            0
        };
        if settled == SETTLED_RUNS {
            break;
        }
    }
    Ok(())
}

/// Rehearse one step of `engine` and measure it in the step scratch; with no step scratch (the
/// allocator not given one) the rehearsal only warms the engine and measures nothing.
///
/// # Errors
/// A stage refused the zero inputs ([`HarnessError::Rehearsal`]), or blocks allocated in the
/// rehearsed step outlived it ([`HarnessError::StepScratchNotEmpty`]).
pub fn rehearse<E: Engine>(
    engine: &mut E,
    alloc: &'static ArenaAllocator,
) -> Result<Rehearsal, HarnessError> {
    let d = engine.dims().clone();
    let mut b = alloc.host_side(|| Buffers {
        image: vec![0; d.image_bytes()],
        value: vec![0.0; d.value_len()],
        query: vec![0.0; d.bev_len()],
        weights: vec![0.0; d.weights_len()],
        gathered: vec![0.0; d.bev_len()],
        camera_bev: vec![0.0; d.bev_len()],
        crop: vec![0; d.crop_bytes()],
        satellite_bev: vec![0.0; d.bev_len()],
        logits: vec![0.0; d.logits_len()],
        points: vec![0.0; d.points_len()],
    });
    let previous = alloc.region();
    alloc.set_region(ArenaRegion::GraphEngine);
    // With several engine threads, which worker runs which tile varies from run to run, and a
    // worker grows its lasting per-thread buffers the first time it meets a larger product:
    // warm runs until the lasting buffers stop growing.
    let warm = warm_up(engine, &mut b, alloc);
    alloc.set_region(ArenaRegion::Step);
    let before = alloc.stats().step_scratch;
    alloc.reset_step_scratch_peak();
    let rehearsed = warm.and_then(|()| run_stages(engine, &mut b));
    let after = alloc.stats().step_scratch;
    alloc.set_region(previous);
    // `dealloc` routes the host-side blocks back by address.
    drop(b);
    rehearsed.map_err(HarnessError::Rehearsal)?;
    if after.current_bytes != before.current_bytes {
        return Err(HarnessError::StepScratchNotEmpty {
            when: "after the load-time rehearsal",
            live_blocks: after.live_blocks,
            live_bytes: after.current_bytes,
        });
    }
    Ok(Rehearsal {
        step_scratch_peak_bytes: after.peak_bytes - before.current_bytes,
        allocations: after.allocations - before.allocations,
    })
}
