//! The runtime handle and the C functions over it.
//!
//! Every function body runs inside `catch_unwind`: nothing unwinds into C. Pointers are checked
//! for NULL; their validity, lengths and lifetimes are the caller's side of the contract in
//! `satmap.h`.

use core::ffi::c_char;
use std::fmt::Write as _;
use std::panic::{AssertUnwindSafe, catch_unwind};

use satmap_runtime::calibration::from_toml_file;
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::glam::{DVec2, Vec3};
use satmap_runtime::satellite::{Coverage, CropSpec, SatelliteSource};
use satmap_runtime::{CameraImage, EgoMotion, EgoPose, Frame, SatMap};

use crate::create::path_of;
use crate::ffi_types::{SATMAP_NUM_CAMERAS, SatmapFrame};
use crate::status::SatmapStatus;

/// The satellite crop the caller hands in with each frame.
pub(crate) struct CallerCrop {
    pub(crate) rgb: *const u8,
    pub(crate) len: usize,
}

impl SatelliteSource for CallerCrop {
    fn crop(&mut self, _pose: &EgoPose, _spec: &CropSpec, out: &mut [u8]) -> Coverage {
        if self.rgb.is_null() {
            out.fill(0);
            return Coverage::None;
        }
        if self.len != out.len() {
            out.fill(0);
            return Coverage::Corrupt;
        }
        // SAFETY: the caller guarantees `len` readable bytes at `rgb` until the step ends.
        out.copy_from_slice(unsafe { core::slice::from_raw_parts(self.rgb, self.len) });
        Coverage::Full
    }
}

/// An opaque runtime: created by `satmap_create`, freed by `satmap_destroy`.
pub struct SatmapRuntime {
    pub(crate) map: SatMap<TractEngine, CallerCrop>,
    pub(crate) message: heapless::String<256>,
    pub(crate) liveness: Liveness,
}

/// Whether a handle may still be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Liveness {
    /// Every call is served.
    Usable,
    /// A call panicked inside the runtime (a bug, never bad input: tract's panics are caught
    /// and named by the engine). What the unwound call left half done is unknown, so nothing
    /// is served any more: every call but `satmap_last_error` and `satmap_destroy` answers
    /// `SATMAP_STATUS_PANIC`, `satmap_reset` included.
    Dead,
}

/// The message a dead handle keeps.
const DEAD_MESSAGE: &str = "a call panicked inside the runtime (a bug): this handle is dead; \
                            satmap_destroy it and satmap_create another";

impl SatmapRuntime {
    pub(crate) fn fail(
        &mut self,
        status: SatmapStatus,
        what: &dyn core::fmt::Display,
    ) -> SatmapStatus {
        self.message.clear();
        // A message longer than the buffer is cut, never an error.
        let _ = write!(self.message, "{what}");
        status
    }
}

/// Run `f`, turning a panic into [`SatmapStatus::Panic`].
pub(crate) fn guard(f: impl FnOnce() -> SatmapStatus) -> SatmapStatus {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or(SatmapStatus::Panic)
}

/// The Rust frame a C frame describes.
///
/// # Safety
/// Every non-NULL pointer of `f` is valid for its stated length for `'a`.
unsafe fn frame_of<'a>(f: &'a SatmapFrame) -> Frame<'a> {
    let images = core::array::from_fn::<_, SATMAP_NUM_CAMERAS, _>(|c| {
        let cam = &f.cameras[c];
        (!cam.rgb.is_null()).then(|| CameraImage {
            width_px: cam.width_px,
            height_px: cam.height_px,
            // SAFETY: per this function's contract.
            rgb: unsafe { core::slice::from_raw_parts(cam.rgb, cam.len) },
            capture_us: cam.capture_us,
            valid: cam.valid != 0,
        })
    });
    Frame {
        sequence: f.sequence,
        timestamp_us: f.timestamp_us,
        pose: EgoPose::new(DVec2::from_array(f.position_m), f.yaw_rad),
        motion: EgoMotion {
            acceleration_mps2: Vec3::from_array(f.acceleration_mps2),
            rotation_rate_radps: Vec3::from_array(f.rotation_rate_radps),
            velocity_mps: Vec3::from_array(f.velocity_mps),
        },
        images,
    }
}

