//! The product's micro-kernel per tier: one 12 x 32 tile over a block of 256 (the engine's
//! `KC`), its panels in L1 as in the engine's blocking; a tier this CPU lacks is not measured
//! (and says so). Throughput in elements is multiply-adds (`kc x 12 x 32` a tile).
//!
//! Run: `cargo bench -p satmap-kernels --bench gemm_tiles`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use satmap_kernels::Tier;
use satmap_kernels::gemm::{self, MR, NR, Tile, TileBias, TileFinish};

/// `k` a block, as the engine's product takes it.
const KC: usize = 256;

fn values(len: usize, seed: u32) -> Vec<f32> {
    let mut s = seed | 1;
    (0..len)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let a = values(KC * MR, 1);
    let b = values(KC * NR, 2);
    let bias = values(NR, 3);
    let mut out = vec![0.0f32; MR * NR];
    let mut group = c.benchmark_group("gemm_tile");
    group.throughput(Throughput::Elements((KC * MR * NR) as u64));
    for tier in Tier::ALL {
        if !tier.runs_here() {
            eprintln!("gemm_tile/{tier}: skipped, this CPU lacks the tier");
            continue;
        }
        // A whole tile (the bulk of every product) and an edge tile of 5 x 17.
        for (rows, cols) in [(MR, NR), (5, 17)] {
            group.bench_function(format!("{tier}/{rows}x{cols}"), |bench| {
                bench.iter(|| {
                    let done = gemm::run(
                        tier,
                        Tile {
                            a: black_box(&a),
                            b: black_box(&b),
                            c: &mut out,
                            ldc: NR,
                            rows,
                            cols,
                            accumulate: false,
                            finish: TileFinish {
                                bias: TileBias::PerCol(&bias),
                                residual: None,
                                floor: Some(0.0),
                            },
                        },
                    );
                    assert!(done, "a tier of this CPU runs a sized tile");
                    black_box(&out);
                });
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
