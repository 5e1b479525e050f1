//! Minimal reproduction of the tract 0.23.9 limitation that dominates `bev_query` (docs/perf.md):
//! a float `ReduceSum` over a middle axis falls back to ndarray's `sum_axis` (tract's fast paths
//! cover the last axis and leading axes only). The shape is the deformable sampling's weighted
//! corner sum in `test`: `[Q = 3200, heads = 8, 4 corners x 8 points = 32, dh = 4]`, summed over
//! axis 2. The same tensor summed over its last axis (the fast path, same element count) and a
//! plain loop over axis 2 give the scale.
//!
//! Run: `cargo bench -p satmap-engine-tract --bench tract_reduce --profile test`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use tract_nnef::prelude::*;
use tract_nnef::tract_core::ops::nn::Reducer;

const SHAPE: [usize; 4] = [3200, 8, 32, 4];

/// Sum over axis 2 of a row-major `[a, b, c, d]` buffer: `out[a, b, d]`.
fn loop_sum_axis2(x: &[f32], out: &mut [f32]) {
    let [_, _, c, d] = SHAPE;
    for (o, block) in out.chunks_exact_mut(d).zip(x.chunks_exact(c * d)) {
        o.fill(0.0);
        for row in block.chunks_exact(d) {
            for (acc, v) in o.iter_mut().zip(row) {
                *acc += *v;
            }
        }
    }
}

fn bench(c: &mut Criterion) {
    let n: usize = SHAPE.iter().product();
    let data: Vec<f32> = (0..n).map(|i| (i % 97) as f32 * 0.01).collect();
    let input = Tensor::from_shape(&SHAPE, &data).expect("shape");
    let mut out = vec![0.0f32; n / SHAPE[2]];
    let mut g = c.benchmark_group("tract_reduce_sum_3200x8x32x4");
    g.sample_size(10);
    g.bench_function("tract_axis2_middle", |b| {
        b.iter(|| Reducer::Sum.reduce(&[2], black_box(&input)).expect("runs"))
    });
    g.bench_function("tract_axis3_last", |b| {
        b.iter(|| Reducer::Sum.reduce(&[3], black_box(&input)).expect("runs"))
    });
    g.bench_function("plain_loop_axis2", |b| {
        b.iter(|| loop_sum_axis2(black_box(&data), &mut out))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
