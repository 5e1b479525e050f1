//! Creating and destroying a runtime: the caller's regions checked (count, NULL, overlap), the
//! bundle opened under the caller's trust, the calibration read, the look-up table built.

use core::ffi::{CStr, c_char};
use std::path::Path;

use satmap_runtime::SatMap;
use satmap_runtime::bundle::{Bundle, BundlePublicKey, Sha256Digest, Trust};
use satmap_runtime::calibration::from_toml_file;
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::frame::FrameLimits;
use satmap_runtime::placement::{REGION_ALIGN, REGIONS, RuntimeRegions};

use crate::ffi_types::{
    SATMAP_REGION_COUNT, SATMAP_TRUST_PINNED, SATMAP_TRUST_SELF_CONSISTENT, SATMAP_TRUST_SIGNED,
    SatmapBundleTrust, SatmapRegion, SatmapRegionInfo,
};
use crate::runtime::{CallerCrop, Liveness, SatmapRuntime, guard};
use crate::status::SatmapStatus;

/// Region names with their NUL, in [`REGIONS`] order.
const REGION_NAMES: [&CStr; SATMAP_REGION_COUNT] = [
    c"value_features",
    c"gkt_lut",
    c"bev_query",
    c"gkt_weights",
    c"gathered",
    c"camera_bev",
    c"satellite_crop",
    c"satellite_bev",
    c"class_logits",
    c"points",
];

/// Name, size and alignment of caller region `id` (`0..SATMAP_REGION_COUNT`).
///
/// # Safety
/// `info` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_region_info(
    id: usize,
    info: *mut SatmapRegionInfo,
) -> SatmapStatus {
    guard(|| {
        // SAFETY: NULL or valid, per the contract.
        let Some(info) = (unsafe { info.as_mut() }) else {
            return SatmapStatus::NullArgument;
        };
        let (Some(spec), Some(name)) = (REGIONS.get(id), REGION_NAMES.get(id)) else {
            return SatmapStatus::InvalidArgument;
        };
        *info = SatmapRegionInfo {
            name: name.as_ptr(),
            bytes: spec.bytes,
            align: REGION_ALIGN,
        };
        SatmapStatus::Ok
    })
}

/// Whether any two regions share a byte, or one's end wraps past the address space. Empty
/// regions share nothing (they are refused later as too small).
fn regions_overlap(regions: &[SatmapRegion]) -> bool {
    let mut spans = [(0usize, 0usize); SATMAP_REGION_COUNT];
    for (span, r) in spans.iter_mut().zip(regions) {
        let start = r.data as usize;
        let Some(end) = start.checked_add(r.len) else {
            return true;
        };
        *span = (start, end);
    }
    spans.iter().enumerate().any(|(i, &(a0, a1))| {
        spans[i + 1..]
            .iter()
            .any(|&(b0, b1)| a0 < a1 && b0 < b1 && a0 < b1 && b0 < a1)
    })
}

pub(crate) fn path_of<'a>(p: *const c_char) -> Result<&'a Path, SatmapStatus> {
    if p.is_null() {
        return Err(SatmapStatus::NullArgument);
    }
    // SAFETY: non-NULL and NUL-terminated, per the contract.
    let s = unsafe { CStr::from_ptr(p) };
    s.to_str()
        .map(Path::new)
        .map_err(|_| SatmapStatus::InvalidArgument)
}

/// Create a runtime over the caller's regions: load and verify the bundle (a compiled `.satmap`
/// file; a folder of ONNX stages only where the library was built with the host's `onnx`
/// feature), read the calibration (TOML), build the look-up table in `gkt_lut`. `regions` holds
/// `SATMAP_REGION_COUNT` entries in region id order, no two sharing a byte
/// (`SATMAP_STATUS_REGIONS_OVERLAP`); each must stay valid and untouched until
/// `satmap_destroy`. On failure `*out` is NULL and nothing is kept. Accepts any bundle whose own
/// hashes agree (development): an ECU uses [`satmap_create_trusted`].
///
/// # Safety
/// `regions` points to `region_count` entries whose memory is valid as stated; the paths are
/// NUL-terminated; `out` is valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_create(
    regions: *const SatmapRegion,
    region_count: usize,
    bundle_path: *const c_char,
    calibration_toml: *const c_char,
    out: *mut *mut SatmapRuntime,
) -> SatmapStatus {
    // SAFETY: the same contract.
    unsafe {
        create(
            regions,
            region_count,
            bundle_path,
            calibration_toml,
            Ok(Trust::SelfConsistent),
            out,
        )
    }
}

