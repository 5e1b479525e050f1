//! Speed of synthetic frame generation: six 320x192 camera images plus the ground truth cut to
//! the patch, on one core. The target is at least 20 frames per second (50 ms per frame).

use criterion::{Criterion, criterion_group, criterion_main};
use satmap_sim::synth::{DriveConfig, LightingPreset, SyntheticDrive};

fn synth_frame(c: &mut Criterion) {
    let config = DriveConfig {
        image_width_px: 320,
        image_height_px: 192,
        num_frames: 200,
        lighting: Some(LightingPreset::Day),
        ..DriveConfig::default()
    };
    let Ok(drive) = SyntheticDrive::new(7, config) else {
        eprintln!("drive setup failed");
        return;
    };
    let mut images = vec![0u8; drive.image_bytes()];
    let mut index = 0usize;
    c.bench_function("synth_frame_320x192_six_cameras_plus_gt", |b| {
        b.iter(|| {
            index = (index + 1) % drive.len();
            let (pose, _) = drive.pose_and_motion(index);
            drive.render_images(index, &mut images);
            std::hint::black_box(drive.ground_truth_at(&pose));
        });
    });
    c.bench_function("synth_frame_owned_320x192", |b| {
        b.iter(|| {
            index = (index + 1) % drive.len();
            std::hint::black_box(drive.frame(index));
        });
    });
}

criterion_group!(benches, synth_frame);
criterion_main!(benches);
