//! Unit tests of the step state machine over the pure-Rust engine double (`test_support`): the
//! stage order, determinism, every input check, engine failures, degraded mode, deadline flag,
//! recalibration and the no-allocation guarantee.

use alloc::vec::Vec;

use super::*;
use crate::can_bus::can_bus;
use crate::engine::{BackendFault, EngineError, EngineErrorKind, Stage};
use crate::frame::{CameraImage, FrameError};
use crate::gkt::gather_sum;
use crate::pose::EgoPose;
use crate::satellite::{Coverage, CropSpec, FixedCrop, NoSatellite};
use crate::test_support::{FakeEngine, Images, count_allocations, crop, nuscenes_like};

fn runtime<'a>(crop: &'a [u8]) -> SatMap<FakeEngine, FixedCrop<'a>> {
    let dims = ModelDims::test_config();
    SatMap::new(FakeEngine::new(dims), &nuscenes_like(), FixedCrop(crop)).unwrap()
}

/// Digest of a good step on `images` at `sequence`, from a fresh runtime.
fn fresh_digest(images: &Images, sequence: u64) -> u64 {
    let c = crop(&ModelDims::test_config());
    let mut rt = runtime(&c);
    rt.step(&images.frame(sequence)).unwrap().digest
}

#[test]
fn good_step_runs_every_stage_and_publishes() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let mut rt = runtime(&c);
    let images = Images::new(&dims, 1);
    assert!(rt.last_map().is_none());
    let out = rt.step(&images.frame(1)).unwrap().clone();
    assert_eq!(out.sequence, 1);
    assert_eq!(out.timestamp_us, 1_100_000);
    assert_eq!(out.elements.len(), 50);
    assert_eq!(
        out.health,
        Health {
            satellite: SatellitePrior::Present,
            degraded: false,
            deadline_overrun: false,
            cameras: Default::default(),
        }
    );
    assert_eq!(out.digest, map_frame::digest(&out.elements));
    assert!(out.elements.windows(2).all(|w| w[0].score >= w[1].score));
    use Stage::*;
    assert_eq!(
        rt.engine().calls.as_slice(),
        [
            BevQuery,
            ImageEncoder,
            ImageEncoder,
            ImageEncoder,
            ImageEncoder,
            ImageEncoder,
            ImageEncoder,
            BevEncoder,
            SatelliteEncoder,
            MapDecoder
        ]
    );
    // Intermediate buffers are consistent with each other.
    let mut gathered = alloc::vec![0.0f32; dims.bev_len()];
    gather_sum(
        rt.lut(),
        rt.buffers().value(),
        rt.buffers().weights(),
        &mut gathered,
        crate::frame::CameraMask::ALL,
    )
    .unwrap();
    assert_eq!(gathered, rt.buffers().gathered());
    assert_eq!(rt.buffers().crop(), c.as_slice());
    assert_eq!(
        rt.buffers().can_bus(),
        &can_bus(&images.frame(1).pose, &images.frame(1).motion)
    );
    assert_eq!(rt.last_map(), Some(&out));
}

#[test]
fn deterministic_across_instances_and_sensitive_to_inputs() {
    let dims = ModelDims::test_config();
    let a = Images::new(&dims, 1);
    let b = Images::new(&dims, 2);
    assert_eq!(fresh_digest(&a, 5), fresh_digest(&a, 5));
    assert_ne!(fresh_digest(&a, 5), fresh_digest(&b, 5));
    // Same frame content at a later sequence: yaw and speed differ, so the map differs.
    assert_ne!(fresh_digest(&a, 5), fresh_digest(&a, 6));
}

