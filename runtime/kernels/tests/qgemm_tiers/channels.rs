//! The channel-first integer product's (the convolutions') tests, run for every tier by
//! `int_tier_tests!`: each tier against a scalar reference written out here (the integer sums
//! from the unpacked weights and patches, then the per-channel finish), so against the generic
//! tier, bit for bit, over ragged channels, `k` and pixel counts, every finish and the extreme
//! values.

use satmap_kernels::gemm::floor;
use satmap_kernels::qgemm::{self, IntTier, Line, QProductError, QRows, RowFinish, padded_k};

use super::{bytes, floats};

/// Patches `x [k][cols]` packed as the product reads them (`qgemm::pack`'s line layout): panel
/// `p`'s line `g` holds, for each of its 16 columns `c` in turn, summed rows `4g..4g + 4` of
/// column `16p + c`; zeros past `k` and past `cols`.
fn patch_lines(x: &[i8], k: usize, cols: usize) -> Vec<Line> {
    let groups = padded_k(k) / 4;
    let panels = cols.div_ceil(16);
    let mut lines = vec![Line([0; 64]); panels * groups];
    for kk in 0..k {
        for col in 0..cols {
            let (p, c) = (col / 16, col % 16);
            lines[p * groups + kk / 4].0[4 * c + kk % 4] = x[kk * cols + col];
        }
    }
    lines
}

/// Which finish a case runs.
#[derive(Clone, Copy, Debug)]
enum Finishing {
    Scale,
    Bias,
    BiasResidualFloor,
}

/// Runs one case on `tier` and compares every output (and the values around) with the reference.
fn run_case(
    tier: IntTier,
    w: &[i8],
    x: &[i8],
    (m, k, cols): (usize, usize, usize),
    how: Finishing,
    seed: u64,
) {
    let rows = QRows::from_int8(w, m, k).expect("rows");
    let lines = patch_lines(x, k, cols);
    let scale: Vec<f32> = floats(m, seed + 3)
        .iter()
        .map(|v| v.abs() * 1e-3 + 1e-5)
        .collect();
    let bias = floats(m, seed + 4);
    // The residual with a wider stride than the block, as a convolution's map has.
    let ld = cols + 3;
    let residual = floats(m * ld, seed + 5);
    let (bias_ref, res_ref, fl) = match how {
        Finishing::Scale => (None, None, None),
        Finishing::Bias => (Some(&bias[..]), None, None),
        Finishing::BiasResidualFloor => (Some(&bias[..]), Some(&residual[..]), Some(0.0)),
    };
    let ldc = cols + 2;
    let mut c = vec![-7.5f32; m * ldc];
    let finish = RowFinish {
        scale: &scale,
        bias: bias_ref,
        residual: res_ref.map(|r| (r, ld)),
        floor: fl,
    };
    qgemm::channel_product(tier, &rows, &lines, cols, finish, &mut c, ldc).expect("runs");
    for o in 0..m {
        for p in 0..ldc {
            let got = c[o * ldc + p];
            if p >= cols {
                assert_eq!(got, -7.5, "{tier}: wrote past the row at [{o}][{p}]");
                continue;
            }
            let s: i32 = (0..k)
                .map(|kk| i32::from(w[o * k + kk]) * i32::from(x[kk * cols + p]))
                .sum();
            let mut v = s as f32 * scale[o];
            if let Some(b) = bias_ref {
                v += b[o];
            }
            if let Some(r) = res_ref {
                v += r[o * ld + p];
            }
            let want = fl.map_or(v, |f| floor(v, f));
            assert_eq!(
                got.to_bits(),
                want.to_bits(),
                "{tier} {how:?} m {m} k {k} cols {cols}: [{o}][{p}] {got} vs {want}"
            );
        }
    }
}

pub fn ragged_shapes(tier: IntTier) {
    let mut seed = 100;
    for m in [1, 3, 8, 9, 17, 32] {
        for k in [1, 3, 4, 5, 31, 147] {
            for cols in [1, 15, 16, 17, 33, 40] {
                for how in [
                    Finishing::Scale,
                    Finishing::Bias,
                    Finishing::BiasResidualFloor,
                ] {
                    seed += 1;
                    let w = bytes(m * k, seed);
                    let x = bytes(k * cols, seed + 1);
                    run_case(tier, &w, &x, (m, k, cols), how, seed);
                }
            }
        }
    }
}

pub fn extremes(tier: IntTier) {
    // Every product at its largest magnitude, both signs, over a long `k` (the patches are the
    // VNNI tiers' flipped operand: -128 becomes 0, 127 becomes 255).
    let (m, k, cols) = (9, 4096, 33);
    for (wv, xv) in [
        (127i8, 127i8),
        (127, -128),
        (-128, -128),
        (-128, 127),
        (-127, 1),
    ] {
        let w = vec![wv; m * k];
        let x = vec![xv; k * cols];
        run_case(tier, &w, &x, (m, k, cols), Finishing::Bias, 7);
    }
    let w = vec![127i8; m * k];
    let x: Vec<i8> = (0..k * cols)
        .map(|i| if i % 3 == 0 { -128 } else { 127 })
        .collect();
    run_case(tier, &w, &x, (m, k, cols), Finishing::BiasResidualFloor, 8);
}

pub fn refuses_short_slices(tier: IntTier) {
    let (m, k, cols) = (3, 5, 17);
    let rows = QRows::from_int8(&bytes(m * k, 1), m, k).unwrap();
    let lines = patch_lines(&bytes(k * cols, 2), k, cols);
    let scale = vec![1.0f32; m];
    let finish = RowFinish {
        scale: &scale,
        bias: None,
        residual: None,
        floor: None,
    };
    let mut c = vec![0.0f32; m * cols];
    assert!(matches!(
        qgemm::channel_product(tier, &rows, &lines[1..], cols, finish, &mut c, cols),
        Err(QProductError::Short { what: "lines", .. })
    ));
    assert!(matches!(
        qgemm::channel_product(tier, &rows, &lines, cols, finish, &mut c[1..], cols),
        Err(QProductError::Short { what: "c", .. })
    ));
    let short_scale = RowFinish {
        scale: &scale[1..],
        ..finish
    };
    assert!(matches!(
        qgemm::channel_product(tier, &rows, &lines, cols, short_scale, &mut c, cols),
        Err(QProductError::Short { what: "scale", .. })
    ));
    assert!(c.iter().all(|&v| v == 0.0), "a refused product wrote");
    assert!(QRows::from_int8(&bytes(10, 1), 3, 4).is_err());
    assert!(QRows::from_int8(&[], 3, 0).is_err(), "k = 0");
    // Sizes whose spans overflow are refused, not wrapped.
    assert!(matches!(
        qgemm::channel_product(tier, &rows, &lines, cols, finish, &mut c, usize::MAX),
        Err(QProductError::Short { what: "c", .. })
    ));
}
