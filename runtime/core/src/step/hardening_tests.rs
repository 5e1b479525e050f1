//! Integrity and hardening (issue 13, item 2): frame checks that cannot lock the runtime out,
//! plausibility ranges of pose and ego motion, the explicit restart, and calibration range
//! checks. Every refused input must name its field and value, change nothing, and leave the
//! next normal frame stepping exactly as on an undisturbed runtime.

use glam::DVec3;

use super::*;
use crate::calibration::{CalibrationFault, CalibrationField};
use crate::frame::{FrameError, InvalidLimits};
use crate::pose::Axis;
use crate::satellite::FixedCrop;
use crate::test_support::{
    FakeEngine, Images, count_allocations, crop, fake_runtime, nuscenes_like,
};

/// The last map of a fresh runtime that stepped `sequences` (normal frames) in order.
fn undisturbed(crop: &[u8], images: &Images, sequences: &[u64]) -> MapFrame {
    let mut rt = fake_runtime(crop);
    let mut last = None;
    for &s in sequences {
        last = Some(rt.step(&images.frame(s)).unwrap().clone());
    }
    last.unwrap()
}

#[test]
fn sequence_max_is_refused_and_the_next_normal_frame_steps_as_on_a_fresh_runtime() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 11);
    let expected = undisturbed(&c, &images, &[1, 2]);
    let mut rt = fake_runtime(&c);
    let first = rt.step(&images.frame(1)).unwrap().clone();
    let mut bad = images.frame(2);
    bad.sequence = u64::MAX;
    let refused = StepError::Frame(FrameError::SequenceGapTooLarge {
        previous: 1,
        got: u64::MAX,
        max_gap: 1000,
    });
    // Refused twice: the first refusal did not adopt the sequence.
    assert_eq!(rt.step(&bad).unwrap_err(), refused);
    assert_eq!(rt.step(&bad).unwrap_err(), refused);
    assert_eq!(rt.last_map(), Some(&first));
    let text = refused.to_string();
    assert!(
        text.contains("18446744073709551615") && text.contains("1000") && text.contains(" 1;"),
        "{text}"
    );
    assert_eq!(rt.step(&images.frame(2)).unwrap(), &expected);
}

#[test]
fn timestamp_max_is_refused_and_the_next_normal_frame_steps_as_on_a_fresh_runtime() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 12);
    let expected = undisturbed(&c, &images, &[1, 2]);
    let mut rt = fake_runtime(&c);
    let first = rt.step(&images.frame(1)).unwrap().clone();
    let mut bad = images.frame(2);
    bad.timestamp_us = u64::MAX;
    let refused = StepError::Frame(FrameError::TimestampGapTooLarge {
        previous_us: 1_100_000,
        got_us: u64::MAX,
        max_gap_us: 10_000_000,
    });
    assert_eq!(rt.step(&bad).unwrap_err(), refused);
    assert_eq!(rt.step(&bad).unwrap_err(), refused);
    assert_eq!(rt.last_map(), Some(&first));
    let text = refused.to_string();
    assert!(
        text.contains("18446744073709551615") && text.contains("10000000"),
        "{text}"
    );
    assert_eq!(rt.step(&images.frame(2)).unwrap(), &expected);
}

