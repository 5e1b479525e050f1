//! Every tract stage and the whole step, on a bundle's recorded reference inputs
//! (`reference.safetensors`, written by `models/`): `test` by default, any bundle through
//! `SATMAP_BENCH_BUNDLE` (an absolute path, e.g. `$PWD/models/build/nano`: benches run in `runtime/`).
//!
//! Run: `cargo bench -p satmap-runtime --bench stages` (or `--profile test` to reuse the test
//! build, whose code is optimised too).

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DVec2, Vec3};
use safetensors::SafeTensors;
use satmap_runtime::calibration::from_toml_file;
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{CameraImage, EgoMotion, EgoPose, Engine, Frame, SatMap};

fn f32s(st: &SafeTensors<'_>, name: &str) -> Vec<f32> {
    st.tensor(name)
        .expect("reference tensor")
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

fn bench(c: &mut Criterion) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let bundle = std::env::var("SATMAP_BENCH_BUNDLE")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("models/bundles/test"));
    let mut engine = TractEngine::open(&bundle).expect("bundle loads");
    let config = engine.dims().clone();
    let bytes = std::fs::read(bundle.join("reference.safetensors")).expect("reference file");
    let st = SafeTensors::deserialize(&bytes).expect("reference parses");
    let image = st
        .tensor("image_encoder.image")
        .expect("image")
        .data()
        .to_vec();
    let crop = st
        .tensor("satellite_encoder.satellite")
        .expect("crop")
        .data()
        .to_vec();
    let can_bus: [f32; 18] = f32s(&st, "bev_query.can_bus")
        .try_into()
        .expect("18 values");
    let query = f32s(&st, "bev_encoder.bev_query");
    let gathered = f32s(&st, "bev_encoder.gathered");
    let cam_bev = f32s(&st, "map_decoder.camera_bev");
    let sat_bev = f32s(&st, "map_decoder.satellite_bev");
    let name = bundle
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();

    let mut value = vec![0.0; config.value_len()];
    let mut q = vec![0.0; config.bev_len()];
    let mut w = vec![0.0; config.weights_len()];
    let mut bev = vec![0.0; config.bev_len()];
    let mut logits = vec![0.0; config.logits_len()];
    let mut points = vec![0.0; config.points_len()];
    let mut g = c.benchmark_group(format!("stage/{name}"));
    g.sample_size(10);
    g.bench_function("image_encoder", |b| {
        b.iter(|| {
            engine
                .encode_image(0, black_box(&image), &mut value)
                .expect("runs")
        })
    });
    g.bench_function("bev_query", |b| {
        b.iter(|| {
            engine
                .bev_query(black_box(&can_bus), &mut q, &mut w)
                .expect("runs")
        })
    });
    g.bench_function("bev_encoder", |b| {
        b.iter(|| {
            engine
                .bev_encode(black_box(&query), &gathered, &mut bev)
                .expect("runs")
        })
    });
    g.bench_function("satellite_encoder", |b| {
        b.iter(|| {
            engine
                .encode_satellite(black_box(&crop), &mut bev)
                .expect("runs")
        })
    });
    g.bench_function("map_decoder", |b| {
        b.iter(|| {
            engine
                .decode_map(black_box(&cam_bev), &sat_bev, &mut logits, &mut points)
                .expect("runs")
        })
    });
    g.finish();

    let calibration =
        from_toml_file(&root.join("models/calibration/nuscenes_like.toml")).expect("calibration");
    let mut map = SatMap::new(engine, &calibration, FixedCrop(&crop)).expect("init");
    let (width_px, height_px) = (config.image_w as u32, config.image_h as u32);
    let mut sequence = 0u64;
    let mut g = c.benchmark_group(format!("step/{name}"));
    g.sample_size(10);
    g.bench_function("step", |b| {
        b.iter(|| {
            sequence += 1;
            let frame = Frame {
                sequence,
                timestamp_us: sequence * 100_000,
                pose: EgoPose::new(DVec2::ZERO, 0.3),
                motion: EgoMotion {
                    acceleration_mps2: Vec3::new(0.1, 0.4, 0.0),
                    rotation_rate_radps: Vec3::new(0.0, 0.0, 0.05),
                    velocity_mps: Vec3::new(0.0, 10.0, 0.0),
                },
                images: core::array::from_fn(|_| {
                    Some(CameraImage {
                        width_px,
                        height_px,
                        rgb: &image,
                        capture_us: 0,
                        valid: true,
                    })
                }),
            };
            map.step(black_box(&frame)).expect("steps").digest
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
