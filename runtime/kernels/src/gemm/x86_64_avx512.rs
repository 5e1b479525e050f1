//! The AVX-512F tier: one [`MR`] x [`NR`] tile of C over one block of `k` in registers.
//!
//! 24 accumulators (12 rows x two 16-lane vectors along the row), per `k` two vector loads of
//! B and 12 broadcasts of A for 24 fused multiply-adds: the multiply-adds, not the loads, set
//! the pace (tract's 16x12 tile loads once per multiply-add, and uses 12 of the 32 registers).
//! Edges are masked lanes; the finish runs on the registers before the one store.

use core::arch::x86_64::*;

use super::{MR, NR, Tile, TileBias, TileFinish};

/// Values of A ahead of the current step the kernel prefetches: 32 steps, ~400 cycles.
const A_PREFETCH: usize = 32 * MR;

/// Run `t` (sized by the caller).
///
/// # Safety
/// The CPU has AVX-512F and `t`'s slices cover its sizes ([`Tile`]'s checks in
/// [`super::run`]).
pub(super) unsafe fn run(t: Tile<'_>) {
    let Tile {
        a,
        b,
        c,
        ldc,
        rows,
        cols,
        accumulate,
        finish,
    } = t;
    let shape = (ldc, rows, cols, accumulate);
    // SAFETY: as this function's contract: every pointer the kernel forms stays inside the
    // slices: `kc` steps of MR values of `a` and NR of `b`, rows `< rows` of C at `ldc` apart
    // with lanes `< cols` (masked), bias lanes `< rows` / `< cols`, residual rows `< rows` at
    // `ld` apart with lanes `< cols` (masked).
    unsafe {
        // A panel's last rows past `m` are zeros: a tile of 4 or 8 rows skips their
        // multiply-adds (a 64-channel convolution is 5 full panels and one of 4 rows).
        match rows {
            ..=4 => tile::<4>(a, b, c.as_mut_ptr(), shape, finish),
            5..=8 => tile::<8>(a, b, c.as_mut_ptr(), shape, finish),
            _ => tile::<MR>(a, b, c.as_mut_ptr(), shape, finish),
        }
    }
}

/// Lane masks of the two vectors of a row for `cols` valid columns.
fn masks(cols: usize) -> (__mmask16, __mmask16) {
    let lo = if cols >= 16 {
        0xffff
    } else {
        (1u32 << cols) - 1
    };
    let hi = if cols >= NR {
        0xffff
    } else if cols > 16 {
        (1u32 << (cols - 16)) - 1
    } else {
        0
    };
    (lo as __mmask16, hi as __mmask16)
}

/// Expands `$body!(r)` for the 12 rows, with `r` a literal (the accumulators stay in
/// registers only if every index is a constant).
macro_rules! rows {
    ($body:ident) => {
        $body!(0);
        $body!(1);
        $body!(2);
        $body!(3);
        $body!(4);
        $body!(5);
        $body!(6);
        $body!(7);
        $body!(8);
        $body!(9);
        $body!(10);
        $body!(11);
    };
}

