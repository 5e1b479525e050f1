//! The VNNI tiers: `vpdpbusd` sums four unsigned-by-signed byte products into each i32 lane,
//! so one instruction does four columns' four `k` values a lane. The activations are signed, so
//! each broadcast group of four has its sign bits flipped (`a + 128` as unsigned) and the
//! driver takes `128 * column sum` away afterwards ([`super::drive`]); the wrapped i32
//! arithmetic is exact modulo `2^32` and the true sum fits, so the result is exact.
//!
//! AVX-512: a tile's [`QMR`] rows are eight 16-lane accumulators, per group one load of the
//! panel's line and eight broadcasts (each a load with the flip). AVX-VNNI (8 lanes): two
//! passes of four rows, each eight accumulators and the line's two halves.

use core::arch::x86_64::*;

use super::channels::{ChannelJob, drive_channels, finish_tile};
use super::pack::Line;
use super::{IntSums, Job, QMR, QNR, drive};

/// The sign bits of four bytes.
const FLIP: i32 = 0x8080_8080_u32 as i32;

/// Each tile row's first byte: rows past `rows` read row 0 (their sums are never stored).
#[inline(always)]
fn row_starts(a: &[i8], kp: usize, rows: usize) -> [*const i8; QMR] {
    core::array::from_fn(|r| {
        let row = if r < rows { r } else { 0 };
        a[row * kp..].as_ptr()
    })
}

/// The whole product on AVX-512 VNNI: tiles of [`QMR`] rows and two panels (sixteen
/// accumulators, per group two line loads and eight broadcasts), the last odd panel alone,
/// each finished in registers: the offset taken away, then the finish's steps as
/// [`super::finish_rows`] takes them, each one IEEE operation (the same bits), stored masked at
/// the edge.
///
/// # Safety
/// The CPU has AVX-512F/BW and AVX-512 VNNI; `job`'s slices cover its sizes.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) unsafe fn product_512(job: &Job<'_>, c: &mut [f32]) {
    let panels = job.b.panels();
    for r0 in (0..job.rows).step_by(QMR) {
        let mut p = 0;
        while p + 2 <= panels {
            // SAFETY: the caller's contract; rows `r0..` and panels `p, p + 1` exist.
            unsafe { tile_512::<2>(job, c, r0, p) };
            p += 2;
        }
        if p < panels {
            // SAFETY: as above, panel `p` exists.
            unsafe { tile_512::<1>(job, c, r0, p) };
        }
    }
}

/// Rows `r0..r0 + QMR` (fewer at the end) of panels `p..p + P`, summed and finished into `c`.
///
/// # Safety
/// As [`product_512`]; `r0 < job.rows`, `p + P <= job.b.panels()`.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
#[inline]
unsafe fn tile_512<const P: usize>(job: &Job<'_>, c: &mut [f32], r0: usize, p: usize) {
    const _: () = assert!(QNR == 16);
    let (kp, rows, n) = (job.kp, (job.rows - r0).min(QMR), job.b.n());
    let starts = row_starts(&job.a[r0 * kp..], kp, rows);
    let lines: [&[Line]; P] = core::array::from_fn(|h| job.b.panel(p + h));
    let flip = _mm512_set1_epi32(FLIP);
    let mut acc = [[_mm512_setzero_si512(); P]; QMR];
    // `g` walks the same line of each of the `P` panels.
    #[allow(clippy::needless_range_loop)]
    for g in 0..kp / 4 {
        // SAFETY: each panel has `kp / 4` lines of 64 bytes on a 64-byte boundary.
        let b: [__m512i; P] =
            core::array::from_fn(|h| unsafe { _mm512_load_si512(lines[h][g].0.as_ptr().cast()) });
        for (acc, &row) in acc.iter_mut().zip(&starts) {
            // SAFETY: `4 * g + 4 <= kp`: four bytes of the row.
            let v = unsafe { row.add(4 * g).cast::<i32>().read_unaligned() };
            let x = _mm512_xor_si512(_mm512_set1_epi32(v), flip);
            for (acc, &b) in acc.iter_mut().zip(&b) {
                *acc = _mm512_dpbusd_epi32(*acc, x, b);
            }
        }
    }
    let f = job.finish;
    for h in 0..P {
        let col0 = (p + h) * QNR;
        let cols = (n - col0).min(QNR);
        let mask: __mmask16 = if cols == QNR { !0 } else { (1u16 << cols) - 1 };
        // SAFETY: the column sums hold `QNR` a panel; the finish's vectors hold `n` values
        // (checked by `product`), read masked past `cols`.
        let (offset, scale) = unsafe {
            (
                _mm512_slli_epi32::<7>(_mm512_loadu_si512(
                    job.b.col_sums()[col0..].as_ptr().cast(),
                )),
                _mm512_maskz_loadu_ps(mask, f.scale[col0..].as_ptr()),
            )
        };
        // SAFETY: as above.
        let bias = f
            .bias
            .map(|b| unsafe { _mm512_maskz_loadu_ps(mask, b[col0..].as_ptr()) });
        let floor = f.floor.map(|s| _mm512_set1_ps(s));
        for (r, acc) in acc.iter().enumerate().take(rows) {
            let sum = _mm512_sub_epi32(acc[h], offset);
            let mut v = _mm512_mul_ps(_mm512_cvtepi32_ps(sum), scale);
            if let Some(bias) = bias {
                v = _mm512_add_ps(v, bias);
            }
            if let Some((res, ld)) = f.residual {
                // SAFETY: the residual holds `rows` rows of `ld >= n` (checked by `product`).
                let x =
                    unsafe { _mm512_maskz_loadu_ps(mask, res[(r0 + r) * ld + col0..].as_ptr()) };
                v = _mm512_add_ps(v, x);
            }
            if let Some(s) = floor {
                // `floor(v, s)`: `s` where `v` is NaN or `s > v`.
                let take = _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(v, v)
                    | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(s, v);
                v = _mm512_mask_blend_ps(take, v, s);
            }
            // SAFETY: C holds `rows` rows of `ldc >= n` (checked by `product`), stored masked.
            unsafe { _mm512_mask_storeu_ps(c[(r0 + r) * job.ldc + col0..].as_mut_ptr(), mask, v) };
        }
    }
}

