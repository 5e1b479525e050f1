//! The published map frame over C: serialised with its E2E protection
//! (`satmap_map_frame`), and the receiver's check of such bytes (`satmap_check_map_frame`).

use satmap_runtime::map_frame::wire;

use crate::runtime::{Liveness, SatmapRuntime, guard};
use crate::status::SatmapStatus;

/// Serialise the last published map frame with its E2E protection (layout in
/// ARCHITECTURE.md, "Protected map frame") into `buf`; `*written` receives its length.
/// `SATMAP_MAX_WIRE_BYTES` always suffices.
///
/// # Safety
/// `rt` from `satmap_create`; `buf` valid for `cap` bytes; `written` valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_map_frame(
    rt: *const SatmapRuntime,
    data_id: u32,
    buf: *mut u8,
    cap: usize,
    written: *mut usize,
) -> SatmapStatus {
    guard(|| {
        // SAFETY: NULL or valid, per the contract.
        let (Some(rt), Some(written)) = (unsafe { rt.as_ref() }, unsafe { written.as_mut() })
        else {
            return SatmapStatus::NullArgument;
        };
        if rt.liveness == Liveness::Dead {
            return SatmapStatus::Panic;
        }
        *written = 0;
        if buf.is_null() {
            return SatmapStatus::NullArgument;
        }
        let Some(map) = rt.map.last_map() else {
            return SatmapStatus::NoMapYet;
        };
        // SAFETY: `cap` writable bytes, per the contract.
        let out = unsafe { core::slice::from_raw_parts_mut(buf, cap) };
        match wire::serialise(map, data_id, out) {
            Ok(n) => {
                *written = n;
                SatmapStatus::Ok
            }
            Err(e) => SatmapStatus::from(&e),
        }
    })
}

/// Check a received serialised map frame (length, CRC-32/AUTOSAR, data id, then every field:
/// element count against the length, reserved bytes, health codes, coverage, classes, scores
/// finite in [0, 1], finite points); on success `*sequence` and `*counter` (each may be NULL)
/// receive the frame's sequence and E2E counter. A frame that passes can be read by its element
/// count without reading past `len`. A `len` above the largest map frame is refused unread.
///
/// # Safety
/// `bytes` valid for `len` bytes; `sequence` and `counter` NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn satmap_check_map_frame(
    bytes: *const u8,
    len: usize,
    data_id: u32,
    sequence: *mut u64,
    counter: *mut u16,
) -> SatmapStatus {
    guard(|| {
        if bytes.is_null() {
            return SatmapStatus::NullArgument;
        }
        // No map frame is longer: refused before a slice is made of a length no buffer has
        // (`SIZE_MAX` would break the slice's own contract).
        if len > wire::MAX_WIRE_BYTES {
            return SatmapStatus::WireInvalid;
        }
        // SAFETY: `len` readable bytes, per the contract, and at most MAX_WIRE_BYTES.
        let frame = unsafe { core::slice::from_raw_parts(bytes, len) };
        match wire::check(frame, data_id) {
            Ok(c) => {
                // SAFETY: NULL or valid, per the contract.
                if let Some(s) = unsafe { sequence.as_mut() } {
                    *s = c.sequence;
                }
                // SAFETY: NULL or valid, per the contract.
                if let Some(n) = unsafe { counter.as_mut() } {
                    *n = c.counter;
                }
                SatmapStatus::Ok
            }
            Err(e) => SatmapStatus::from(&e),
        }
    })
}
