//! The generic tier: the tile's fused multiply-add chains in portable Rust, the definition of
//! the bits every other tier reproduces.

use super::{MR, NR, Sums};

/// `sums[r][c] = fma(a[k][r], b[k][c], sums[r][c])` for `k` ascending over the block, rows
/// `< rows` (the panel's rows past them are zero padding).
pub(super) fn tile(a: &[f32], b: &[f32], sums: &mut Sums, rows: usize) {
    for (ak, bk) in a.chunks_exact(MR).zip(b.chunks_exact(NR)) {
        for (row, &x) in sums.iter_mut().zip(ak).take(rows) {
            for (acc, &y) in row.iter_mut().zip(bk) {
                *acc = x.mul_add(y, *acc);
            }
        }
    }
}
