//! The `#[repr(C)]` types and constants of the header.

use satmap_runtime::StepSlice;
use satmap_runtime::calibration::NUM_CAMERAS;
use satmap_runtime::map_frame::wire::{DEFAULT_DATA_ID, MAX_WIRE_BYTES};
use satmap_runtime::placement::{REGION_ALIGN, REGIONS};

/// Cameras in the rig (model order: front, front right, front left, back, back left, back right).
pub const SATMAP_NUM_CAMERAS: usize = 6;
/// Caller regions `satmap_create` takes (ids `0..SATMAP_REGION_COUNT`).
pub const SATMAP_REGION_COUNT: usize = 10;
/// Alignment every caller region must have, bytes.
pub const SATMAP_REGION_ALIGN: usize = 16;
/// Largest serialised map frame, bytes.
pub const SATMAP_MAX_WIRE_BYTES: usize = 8444;
/// The map message's default E2E data id ("SMAP").
pub const SATMAP_DEFAULT_DATA_ID: u32 = 0x534D_4150;

// The header's literals are the runtime's values.
const _: () = assert!(SATMAP_NUM_CAMERAS == NUM_CAMERAS);
const _: () = assert!(SATMAP_REGION_COUNT == REGIONS.len());
const _: () = assert!(SATMAP_REGION_ALIGN == REGION_ALIGN);
const _: () = assert!(SATMAP_MAX_WIRE_BYTES == MAX_WIRE_BYTES);
const _: () = assert!(SATMAP_DEFAULT_DATA_ID == DEFAULT_DATA_ID);

/// `SatmapBundleTrust::kind`: any bundle whose own hashes agree (development only).
pub const SATMAP_TRUST_SELF_CONSISTENT: u32 = 0;
/// `SatmapBundleTrust::kind`: only the bundle whose digest is `pinned_sha256`.
pub const SATMAP_TRUST_PINNED: u32 = 1;
/// `SatmapBundleTrust::kind`: any bundle signed by the secret half of `public_key`.
pub const SATMAP_TRUST_SIGNED: u32 = 2;

/// Which bundles `satmap_create_trusted` accepts.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SatmapBundleTrust {
    /// `SATMAP_TRUST_SELF_CONSISTENT`, `SATMAP_TRUST_PINNED` or `SATMAP_TRUST_SIGNED`.
    pub kind: u32,
    /// The pinned bundle digest (SHA-256, raw bytes; `satmap-sim check-bundle` prints it in
    /// hex); read for `SATMAP_TRUST_PINNED`.
    pub pinned_sha256: [u8; 32],
    /// The Ed25519 public key (raw bytes; `keygen`'s `.pub` file holds them in hex); read for
    /// `SATMAP_TRUST_SIGNED`.
    pub public_key: [u8; 32],
}

/// One caller-owned memory region.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SatmapRegion {
    /// Start; `SATMAP_REGION_ALIGN`-aligned, valid and untouched until `satmap_destroy`.
    pub data: *mut u8,
    /// Bytes available (at least the region's `bytes` from `satmap_region_info`).
    pub len: usize,
}

/// A region's name and size, from `memory_layout.toml`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SatmapRegionInfo {
    /// NUL-terminated name, static storage.
    pub name: *const core::ffi::c_char,
    /// Bytes the caller must provide.
    pub bytes: usize,
    /// Alignment, bytes.
    pub align: usize,
}

/// One camera's image for a step.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SatmapCameraImage {
    /// u8 RGB, row-major HWC, `height_px * width_px * 3` bytes; NULL when the camera delivered
    /// nothing (it is then left out of the step).
    pub rgb: *const u8,
    /// Bytes at `rgb`.
    pub len: usize,
    /// Width, pixels.
    pub width_px: u32,
    /// Height, pixels.
    pub height_px: u32,
    /// Capture time, µs, on the frame's clock (older than the stale limit: left out).
    pub capture_us: u64,
    /// Nonzero when the camera vouches for the image; 0 leaves it out.
    pub valid: u8,
}

/// The input of one step. Pointers must stay valid for the call (`satmap_step`) or until
/// `satmap_step_finish` / `satmap_step_abort` (staged step).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SatmapFrame {
    /// Strictly increasing counter.
    pub sequence: u64,
    /// Capture time, µs, strictly increasing.
    pub timestamp_us: u64,
    /// Ego position in the route frame, metres (x east, y north).
    pub position_m: [f64; 2],
    /// Ego yaw in the route frame, radians.
    pub yaw_rad: f64,
    /// Ego acceleration (ego frame: x right, y forward, z up), m/s^2.
    pub acceleration_mps2: [f32; 3],
    /// Ego rotation rate (ego frame), rad/s.
    pub rotation_rate_radps: [f32; 3],
    /// Ego velocity (ego frame), m/s.
    pub velocity_mps: [f32; 3],
    /// One image per camera, model order.
    pub cameras: [SatmapCameraImage; SATMAP_NUM_CAMERAS],
    /// Ego-centred satellite crop, u8 RGB `[sat_h, sat_w, 3]`; NULL when there is none (the
    /// step then runs degraded, camera only).
    pub satellite_rgb: *const u8,
    /// Bytes at `satellite_rgb` (a wrong length is treated as a corrupt prior).
    pub satellite_len: usize,
}

/// A slice of a staged step (`satmap_step_run_next`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SatmapSlice {
    /// CAN-bus vector and `bev_query`.
    BevQuery = 0,
    /// `image_encoder` of camera 0 (cameras 1..5 follow as 2..6).
    ImageEncoder0 = 1,
    /// `image_encoder` of camera 1.
    ImageEncoder1 = 2,
    /// `image_encoder` of camera 2.
    ImageEncoder2 = 3,
    /// `image_encoder` of camera 3.
    ImageEncoder3 = 4,
    /// `image_encoder` of camera 4.
    ImageEncoder4 = 5,
    /// `image_encoder` of camera 5.
    ImageEncoder5 = 6,
    /// The native GKT gather-sum.
    GktGather = 7,
    /// `bev_encoder`.
    BevEncoder = 8,
    /// Satellite crop and `satellite_encoder`.
    Satellite = 9,
    /// `map_decoder` and the output checks.
    MapDecoder = 10,
}

impl From<StepSlice> for SatmapSlice {
    fn from(s: StepSlice) -> Self {
        match s.id() {
            0 => Self::BevQuery,
            1 => Self::ImageEncoder0,
            2 => Self::ImageEncoder1,
            3 => Self::ImageEncoder2,
            4 => Self::ImageEncoder3,
            5 => Self::ImageEncoder4,
            6 => Self::ImageEncoder5,
            7 => Self::GktGather,
            8 => Self::BevEncoder,
            9 => Self::Satellite,
            _ => Self::MapDecoder,
        }
    }
}

/// What `satmap_step_run_next` ran.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SatmapSliceInfo {
    /// The slice.
    pub slice: SatmapSlice,
    /// Slices still to run before `satmap_step_finish`.
    pub remaining: u8,
}
