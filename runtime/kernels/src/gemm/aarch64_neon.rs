//! The NEON tier: the tile in six sub-tiles of 4 rows x 16 columns, each 16 accumulators
//! (4 rows x four 4-lane vectors) of the 32 registers: per `k` one load of four A values, four
//! loads of B and sixteen fused multiply-adds by lane. A sub-tile wholly past the tile's rows
//! or columns is skipped; the sums go back to [`Sums`] for the finish.

use core::arch::aarch64::*;

use super::{MR, NR, Sums};

/// Rows of a sub-tile (one A vector).
const SUB_ROWS: usize = 4;
/// Columns of a sub-tile (four 4-lane vectors).
const SUB_COLS: usize = 16;

/// The block's chains into `sums`, for a tile of `rows x cols` valid values.
///
/// # Safety
/// The CPU has NEON; `b` holds at least `a.len() / MR` steps of [`NR`] values.
#[target_feature(enable = "neon")]
pub(super) unsafe fn tile(a: &[f32], b: &[f32], sums: &mut Sums, (rows, cols): (usize, usize)) {
    const _: () = assert!(MR == 3 * SUB_ROWS && NR == 2 * SUB_COLS);
    let kc = a.len() / MR;
    for r0 in (0..rows).step_by(SUB_ROWS) {
        for c0 in (0..cols).step_by(SUB_COLS) {
            // SAFETY: the caller's contract; `r0 + SUB_ROWS <= MR`, `c0 + SUB_COLS <= NR`.
            unsafe { sub_tile(a, b, sums, (r0, c0), kc) };
        }
    }
}

/// Rows `r0..r0 + 4`, columns `c0..c0 + 16` of the tile over `kc` steps.
///
/// # Safety
/// As [`tile`], with `r0 + SUB_ROWS <= MR`, `c0 + SUB_COLS <= NR` and `kc` steps in `a`, `b`.
#[target_feature(enable = "neon")]
unsafe fn sub_tile(a: &[f32], b: &[f32], sums: &mut Sums, (r0, c0): (usize, usize), kc: usize) {
    // SAFETY: every row index is `r0 + r < MR` and every lane `c0 + 16 <= NR` (contract);
    // `ap` and `bp` step `kc` times through `a` and `b` (contract).
    unsafe {
        let mut acc = [[vdupq_n_f32(0.0); 4]; SUB_ROWS];
        /// Expands `$body!(r)` for the four rows with `r` a literal, so that the accumulators
        /// stay in registers.
        macro_rules! rows {
            ($body:ident) => {
                $body!(0);
                $body!(1);
                $body!(2);
                $body!(3);
            };
        }
        macro_rules! load {
            ($r:literal) => {
                let p = sums[r0 + $r][c0..].as_ptr();
                for v in 0..4 {
                    acc[$r][v] = vld1q_f32(p.add(4 * v));
                }
            };
        }
        rows!(load);
        let (mut ap, mut bp) = (a.as_ptr().add(r0), b.as_ptr().add(c0));
        for _ in 0..kc {
            let x = vld1q_f32(ap);
            let bv = [
                vld1q_f32(bp),
                vld1q_f32(bp.add(4)),
                vld1q_f32(bp.add(8)),
                vld1q_f32(bp.add(12)),
            ];
            macro_rules! step {
                ($r:literal) => {
                    for v in 0..4 {
                        acc[$r][v] = vfmaq_laneq_f32::<$r>(acc[$r][v], bv[v], x);
                    }
                };
            }
            rows!(step);
            ap = ap.add(MR);
            bp = bp.add(NR);
        }
        macro_rules! store {
            ($r:literal) => {
                let p = sums[r0 + $r][c0..].as_mut_ptr();
                for v in 0..4 {
                    vst1q_f32(p.add(4 * v), acc[$r][v]);
                }
            };
        }
        rows!(store);
    }
}