/// Every bad input returns its own error, leaves the state untouched, and the next good
/// frame steps exactly as if the bad one never came.
#[test]
fn each_bad_input_then_a_good_step() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 3);
    let short = alloc::vec![0u8; dims.image_bytes() - 3];
    let small = alloc::vec![0u8; 100 * 50 * 3];

    type Case = (&'static str, fn(&mut Frame<'_>), fn(StepError) -> bool);
    let cases: [Case; 9] = [
        (
            "repeated sequence",
            |f| f.sequence = 1,
            |e| {
                e == StepError::Frame(FrameError::SequenceNotIncreasing {
                    previous: 1,
                    got: 1,
                })
            },
        ),
        (
            "old sequence",
            |f| f.sequence = 0,
            |e| {
                e == StepError::Frame(FrameError::SequenceNotIncreasing {
                    previous: 1,
                    got: 0,
                })
            },
        ),
        (
            "timestamp",
            |f| f.timestamp_us = 1_100_000,
            |e| {
                e == StepError::Frame(FrameError::TimestampNotIncreasing {
                    previous_us: 1_100_000,
                    got_us: 1_100_000,
                })
            },
        ),
        (
            "nan pose",
            |f| f.pose.position_m.x = f64::NAN,
            |e| e == StepError::Frame(FrameError::NonFinitePose),
        ),
        (
            "inf yaw",
            |f| f.pose.yaw_rad = f64::INFINITY,
            |e| e == StepError::Frame(FrameError::NonFinitePose),
        ),
        (
            "nan motion",
            |f| f.motion.velocity_mps.y = f32::NAN,
            |e| e == StepError::Frame(FrameError::NonFiniteMotion),
        ),
        (
            "no camera left",
            |f| f.images = [None; 6],
            |e| {
                e == StepError::Frame(FrameError::NoCameraLeft {
                    states: [crate::frame::CameraState::Missing; 6],
                })
            },
        ),
        (
            "wrong size",
            |f| {
                if let Some(img) = f.images[2].as_mut() {
                    img.width_px = 100;
                    img.height_px = 50;
                }
            },
            |e| {
                e == StepError::Frame(FrameError::WrongImageSize {
                    camera: 2,
                    expected_width_px: 320,
                    expected_height_px: 180,
                    got_width_px: 100,
                    got_height_px: 50,
                })
            },
        ),
        (
            "wrong length",
            |_| {},
            |e| {
                e == StepError::Frame(FrameError::WrongImageLength {
                    camera: 5,
                    expected_bytes: 172_800,
                    got_bytes: 172_797,
                })
            },
        ),
    ];
    let expected_good = {
        let mut rt = runtime(&c);
        rt.step(&images.frame(1)).unwrap();
        rt.step(&images.frame(2)).unwrap().clone()
    };
    for (name, corrupt, is_expected) in cases {
        let mut rt = runtime(&c);
        let first = rt.step(&images.frame(1)).unwrap().clone();
        let mut bad = images.frame(2);
        corrupt(&mut bad);
        if name == "wrong length" {
            bad.images[5] = Some(CameraImage {
                width_px: 320,
                height_px: 180,
                rgb: &short,
                capture_us: 0,
                valid: true,
            });
        }
        let _ = &small;
        let err = rt.step(&bad).unwrap_err();
        assert!(is_expected(err), "{name}: got {err:?}");
        assert_eq!(rt.last_map(), Some(&first), "{name}: state changed");
        let good = rt.step(&images.frame(2)).unwrap();
        assert_eq!(good, &expected_good, "{name}: next good step differs");
    }
}

#[test]
fn engine_failure_and_nan_output_leave_state_untouched() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 4);
    for stage in Stage::ALL {
        let mut rt = runtime(&c);
        let first = rt.step(&images.frame(1)).unwrap().clone();
        rt.engine_mut().fail_next = Some(stage);
        let err = rt.step(&images.frame(2)).unwrap_err();
        assert_eq!(
            err,
            StepError::Engine(EngineError {
                stage,
                kind: EngineErrorKind::Backend(BackendFault::RunFailed)
            })
        );
        assert_eq!(rt.last_map(), Some(&first));
        assert_eq!(rt.step(&images.frame(2)).unwrap().sequence, 2);
    }
    let mut rt = runtime(&c);
    rt.engine_mut().nan_next = true;
    assert_eq!(
        rt.step(&images.frame(1)).unwrap_err(),
        StepError::NonFiniteOutput {
            slice: StepSlice::MapDecoder
        }
    );
    assert!(rt.last_map().is_none());
    // The failed first frame did not count: the same sequence is accepted now.
    assert_eq!(rt.step(&images.frame(1)).unwrap().sequence, 1);
}

