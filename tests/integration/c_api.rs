//! The ECU integration surface over the committed compiled `test` bundle: the C API (called from Rust
//! here, from C in `examples/c/replay.c`), caller-placed regions, the staged step and the
//! protected map frame, on the committed scenario `examples/c/scenario.bin` (made from the
//! golden inputs; it and its digests per kernel family are kept current by the ECU tests,
//! `tests/ecu/tests/ecu/scenario.rs`, whose library builds the scenario's frames here too).

use std::ffi::CString;

use crate::common::{GoldenFrame, calibration, compiled_engine, root};
use satmap_capi::{
    SATMAP_DEFAULT_DATA_ID, SATMAP_MAX_WIRE_BYTES, SATMAP_REGION_COUNT, SatmapCameraImage,
    SatmapFrame, SatmapRegion, SatmapRegionInfo, SatmapRuntime, SatmapSliceInfo, SatmapStatus,
};
use satmap_ecu_tests::scenario::{STEPS, Step, SwitchCrop, frame, rust_run, sets, timestamp_us};
use satmap_runtime::frame::FrameLimits;
use satmap_runtime::map_frame::wire;
use satmap_runtime::placement::{REGION_ALIGN, REGIONS};
use satmap_runtime::{Frame, InitError, MemoryError, RuntimeRegions, SatMap};

/// `len` zeroed bytes at a `REGION_ALIGN` boundary, leaked (the test stands in for a linker
/// script's static sections).
fn region(len: usize) -> &'static mut [u8] {
    let v: &'static mut [u8] = Vec::leak(vec![0u8; len + REGION_ALIGN]);
    let skip = v.as_ptr().align_offset(REGION_ALIGN);
    &mut v[skip..skip + len]
}

fn regions(short: Option<usize>) -> RuntimeRegions {
    let r = |i: usize| region(REGIONS[i].bytes - usize::from(short == Some(i)));
    RuntimeRegions {
        value_features: r(0),
        gkt_lut: r(1),
        bev_query: r(2),
        gkt_weights: r(3),
        gathered: r(4),
        camera_bev: r(5),
        satellite_crop: r(6),
        satellite_bev: r(7),
        class_logits: r(8),
        points: r(9),
    }
}

#[test]
fn placed_regions_step_like_the_heap_and_a_short_or_misaligned_region_is_named() {
    let sets = sets();
    let heap = rust_run(&sets);
    let mut map = SatMap::in_regions(
        compiled_engine(),
        &calibration(),
        SwitchCrop(None),
        FrameLimits::DEFAULT,
        regions(None),
    )
    .unwrap();
    for (s, want) in STEPS.iter().zip(&heap) {
        let g = &sets[s.set];
        map.satellite_mut().0 = s.satellite.then(|| g.satellite.clone());
        assert_eq!(map.step(&frame(g, *s)).unwrap(), want);
    }
    for (i, spec) in REGIONS.iter().enumerate() {
        let e = SatMap::in_regions(
            compiled_engine(),
            &calibration(),
            SwitchCrop(None),
            FrameLimits::DEFAULT,
            regions(Some(i)),
        )
        .err();
        assert_eq!(
            e,
            Some(InitError::Memory(MemoryError::RegionTooSmall {
                region: spec.name,
                needed_bytes: spec.bytes,
                capacity_bytes: spec.bytes - 1,
            })),
            "region {} one byte short",
            spec.name
        );
    }
    let mut r = regions(None);
    let v: &'static mut [u8] = Vec::leak(vec![0u8; REGIONS[2].bytes + REGION_ALIGN + 1]);
    let skip = v.as_ptr().align_offset(REGION_ALIGN) + 1;
    r.bev_query = &mut v[skip..skip + REGIONS[2].bytes];
    assert_eq!(
        SatMap::in_regions(
            compiled_engine(),
            &calibration(),
            SwitchCrop(None),
            FrameLimits::DEFAULT,
            r
        )
        .err(),
        Some(InitError::Memory(MemoryError::RegionMisaligned {
            region: "bev_query",
            align: REGION_ALIGN
        }))
    );
}

#[test]
fn staged_steps_equal_one_call_steps_over_a_replay() {
    let sets = sets();
    let one_call = rust_run(&sets);
    let mut map = SatMap::new(compiled_engine(), &calibration(), SwitchCrop(None)).unwrap();
    for (s, want) in STEPS.iter().zip(&one_call) {
        let g = &sets[s.set];
        map.satellite_mut().0 = s.satellite.then(|| g.satellite.clone());
        let f = frame(g, *s);
        map.step_begin(&f).unwrap();
        // A frame arriving mid-step is refused, and the step goes on.
        let next = Frame {
            sequence: s.sequence + 1,
            ..f
        };
        assert_eq!(
            map.step(&next).err(),
            Some(satmap_runtime::StepError::StepInProgress {
                sequence: s.sequence
            })
        );
        assert!(map.step_begin(&next).is_err());
        assert!(matches!(
            map.step_finish().err(),
            Some(satmap_runtime::StepError::StepIncomplete { .. })
        ));
        let mut slices = Vec::new();
        loop {
            let done = map.step_run_next(&f).unwrap();
            slices.push(done.slice);
            if !done.more() {
                break;
            }
        }
        // One slice per camera that takes part, plus five.
        assert_eq!(slices.len(), s.present.count_ones() as usize + 5);
        assert_eq!(map.step_finish().unwrap(), want, "frame {}", s.sequence);
    }
}