/// Rows of one AVX-VNNI pass.
const PASS_ROWS: usize = 4;

/// The whole product on AVX-VNNI.
///
/// # Safety
/// The CPU has AVX2 and AVX-VNNI; `job`'s slices cover its sizes.
#[target_feature(enable = "avx2,fma,avxvnni")]
pub(super) unsafe fn product_256(job: &Job<'_>, c: &mut [f32]) {
    let kp = job.kp;
    drive(job, c, true, |a, rows, lines, sums| {
        // SAFETY: the caller's contract; `drive` passes `rows` rows of `kp` bytes.
        unsafe { tile_256::<false>(a, kp, rows, lines, sums) }
    });
}

/// The channel-first product on AVX-VNNI: the patches' sign bits flipped as each line is
/// loaded, `128 * row sum` taken away by the finish ([`super::channels`]).
///
/// # Safety
/// The CPU has AVX2 and AVX-VNNI; `job`'s slices cover its sizes.
#[target_feature(enable = "avx2,fma,avxvnni")]
pub(super) unsafe fn channels_256(job: &ChannelJob<'_>, c: &mut [f32]) {
    let kp = job.kp;
    drive_channels(job, c, true, |a, rows, lines, sums| {
        // SAFETY: the caller's contract; the driver passes `rows` rows of `kp` bytes.
        unsafe { tile_256::<true>(a, kp, rows, lines, sums) }
    });
}

/// The channel-first product on AVX-512 VNNI: tiles of [`QMR`] weight rows and two patch
/// panels (the last odd panel alone), the patches' sign bits flipped as each line is loaded,
/// the sums finished by the shared finish ([`super::channels`]).
///
/// # Safety
/// The CPU has AVX-512F/BW and AVX-512 VNNI; `job`'s slices cover its sizes.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
pub(super) unsafe fn channels_512(job: &ChannelJob<'_>, c: &mut [f32]) {
    let (kp, m) = (job.kp, job.w.m());
    let groups = kp / 4;
    let panels = job.cols.div_ceil(QNR);
    let panel = |p: usize| &job.lines[p * groups..][..groups];
    let mut sums: [IntSums; 2] = [[[0; QNR]; QMR]; 2];
    // A tile's weight rows stay in L1 while the block's panels stream past them.
    for r0 in (0..m).step_by(QMR) {
        let rows = (m - r0).min(QMR);
        let a = job.w.rows_from(r0);
        let mut p = 0;
        while p < panels {
            let pair = p + 2 <= panels;
            if pair {
                // SAFETY: the caller's contract; rows `r0..r0 + rows` and panels `p, p + 1`.
                unsafe { flipped_sums_512::<2>(a, kp, rows, [panel(p), panel(p + 1)], &mut sums) };
            } else {
                // SAFETY: as above, panel `p`.
                unsafe { flipped_sums_512::<1>(a, kp, rows, [panel(p)], &mut sums) };
            }
            for (h, s) in sums.iter_mut().enumerate().take(if pair { 2 } else { 1 }) {
                finish_tile(job, s, (r0, rows), p + h, true, c);
            }
            p += if pair { 2 } else { 1 };
        }
    }
}

