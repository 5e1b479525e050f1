//! The VNNI tiers: `vpdpbusd` sums four unsigned-by-signed byte products into each i32 lane,
//! so one instruction does four columns' four `k` values a lane. The activations are signed, so
//! each broadcast group of four has its sign bits flipped (`a + 128` as unsigned) and the
//! caller takes `128 * column sum` away afterwards ([`super::product`]); the wrapped i32
//! arithmetic is exact modulo `2^32` and the true sum fits, so the result is exact.
//!
//! AVX-512: a tile's [`QMR`] rows are eight 16-lane accumulators, per group one load of the
//! panel's line and eight broadcasts. AVX-VNNI (8 lanes): two passes of four rows, each eight
//! accumulators and the line's two halves.

use core::arch::x86_64::*;

use super::pack::Line;
use super::{IntSums, QMR, QNR};

/// The four activation bytes of group `g` of row `r` (row `r` at `r * kp`) as one i32, sign
/// bits flipped. Rows past `rows` read row 0 (their sums are never stored).
///
/// # Safety
/// `a` holds `rows >= 1` rows of `kp` bytes and `4 * g + 4 <= kp`.
#[inline(always)]
unsafe fn group(a: &[i8], kp: usize, rows: usize, r: usize, g: usize) -> i32 {
    let row = if r < rows { r } else { 0 };
    // SAFETY: the caller's contract bounds the 4 bytes read.
    let v = unsafe {
        a.as_ptr()
            .add(row * kp + 4 * g)
            .cast::<i32>()
            .read_unaligned()
    };
    v ^ (0x8080_8080_u32 as i32)
}

/// The sums of `rows` rows of `a` against one panel's `lines`, on AVX-512 VNNI.
///
/// # Safety
/// The CPU has AVX-512F and AVX-512 VNNI; `1 <= rows <= QMR`; `a` holds `rows` rows of `kp`
/// bytes; `lines.len() == kp / 4`.
#[target_feature(enable = "avx512f,avx512vnni")]
pub(super) unsafe fn tile_512(
    a: &[i8],
    kp: usize,
    rows: usize,
    lines: &[Line],
    sums: &mut IntSums,
) {
    const _: () = assert!(QNR == 16);
    let mut acc = [_mm512_setzero_si512(); QMR];
    for (g, line) in lines.iter().enumerate() {
        // SAFETY: a line is 64 bytes on a 64-byte boundary.
        let b = unsafe { _mm512_load_si512(line.0.as_ptr().cast()) };
        for (r, acc) in acc.iter_mut().enumerate() {
            // SAFETY: the caller's contract (`4 * g + 4 <= kp`).
            let x = _mm512_set1_epi32(unsafe { group(a, kp, rows, r, g) });
            *acc = _mm512_dpbusd_epi32(*acc, x, b);
        }
    }
    for (row, acc) in sums.iter_mut().zip(acc).take(rows) {
        // SAFETY: a row of sums is 16 i32.
        unsafe { _mm512_storeu_si512(row.as_mut_ptr().cast(), acc) };
    }
}

/// Rows of one AVX-VNNI pass.
const PASS_ROWS: usize = 4;

/// The sums of `rows` rows of `a` against one panel's `lines`, on AVX-VNNI.
///
/// # Safety
/// The CPU has AVX2 and AVX-VNNI; otherwise as [`tile_512`].
#[target_feature(enable = "avx2,avxvnni")]
pub(super) unsafe fn tile_256(
    a: &[i8],
    kp: usize,
    rows: usize,
    lines: &[Line],
    sums: &mut IntSums,
) {
    for r0 in (0..rows).step_by(PASS_ROWS) {
        let mut acc = [[_mm256_setzero_si256(); 2]; PASS_ROWS];
        for (g, line) in lines.iter().enumerate() {
            let p = line.0.as_ptr().cast::<__m256i>();
            // SAFETY: a line is 64 bytes on a 64-byte boundary: two aligned 32-byte halves.
            let (b0, b1) = unsafe { (_mm256_load_si256(p), _mm256_load_si256(p.add(1))) };
            for (r, acc) in acc.iter_mut().enumerate() {
                // SAFETY: the caller's contract (`4 * g + 4 <= kp`).
                let x = _mm256_set1_epi32(unsafe { group(a, kp, rows, r0 + r, g) });
                acc[0] = _mm256_dpbusd_avx_epi32(acc[0], x, b0);
                acc[1] = _mm256_dpbusd_avx_epi32(acc[1], x, b1);
            }
        }
        for (r, acc) in acc.iter().enumerate().take(rows - r0) {
            let p = sums[r0 + r].as_mut_ptr().cast::<__m256i>();
            // SAFETY: a row of sums is 16 i32: two 8-lane halves.
            unsafe {
                _mm256_storeu_si256(p, acc[0]);
                _mm256_storeu_si256(p.add(1), acc[1]);
            }
        }
    }
}
