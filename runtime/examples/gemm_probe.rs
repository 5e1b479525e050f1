use satmap_runtime::engine_tract::gemm;
use std::time::Instant;
fn main() {
    for &(m, n, k) in &[
        (12usize, 128usize, 256usize),
        (96, 1024, 256),
        (256, 1024, 2304),
        (64, 3600, 576),
        (256, 3200, 4608),
    ] {
        let a: Vec<f32> = (0..m * k).map(|i| (i % 7) as f32 * 0.1).collect();
        let b: Vec<f32> = (0..k * n).map(|i| (i % 5) as f32 * 0.1).collect();
        let pa = gemm::PackedA::from_row_major(&a, m, k);
        let pb = gemm::PackedB::from_row_major(&b, k, n);
        let mut c = vec![0.0f32; m * n];
        let ops = gemm::Operands {
            a: pa.as_slice(),
            b: gemm::BSource::Packed(pb.as_slice()),
            m,
            n,
            k,
        };
        let flop = 2.0 * (m * n * k) as f64;
        let reps = ((2e10 / flop) as usize).max(3);
        let mut best = f64::MAX;
        for _ in 0..5 {
            let t = Instant::now();
            for _ in 0..reps {
                assert!(gemm::product(&ops, &mut c, gemm::Bias::None));
            }
            best = best.min(t.elapsed().as_secs_f64() / reps as f64);
        }
        println!("{m}x{n}x{k}: {:.1} GFLOP/s", flop / best / 1e9);
    }
}
