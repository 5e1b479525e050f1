//! The channel-first integer product of a convolution: `c[o][p] = finish(sum_k w[o][k] *
//! x[k][p])`, the weights' rows (output channels, [`QRows`]) times the patches of a block of
//! output pixels packed in [`Line`] panels (the engine packs them from its quantised map), the
//! output in the
//! convolution's own layout (a channel's pixels in a row), finished per row: the activation's
//! scale times the channel's weight scale, the channel's bias, a residual, a floor.
//!
//! The roles of the linear product swapped: there the activation rows are broadcast and the
//! weights are packed; here the weights are broadcast and the patches packed, so a tile is a
//! few channels by 16 pixels and a convolution of 8 channels over 15,360 pixels fills whole
//! tiles (as a linear product it would fill half of each 16-column panel). The sums are the
//! same exact i32 sums (`generic::tile` defines them) and every tier's tile is the linear
//! product's, but for the VNNI tiers: they flip the sign bits of the packed *patches* (the
//! unsigned operand of `vpdpbusd`) and take away `128 * row sum` of the weights, stored at
//! quantisation, so the correction needs no pass over the patches.

use super::pack::{Line, padded_k};
use super::quantize::{quantize, scale_for};
use super::{IntSums, IntTier, MAX_K, PackError, QMR, QNR, QProductError, check};
use crate::gemm::floor;

/// Int8 weight rows (one an output channel, `padded_k(k)` bytes, zeros past `k`) with each
/// row's sum.
#[derive(Clone, Debug)]
pub struct QRows {
    m: usize,
    k: usize,
    rows: Vec<i8>,
    row_sums: Vec<i32>,
}

impl QRows {
    /// `w [m][k]` (row-major f32) quantised with one symmetric scale per row: the rows and the
    /// scales, `w[o][k] ~= q[o][k] * scales[o]`. Rows that are already int8 times a per-row
    /// scale (an int8 bundle's convolution kernels) come back as exactly those int8 values.
    ///
    /// # Errors
    /// `w` not `m x k` or `k` zero, or `k` over [`MAX_K`].
    pub fn quantise(w: &[f32], m: usize, k: usize) -> Result<(Self, Vec<f32>), PackError> {
        if k == 0 || m.checked_mul(k) != Some(w.len()) {
            return Err(PackError::Size {
                len: w.len(),
                k,
                n: m,
            });
        }
        let mut q = vec![0i8; m * k];
        let mut scales = Vec::with_capacity(m);
        for (src, dst) in w.chunks_exact(k.max(1)).zip(q.chunks_exact_mut(k.max(1))) {
            let s = scale_for(src.iter().fold(0.0f32, |a, v| a.max(v.abs())));
            for (q, &v) in dst.iter_mut().zip(src) {
                // The division, as `weights_per_column`: a stored `q * s` divided by `s` is `q`.
                *q = quantize(v / s, 1.0);
            }
            scales.push(s);
        }
        Ok((Self::from_int8(&q, m, k)?, scales))
    }

    /// Rows `q [m][k]` (row-major int8) as they are.
    ///
    /// # Errors
    /// `q` not `m x k` or `k` zero, or `k` over [`MAX_K`].
    pub fn from_int8(q: &[i8], m: usize, k: usize) -> Result<Self, PackError> {
        if k == 0 || m.checked_mul(k) != Some(q.len()) {
            return Err(PackError::Size {
                len: q.len(),
                k,
                n: m,
            });
        }
        if k > MAX_K {
            return Err(PackError::TooLong { k });
        }
        let kp = padded_k(k);
        let mut rows = vec![0i8; m * kp];
        let mut row_sums = vec![0i32; m];
        for ((src, dst), sum) in q
            .chunks_exact(k.max(1))
            .zip(rows.chunks_exact_mut(kp.max(1)))
            .zip(&mut row_sums)
        {
            dst[..k].copy_from_slice(src);
            *sum = src.iter().map(|&v| i32::from(v)).sum();
        }
        Ok(Self {
            m,
            k,
            rows,
            row_sums,
        })
    }

    /// Rows (output channels).
    #[must_use]
    pub fn m(&self) -> usize {
        self.m
    }