#[test]
fn gaps_just_inside_the_limits_are_accepted_and_just_beyond_refused() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 13);
    let expected = undisturbed(&c, &images, &[1, 2]);
    // `Images::frame(1)` is at 1.1 s; frame 2's content with other counters.
    let after_first = |sequence: u64, timestamp_us: u64| {
        let mut f = images.frame(2);
        f.sequence = sequence;
        crate::test_support::retime(&mut f, timestamp_us);
        f
    };
    let cases: [(u64, u64, Option<StepError>); 4] = [
        (1 + 1000, 1_200_000, None),
        (
            1 + 1001,
            1_200_000,
            Some(StepError::Frame(FrameError::SequenceGapTooLarge {
                previous: 1,
                got: 1002,
                max_gap: 1000,
            })),
        ),
        (2, 1_100_000 + 10_000_000, None),
        (
            2,
            1_100_000 + 10_000_001,
            Some(StepError::Frame(FrameError::TimestampGapTooLarge {
                previous_us: 1_100_000,
                got_us: 11_100_001,
                max_gap_us: 10_000_000,
            })),
        ),
    ];
    for (sequence, timestamp_us, refusal) in cases {
        let mut rt = fake_runtime(&c);
        let first = rt.step(&images.frame(1)).unwrap().clone();
        let result = rt.step(&after_first(sequence, timestamp_us)).cloned();
        match refusal {
            None => {
                let out = result.unwrap();
                assert_eq!((out.sequence, out.timestamp_us), (sequence, timestamp_us));
                // The counters do not reach the network: same map as the undisturbed step.
                assert_eq!(out.digest, expected.digest);
            }
            Some(refusal) => {
                assert_eq!(result.unwrap_err(), refusal);
                assert_eq!(rt.last_map(), Some(&first));
                assert_eq!(rt.step(&images.frame(2)).unwrap(), &expected);
            }
        }
    }
}

#[test]
fn configured_gaps_are_the_ones_checked() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 14);
    let limits = FrameLimits {
        max_sequence_gap: 1,
        max_timestamp_gap_us: 100_000,
        ..FrameLimits::DEFAULT
    };
    let mut rt = SatMap::with_limits(
        FakeEngine::new(dims.clone()),
        &nuscenes_like(),
        FixedCrop(&c),
        limits,
    )
    .unwrap();
    assert_eq!(rt.limits(), &limits);
    rt.step(&images.frame(1)).unwrap();
    // `Images` frames are 100 ms apart: one step is exactly at both limits.
    rt.step(&images.frame(2)).unwrap();
    assert_eq!(
        rt.step(&images.frame(4)).unwrap_err(),
        StepError::Frame(FrameError::SequenceGapTooLarge {
            previous: 2,
            got: 4,
            max_gap: 1
        })
    );
    let mut late = images.frame(3);
    late.timestamp_us += 1;
    assert_eq!(
        rt.step(&late).unwrap_err(),
        StepError::Frame(FrameError::TimestampGapTooLarge {
            previous_us: 1_200_000,
            got_us: 1_300_001,
            max_gap_us: 100_000
        })
    );
    assert_eq!(rt.step(&images.frame(3)).unwrap().sequence, 3);
}

#[test]
fn reset_allows_a_restart_from_sequence_zero() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 15);
    let mut rt = fake_runtime(&c);
    rt.step(&images.frame(5)).unwrap();
    let sixth = rt.step(&images.frame(6)).unwrap().clone();
    // Without a reset a restarted counter is refused, and changes nothing.
    assert_eq!(
        rt.step(&images.frame(0)).unwrap_err(),
        StepError::Frame(FrameError::SequenceNotIncreasing {
            previous: 6,
            got: 0
        })
    );
    assert_eq!(rt.last_map(), Some(&sixth));
    let ((), allocations) = count_allocations(|| rt.reset());
    assert_eq!(allocations, 0);
    assert!(rt.last_map().is_none());
    // The same map as a fresh runtime's, but the E2E counter keeps counting across the reset.
    let after = rt.step(&images.frame(0)).unwrap().clone();
    let fresh = undisturbed(&c, &images, &[0]);
    assert_eq!(after.e2e_counter, sixth.e2e_counter + 1);
    assert_eq!(
        MapFrame {
            e2e_counter: fresh.e2e_counter,
            ..after
        },
        fresh
    );
    assert_eq!(
        rt.step(&images.frame(1)).unwrap().digest,
        undisturbed(&c, &images, &[0, 1]).digest
    );
}

