//! No healthy map from bad data: with the frame limits opened to infinity (allowed), a finite
//! but absurd velocity makes the real `test` bundle's `bev_query` non-finite. The step must fail
//! naming that slice and publish nothing, where it used to publish a full map marked healthy;
//! the next good frame steps normally.

use satmap_ecu_tests::golden::{GoldenFrame, calibration, compiled_engine};
use satmap_runtime::frame::FrameLimits;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{SatMap, StepError, StepSlice};

#[test]
fn a_finite_but_absurd_velocity_fails_the_step_at_the_first_non_finite_stage() {
    let g = GoldenFrame::load(0);
    let open = FrameLimits {
        max_abs_velocity_mps: f32::INFINITY,
        max_abs_acceleration_mps2: f32::INFINITY,
        max_abs_rotation_rate_radps: f32::INFINITY,
        ..FrameLimits::DEFAULT
    };
    let mut map = SatMap::with_limits(
        compiled_engine(),
        &calibration(),
        FixedCrop(&g.satellite),
        open,
    )
    .unwrap();
    let (w, h) = (map.dims().image_w as u32, map.dims().image_h as u32);
    let mut frame = g.frame(1, w, h);
    frame.motion.velocity_mps.y = 3e38;
    let err = map.step(&frame).unwrap_err();
    println!("3e38 m/s: {err}");
    assert!(
        matches!(
            err,
            StepError::NonFiniteOutput {
                slice: StepSlice::BevQuery
            }
        ),
        "{err:?}"
    );
    assert!(map.last_map().is_none(), "a map was published");
    let good = map.step(&g.frame(1, w, h)).unwrap();
    assert!(!good.health.degraded);
    assert!(!good.elements.is_empty());
}