/// A length no map frame has (up to `SIZE_MAX`) is refused before anything is read.
#[test]
fn a_map_frame_length_beyond_the_largest_is_refused_unread() {
    let buf = [0u8; 64];
    for len in [wire::MAX_WIRE_BYTES + 1, usize::MAX / 2, usize::MAX] {
        // SAFETY: the check refuses these lengths before it makes a slice of `buf`.
        let status = unsafe {
            satmap_capi::satmap_check_map_frame(
                buf.as_ptr(),
                len,
                SATMAP_DEFAULT_DATA_ID,
                std::ptr::null_mut(),
                std::ptr::null_mut(),
            )
        };
        assert_eq!(status, SatmapStatus::WireInvalid, "length {len}");
    }
}

pub(crate) fn c_frame(g: &GoldenFrame, s: Step) -> SatmapFrame {
    let per = g.images.len() / 6;
    let ts = timestamp_us(s.sequence);
    SatmapFrame {
        sequence: s.sequence,
        timestamp_us: ts,
        position_m: g.pose.position_m.to_array(),
        yaw_rad: g.pose.yaw_rad,
        acceleration_mps2: g.motion.acceleration_mps2.to_array(),
        rotation_rate_radps: g.motion.rotation_rate_radps.to_array(),
        velocity_mps: g.motion.velocity_mps.to_array(),
        cameras: core::array::from_fn(|c| SatmapCameraImage {
            rgb: if s.present >> c & 1 == 1 {
                g.images[c * per..].as_ptr()
            } else {
                std::ptr::null()
            },
            len: per,
            width_px: 320,
            height_px: 180,
            capture_us: ts,
            valid: 1,
        }),
        satellite_rgb: if s.satellite {
            g.satellite.as_ptr()
        } else {
            std::ptr::null()
        },
        satellite_len: g.satellite.len(),
    }
}

/// Every caller region, sized and named as `satmap_region_info` says, each its own memory.
pub(crate) fn c_regions() -> Vec<SatmapRegion> {
    (0..SATMAP_REGION_COUNT)
        .map(|i| {
            let mut info = SatmapRegionInfo {
                name: std::ptr::null(),
                bytes: 0,
                align: 0,
            };
            // SAFETY: valid out pointer.
            assert_eq!(
                unsafe { satmap_capi::satmap_region_info(i, &mut info) },
                SatmapStatus::Ok
            );
            // SAFETY: a static NUL-terminated name.
            let name = unsafe { std::ffi::CStr::from_ptr(info.name) };
            assert_eq!(name.to_str().unwrap(), REGIONS[i].name);
            let r = region(info.bytes);
            SatmapRegion {
                data: r.as_mut_ptr(),
                len: r.len(),
            }
        })
        .collect()
}

/// `satmap_create` on `regions` with the committed compiled bundle and calibration.
pub(crate) fn create(regions: &[SatmapRegion]) -> (SatmapStatus, *mut SatmapRuntime) {
    let bundle = CString::new(root().join("models/bundles/test.satmap").to_str().unwrap()).unwrap();
    let cal = root().join("models/calibration/nuscenes_like.toml");
    let cal = CString::new(cal.to_str().unwrap()).unwrap();
    let mut rt: *mut SatmapRuntime = std::ptr::null_mut();
    // SAFETY: `regions.len()` entries; NUL-terminated paths; valid out pointer.
    let status = unsafe {
        satmap_capi::satmap_create(
            regions.as_ptr(),
            regions.len(),
            bundle.as_ptr(),
            cal.as_ptr(),
            &mut rt,
        )
    };
    (status, rt)
}