/// A finite normalised point of 1e37 would decode to an infinite coordinate in metres (and
/// reach the evaluator's polygon buffer as NaN): refused like a NaN, the last map kept.
#[test]
fn a_huge_finite_point_is_refused_as_non_finite_output() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 4);
    let mut rt = runtime(&c);
    let first = rt.step(&images.frame(1)).unwrap().clone();
    rt.engine_mut().huge_point_next = true;
    assert_eq!(
        rt.step(&images.frame(2)).unwrap_err(),
        StepError::NonFiniteOutput {
            slice: StepSlice::MapDecoder
        }
    );
    assert_eq!(rt.last_map(), Some(&first));
    assert!(
        first
            .elements
            .iter()
            .all(|e| e.points_m.iter().all(|p| p.is_finite()))
    );
    assert_eq!(rt.step(&images.frame(2)).unwrap().sequence, 2);
}

/// Satellite sources for the degraded-mode test.
struct Scripted(Coverage);

impl SatelliteSource for Scripted {
    fn crop(&mut self, _pose: &EgoPose, _spec: &CropSpec, out: &mut [u8]) -> Coverage {
        out.fill(9);
        self.0
    }
}

#[test]
fn degraded_mode_feeds_zeros_and_flags_health() {
    let dims = ModelDims::test_config();
    let images = Images::new(&dims, 5);
    let mut none =
        SatMap::new(FakeEngine::new(dims.clone()), &nuscenes_like(), NoSatellite).unwrap();
    let out = none.step(&images.frame(1)).unwrap().clone();
    assert_eq!(out.health.satellite, SatellitePrior::Missing);
    assert!(out.health.degraded);
    assert!(none.buffers().satellite_bev().iter().all(|v| v == 0.0));
    assert!(!none.engine().calls.contains(&Stage::SatelliteEncoder));

    let mut corrupt = SatMap::new(
        FakeEngine::new(dims.clone()),
        &nuscenes_like(),
        Scripted(Coverage::Corrupt),
    )
    .unwrap();
    let out_c = corrupt.step(&images.frame(1)).unwrap().clone();
    assert_eq!(out_c.health.satellite, SatellitePrior::Corrupt);
    assert!(out_c.health.degraded);
    // Same camera input, same zeros fed: same map as with no source at all.
    assert_eq!(out_c.digest, out.digest);

    let mut partial = SatMap::new(
        FakeEngine::new(dims.clone()),
        &nuscenes_like(),
        Scripted(Coverage::Partial {
            covered_permille: 640,
        }),
    )
    .unwrap();
    let out_p = partial.step(&images.frame(1)).unwrap();
    assert_eq!(
        out_p.health.satellite,
        SatellitePrior::Partial {
            covered_permille: 640
        }
    );
    assert!(!out_p.health.degraded);
    assert_ne!(out_p.digest, out.digest);

    // A degraded step is followed by a normal one when imagery returns.
    let c = crop(&dims);
    let mut rt = runtime(&c);
    rt.step(&images.frame(1)).unwrap();
    assert!(!rt.last_map().unwrap().health.degraded);
}

#[test]
fn deadline_flag_is_per_step() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 6);
    let mut rt = runtime(&c);
    let d1 = rt.step(&images.frame(1)).unwrap().digest;
    rt.mark_deadline_overrun();
    let m = rt.last_map().unwrap();
    assert!(m.health.deadline_overrun);
    assert_eq!(m.digest, d1);
    assert!(!rt.step(&images.frame(2)).unwrap().health.deadline_overrun);
}