/// Run `f` on the live runtime behind `rt`: NULL is `NullArgument`, a dead handle `Panic`; a
/// panic inside `f` is `Panic` and leaves the handle dead ([`Liveness::Dead`]).
pub(crate) fn with_runtime(
    rt: *mut SatmapRuntime,
    f: impl FnOnce(&mut SatmapRuntime) -> SatmapStatus,
) -> SatmapStatus {
    // SAFETY: NULL or from satmap_create, per the contract.
    let Some(handle) = (unsafe { rt.as_mut() }) else {
        return SatmapStatus::NullArgument;
    };
    if handle.liveness == Liveness::Dead {
        return SatmapStatus::Panic;
    }
    let status = guard(|| f(handle));
    if status == SatmapStatus::Panic {
        // SAFETY: the same valid pointer; the closure's borrow ended with the unwind.
        if let Some(handle) = unsafe { rt.as_mut() } {
            handle.liveness = Liveness::Dead;
            handle.fail(SatmapStatus::Panic, &DEAD_MESSAGE);
        }
    }
    status
}

/// Run `f` on the runtime and frame behind the pointers ([`with_runtime`]).
pub(crate) fn with_frame(
    rt: *mut SatmapRuntime,
    frame: *const SatmapFrame,
    f: impl FnOnce(&mut SatmapRuntime, &Frame<'_>) -> SatmapStatus,
) -> SatmapStatus {
    with_runtime(rt, |rt| {
        // SAFETY: NULL or a valid frame, per the contract.
        let Some(frame) = (unsafe { frame.as_ref() }) else {
            return SatmapStatus::NullArgument;
        };
        // SAFETY: the frame's pointers are valid for this call, per the contract.
        let rust_frame = unsafe { frame_of(frame) };
        *rt.map.satellite_mut() = CallerCrop {
            rgb: frame.satellite_rgb,
            len: frame.satellite_len,
        };
        f(rt, &rust_frame)
    })
}

/// Rebuild the look-up table for a new calibration file (TOML); the previous one stays in use
/// on failure.
///
/// # Safety
/// `rt` from `satmap_create`; `calibration_toml` NUL-terminated.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_recalibrate(
    rt: *mut SatmapRuntime,
    calibration_toml: *const c_char,
) -> SatmapStatus {
    with_runtime(rt, |rt| {
        let path = match path_of(calibration_toml) {
            Ok(p) => p,
            Err(e) => return e,
        };
        let calibration = match from_toml_file(path) {
            Ok(c) => c,
            Err(e) => return rt.fail(SatmapStatus::Calibration, &e),
        };
        match rt.map.recalibrate(&calibration) {
            Ok(()) => SatmapStatus::Ok,
            Err(e) => rt.fail(SatmapStatus::Calibration, &e),
        }
    })
}

/// Restart the runtime's frame counters and drop a staged step in progress (`SatMap::reset`):
/// the next frame is accepted whatever its sequence and timestamp, and no map is published
/// until it steps. For a genuine restart of the caller's counters, or to leave a state the
/// frame checks refuse. Calibration, bundle and regions are kept. A dead handle (an earlier
/// `SATMAP_STATUS_PANIC`) answers `SATMAP_STATUS_PANIC`: it can only be destroyed.
///
/// # Safety
/// `rt` from `satmap_create`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_reset(rt: *mut SatmapRuntime) -> SatmapStatus {
    with_runtime(rt, |rt| {
        rt.map.reset();
        SatmapStatus::Ok
    })
}

/// Copy the message of the runtime's last failed call into `buf` (NUL-terminated, cut to
/// `cap`); returns the message length without the NUL.
///
/// # Safety
/// `rt` from `satmap_create`; `buf` NULL or valid for `cap` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_last_error(
    rt: *const SatmapRuntime,
    buf: *mut c_char,
    cap: usize,
) -> usize {
    catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: NULL or from satmap_create.
        let Some(rt) = (unsafe { rt.as_ref() }) else {
            return 0;
        };
        let msg = rt.message.as_bytes();
        if !buf.is_null() && cap > 0 {
            let n = msg.len().min(cap - 1);
            // SAFETY: `cap` writable bytes, per the contract; n + 1 <= cap.
            unsafe {
                core::ptr::copy_nonoverlapping(msg.as_ptr(), buf.cast::<u8>(), n);
                *buf.add(n) = 0;
            }
        }
        msg.len()
    }))
    .unwrap_or(0)
}

/// The family of graph kernels this CPU runs (`intel-avx512f`, `amd-fma`, `aarch64-neon`, ...),
/// as a static NUL-terminated string. Map digests are bit-identical within a family, not across
/// families, so digests recorded on one ECU are compared with runs of the same family
/// (`examples/c/expected-<family>.txt`). Never NULL; the string lives as long as the program.
#[unsafe(no_mangle)]
pub extern "C" fn satmap_kernel_family() -> *const c_char {
    catch_unwind(satmap_runtime::engine_tract::KernelFamily::detect)
        .unwrap_or(satmap_runtime::engine_tract::KernelFamily::Generic)
        .c_name()
        .as_ptr()
}