/// The sums of `rows` weight rows of `a` against `P` patch panels, the lines' sign bits
/// flipped (unsigned patches + 128 by signed weights), into `sums[..P]`.
///
/// # Safety
/// As [`channels_512`]; `1 <= rows <= QMR`, `a` holds `rows` rows of `kp` bytes, each panel
/// `kp / 4` lines.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
#[inline]
unsafe fn flipped_sums_512<const P: usize>(
    a: &[i8],
    kp: usize,
    rows: usize,
    lines: [&[Line]; P],
    sums: &mut [IntSums; 2],
) {
    const _: () = assert!(QNR == 16);
    let starts = row_starts(a, kp, rows);
    let flip = _mm512_set1_epi32(FLIP);
    let mut acc = [[_mm512_setzero_si512(); P]; QMR];
    #[allow(clippy::needless_range_loop)]
    for g in 0..kp / 4 {
        // SAFETY: each panel has `kp / 4` lines of 64 bytes on a 64-byte boundary.
        let b: [__m512i; P] = core::array::from_fn(|h| {
            _mm512_xor_si512(
                unsafe { _mm512_load_si512(lines[h][g].0.as_ptr().cast()) },
                flip,
            )
        });
        for (acc, &row) in acc.iter_mut().zip(&starts) {
            // SAFETY: `4 * g + 4 <= kp`: four bytes of the row.
            let v = unsafe { row.add(4 * g).cast::<i32>().read_unaligned() };
            let x = _mm512_set1_epi32(v);
            for (acc, &b) in acc.iter_mut().zip(&b) {
                *acc = _mm512_dpbusd_epi32(*acc, b, x);
            }
        }
    }
    for (r, acc) in acc.iter().enumerate().take(rows) {
        for (h, &v) in acc.iter().enumerate() {
            // SAFETY: a row of sums is 16 i32.
            unsafe { _mm512_storeu_si512(sums[h][r].as_mut_ptr().cast(), v) };
        }
    }
}

/// The sums of `rows` rows of `a` against one panel's `lines`, on AVX-VNNI: the rows' bytes
/// are the flipped (unsigned) operand, or with `FLIP_LINES` the lines' (the channel-first
/// product's patches).
///
/// # Safety
/// As [`product_256`]; otherwise as [`tile_512`].
#[target_feature(enable = "avx2,avxvnni")]
#[inline]
unsafe fn tile_256<const FLIP_LINES: bool>(
    a: &[i8],
    kp: usize,
    rows: usize,
    lines: &[Line],
    sums: &mut IntSums,
) {
    let starts = row_starts(a, kp, rows);
    let flip = _mm256_set1_epi32(FLIP);
    for r0 in (0..rows).step_by(PASS_ROWS) {
        let mut acc = [[_mm256_setzero_si256(); 2]; PASS_ROWS];
        for (g, line) in lines.iter().enumerate() {
            let p = line.0.as_ptr().cast::<__m256i>();
            // SAFETY: a line is 64 bytes on a 64-byte boundary: two aligned 32-byte halves.
            let (mut b0, mut b1) = unsafe { (_mm256_load_si256(p), _mm256_load_si256(p.add(1))) };
            if FLIP_LINES {
                b0 = _mm256_xor_si256(b0, flip);
                b1 = _mm256_xor_si256(b1, flip);
            }
            for (r, acc) in acc.iter_mut().enumerate() {
                // SAFETY: `4 * g + 4 <= kp`: four bytes of a row (`r0 + r < QMR`).
                let v = unsafe { starts[r0 + r].add(4 * g).cast::<i32>().read_unaligned() };
                if FLIP_LINES {
                    let x = _mm256_set1_epi32(v);
                    acc[0] = _mm256_dpbusd_avx_epi32(acc[0], b0, x);
                    acc[1] = _mm256_dpbusd_avx_epi32(acc[1], b1, x);
                } else {
                    let x = _mm256_xor_si256(_mm256_set1_epi32(v), flip);
                    acc[0] = _mm256_dpbusd_avx_epi32(acc[0], x, b0);
                    acc[1] = _mm256_dpbusd_avx_epi32(acc[1], x, b1);
                }
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
