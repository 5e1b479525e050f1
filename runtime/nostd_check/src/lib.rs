//! no_std canary: links the satmap-runtime core (look-up table, gather-sum kernel, CAN-bus
//! vector, decode, digest) into a `staticlib` with its own `#[panic_handler]` and a TLSF global
//! allocator over a static array, the way an ECU image would. If any dependency pulls std in, the
//! build fails with a duplicate `panic_impl` lang item.
//!
//! Build (stable, no nightly): `cargo rustc -p satmap-nostd-check -- -C panic=abort`.
//! Plain `cargo build -p satmap-nostd-check` fails on this host (x86_64 Linux, rustc 1.95) with
//! "unwinding panics are not supported without std": the workspace's dev profile is
//! `panic = "unwind"` and a no_std artifact has no unwinder. `-C panic=abort` on this final crate
//! alone is enough (dependencies stay as built; a staticlib is not linked by rustc, so core's
//! unwind tables are never resolved). A `panic = "abort"` dev profile would also work but would
//! rebuild every host crate of the workspace with another panic strategy. Build it on its own:
//! in a workspace-wide build cargo unifies features with the host crates and std gets linked in.
//! Checked: `nm -C target/debug/libsatmap_nostd_check.a | grep ' std::'` finds nothing.
#![no_std]

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, Ordering};

use embedded_alloc::TlsfHeap;
use satmap_runtime::calibration::{CameraCalibration, NUM_CAMERAS};
use satmap_runtime::can_bus::can_bus;
use satmap_runtime::decode::decode;
use satmap_runtime::gkt::{Lut, gather_sum};
use satmap_runtime::glam::{DQuat, DVec2, DVec3};
use satmap_runtime::map_frame::{MapElement, digest};
use satmap_runtime::{Calibration, EgoMotion, EgoPose, ModelDims};

extern crate alloc;

/// Heap for the check: the test-config look-up table (~2.3 MB at its worst-case capacity) and
/// the kernel's buffers.
const HEAP_BYTES: usize = 4 << 20;

#[global_allocator]
static HEAP: TlsfHeap = TlsfHeap::empty();

static HEAP_READY: AtomicBool = AtomicBool::new(false);

/// Single-core critical section: this canary runs on one thread and takes no interrupts.
struct SingleCore;
critical_section::set_impl!(SingleCore);

// SAFETY: the canary is single-threaded and interrupt-free, so there is nothing to exclude.
unsafe impl critical_section::Impl for SingleCore {
    unsafe fn acquire() -> critical_section::RawRestoreState {}
    unsafe fn release(_restore: critical_section::RawRestoreState) {}
}

#[panic_handler]
fn panic(_info: &PanicInfo<'_>) -> ! {
    loop {
        core::hint::spin_loop();
    }
}

/// A camera at the ego origin, 1.5 m up, looking along ego heading `yaw_rad` (level).
const fn camera(w: f64, x: f64, y: f64, z: f64) -> CameraCalibration {
    CameraCalibration {
        fx_px: 1260.0,
        fy_px: 1260.0,
        cx_px: 800.0,
        cy_px: 450.0,
        translation_m: DVec3::new(0.0, 0.0, 1.5),
        rotation: DQuat::from_xyzw(x, y, z, w),
    }
}

/// A compile-time rig: front (as `nuscenes_like.toml`) and back cameras, the others repeat them.
const RIG: Calibration = {
    let front = camera(0.707106781186547_5, -0.707106781186547_5, 0.0, 0.0);
    let back = camera(0.0, 0.0, -0.707106781186547_5, 0.707106781186547_5);
    let cameras: [CameraCalibration; NUM_CAMERAS] = [front, front, front, back, back, back];
    Calibration {
        raw_width_px: 1600,
        raw_height_px: 900,
        cameras,
    }
};

/// Build the test-config look-up table from [`RIG`], run the gather-sum and decode on fixed
/// inputs and return the map digest (0 on any error). Called once by the host to prove the core
/// links and runs without std.
#[unsafe(no_mangle)]
pub extern "C" fn satmap_nostd_check() -> u64 {
    if !HEAP_READY.swap(true, Ordering::AcqRel) {
        // SAFETY: runs once (guarded by HEAP_READY), before any allocation.
        unsafe {
            embedded_alloc::init!(HEAP, HEAP_BYTES);
        }
    }
    let dims = ModelDims::test_config();
    if dims.validate().is_err() {
        return 0;
    }
    let Ok(lut) = Lut::new(&dims, &RIG) else {
        return 0;
    };
    let values = alloc::vec![0.25f32; NUM_CAMERAS * dims.value_len()];
    let weights = alloc::vec![1.0f32 / 15.0; dims.weights_len()];
    let mut gathered = alloc::vec![0.0f32; dims.bev_len()];
    if gather_sum(&lut, &values, &weights, &mut gathered).is_err() {
        return 0;
    }
    let bus = can_bus(&EgoPose::new(DVec2::ZERO, 0.5), &EgoMotion::default());
    let logits: alloc::vec::Vec<f32> = (0..dims.logits_len())
        .map(|i| gathered[i * 7] + bus[3] * i as f32 * 0.01)
        .collect();
    let points = alloc::vec![0.5f32; dims.points_len()];
    let mut elements: satmap_runtime::heapless::Vec<MapElement, 50> =
        satmap_runtime::heapless::Vec::new();
    decode(&dims, &logits, &points, &mut elements);
    digest(&elements) ^ lut.len() as u64
}
