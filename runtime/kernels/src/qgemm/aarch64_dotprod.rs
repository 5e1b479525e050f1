//! The aarch64 tier: `sdot` (Armv8.2 `dotprod`) sums four signed byte products into each i32
//! lane, so a line (four 16-byte vectors of four columns' four `k` values) against the row's
//! four activation bytes repeated is four instructions. Four rows a pass: sixteen accumulators
//! of the 32 registers. `sdot` is written as inline assembly: its intrinsic (`vdotq_s32`) is not
//! stable Rust yet.

use core::arch::aarch64::*;
use core::arch::asm;

use super::channels::{ChannelJob, drive_channels};
use super::pack::Line;
use super::{IntSums, Job, QNR, drive};

/// Rows of one pass.
const PASS_ROWS: usize = 4;

/// `acc + (a . b)` per 4-byte lane group.
#[inline(always)]
fn sdot(acc: int32x4_t, a: int8x16_t, b: int8x16_t) -> int32x4_t {
    let mut acc = acc;
    // SAFETY: `sdot` reads and writes vector registers only; callers run with `dotprod`.
    unsafe {
        asm!(
            "sdot {acc:v}.4s, {a:v}.16b, {b:v}.16b",
            acc = inout(vreg) acc,
            a = in(vreg) a,
            b = in(vreg) b,
            options(pure, nomem, nostack, preserves_flags)
        );
    }
    acc
}

/// The whole product with the dot-product instructions.
///
/// # Safety
/// The CPU has the dot-product instructions; `job`'s slices cover its sizes.
#[target_feature(enable = "neon,dotprod")]
pub(super) unsafe fn product(job: &Job<'_>, c: &mut [f32]) {
    let kp = job.kp;
    drive(job, c, false, |a, rows, lines, sums| {
        // SAFETY: the caller's contract; `drive` passes `rows` rows of `kp` bytes.
        unsafe { tile(a, kp, rows, lines, sums) }
    });
}

/// The channel-first product with the dot-product instructions (signed by signed: no offset).
///
/// # Safety
/// The CPU has the dot-product instructions; `job`'s slices cover its sizes.
#[target_feature(enable = "neon,dotprod")]
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
/// The CPU has the dot-product instructions; `1 <= rows <= QMR`; `a` holds `rows` rows of `kp`
/// bytes; `lines.len() == kp / 4`.
#[target_feature(enable = "neon,dotprod")]
#[inline]
unsafe fn tile(a: &[i8], kp: usize, rows: usize, lines: &[Line], sums: &mut IntSums) {
    const _: () = assert!(QNR == 16);
    for r0 in (0..rows).step_by(PASS_ROWS) {
        let mut acc = [[vdupq_n_s32(0); 4]; PASS_ROWS];
        for (g, line) in lines.iter().enumerate() {
            let p = line.0.as_ptr();
            // SAFETY: a line is four 16-byte vectors.
            let b = unsafe {
                [
                    vld1q_s8(p),
                    vld1q_s8(p.add(16)),
                    vld1q_s8(p.add(32)),
                    vld1q_s8(p.add(48)),
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
                let x = vreinterpretq_s8_s32(vdupq_n_s32(v));
                for (acc, &b) in acc.iter_mut().zip(&b) {
                    *acc = sdot(*acc, b, x);
                }
            }
        }
        for (r, acc) in acc.iter().enumerate().take(rows - r0) {
            for (q, &v) in acc.iter().enumerate() {
                // SAFETY: four i32 into the row's columns `4q..4q + 4`.
                unsafe { vst1q_s32(sums[r0 + r][4 * q..].as_mut_ptr(), v) };
            }
        }
    }
}
