//! The integer product per tier on the linear layers of the `test` model's BEV stages (3200
//! tokens; k 32 and 64; n 32 to 128), with the activation's quantisation apart: what a
//! `QuantLinear` op spends, one thread. A tier this CPU lacks is not measured (and says so).
//! Throughput in elements is multiply-adds.
//!
//! Run: `cargo bench -p satmap-kernels --bench qgemm_product`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use satmap_kernels::qgemm::{self, IntTier, PackedQB, QFinish, padded_k, quantize};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("qgemm");
    for (m, k, n) in [(3200, 32, 128), (3200, 64, 32), (1000, 256, 32)] {
        let x: Vec<f32> = (0..m * k)
            .map(|i| ((i * 31) % 97) as f32 / 48.0 - 1.0)
            .collect();
        let w: Vec<i8> = (0..k * n).map(|i| ((i * 37) % 255) as i32 as i8).collect();
        let b = PackedQB::pack(&w, k, n).unwrap();
        let scale = vec![1e-3f32; n];
        let bias = vec![0.5f32; n];
        let mut a = vec![0i8; m * padded_k(k)];
        let mut out = vec![0.0f32; m * n];
        group.throughput(Throughput::Elements((m * k) as u64));
        group.bench_function(format!("quantise m{m} k{k}"), |bch| {
            bch.iter(|| quantize::activations(black_box(&x), m, k, 1.0 / 0.01, &mut a));
        });
        group.throughput(Throughput::Elements((m * k * n) as u64));
        for tier in IntTier::ALL {
            if !tier.runs_here() {
                eprintln!("qgemm/{tier}: skipped, this CPU lacks the tier");
                continue;
            }
            let finish = QFinish {
                scale: &scale,
                bias: Some(&bias),
                residual: None,
                floor: None,
            };
            group.bench_function(format!("{tier} m{m} k{k} n{n}"), |bch| {
                bch.iter(|| {
                    qgemm::product(tier, black_box(&a), m, &b, finish, &mut out, n).unwrap()
                });
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
