//! Native GKT gather-sum, look-up-table build and the table's per-step integrity check, for the `test` and paper shapes, with the
//! table built from the committed nuScenes-like calibration.
//!
//! Run: `cargo bench -p satmap-core --features std --bench gkt_kernel` (`std` for the AVX2 detection the product uses).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use satmap_core::ModelDims;
use satmap_core::gkt::{Lut, gather_sum};

fn noise(len: usize, seed: u32) -> Vec<f32> {
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
    let calibration = satmap_core::calibration_rig::NUSCENES_LIKE;
    for (name, dims) in [
        ("test", ModelDims::test_config()),
        ("paper", ModelDims::paper_config()),
    ] {
        let lut = Lut::new(&dims, &calibration).expect("LUT builds");
        let values = noise(6 * dims.value_len(), 1);
        let weights = noise(dims.weights_len(), 2);
        let mut out = vec![0.0f32; dims.bev_len()];
        c.bench_function(&format!("gather_sum/{name}"), |b| {
            b.iter(|| {
                gather_sum(
                    &lut,
                    black_box(&values),
                    black_box(&weights),
                    &mut out,
                    satmap_core::CameraMask::ALL,
                )
                .expect("sizes match");
                black_box(&out);
            });
        });
        // The digest every step checks before the gather (the table is caller memory).
        c.bench_function(&format!("lut_verify/{name}"), |b| {
            b.iter(|| black_box(&lut).verify().expect("the table is intact"));
        });
        let mut lut = lut;
        c.bench_function(&format!("lut_rebuild/{name}"), |b| {
            b.iter(|| {
                lut.rebuild(black_box(&calibration))
                    .expect("valid calibration")
            });
        });
        eprintln!(
            "{name}: {} (camera, query) entries for {} queries",
            lut.len(),
            dims.num_queries()
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
