//! A staged step reads each part of the frame in its own slice: what a slice reads must be what
//! `step_begin` checked. Another pose or motion, a NaN yaw, another image or the same buffer
//! rewritten between slices is refused, the staged step goes on, and given the checked content
//! it publishes what the one-call step publishes.

use super::*;
use crate::test_support::{Images, crop, fake_runtime};

#[test]
fn what_a_slice_reads_must_be_what_step_begin_checked() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 3);
    let other = Images::new(&dims, 99);
    let one_call = fake_runtime(&c).step(&images.frame(1)).unwrap().digest;

    let mut rt = fake_runtime(&c);
    let good = images.frame(1);
    rt.step_begin(&good).unwrap();
    let changed = |part| Err::<SliceDone, _>(StepError::FrameChanged { sequence: 1, part });
    // The bev_query slice reads pose and motion.
    let mut nan_yaw = images.frame(1);
    nan_yaw.pose.yaw_rad = f64::NAN;
    assert_eq!(rt.step_run_next(&nan_yaw), changed(FramePart::Motion));
    let mut fast = images.frame(1);
    fast.motion.velocity_mps.y = 1e30;
    assert_eq!(rt.step_run_next(&fast), changed(FramePart::Motion));
    assert_eq!(rt.step_run_next(&good).unwrap().slice, StepSlice::BevQuery);
    // Camera 0's slice reads its image: another buffer, or the same bytes rewritten.
    let mut swapped = images.frame(1);
    swapped.images[0] = other.frame(1).images[0];
    assert_eq!(
        rt.step_run_next(&swapped),
        changed(FramePart::Image { camera: 0 })
    );
    let mut rewritten = images.rgb.clone();
    rewritten[17] ^= 1;
    let mut edited = images.frame(1);
    if let Some(image) = edited.images[0].as_mut() {
        image.rgb = &rewritten[..dims.image_bytes()];
    }
    assert_eq!(
        rt.step_run_next(&edited),
        changed(FramePart::Image { camera: 0 })
    );
    // A camera's slice does not read the others' images: camera 1's change waits for its slice.
    let mut late = images.frame(1);
    late.images[1] = other.frame(1).images[1];
    assert_eq!(
        rt.step_run_next(&late).unwrap().slice,
        StepSlice::ImageEncoder { camera: 0 }
    );
    assert_eq!(
        rt.step_run_next(&late),
        changed(FramePart::Image { camera: 1 })
    );
    // With the checked frame the staged step goes on and publishes the one-call step's map.
    while rt.step_run_next(&good).unwrap().more() {}
    assert_eq!(rt.step_finish().unwrap().digest, one_call);
}