/// The first frame after init (or reset) is the anchor and is never refused for its counters;
/// if it carried corrupt ones, the integrator sees every later frame refused and resets.
#[test]
fn a_corrupt_first_frame_is_recovered_by_reset() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 16);
    let mut rt = fake_runtime(&c);
    let mut anchor = images.frame(1);
    anchor.sequence = u64::MAX;
    crate::test_support::retime(&mut anchor, u64::MAX);
    assert_eq!(rt.step(&anchor).unwrap().sequence, u64::MAX);
    assert_eq!(
        rt.step(&images.frame(2)).unwrap_err(),
        StepError::Frame(FrameError::SequenceNotIncreasing {
            previous: u64::MAX,
            got: 2
        })
    );
    rt.reset();
    rt.step(&images.frame(1)).unwrap();
    let fresh = undisturbed(&c, &images, &[1, 2]);
    assert_eq!(
        &MapFrame {
            e2e_counter: fresh.e2e_counter,
            ..rt.step(&images.frame(2)).unwrap().clone()
        },
        &fresh
    );
}

#[test]
fn each_implausible_field_is_refused_then_the_runtime_steps_normally() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 17);
    let expected = undisturbed(&c, &images, &[1, 2]);
    type Case = (fn(&mut Frame<'_>), StepError, &'static str);
    let cases: [Case; 10] = [
        (
            |f| f.motion.velocity_mps.y = 3e38,
            StepError::Frame(FrameError::VelocityOutOfRange {
                axis: Axis::Y,
                value_mps: 3e38,
                limit_mps: 100.0,
            }),
            "velocity y = 3e38 m/s",
        ),
        (
            |f| f.motion.velocity_mps.x = -100.5,
            StepError::Frame(FrameError::VelocityOutOfRange {
                axis: Axis::X,
                value_mps: -100.5,
                limit_mps: 100.0,
            }),
            "velocity x = -1.005e2 m/s",
        ),
        (
            |f| f.pose.yaw_rad = 1e308,
            StepError::Frame(FrameError::YawOutOfRange {
                value_rad: 1e308,
                limit_rad: 1e4,
            }),
            "yaw = 1e308 rad",
        ),
        (
            |f| f.pose.yaw_rad = -10_000.5,
            StepError::Frame(FrameError::YawOutOfRange {
                value_rad: -10_000.5,
                limit_rad: 1e4,
            }),
            "yaw = -1.00005e4 rad",
        ),
        (
            |f| f.pose.position_m.x = 1e300,
            StepError::Frame(FrameError::PositionOutOfRange {
                axis: Axis::X,
                value_m: 1e300,
                limit_m: 1e7,
            }),
            "position x = 1e300 m",
        ),
        (
            |f| f.pose.position_m.y = -1e300,
            StepError::Frame(FrameError::PositionOutOfRange {
                axis: Axis::Y,
                value_m: -1e300,
                limit_m: 1e7,
            }),
            "position y = -1e300 m",
        ),
        (
            // Gravity plus a 10 g jolt.
            |f| f.motion.acceleration_mps2.z = 110.0,
            StepError::Frame(FrameError::AccelerationOutOfRange {
                axis: Axis::Z,
                value_mps2: 110.0,
                limit_mps2: 100.0,
            }),
            "acceleration z = 1.1e2 m/s^2",
        ),
        (
            |f| f.motion.acceleration_mps2.x = -3e38,
            StepError::Frame(FrameError::AccelerationOutOfRange {
                axis: Axis::X,
                value_mps2: -3e38,
                limit_mps2: 100.0,
            }),
            "acceleration x = -3e38 m/s^2",
        ),
        (
            |f| f.motion.rotation_rate_radps.z = 10.5,
            StepError::Frame(FrameError::RotationRateOutOfRange {
                axis: Axis::Z,
                value_radps: 10.5,
                limit_radps: 10.0,
            }),
            "rotation rate z = 1.05e1 rad/s",
        ),
        (
            |f| f.motion.rotation_rate_radps.x = -1e30,
            StepError::Frame(FrameError::RotationRateOutOfRange {
                axis: Axis::X,
                value_radps: -1e30,
                limit_radps: 10.0,
            }),
            "rotation rate x = -1e30 rad/s",
        ),
    ];
    for (corrupt, refusal, text) in cases {
        let mut rt = fake_runtime(&c);
        let first = rt.step(&images.frame(1)).unwrap().clone();
        let mut bad = images.frame(2);
        corrupt(&mut bad);
        let err = rt.step(&bad).unwrap_err();
        assert_eq!(err, refusal);
        assert!(err.to_string().contains(text), "{err} lacks {text:?}");
        assert_eq!(rt.last_map(), Some(&first), "{refusal:?}: state changed");
        assert_eq!(
            rt.step(&images.frame(2)).unwrap(),
            &expected,
            "{refusal:?}: next good step differs"
        );
    }
}

