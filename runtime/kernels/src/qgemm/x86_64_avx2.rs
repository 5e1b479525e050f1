//! The AVX2 tier (no dot-product instructions): each 16-byte quarter of a line (four columns'
//! four `k` values) widened to sixteen i16, the row's four activation bytes widened and
//! repeated beside them, and `vpmaddwd` sums adjacent pairs into i32 (exact: two products of
//! magnitude `<= 2^14`). A column's sum is the sum of its two pair lanes, taken once at the end
//! of the tile. Two rows a pass: eight accumulators, four widened quarters, one activation.

use core::arch::x86_64::*;

use super::channels::{ChannelJob, drive_channels};
use super::pack::Line;
use super::{IntSums, Job, QNR, drive};

/// Rows of one pass.
const PASS_ROWS: usize = 2;

/// The whole product on AVX2.
///
/// # Safety
/// The CPU has AVX2 and FMA; `job`'s slices cover its sizes.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn product(job: &Job<'_>, c: &mut [f32]) {
    let kp = job.kp;
    drive(job, c, false, |a, rows, lines, sums| {
        // SAFETY: the caller's contract; `drive` passes `rows` rows of `kp` bytes.
        unsafe { tile(a, kp, rows, lines, sums) }
    });
}

/// The channel-first product on AVX2 (signed by signed: no offset).
///
/// # Safety
/// The CPU has AVX2 and FMA; `job`'s slices cover its sizes.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn channels(job: &ChannelJob<'_>, c: &mut [f32]) {
    let kp = job.kp;
    drive_channels(job, c, false, |a, rows, lines, sums| {
        // SAFETY: the caller's contract; the driver passes `rows` rows of `kp` bytes.
        unsafe { tile(a, kp, rows, lines, sums) }
    });
}

/// The sums of `rows` rows of `a` against one panel's `lines`.
///
/// # Safety
/// The CPU has AVX2; `1 <= rows <= QMR`; `a` holds `rows` rows of `kp` bytes; `lines.len() ==
/// kp / 4`.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn tile(a: &[i8], kp: usize, rows: usize, lines: &[Line], sums: &mut IntSums) {
    const _: () = assert!(QNR == 16);
    for r0 in (0..rows).step_by(PASS_ROWS) {
        let mut acc = [[_mm256_setzero_si256(); 4]; PASS_ROWS];
        for (g, line) in lines.iter().enumerate() {
            let p = line.0.as_ptr().cast::<__m128i>();
            // SAFETY: a line is four 16-byte quarters on a 64-byte boundary.
            let b = unsafe {
                [
                    _mm256_cvtepi8_epi16(_mm_load_si128(p)),
                    _mm256_cvtepi8_epi16(_mm_load_si128(p.add(1))),
                    _mm256_cvtepi8_epi16(_mm_load_si128(p.add(2))),
                    _mm256_cvtepi8_epi16(_mm_load_si128(p.add(3))),
                ]
            };
            for (r, acc) in acc.iter_mut().enumerate() {
                let row = if r0 + r < rows { r0 + r } else { 0 };
                // SAFETY: `4 * g + 4 <= kp` (contract): the row's 4 bytes of group `g`.
                let v = unsafe {
                    a.as_ptr()
                        .add(row * kp + 4 * g)
                        .cast::<i32>()
                        .read_unaligned()
                };
                let x = _mm256_cvtepi8_epi16(_mm_set1_epi32(v));
                for (acc, &b) in acc.iter_mut().zip(&b) {
                    *acc = _mm256_add_epi32(*acc, _mm256_madd_epi16(x, b));
                }
            }
        }
        for (r, acc) in acc.iter().enumerate().take(rows - r0) {
            for (q, &v) in acc.iter().enumerate() {
                let mut pairs = [0i32; 8];
                // SAFETY: eight i32 into an array of eight.
                unsafe { _mm256_storeu_si256(pairs.as_mut_ptr().cast(), v) };
                for c in 0..4 {
                    sums[r0 + r][4 * q + c] = pairs[2 * c].wrapping_add(pairs[2 * c + 1]);
                }
            }
        }
    }
}
