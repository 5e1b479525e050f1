//! The step functions over a runtime handle: one whole step, or the staged step slice by slice
//! (`satmap_step_begin`, `satmap_step_run_next`, `satmap_step_finish`, `satmap_step_abort`).

use crate::ffi_types::{SatmapFrame, SatmapSliceInfo};
use crate::runtime::{SatmapRuntime, with_frame, with_runtime};
use crate::status::SatmapStatus;

/// Run one whole step on `frame`.
///
/// # Safety
/// `rt` from `satmap_create`; `frame` and its pointers valid for the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_step(
    rt: *mut SatmapRuntime,
    frame: *const SatmapFrame,
) -> SatmapStatus {
    with_frame(rt, frame, |rt, f| match rt.map.step(f) {
        Ok(_) => SatmapStatus::Ok,
        Err(e) => rt.fail(SatmapStatus::from(&e), &e),
    })
}

/// Start a staged step: check `frame`, run nothing. The frame and its pointers must stay valid
/// until `satmap_step_finish` or `satmap_step_abort`.
///
/// # Safety
/// As [`satmap_step`], with the longer lifetime.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_step_begin(
    rt: *mut SatmapRuntime,
    frame: *const SatmapFrame,
) -> SatmapStatus {
    with_frame(rt, frame, |rt, f| match rt.map.step_begin(f) {
        Ok(()) => SatmapStatus::Ok,
        Err(e) => rt.fail(SatmapStatus::from(&e), &e),
    })
}

/// Run the next slice of the staged step; `frame` is the one given to `satmap_step_begin`.
/// `info` (may be NULL) receives the slice and how many remain.
///
/// # Safety
/// As [`satmap_step_begin`]; `info` NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_step_run_next(
    rt: *mut SatmapRuntime,
    frame: *const SatmapFrame,
    info: *mut SatmapSliceInfo,
) -> SatmapStatus {
    with_frame(rt, frame, |rt, f| match rt.map.step_run_next(f) {
        Ok(done) => {
            // SAFETY: NULL or valid, per the contract.
            if let Some(info) = unsafe { info.as_mut() } {
                *info = SatmapSliceInfo {
                    slice: done.slice.into(),
                    remaining: done.remaining,
                };
            }
            SatmapStatus::Ok
        }
        Err(e) => rt.fail(SatmapStatus::from(&e), &e),
    })
}

/// Publish the staged step's map.
///
/// # Safety
/// `rt` from `satmap_create`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_step_finish(rt: *mut SatmapRuntime) -> SatmapStatus {
    with_runtime(rt, |rt| match rt.map.step_finish() {
        Ok(_) => SatmapStatus::Ok,
        Err(e) => rt.fail(SatmapStatus::from(&e), &e),
    })
}

/// Drop the staged step in progress, if any.
///
/// # Safety
/// `rt` from `satmap_create`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_step_abort(rt: *mut SatmapRuntime) -> SatmapStatus {
    with_runtime(rt, |rt| {
        rt.map.step_abort();
        SatmapStatus::Ok
    })
}