/// Regions that share bytes are refused before the runtime makes anything of them (the cases of
/// issue 38: all ten on one buffer, `camera_bev` with `satellite_bev`, `class_logits` with
/// `points`, `gkt_lut` inside `value_features`, and a region wrapping the address space); the
/// same regions apart create a runtime.
#[test]
fn overlapping_caller_regions_are_refused_at_create() {
    let apart = c_regions();
    let id = |name: &str| REGIONS.iter().position(|r| r.name == name).unwrap();
    let big = region(apart.iter().map(|r| r.len).max().unwrap());
    let mut cases: Vec<(&str, Vec<SatmapRegion>)> = Vec::new();
    let all_on_one = apart
        .iter()
        .map(|r| SatmapRegion {
            data: big.as_mut_ptr(),
            len: r.len,
        })
        .collect();
    cases.push(("all ten on one buffer", all_on_one));
    for (a, b) in [
        ("camera_bev", "satellite_bev"),
        ("class_logits", "points"),
        ("gkt_lut", "value_features"),
    ] {
        let mut shared = apart.clone();
        // `a` starts 64 bytes into `b`: a partial overlap.
        // SAFETY: inside `b`'s region (every region is more than 64 bytes).
        shared[id(a)].data = unsafe { apart[id(b)].data.add(64) };
        cases.push((a, shared));
    }
    let mut wrapping = apart.clone();
    wrapping[0].len = usize::MAX;
    cases.push(("a region past the address space", wrapping));
    for (what, regions) in &cases {
        let (status, rt) = create(regions);
        assert_eq!(status, SatmapStatus::RegionsOverlap, "{what}");
        assert!(rt.is_null(), "{what}");
    }
    let (status, rt) = create(&apart);
    assert_eq!(status, SatmapStatus::Ok);
    // SAFETY: from satmap_create, destroyed once.
    unsafe { satmap_capi::satmap_destroy(rt) };
}

#[test]
fn the_c_api_computes_the_rust_run_and_protects_its_output() {
    let sets = sets();
    let rust = rust_run(&sets);
    // The compiled bundle, as an ECU loads it (and as `rust_run` does).
    let (status, rt) = create(&c_regions());
    assert_eq!(status, SatmapStatus::Ok);
    let mut buf = vec![0u8; SATMAP_MAX_WIRE_BYTES];
    for (s, want) in STEPS.iter().zip(&rust) {
        let f = c_frame(&sets[s.set], *s);
        // SAFETY: rt from satmap_create; the frame's pointers outlive the calls.
        unsafe {
            if s.staged {
                assert_eq!(satmap_capi::satmap_step_begin(rt, &f), SatmapStatus::Ok);
                assert_eq!(
                    satmap_capi::satmap_step_begin(rt, &f),
                    SatmapStatus::StepInProgress
                );
                let mut info = SatmapSliceInfo {
                    slice: satmap_capi::SatmapSlice::BevQuery,
                    remaining: 0,
                };
                loop {
                    assert_eq!(
                        satmap_capi::satmap_step_run_next(rt, &f, &mut info),
                        SatmapStatus::Ok
                    );
                    if info.remaining == 0 {
                        break;
                    }
                }
                assert_eq!(satmap_capi::satmap_step_finish(rt), SatmapStatus::Ok);
            } else {
                assert_eq!(satmap_capi::satmap_step(rt, &f), SatmapStatus::Ok);
            }
            let mut n = 0usize;
            assert_eq!(
                satmap_capi::satmap_map_frame(
                    rt,
                    SATMAP_DEFAULT_DATA_ID,
                    buf.as_mut_ptr(),
                    buf.len(),
                    &mut n
                ),
                SatmapStatus::Ok
            );
            let mut seq = 0u64;
            assert_eq!(
                satmap_capi::satmap_check_map_frame(
                    buf.as_ptr(),
                    n,
                    SATMAP_DEFAULT_DATA_ID,
                    &mut seq,
                    std::ptr::null_mut()
                ),
                SatmapStatus::Ok
            );
            assert_eq!(seq, s.sequence);
            let back = wire::deserialise(&buf[..n], SATMAP_DEFAULT_DATA_ID).unwrap();
            assert_eq!(back.digest, want.digest);
            assert_eq!(back.elements, want.elements);
            assert_eq!(back.health, want.health);
            // Every single-bit flip of the serialised frame fails the check.
            for bit in 0..n * 8 {
                buf[bit / 8] ^= 1 << (bit % 8);
                assert_ne!(
                    satmap_capi::satmap_check_map_frame(
                        buf.as_ptr(),
                        n,
                        SATMAP_DEFAULT_DATA_ID,
                        std::ptr::null_mut(),
                        std::ptr::null_mut()
                    ),
                    SatmapStatus::Ok,
                    "bit {bit} flipped in frame {}",
                    s.sequence
                );
                buf[bit / 8] ^= 1 << (bit % 8);
            }
        }
    }
    // A rejected frame leaves the runtime usable, with a message.
    let mut old = c_frame(&sets[0], STEPS[0]);
    old.sequence = 1;
    // SAFETY: as above.
    unsafe {
        assert_eq!(
            satmap_capi::satmap_step(rt, &old),
            SatmapStatus::FrameRejected
        );
        let mut msg = [0i8; 128];
        let len = satmap_capi::satmap_last_error(rt, msg.as_mut_ptr().cast(), msg.len());
        assert!(len > 0);
        assert_eq!(
            satmap_capi::satmap_step(std::ptr::null_mut(), &old),
            SatmapStatus::NullArgument
        );
        satmap_capi::satmap_destroy(rt);
    }
}
