//! Every tract stage and the whole step, on a bundle's recorded reference inputs
//! (`reference.safetensors`, written by `models/`; read by `bench_stages::ReferenceInputs`, the
//! loader `satmap-sim bench-stages` uses): `test` by default, any bundle through
//! `SATMAP_BENCH_BUNDLE` (an absolute path, e.g. `$PWD/models/build/nano`: benches run in
//! `firmware_sim/`).
//!
//! Run: `cargo bench -p satmap-sim --bench stages --profile test` (the test build's profile,
//! whose code is optimised too).

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use satmap_runtime::calibration::from_toml_file;
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{Engine, FeaturesMut, FeaturesRef, SatMap};
use satmap_sim::cli::bench_stages::{ReferenceInputs, still_frame};

fn bench(c: &mut Criterion) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let bundle = std::env::var("SATMAP_BENCH_BUNDLE")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("models/bundles/test"));
    let mut engine = TractEngine::open(&bundle).expect("bundle loads");
    let config = engine.dims().clone();
    let r = ReferenceInputs::load(&bundle, &config).expect("reference inputs");
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
                .encode_image(0, black_box(&r.image), &mut value)
                .expect("runs")
        })
    });
    g.bench_function("bev_query", |b| {
        b.iter(|| {
            engine
                .bev_query(black_box(&r.can_bus), &mut q, &mut w)
                .expect("runs")
        })
    });
    g.bench_function("bev_encoder", |b| {
        b.iter(|| {
            engine
                .bev_encode(black_box(&r.query), &r.gathered, FeaturesMut::F32(&mut bev))
                .expect("runs")
        })
    });
    g.bench_function("satellite_encoder", |b| {
        b.iter(|| {
            engine
                .encode_satellite(black_box(&r.crop), FeaturesMut::F32(&mut bev))
                .expect("runs")
        })
    });
    g.bench_function("map_decoder", |b| {
        b.iter(|| {
            engine
                .decode_map(
                    FeaturesRef::F32(black_box(&r.camera_bev)),
                    FeaturesRef::F32(&r.satellite_bev),
                    &mut logits,
                    &mut points,
                )
                .expect("runs")
        })
    });
    g.finish();

    let calibration =
        from_toml_file(&root.join("models/calibration/nuscenes_like.toml")).expect("calibration");
    let mut map = SatMap::new(engine, &calibration, FixedCrop(&r.crop)).expect("init");
    let mut sequence = 0u64;
    let mut g = c.benchmark_group(format!("step/{name}"));
    g.sample_size(10);
    g.bench_function("step", |b| {
        b.iter(|| {
            sequence += 1;
            let frame = still_frame(sequence, &r.image, &config);
            map.step(black_box(&frame)).expect("steps").digest
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