/// [`satmap_create`] accepting only the bundle `trust` allows, decided on the bundle's raw bytes
/// before any of them is parsed: `SATMAP_TRUST_PINNED` accepts the one bundle whose digest is
/// `pinned_sha256` (else `SATMAP_STATUS_BUNDLE_NOT_PINNED`); `SATMAP_TRUST_SIGNED` any bundle
/// whose signature file (`<bundle_path>.sig`: 128 lowercase hex digits, from `satmap-sim
/// sign-bundle`) verifies under the Ed25519 `public_key` (else `SATMAP_STATUS_BUNDLE_UNSIGNED`
/// or `SATMAP_STATUS_BUNDLE_SIGNATURE`). What an ECU should call.
///
/// # Safety
/// As [`satmap_create`]; `trust` is NULL or valid for a read.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_create_trusted(
    regions: *const SatmapRegion,
    region_count: usize,
    bundle_path: *const c_char,
    calibration_toml: *const c_char,
    trust: *const SatmapBundleTrust,
    out: *mut *mut SatmapRuntime,
) -> SatmapStatus {
    // SAFETY: NULL or valid, per the contract.
    let trust = match unsafe { trust.as_ref() } {
        None => Err(SatmapStatus::NullArgument),
        Some(t) => trust_of(t),
    };
    // SAFETY: the same contract.
    unsafe {
        create(
            regions,
            region_count,
            bundle_path,
            calibration_toml,
            trust,
            out,
        )
    }
}

/// The Rust trust a C one describes; an unknown kind or a public key that is no curve point
/// is `SATMAP_STATUS_INVALID_ARGUMENT`.
fn trust_of(t: &SatmapBundleTrust) -> Result<Trust, SatmapStatus> {
    match t.kind {
        SATMAP_TRUST_SELF_CONSISTENT => Ok(Trust::SelfConsistent),
        SATMAP_TRUST_PINNED => Ok(Trust::Pinned(Sha256Digest::from_bytes(t.pinned_sha256))),
        SATMAP_TRUST_SIGNED => BundlePublicKey::from_bytes(&t.public_key)
            .map(Trust::Signed)
            .map_err(|_| SatmapStatus::InvalidArgument),
        _ => Err(SatmapStatus::InvalidArgument),
    }
}

/// Both create functions; `trust` is the caller's, already read (its error is returned once
/// `out` is cleared).
///
/// # Safety
/// As [`satmap_create`].
unsafe fn create(
    regions: *const SatmapRegion,
    region_count: usize,
    bundle_path: *const c_char,
    calibration_toml: *const c_char,
    trust: Result<Trust, SatmapStatus>,
    out: *mut *mut SatmapRuntime,
) -> SatmapStatus {
    guard(|| {
        // SAFETY: NULL or valid, per the contract.
        let Some(out) = (unsafe { out.as_mut() }) else {
            return SatmapStatus::NullArgument;
        };
        *out = core::ptr::null_mut();
        let trust = match trust {
            Ok(t) => t,
            Err(status) => return status,
        };
        if regions.is_null() {
            return SatmapStatus::NullArgument;
        }
        if region_count != SATMAP_REGION_COUNT {
            return SatmapStatus::InvalidArgument;
        }
        // SAFETY: `region_count` entries, per the contract.
        let given = unsafe { core::slice::from_raw_parts(regions, region_count) };
        if given.iter().any(|r| r.data.is_null()) {
            return SatmapStatus::NullArgument;
        }
        // Before any slice is made of them: two overlapping regions would be two `&mut` to the
        // same bytes (the runtime then computed a wrong map, or panicked, on every step).
        if regions_overlap(given) {
            return SatmapStatus::RegionsOverlap;
        }
        let (bundle, calibration) = match (path_of(bundle_path), path_of(calibration_toml)) {
            (Ok(b), Ok(c)) => (b, c),
            (Err(e), _) | (_, Err(e)) => return e,
        };
        // SAFETY: each region is valid, unaliased and outlives the runtime (the contract:
        // untouched until satmap_destroy), which is what `'static` stands for here.
        let region =
            |i: usize| unsafe { core::slice::from_raw_parts_mut(given[i].data, given[i].len) };
        let placed = RuntimeRegions {
            value_features: region(0),
            gkt_lut: region(1),
            bev_query: region(2),
            gkt_weights: region(3),
            gathered: region(4),
            camera_bev: region(5),
            satellite_crop: region(6),
            satellite_bev: region(7),
            class_logits: region(8),
            points: region(9),
        };
        let Ok(calibration) = from_toml_file(calibration) else {
            return SatmapStatus::Calibration;
        };
        let engine = match Bundle::open_trusted(bundle, &trust) {
            Ok(b) => TractEngine::load(&b),
            Err(e) => Err(e),
        };
        let engine = match engine {
            Ok(engine) => engine,
            Err(e) => return SatmapStatus::from(&e),
        };
        let satellite = CallerCrop {
            rgb: core::ptr::null(),
            len: 0,
        };
        match SatMap::in_regions(
            engine,
            &calibration,
            satellite,
            FrameLimits::DEFAULT,
            placed,
        ) {
            Ok(map) => {
                *out = Box::into_raw(Box::new(SatmapRuntime {
                    map,
                    message: heapless::String::new(),
                    liveness: Liveness::Usable,
                }));
                SatmapStatus::Ok
            }
            Err(e) => SatmapStatus::from(&e),
        }
    })
}

/// Free a runtime (NULL is ignored); its regions belong to the caller again.
///
/// # Safety
/// `rt` is NULL or from `satmap_create`, and not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_destroy(rt: *mut SatmapRuntime) {
    let _ = guard(|| {
        if !rt.is_null() {
            // SAFETY: from Box::into_raw in satmap_create, freed once.
            drop(unsafe { Box::from_raw(rt) });
        }
        SatmapStatus::Ok
    });
}
