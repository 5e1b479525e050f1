//! Caller memory over the C API (issue 38, part 3): a stray write into the `gkt_lut` region
//! fails every step with `SATMAP_STATUS_LUT_CORRUPT` (nothing published) until
//! `satmap_recalibrate` builds the table again, after which the maps are a clean runtime's;
//! `satmap_reset` lets the counters restart.

use std::ffi::CString;

use satmap_capi::{SATMAP_DEFAULT_DATA_ID, SATMAP_MAX_WIRE_BYTES, SatmapRuntime, SatmapStatus};
use satmap_ecu_tests::scenario::{STEPS, sets};
use satmap_runtime::placement::REGIONS;

use crate::c_api::{c_frame, c_regions, create};
use crate::common::root;

/// The last published map frame's bytes.
fn wire(rt: *mut SatmapRuntime) -> Vec<u8> {
    let mut buf = vec![0u8; SATMAP_MAX_WIRE_BYTES];
    let mut written = 0usize;
    // SAFETY: rt from satmap_create; buf and written valid.
    let status = unsafe {
        satmap_capi::satmap_map_frame(
            rt,
            SATMAP_DEFAULT_DATA_ID,
            buf.as_mut_ptr(),
            buf.len(),
            &mut written,
        )
    };
    assert_eq!(status, SatmapStatus::Ok);
    buf.truncate(written);
    buf
}

#[test]
fn a_corrupted_lut_region_fails_every_step_until_recalibrate() {
    let sets = sets();
    let frames: Vec<_> = STEPS.iter().map(|s| c_frame(&sets[s.set], *s)).collect();
    let clean_regions = c_regions();
    let (status, clean) = create(&clean_regions);
    assert_eq!(status, SatmapStatus::Ok);
    let regions = c_regions();
    let (status, rt) = create(&regions);
    assert_eq!(status, SatmapStatus::Ok);
    let lut = regions[REGIONS.iter().position(|r| r.name == "gkt_lut").unwrap()];
    let cal = CString::new(
        root()
            .join("models/calibration/nuscenes_like.toml")
            .to_str()
            .unwrap(),
    )
    .unwrap();
    // SAFETY: runtimes from satmap_create; frames' pointers live across the calls; the byte
    // flipped is inside the caller's own gkt_lut region, as a stray write would be.
    unsafe {
        for rt in [clean, rt] {
            assert_eq!(satmap_capi::satmap_step(rt, &frames[0]), SatmapStatus::Ok);
        }
        *lut.data.add(100) ^= 0x04;
        for _ in 0..2 {
            assert_eq!(
                satmap_capi::satmap_step(rt, &frames[1]),
                SatmapStatus::LutCorrupt
            );
        }
        // The published map is still the last good one.
        assert_eq!(wire(rt), wire(clean));
        assert_eq!(
            satmap_capi::satmap_recalibrate(rt, cal.as_ptr()),
            SatmapStatus::Ok
        );
        for rt in [clean, rt] {
            assert_eq!(satmap_capi::satmap_step(rt, &frames[1]), SatmapStatus::Ok);
        }
        assert_eq!(wire(rt), wire(clean));

        // Counters restart only after satmap_reset.
        assert_eq!(
            satmap_capi::satmap_step(rt, &frames[0]),
            SatmapStatus::FrameRejected
        );
        assert_eq!(satmap_capi::satmap_reset(rt), SatmapStatus::Ok);
        assert_eq!(satmap_capi::satmap_step(rt, &frames[0]), SatmapStatus::Ok);
        assert_eq!(
            satmap_capi::satmap_reset(std::ptr::null_mut()),
            SatmapStatus::NullArgument
        );
        satmap_capi::satmap_destroy(rt);
        satmap_capi::satmap_destroy(clean);
    }
}