#[target_feature(enable = "avx512f")]
/// `a`, `b` hold `kc` steps of the panels; `c` and `(ldc, rows, cols, accumulate)` as in
/// [`Tile`]; the multiply-adds of the first `R >= rows` rows only.
unsafe fn tile<const R: usize>(
    a: &[f32],
    b: &[f32],
    c: *mut f32,
    (ldc, rows, cols, accumulate): (usize, usize, usize, bool),
    finish: TileFinish<'_>,
) {
    const _: () = assert!(MR == 12 && NR == 32);
    let kc = a.len() / MR;
    let (m0, m1) = masks(cols);
    let zero = _mm512_setzero_ps();
    let mut acc = [[zero; 2]; MR];
    unsafe {
        if accumulate {
            macro_rules! load {
                ($r:literal) => {
                    if $r < rows {
                        let p = c.add($r * ldc);
                        acc[$r][0] = _mm512_maskz_loadu_ps(m0, p);
                        acc[$r][1] = _mm512_maskz_loadu_ps(m1, p.add(16));
                    }
                };
            }
            rows!(load);
        }
        let (mut ap, mut bp) = (a.as_ptr(), b.as_ptr());
        // Loads through the masked intrinsic: `_mm512_loadu_ps` is a `copy_nonoverlapping`
        // whose precondition checks (on in the test profile's debug assertions) sent every
        // vector through the stack, at half the speed.
        let all = 0xffff;
        for _ in 0..kc {
            // A streams from L3 or memory where its product has few columns (ResNet's last
            // stage reads 9 MiB of weights for 60 pixels): ask for it a few hundred cycles
            // ahead. A hint, never a fault, wherever the address falls.
            _mm_prefetch::<_MM_HINT_T0>(ap.wrapping_add(A_PREFETCH).cast());
            let b0 = _mm512_maskz_loadu_ps(all, bp);
            let b1 = _mm512_maskz_loadu_ps(all, bp.add(16));
            macro_rules! step {
                ($r:literal) => {
                    if $r < R {
                        let x = _mm512_set1_ps(*ap.add($r));
                        acc[$r][0] = _mm512_fmadd_ps(x, b0, acc[$r][0]);
                        acc[$r][1] = _mm512_fmadd_ps(x, b1, acc[$r][1]);
                    }
                };
            }
            rows!(step);
            ap = ap.add(MR);
            bp = bp.add(NR);
        }
        match finish.bias {
            TileBias::None => {}
            TileBias::PerRow(b) => {
                macro_rules! row_bias {
                    ($r:literal) => {
                        if $r < rows {
                            let v = _mm512_set1_ps(b[$r]);
                            acc[$r][0] = _mm512_add_ps(acc[$r][0], v);
                            acc[$r][1] = _mm512_add_ps(acc[$r][1], v);
                        }
                    };
                }
                rows!(row_bias);
            }
            TileBias::PerCol(b) => {
                let v0 = _mm512_maskz_loadu_ps(m0, b.as_ptr());
                let v1 = _mm512_maskz_loadu_ps(m1, b.as_ptr().add(16));
                macro_rules! col_bias {
                    ($r:literal) => {
                        acc[$r][0] = _mm512_add_ps(acc[$r][0], v0);
                        acc[$r][1] = _mm512_add_ps(acc[$r][1], v1);
                    };
                }
                rows!(col_bias);
            }
        }
        if let Some((res, ld)) = finish.residual {
            let p = res.as_ptr();
            macro_rules! residual {
                ($r:literal) => {
                    if $r < rows {
                        let q = p.add($r * ld);
                        let v0 = _mm512_maskz_loadu_ps(m0, q);
                        let v1 = _mm512_maskz_loadu_ps(m1, q.add(16));
                        acc[$r][0] = _mm512_add_ps(acc[$r][0], v0);
                        acc[$r][1] = _mm512_add_ps(acc[$r][1], v1);
                    }
                };
            }
            rows!(residual);
        }
        if let Some(floor) = finish.floor {
            // LLVM's x86 lowering of `f32::max(v, s)` (tract's by-scalar Max): `vmaxps(s,
            // v)`, which is `s > v ? s : v` (so `v` for NaN and for equal zeros), then `s`
            // where `v` is NaN.
            let s = _mm512_set1_ps(floor);
            macro_rules! floor {
                ($r:literal) => {
                    for half in 0..2 {
                        let v = acc[$r][half];
                        let nan = _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(v, v);
                        acc[$r][half] = _mm512_mask_blend_ps(nan, _mm512_max_ps(s, v), s);
                    }
                };
            }
            rows!(floor);
        }
        macro_rules! store {
            ($r:literal) => {
                if $r < rows {
                    let p = c.add($r * ldc);
                    _mm512_mask_storeu_ps(p, m0, acc[$r][0]);
                    _mm512_mask_storeu_ps(p.add(16), m1, acc[$r][1]);
                }
            };
        }
        rows!(store);
    }
}
