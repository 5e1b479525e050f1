//! A panic inside a call leaves the handle dead, and says so: every later call answers
//! `SATMAP_STATUS_PANIC` (`satmap_reset` included) and `satmap_last_error` tells the caller to
//! destroy it. The panic is injected through the crate's own wrapper, since no input reaches one
//! (that is the point of every other check).

use std::ffi::CString;

use satmap_runtime::placement::{REGION_ALIGN, REGIONS};

use crate::ffi_types::SatmapRegion;
use crate::runtime::with_runtime;
use crate::status::SatmapStatus;
use crate::{SatmapRuntime, satmap_create, satmap_destroy, satmap_last_error, satmap_reset};

fn region(len: usize) -> SatmapRegion {
    let v: &'static mut [u8] = Vec::leak(vec![0u8; len + REGION_ALIGN]);
    let skip = v.as_ptr().align_offset(REGION_ALIGN);
    SatmapRegion {
        data: v[skip..].as_mut_ptr(),
        len,
    }
}

#[test]
fn a_panic_kills_the_handle_and_every_later_call_says_so() {
    let regions: Vec<SatmapRegion> = REGIONS.iter().map(|r| region(r.bytes)).collect();
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");
    let bundle = CString::new(format!("{root}/models/bundles/test.satmap")).unwrap();
    let cal = CString::new(format!("{root}/models/calibration/nuscenes_like.toml")).unwrap();
    let mut rt: *mut SatmapRuntime = std::ptr::null_mut();
    // SAFETY: every region valid and distinct; NUL-terminated paths; valid out pointer.
    let status = unsafe {
        satmap_create(
            regions.as_ptr(),
            regions.len(),
            bundle.as_ptr(),
            cal.as_ptr(),
            &mut rt,
        )
    };
    assert_eq!(status, SatmapStatus::Ok);
    // SAFETY: rt from satmap_create.
    unsafe {
        assert_eq!(satmap_reset(rt), SatmapStatus::Ok);
        assert_eq!(
            with_runtime(rt, |_| panic!("injected")),
            SatmapStatus::Panic
        );
        assert_eq!(satmap_reset(rt), SatmapStatus::Panic);
        assert_eq!(with_runtime(rt, |_| SatmapStatus::Ok), SatmapStatus::Panic);
        let mut buf = [0 as core::ffi::c_char; 256];
        let n = satmap_last_error(rt, buf.as_mut_ptr(), buf.len());
        let message = core::ffi::CStr::from_ptr(buf.as_ptr()).to_str().unwrap();
        assert_eq!(n, message.len());
        assert!(
            message.contains("dead") && message.contains("satmap_destroy"),
            "{message}"
        );
        satmap_destroy(rt);
    }
}