    /// The summed axis.
    #[must_use]
    pub fn k(&self) -> usize {
        self.k
    }

    /// The rows from row `r0` on (the VNNI tiles' operand: x86 only).
    #[cfg(target_arch = "x86_64")]
    pub(crate) fn rows_from(&self, r0: usize) -> &[i8] {
        &self.rows[r0 * padded_k(self.k)..]
    }
}

/// The finish of the channel-first product, per row (output channel).
#[derive(Clone, Copy, Debug)]
pub struct RowFinish<'a> {
    /// One scale per row: the activation's scale times the row's weight scale.
    pub scale: &'a [f32],
    /// One bias per row.
    pub bias: Option<&'a [f32]>,
    /// Values added after the bias, row `r` at `r * ld`, from the block's first column:
    /// `(values, ld)`.
    pub residual: Option<(&'a [f32], usize)>,
    /// `max(v, floor)` last, with [`floor`]'s bits.
    pub floor: Option<f32>,
}

/// `c[o][col] = finish(sum_k w[o][k] * x[k][col])` for every row of `w` and the `cols`
/// columns of `lines` (panels of `padded_k(w.k()) / 4` lines, zeros past `k` and past
/// `cols`); row `o` of `c` at `o * ldc`.
///
/// # Errors
/// A tier this CPU lacks, or slices shorter than the sizes ([`QProductError`]).
pub fn channel_product(
    tier: IntTier,
    w: &QRows,
    lines: &[Line],
    cols: usize,
    finish: RowFinish<'_>,
    c: &mut [f32],
    ldc: usize,
) -> Result<(), QProductError> {
    if !tier.runs_here() {
        return Err(QProductError::TierAbsent { tier });
    }
    let (m, kp) = (w.m, padded_k(w.k));
    let panels = cols.div_ceil(QNR);
    // Sizes a caller could overflow compare as "more than any slice holds".
    let span = |rows: usize, ld: usize| {
        rows.checked_mul(ld)
            .and_then(|v| v.checked_add(cols))
            .unwrap_or(usize::MAX)
    };
    check("lines", lines.len(), panels.saturating_mul(kp / 4))?;
    check("scale", finish.scale.len(), m)?;
    if let Some(bias) = finish.bias {
        check("bias", bias.len(), m)?;
    }
    if m == 0 || cols == 0 {
        return Ok(());
    }
    check("c", c.len(), span(m - 1, ldc))?;
    check("ldc", ldc, cols)?;
    if let Some((res, ld)) = finish.residual {
        check("residual", res.len(), span(m - 1, ld))?;
        check("residual ld", ld, cols)?;
    }
    let job = ChannelJob {
        w,
        kp,
        lines,
        cols,
        finish,
        ldc,
    };
    match tier {
        IntTier::Generic => drive_channels(&job, c, false, |a, rows, lines, sums| {
            super::generic::tile(a, kp, rows, lines, sums);
        }),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX-512 VNNI is present (`runs_here`); the slices cover the sizes (checked
        // above).
        IntTier::X86_64Avx512Vnni => unsafe { super::x86_64_vnni::channels_512(&job, c) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above, with AVX-VNNI.
        IntTier::X86_64AvxVnni => unsafe { super::x86_64_vnni::channels_256(&job, c) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above, with AVX2.
        IntTier::X86_64Avx2 => unsafe { super::x86_64_avx2::channels(&job, c) },
        #[cfg(target_arch = "aarch64")]
        // SAFETY: as above, with the dot-product instructions.
        IntTier::Aarch64Dotprod => unsafe { super::aarch64_dotprod::channels(&job, c) },
        // Tiers of another architecture never run here (`runs_here`).
        #[allow(unreachable_patterns)]
        _ => return Err(QProductError::TierAbsent { tier }),
    }
    Ok(())
}

/// One checked channel-first product: what every tier's driver walks.
pub(crate) struct ChannelJob<'a> {
    /// The weight rows.
    pub w: &'a QRows,
    /// Bytes a weight row.
    pub kp: usize,
    /// The patch panels.
    pub lines: &'a [Line],
    /// Columns (pixels) of the block.
    pub cols: usize,
    /// The finish.
    pub finish: RowFinish<'a>,
    /// C's row stride.
    pub ldc: usize,
}

/// The channel-first product over tiles of [`QMR`] weight rows and one patch panel (a tile's
/// rows against every panel of the block in turn): `tile`
/// sums a tile (the rows, their count, the panel's lines), then (`offset`: the VNNI tiers'
/// flipped patches) `128 * row sum` is taken away and the tile finished. Inlined into each
/// tier's entry, as [`super::drive`].
#[inline(always)]
pub(crate) fn drive_channels(
    job: &ChannelJob<'_>,
    c: &mut [f32],
    offset: bool,
    mut tile: impl FnMut(&[i8], usize, &[Line], &mut IntSums),
) {
    let groups = job.kp / 4;
    let mut sums: IntSums = [[0; QNR]; QMR];
    // A tile's weight rows stay in L1 while the block's panels stream past them.
    for r0 in (0..job.w.m).step_by(QMR) {
        let tile_rows = (job.w.m - r0).min(QMR);
        let a = &job.w.rows[r0 * job.kp..(r0 + tile_rows) * job.kp];
        for panel in 0..job.cols.div_ceil(QNR) {
            let lines = &job.lines[panel * groups..][..groups];
            tile(a, tile_rows, lines, &mut sums);
            finish_tile(job, &mut sums, (r0, tile_rows), panel, offset, c);
        }
    }
}

/// One tile's sums, the offset taken away where `offset`, finished into `c`: shared by every
/// tier, so every tier gives the same bits; inlined into each tier's build so that it is
/// vectorised for its registers.
#[inline(always)]
pub(crate) fn finish_tile(
    job: &ChannelJob<'_>,
    sums: &mut IntSums,
    (r0, rows): (usize, usize),
    panel: usize,
    offset: bool,
    c: &mut [f32],
) {
    let col0 = panel * QNR;
    let cols = (job.cols - col0).min(QNR);
    let f = job.finish;
    for (r, row) in sums.iter_mut().enumerate().take(rows) {
        let o = r0 + r;
        if offset {
            let off = job.w.row_sums[o].wrapping_mul(128);
            for s in row.iter_mut() {
                *s = s.wrapping_sub(off);
            }
        }
        let mut v = [0.0f32; QNR];
        let scale = f.scale[o];
        for (v, &s) in v.iter_mut().zip(row.iter()) {
            *v = s as f32 * scale;
        }
        if let Some(bias) = f.bias {
            let b = bias[o];
            for v in &mut v {
                *v += b;
            }
        }
        if let Some((res, ld)) = f.residual {
            let mut add = [0.0f32; QNR];
            add[..cols].copy_from_slice(&res[o * ld + col0..][..cols]);
            for (v, &x) in v.iter_mut().zip(&add) {
                *v += x;
            }
        }
        if let Some(fl) = f.floor {
            for v in &mut v {
                *v = floor(*v, fl);
            }
        }
        c[o * job.ldc + col0..][..cols].copy_from_slice(&v[..cols]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn int8_rows_times_scales_come_back_exactly() {
        let (m, k) = (3, 9);
        let q: Vec<i8> = (0..m * k)
            .map(|i| {
                if i % k == 4 {
                    127
                } else {
                    (i as i32 * 29 % 200 - 100) as i8
                }
            })
            .collect();
        let s = [0.02f32, 1.5, 3e-4];
        let w: Vec<f32> = (0..m * k).map(|i| f32::from(q[i]) * s[i / k]).collect();
        let (rows, scales) = QRows::quantise(&w, m, k).expect("quantises");
        let kp = padded_k(k);
        for o in 0..m {
            assert_eq!(&rows.rows[o * kp..][..k], &q[o * k..][..k]);
            assert!(rows.rows[o * kp + k..(o + 1) * kp].iter().all(|&v| v == 0));
            let sum: i32 = q[o * k..][..k].iter().map(|&v| i32::from(v)).sum();
            assert_eq!(rows.row_sums[o], sum);
            assert!((scales[o] - s[o]).abs() <= s[o] * 1e-6);
        }
        assert!(QRows::quantise(&w[1..], m, k).is_err());
    }
}