/// Bounds are inclusive, and a stationary car (acceleration z = gravity) is plausible.
#[test]
fn values_at_the_limits_are_accepted() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 18);
    let mut rt = fake_runtime(&c);
    let mut edge = images.frame(1);
    edge.pose.position_m = glam::DVec2::new(1e7, -1e7);
    edge.pose.yaw_rad = -1e4;
    edge.motion.velocity_mps = glam::Vec3::new(-100.0, 100.0, 0.0);
    edge.motion.acceleration_mps2 = glam::Vec3::new(100.0, -100.0, 9.81);
    edge.motion.rotation_rate_radps = glam::Vec3::new(10.0, -10.0, 0.0);
    assert_eq!(rt.step(&edge).unwrap().sequence, 1);
}

#[test]
fn limits_are_validated_and_configurable() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 19);
    let d = FrameLimits::DEFAULT;
    assert_eq!(FrameLimits::default(), d);
    assert_eq!(fake_runtime(&c).limits(), &d);
    let bad: [(FrameLimits, &str); 7] = [
        (
            FrameLimits {
                max_sequence_gap: 0,
                ..d
            },
            "max_sequence_gap",
        ),
        (
            FrameLimits {
                max_timestamp_gap_us: 0,
                ..d
            },
            "max_timestamp_gap_us",
        ),
        (
            FrameLimits {
                max_abs_position_m: f64::NAN,
                ..d
            },
            "max_abs_position_m",
        ),
        (
            FrameLimits {
                max_abs_yaw_rad: 0.0,
                ..d
            },
            "max_abs_yaw_rad",
        ),
        (
            FrameLimits {
                max_abs_velocity_mps: -1.0,
                ..d
            },
            "max_abs_velocity_mps",
        ),
        (
            FrameLimits {
                max_abs_acceleration_mps2: f32::NAN,
                ..d
            },
            "max_abs_acceleration_mps2",
        ),
        (
            FrameLimits {
                max_abs_rotation_rate_radps: 0.0,
                ..d
            },
            "max_abs_rotation_rate_radps",
        ),
    ];
    for (limits, field) in bad {
        let r = SatMap::with_limits(
            FakeEngine::new(dims.clone()),
            &nuscenes_like(),
            FixedCrop(&c),
            limits,
        );
        assert_eq!(
            r.err(),
            Some(InitError::InvalidLimits(InvalidLimits { field }))
        );
    }
    // A tighter bound refuses the test frames' 8.1 m/s; an infinite one lifts the bound.
    let mut slow = SatMap::with_limits(
        FakeEngine::new(dims.clone()),
        &nuscenes_like(),
        FixedCrop(&c),
        FrameLimits {
            max_abs_velocity_mps: 5.0,
            ..d
        },
    )
    .unwrap();
    assert_eq!(
        slow.step(&images.frame(1)).unwrap_err(),
        StepError::Frame(FrameError::VelocityOutOfRange {
            axis: Axis::Y,
            value_mps: images.frame(1).motion.velocity_mps.y,
            limit_mps: 5.0
        })
    );
    let mut unbounded = SatMap::with_limits(
        FakeEngine::new(dims.clone()),
        &nuscenes_like(),
        FixedCrop(&c),
        FrameLimits {
            max_abs_velocity_mps: f32::INFINITY,
            ..d
        },
    )
    .unwrap();
    let mut fast = images.frame(1);
    fast.motion.velocity_mps.y = 1000.0;
    assert_eq!(unbounded.step(&fast).unwrap().sequence, 1);
}

