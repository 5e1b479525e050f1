//! What f16 BEV storage costs a step: one BEV map of nano's size (80 x 40 x 256 values) stored
//! by a stage (rounded from the engine's f32 output) and loaded by the decoder (widened into its
//! f32 input), in f32 storage (copies) and in f16 storage (half's conversions: F16C on x86 and
//! Armv8 `fcvt` where `std`'s detection finds them). A step stores two maps and loads two.
//!
//! Run: `cargo bench -p satmap-core --features std --bench bev_storage`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use half::f16;
use satmap_core::{FeaturesMut, FeaturesRef};

/// Values of one nano BEV map.
const NANO_BEV_LEN: usize = 80 * 40 * 256;

fn bench(c: &mut Criterion) {
    let engine_out: Vec<f32> = (0..NANO_BEV_LEN)
        .map(|i| ((i % 977) as f32 - 488.0) * 0.013)
        .collect();
    let mut wide = vec![0f32; NANO_BEV_LEN];
    let mut half = vec![f16::ZERO; NANO_BEV_LEN];
    let mut decoder_in = vec![0f32; NANO_BEV_LEN];
    let mut g = c.benchmark_group("bev_storage_nano");
    g.bench_function("store_f32", |b| {
        b.iter(|| FeaturesMut::F32(&mut wide).store(black_box(&engine_out)))
    });
    g.bench_function("store_f16", |b| {
        b.iter(|| FeaturesMut::F16(&mut half).store(black_box(&engine_out)))
    });
    g.bench_function("load_f32", |b| {
        b.iter(|| FeaturesRef::F32(black_box(&wide)).load(&mut decoder_in))
    });
    g.bench_function("load_f16", |b| {
        b.iter(|| FeaturesRef::F16(black_box(&half)).load(&mut decoder_in))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
