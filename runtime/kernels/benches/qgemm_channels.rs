//! The channel-first integer product (the int8 convolutions') per tier on one block of patch
//! panels as `QuantConv` runs it: `test`'s 8-channel stem (k 196 in the quad map's order: 3
//! channels padded to 4, 7x7 taps) and decoder convolution (32 channels, k 576), `nano`'s
//! 64-channel layer (k 576) and its decoder's deepest (256 channels, k 4608), 16 panels a block
//! (2 for k 4608, as the op sizes blocks), one thread. A tier this CPU lacks is not measured
//! (and says so). Throughput in elements is multiply-adds.
//!
//! Run: `cargo bench -p satmap-kernels --bench qgemm_channels`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use satmap_kernels::qgemm::pack::LINE;
use satmap_kernels::qgemm::{self, IntTier, Line, QRows, RowFinish};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("qgemm_channels");
    for (m, k, panels) in [(8, 196, 16), (32, 576, 16), (64, 576, 16), (256, 4608, 2)] {
        let w: Vec<i8> = (0..m * k).map(|i| ((i * 37) % 255) as u8 as i8).collect();
        let rows = QRows::from_int8(&w, m, k).unwrap();
        let groups = k / 4;
        let mut lines = vec![Line([0; LINE]); panels * groups];
        for (i, line) in lines.iter_mut().enumerate() {
            for (j, v) in line.0.iter_mut().enumerate() {
                *v = ((i * 64 + j) * 31 % 251) as u8 as i8;
            }
        }
        let cols = panels * qgemm::QNR;
        let scale = vec![1e-3f32; m];
        let bias = vec![0.5f32; m];
        let mut out = vec![0.0f32; m * cols];
        group.throughput(Throughput::Elements((m * k * cols) as u64));
        for tier in IntTier::ALL {
            if !tier.runs_here() {
                eprintln!("qgemm_channels/{tier}: skipped, this CPU lacks the tier");
                continue;
            }
            let finish = RowFinish {
                scale: &scale,
                bias: Some(&bias),
                residual: None,
                floor: Some(0.0),
            };
            group.bench_function(format!("{tier} m{m} k{k} cols{cols}"), |bch| {
                bch.iter(|| {
                    qgemm::channel_product(
                        tier,
                        &rows,
                        black_box(&lines),
                        cols,
                        finish,
                        &mut out,
                        cols,
                    )
                    .unwrap()
                });
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
