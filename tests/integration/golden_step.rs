//! The whole step (`SatMap` + tract engine over the committed `test` folder bundle, ONNX stages
//! through tract's ONNX front end) against the PyTorch/onnxruntime goldens: every stage, the
//! decoded map, degraded mode and bad inputs. The same checks over the compiled bundle an ECU
//! loads, and determinism, are the ECU tests' (`tests/ecu/`), run on every target; tolerances in
//! `satmap_ecu_tests::parity`.

use crate::common::{GoldenFrame, calibration, engine};
use satmap_ecu_tests::parity::{degraded_frame_matches, golden_frames_match};
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{FrameError, SatMap, StepError};

fn dims_wh(map: &SatMap<TractEngine, impl satmap_runtime::SatelliteSource>) -> (u32, u32) {
    let d = map.dims();
    (d.image_w as u32, d.image_h as u32)
}

#[test]
fn every_stage_and_the_decoded_map_match_the_reference() {
    golden_frames_match(engine, "ONNX folder");
}

#[test]
fn degraded_mode_feeds_zeros_and_matches_the_reference() {
    degraded_frame_matches(engine, "ONNX folder");
}

/// Each bad input returns its own error, leaves the last map untouched, and the next good frame
/// steps normally with the same output as an undisturbed runtime.
#[test]
fn bad_inputs_return_errors_and_the_next_good_frame_steps() {
    let f = GoldenFrame::load(0);
    let mut map = SatMap::new(engine(), &calibration(), FixedCrop(&f.satellite)).unwrap();
    let (w, h) = dims_wh(&map);
    let first = map.step(&f.frame(10, w, h)).unwrap().clone();
    let mut seq = 10u64;

    // Apply `bad` to the frame after `seq`, check the error, then step the good frame.
    let mut case = |edit: &dyn Fn(&mut satmap_runtime::Frame<'_>, u64),
                    check: &dyn Fn(StepError, u64)| {
        let mut bad = f.frame(seq + 1, w, h);
        edit(&mut bad, seq);
        let got = map.step(&bad).unwrap_err();
        check(got, seq);
        let last = map.last_map().expect("a map was published");
        assert!(
            last.digest == first.digest && last.sequence == seq,
            "a failed step must not change the published map"
        );
        seq += 1;
        let good = map.step(&f.frame(seq, w, h)).unwrap();
        assert_eq!(good.digest, first.digest, "good step after {got:?}");
        assert_eq!(good.sequence, seq);
    };

    case(&|b, s| b.sequence = s, &|e, s| {
        assert_eq!(
            e,
            StepError::Frame(FrameError::SequenceNotIncreasing {
                previous: s,
                got: s
            })
        )
    });
    case(&|b, _| b.timestamp_us = 0, &|e, s| {
        assert_eq!(
            e,
            StepError::Frame(FrameError::TimestampNotIncreasing {
                previous_us: 1_000_000 + s * 100_000,
                got_us: 0
            })
        )
    });
    case(&|b, _| b.pose.yaw_rad = f64::NAN, &|e, _| {
        assert_eq!(e, StepError::Frame(FrameError::NonFinitePose))
    });
    case(&|b, _| b.pose.position_m.x = f64::INFINITY, &|e, _| {
        assert_eq!(e, StepError::Frame(FrameError::NonFinitePose))
    });
    case(&|b, _| b.motion.velocity_mps.y = f32::INFINITY, &|e, _| {
        assert_eq!(e, StepError::Frame(FrameError::NonFiniteMotion))
    });
    case(&|b, _| b.images = [None; 6], &|e, _| {
        assert!(matches!(
            e,
            StepError::Frame(FrameError::NoCameraLeft { .. })
        ))
    });
    case(
        &|b, _| {
            if let Some(img) = b.images[5].as_mut() {
                img.width_px /= 2;
            }
        },
        &|e, _| {
            assert!(
                matches!(
                    e,
                    StepError::Frame(FrameError::WrongImageSize {
                        camera: 5,
                        got_width_px: 160,
                        ..
                    })
                ),
                "{e:?}"
            )
        },
    );
    case(
        &|b, _| {
            if let Some(img) = b.images[2].as_mut() {
                img.rgb = &img.rgb[..img.rgb.len() - 1];
            }
        },
        &|e, _| {
            assert!(
                matches!(
                    e,
                    StepError::Frame(FrameError::WrongImageLength { camera: 2, .. })
                ),
                "{e:?}"
            )
        },
    );
}