#[test]
fn calibration_fx_1e300_is_refused_at_new_and_at_recalibrate() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 20);
    let mut bad = nuscenes_like();
    bad.cameras[0].fx_px = 1e300;
    let refused = InitError::InvalidCalibration {
        camera: 0,
        fault: CalibrationFault::FocalOutOfRange {
            field: CalibrationField::FxPx,
            value_px: 1e300,
            // 0.05 and 100 times the raw width of 1600 px.
            min_px: 80.0,
            max_px: 160_000.0,
        },
    };
    let text = refused.to_string();
    assert!(
        text.contains("camera 0") && text.contains("fx_px = 1e300"),
        "{text}"
    );
    assert!(!bad.is_valid());
    let r = SatMap::new(FakeEngine::new(dims.clone()), &bad, FixedCrop(&c));
    assert_eq!(r.err(), Some(refused));

    let expected = undisturbed(&c, &images, &[1, 2]);
    let mut rt = fake_runtime(&c);
    rt.step(&images.frame(1)).unwrap();
    let table = rt.lut().to_dense();
    assert_eq!(rt.recalibrate(&bad), Err(refused));
    assert_eq!(rt.lut().to_dense(), table);
    // The old table is in use: the next step is the undisturbed one.
    assert_eq!(rt.step(&images.frame(2)).unwrap(), &expected);
}

#[test]
fn each_out_of_range_calibration_is_refused_by_recalibrate_and_the_old_table_stays() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 21);
    type Case = (fn(&mut Calibration), usize, fn(CalibrationFault) -> bool);
    let cases: [Case; 7] = [
        (
            |cal| cal.cameras[5].fy_px = 1e-3,
            5,
            |f| {
                f == CalibrationFault::FocalOutOfRange {
                    field: CalibrationField::FyPx,
                    value_px: 1e-3,
                    min_px: 45.0,
                    max_px: 90_000.0,
                }
            },
        ),
        (
            |cal| cal.cameras[1].fx_px = -5.0,
            1,
            |f| {
                f == CalibrationFault::NonPositiveFocal {
                    field: CalibrationField::FxPx,
                    value_px: -5.0,
                }
            },
        ),
        (
            |cal| cal.cameras[2].cx_px = 1600.5,
            2,
            |f| {
                f == CalibrationFault::PrincipalPointOutsideImage {
                    field: CalibrationField::CxPx,
                    value_px: 1600.5,
                    max_px: 1600.0,
                }
            },
        ),
        (
            |cal| cal.cameras[4].translation_m = DVec3::new(0.0, 12.0, 1.5),
            4,
            |f| {
                matches!(f, CalibrationFault::CameraTooFar { distance_m, max_m: 10.0 }
                    if (distance_m - 12.093_386).abs() < 1e-6)
            },
        ),
        (
            |cal| cal.cameras[3].rotation.x = f64::NAN,
            3,
            |f| {
                f == CalibrationFault::NonFinite {
                    field: CalibrationField::Rotation,
                }
            },
        ),
        (
            |cal| cal.cameras[0].rotation = glam::DQuat::from_xyzw(0.0, 0.0, 0.0, 1.01),
            0,
            |f| matches!(f, CalibrationFault::NonUnitRotation { norm } if (norm - 1.01).abs() < 1e-12),
        ),
        (
            |cal| cal.raw_width_px = 0,
            0,
            |f| f == CalibrationFault::ZeroRawSize,
        ),
    ];
    let expected = undisturbed(&c, &images, &[1, 2]);
    let mut rt = fake_runtime(&c);
    rt.step(&images.frame(1)).unwrap();
    let table = rt.lut().to_dense();
    for (corrupt, camera, is_expected) in cases {
        let mut cal = nuscenes_like();
        corrupt(&mut cal);
        match rt.recalibrate(&cal) {
            Err(InitError::InvalidCalibration { camera: got, fault }) => {
                assert_eq!(got, camera, "{fault}");
                assert!(is_expected(fault), "camera {camera}: got {fault:?}");
            }
            other => panic!("camera {camera}: got {other:?}"),
        }
        assert_eq!(rt.lut().to_dense(), table);
    }
    assert_eq!(
        InitError::InvalidCalibration {
            camera: 0,
            fault: CalibrationFault::ZeroRawSize
        }
        .to_string(),
        "calibration: raw_width_px and raw_height_px must be positive"
    );
    assert_eq!(rt.step(&images.frame(2)).unwrap(), &expected);
}
