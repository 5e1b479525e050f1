//! The AVX2 + FMA tier: the tile in four sub-tiles of 6 rows x 16 columns, each 12 accumulators
//! (6 rows x two 8-lane vectors) of the 16 registers, with the two B vectors and the broadcast
//! of A beside them: per `k` two loads and six broadcasts for twelve fused multiply-adds (the
//! shape of tract's own AVX2 kernel, 16 x 6). A sub-tile wholly past the tile's rows or
//! columns is skipped; the sums go back to [`Sums`] for the finish.

use core::arch::x86_64::*;

use super::{MR, NR, Sums};

/// Rows of a sub-tile.
const SUB_ROWS: usize = 6;
/// Columns of a sub-tile (two 8-lane vectors).
const SUB_COLS: usize = 16;

/// The block's chains into `sums`, for a tile of `rows x cols` valid values.
///
/// # Safety
/// The CPU has AVX2 and FMA; `b` holds at least `a.len() / MR` steps of [`NR`] values.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn tile(a: &[f32], b: &[f32], sums: &mut Sums, (rows, cols): (usize, usize)) {
    const _: () = assert!(MR == 2 * SUB_ROWS && NR == 2 * SUB_COLS);
    let kc = a.len() / MR;
    for r0 in (0..rows).step_by(SUB_ROWS) {
        for c0 in (0..cols).step_by(SUB_COLS) {
            // SAFETY: the caller's contract; `r0 + SUB_ROWS <= MR`, `c0 + SUB_COLS <= NR`.
            unsafe { sub_tile(a, b, sums, (r0, c0), kc) };
        }
    }
}

/// Rows `r0..r0 + 6`, columns `c0..c0 + 16` of the tile over `kc` steps.
///
/// # Safety
/// As [`tile`], with `r0 + SUB_ROWS <= MR`, `c0 + SUB_COLS <= NR` and `kc` steps in `a`, `b`.
#[target_feature(enable = "avx2,fma")]
unsafe fn sub_tile(a: &[f32], b: &[f32], sums: &mut Sums, (r0, c0): (usize, usize), kc: usize) {
    let mut acc = [[_mm256_setzero_ps(); 2]; SUB_ROWS];
    // SAFETY: every row index is `r0 + r < MR` and every lane `c0 + 16 <= NR` (contract);
    // `ap` and `bp` step `kc` times through `a` and `b` (contract).
    unsafe {
        /// Expands `$body!(r)` for the six rows with `r` a literal, so that the accumulators
        /// stay in registers.
        macro_rules! rows {
            ($body:ident) => {
                $body!(0);
                $body!(1);
                $body!(2);
                $body!(3);
                $body!(4);
                $body!(5);
            };
        }
        macro_rules! load {
            ($r:literal) => {
                let p = sums[r0 + $r][c0..].as_ptr();
                acc[$r][0] = _mm256_loadu_ps(p);
                acc[$r][1] = _mm256_loadu_ps(p.add(8));
            };
        }
        rows!(load);
        let (mut ap, mut bp) = (a.as_ptr().add(r0), b.as_ptr().add(c0));
        // B through the masked load, all lanes on: `_mm256_loadu_ps` is a `copy_nonoverlapping`
        // whose precondition checks (on in the test profile, which `make bench-peers` runs)
        // cost this loop a third of its speed.
        let all = _mm256_set1_epi32(-1);
        for _ in 0..kc {
            let b0 = _mm256_maskload_ps(bp, all);
            let b1 = _mm256_maskload_ps(bp.add(8), all);
            macro_rules! step {
                ($r:literal) => {
                    let x = _mm256_broadcast_ss(&*ap.add($r));
                    acc[$r][0] = _mm256_fmadd_ps(x, b0, acc[$r][0]);
                    acc[$r][1] = _mm256_fmadd_ps(x, b1, acc[$r][1]);
                };
            }
            rows!(step);
            ap = ap.add(MR);
            bp = bp.add(NR);
        }
        macro_rules! store {
            ($r:literal) => {
                let p = sums[r0 + $r][c0..].as_mut_ptr();
                _mm256_storeu_ps(p, acc[$r][0]);
                _mm256_storeu_ps(p.add(8), acc[$r][1]);
            };
        }
        rows!(store);
    }
}
