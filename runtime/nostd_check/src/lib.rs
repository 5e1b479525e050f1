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
use satmap_runtime::route_pack::{TileCodec, decode_tile};
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

/// An 8 x 8 RGB route-pack tile (bytes 0..192) as zlib (Python's `zlib.compress`, level 6).
const ZLIB_TILE_8PX: [u8; 203] = [
    0x78, 0x9c, 0x01, 0xc0, 0x00, 0x3f, 0xff, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08,
    0x09, 0x0a, 0x0b, 0x0c, 0x0d, 0x0e, 0x0f, 0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18,
    0x19, 0x1a, 0x1b, 0x1c, 0x1d, 0x1e, 0x1f, 0x20, 0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28,
    0x29, 0x2a, 0x2b, 0x2c, 0x2d, 0x2e, 0x2f, 0x30, 0x31, 0x32, 0x33, 0x34, 0x35, 0x36, 0x37, 0x38,
    0x39, 0x3a, 0x3b, 0x3c, 0x3d, 0x3e, 0x3f, 0x40, 0x41, 0x42, 0x43, 0x44, 0x45, 0x46, 0x47, 0x48,
    0x49, 0x4a, 0x4b, 0x4c, 0x4d, 0x4e, 0x4f, 0x50, 0x51, 0x52, 0x53, 0x54, 0x55, 0x56, 0x57, 0x58,
    0x59, 0x5a, 0x5b, 0x5c, 0x5d, 0x5e, 0x5f, 0x60, 0x61, 0x62, 0x63, 0x64, 0x65, 0x66, 0x67, 0x68,
    0x69, 0x6a, 0x6b, 0x6c, 0x6d, 0x6e, 0x6f, 0x70, 0x71, 0x72, 0x73, 0x74, 0x75, 0x76, 0x77, 0x78,
    0x79, 0x7a, 0x7b, 0x7c, 0x7d, 0x7e, 0x7f, 0x80, 0x81, 0x82, 0x83, 0x84, 0x85, 0x86, 0x87, 0x88,
    0x89, 0x8a, 0x8b, 0x8c, 0x8d, 0x8e, 0x8f, 0x90, 0x91, 0x92, 0x93, 0x94, 0x95, 0x96, 0x97, 0x98,
    0x99, 0x9a, 0x9b, 0x9c, 0x9d, 0x9e, 0x9f, 0xa0, 0xa1, 0xa2, 0xa3, 0xa4, 0xa5, 0xa6, 0xa7, 0xa8,
    0xa9, 0xaa, 0xab, 0xac, 0xad, 0xae, 0xaf, 0xb0, 0xb1, 0xb2, 0xb3, 0xb4, 0xb5, 0xb6, 0xb7, 0xb8,
    0xb9, 0xba, 0xbb, 0xbc, 0xbd, 0xbe, 0xbf, 0x01, 0xae, 0x47, 0xa1,
];

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
    // The route-pack tile decoders run without std: a zlib tile inflates exactly, and a stream
    // that is not a JPEG is refused by the JPEG decoder.
    let mut tile = [0u8; 8 * 8 * 3];
    if decode_tile(TileCodec::Deflate, &ZLIB_TILE_8PX, 8, &mut tile).is_err()
        || tile.iter().enumerate().any(|(i, &v)| usize::from(v) != i)
        || decode_tile(TileCodec::Jpeg, &ZLIB_TILE_8PX, 8, &mut tile).is_ok()
    {
        return 0;
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
    if gather_sum(
        &lut,
        &values,
        &weights,
        &mut gathered,
        satmap_runtime::CameraMask::ALL,
    )
    .is_err()
    {
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