#[test]
fn recalibrate_rebuilds_the_table_in_place() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 7);
    let mut rt = runtime(&c);
    let before = rt.step(&images.frame(1)).unwrap().digest;
    let mut moved = nuscenes_like();
    // Turn the front camera 5 degrees to the left.
    moved.cameras[0].rotation =
        glam::DQuat::from_rotation_z(5f64.to_radians()) * moved.cameras[0].rotation;
    let (res, allocations) = count_allocations(|| rt.recalibrate(&moved));
    res.unwrap();
    assert_eq!(allocations, 0);
    assert_eq!(
        rt.lut().to_dense(),
        Lut::new(&dims, &moved).unwrap().to_dense()
    );
    let after = rt.step(&images.frame(2)).unwrap().digest;
    // Compare with a runtime created with the new calibration from the start.
    let mut fresh = SatMap::new(FakeEngine::new(dims.clone()), &moved, FixedCrop(&c)).unwrap();
    fresh.step(&images.frame(1)).unwrap();
    assert_eq!(fresh.step(&images.frame(2)).unwrap().digest, after);
    assert_ne!(before, after);
    // An invalid calibration is refused and the old table stays.
    let mut bad = moved;
    bad.cameras[3].rotation = glam::DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0);
    assert!(matches!(
        rt.recalibrate(&bad),
        Err(InitError::InvalidCalibration { camera: 3, .. })
    ));
    assert_eq!(
        rt.lut().to_dense(),
        Lut::new(&dims, &moved).unwrap().to_dense()
    );
}

#[test]
fn init_rejects_bad_dims_and_calibration() {
    let mut dims = ModelDims::test_config();
    dims.top_k = 60;
    let r = SatMap::new(FakeEngine::new(dims), &nuscenes_like(), NoSatellite);
    assert!(matches!(r, Err(InitError::Dims(_))));
    let mut cal = nuscenes_like();
    cal.cameras[1].fy_px = 0.0;
    let r = SatMap::new(FakeEngine::new(ModelDims::test_config()), &cal, NoSatellite);
    assert!(matches!(
        r,
        Err(InitError::InvalidCalibration { camera: 1, .. })
    ));
}

#[test]
fn step_does_not_allocate() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 8);
    let mut rt = runtime(&c);
    let frames: Vec<Frame<'_>> = (1..=5).map(|s| images.frame(s)).collect();
    let mut bad = images.frame(3);
    bad.images = [None; 6];
    let (digests, allocations) = count_allocations(|| {
        let mut d = [0u64; 5];
        for (i, f) in frames.iter().enumerate() {
            d[i] = rt.step(f).map(|m| m.digest).unwrap_or(0);
            let _ = rt.step(&bad);
        }
        d
    });
    assert_eq!(allocations, 0);
    assert!(digests.iter().all(|&d| d != 0));
    // The counter does see allocations (construction reserves every buffer), and degraded
    // steps allocate nothing either.
    let (none, init_allocations) = count_allocations(|| {
        SatMap::new(FakeEngine::new(dims.clone()), &nuscenes_like(), NoSatellite).unwrap()
    });
    assert!(init_allocations > 0);
    let mut none = none;
    let (res, allocations) = count_allocations(|| none.step(&frames[0]).map(|m| m.health));
    assert!(res.unwrap().degraded);
    assert_eq!(allocations, 0);
}

#[test]
fn a_missing_camera_is_left_out_of_the_step_and_flagged() {
    use crate::frame::CameraState;
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 1);
    let mut rt = runtime(&c);
    let mut f = images.frame(1);
    f.images[4] = None;
    let out = rt.step(&f).unwrap().clone();
    assert_eq!(out.health.cameras[4], CameraState::Missing);
    assert_eq!(out.health.cameras_dropped(), 1 << 4);
    let encoded = rt
        .engine()
        .calls
        .iter()
        .filter(|&&s| s == Stage::ImageEncoder)
        .count();
    assert_eq!(encoded, 5, "the missing camera's encoder must not run");
}
