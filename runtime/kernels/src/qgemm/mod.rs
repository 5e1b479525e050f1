//! The integer product (W8A8): int8 activations times int8 weights, summed in i32, finished in
//! f32 (scale, bias, residual, floor) in the product's one store, per tier ([`IntTier`]).
//!
//! The bits, which `generic.rs` defines: each output's integer sum `sum_k a[r][k] * w[k][c]`
//! is exact in i32 for `k <= MAX_K` (`128 * 128 * MAX_K <= 2^30`), so its order does not matter
//! and every tier gives the same integer; the finish (`finish_rows`) is one portable function
//! every tier shares: `v = (sum as f32) * scale[c]`, then `+ bias[c]`, then `+ residual`, then
//! the floor, one f32 operation each. So every tier gives the generic tier's bits, always.
//!
//! Both operands are symmetric int8 (zero point 0; see [`quantize`]): no zero-point term
//! enters the sum. The tiers: AVX-512 VNNI and AVX-VNNI multiply unsigned by signed bytes
//! (`vpdpbusd`), so they add 128 to each activation (an exclusive or of its sign bit) and
//! subtract `128 * sum_k w[k][c]` (stored with the packed weights, [`PackedQB::col_sums`]);
//! AVX2 widens both to i16 and sums pairs (`vpmaddwd`, exact); aarch64 uses the signed dot
//! product (`sdot`, Armv8.2 `dotprod`).
//!
//! [`channel_product`] is the same product with the roles swapped for convolutions (weights
//! broadcast, patches packed, the output channel-first): see [`channels`].

pub mod channels;
pub mod histogram;
pub mod pack;
pub mod quantize;
mod tier;

#[cfg(target_arch = "aarch64")]
mod aarch64_dotprod;
mod generic;
#[cfg(target_arch = "x86_64")]
mod x86_64_avx2;
#[cfg(target_arch = "x86_64")]
mod x86_64_vnni;

pub use channels::{QRows, RowFinish, channel_product};
pub use pack::{Line, PackError, PackedQB, padded_k};
pub use tier::{INT_TIER_ENV, IntTier, IntTierError};

use crate::gemm::floor;

/// Rows of an integer tile (one call of a tier's kernel).
pub const QMR: usize = 8;

/// Columns of a packed weight panel: one 16-lane vector of i32 sums.
pub const QNR: usize = 16;

/// The longest summed axis: `128 * 128 * MAX_K <= 2^30`, so no sum of int8 products overflows.
pub const MAX_K: usize = 1 << 16;

/// The integer sums of one tile: [`QMR`] rows of one [`QNR`]-column panel.
pub(crate) type IntSums = [[i32; QNR]; QMR];

/// What the product does to its integer sums, in f32, in the order tract's graph computes the
/// float layer: the dequantisation scale, the bias, a residual, a floor.
#[derive(Clone, Copy, Debug)]
pub struct QFinish<'a> {
    /// One scale per output column: the activation's scale times the column's weight scale.
    pub scale: &'a [f32],
    /// One bias per output column.
    pub bias: Option<&'a [f32]>,
    /// Values added after the bias, row `r` at `r * ld`: `(values, ld)`, from the band's first row.
    pub residual: Option<(&'a [f32], usize)>,
    /// `max(v, floor)` last, with [`floor`]'s bits.
    pub floor: Option<f32>,
}

/// A product the slices cannot hold (the caller sizes them: a bug, never input).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum QProductError {
    /// The tier's instructions are not on this CPU.
    #[error("integer tier {tier} is not on this CPU")]
    TierAbsent {
        /// The tier asked for.
        tier: IntTier,
    },
    /// A slice shorter than the sizes it stands for.
    #[error("integer product: {what} holds {len} values, {needed} needed")]
    Short {
        /// Which operand.
        what: &'static str,
        /// Its length.
        len: usize,
        /// What the sizes need.
        needed: usize,
    },
}

/// `c[r][col] = finish(sum_k a[r][k] * b[k][col])` for `rows` rows of `a` (row `r` at
/// `r * padded_k(b.k())`, zeros past `k`), every column of `b`; row `r` of `c` at `r * ldc`.
///
/// # Errors
/// A tier this CPU lacks, or slices shorter than the sizes ([`QProductError`]).
pub fn product(
    tier: IntTier,
    a: &[i8],
    rows: usize,
    b: &PackedQB,
    finish: QFinish<'_>,
    c: &mut [f32],
    ldc: usize,
) -> Result<(), QProductError> {
    if !tier.runs_here() {
        return Err(QProductError::TierAbsent { tier });
    }
    let (n, kp) = (b.n(), padded_k(b.k()));
    check("a", a.len(), rows * kp)?;
    check("scale", finish.scale.len(), n)?;
    if let Some(bias) = finish.bias {
        check("bias", bias.len(), n)?;
    }
    if rows == 0 || n == 0 {
        return Ok(());
    }
    check("c", c.len(), (rows - 1) * ldc + n)?;
    check("ldc", ldc, n)?;
    if let Some((res, ld)) = finish.residual {
        check("residual", res.len(), (rows - 1) * ld + n)?;
        check("residual ld", ld, n)?;
    }
    let job = Job {
        a,
        kp,
        rows,
        b,
        finish,
        ldc,
    };
    match tier {
        IntTier::Generic => drive(&job, c, false, |a, rows, lines, sums| {
            generic::tile(a, kp, rows, lines, sums);
        }),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX-512 VNNI is present (`runs_here`); the slices cover the sizes (checked
        // above, and `PackedQB` holds `kp / 4` lines a panel).
        IntTier::X86_64Avx512Vnni => unsafe { x86_64_vnni::product_512(&job, c) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above, with AVX-VNNI.
        IntTier::X86_64AvxVnni => unsafe { x86_64_vnni::product_256(&job, c) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above, with AVX2.
        IntTier::X86_64Avx2 => unsafe { x86_64_avx2::product(&job, c) },
        #[cfg(target_arch = "aarch64")]
        // SAFETY: as above, with the dot-product instructions.
        IntTier::Aarch64Dotprod => unsafe { aarch64_dotprod::product(&job, c) },
        // Tiers of another architecture never run here (`runs_here`).
        #[allow(unreachable_patterns)]
        _ => return Err(QProductError::TierAbsent { tier }),
    }
    Ok(())
}

/// One checked product: what every tier's driver walks.
pub(crate) struct Job<'a> {
    /// The activation rows (`rows x kp`).
    pub a: &'a [i8],
    /// Bytes an activation row.
    pub kp: usize,
    /// Rows.
    pub rows: usize,
    /// The weights.
    pub b: &'a PackedQB,
    /// The finish.
    pub finish: QFinish<'a>,
    /// C's row stride.
    pub ldc: usize,
}

/// The product over tiles of [`QMR`] rows and one panel: `tile` sums a tile (its activation
/// rows, their count, the panel's lines), then the offset of the unsigned tiers is taken away
/// and the tile finished. Inlined into each tier's entry (compiled with that tier's features),
/// so the finish is vectorised for the tier's registers; every step is exact integer
/// arithmetic or one IEEE operation, so every build gives the same bits.
#[inline(always)]
pub(crate) fn drive(
    job: &Job<'_>,
    c: &mut [f32],
    offset: bool,
    mut tile: impl FnMut(&[i8], usize, &[pack::Line], &mut IntSums),
) {
    let Job {
        a,
        kp,
        rows,
        b,
        finish,
        ldc,
    } = *job;
    let n = b.n();
    let mut sums: IntSums = [[0; QNR]; QMR];
    for r0 in (0..rows).step_by(QMR) {
        let tile_rows = (rows - r0).min(QMR);
        let a_tile = &a[r0 * kp..(r0 + tile_rows) * kp];
        for panel in 0..b.panels() {
            tile(a_tile, tile_rows, b.panel(panel), &mut sums);
            if offset {
                let comp: &[i32; QNR] = b.col_sums()[panel * QNR..][..QNR]
                    .try_into()
                    .unwrap_or(&[0; QNR]);
                for row in sums.iter_mut().take(tile_rows) {
                    for (s, &cs) in row.iter_mut().zip(comp) {
                        *s = s.wrapping_sub(cs.wrapping_mul(128));
                    }
                }
            }
            let col0 = panel * QNR;
            let cols = (n - col0).min(QNR);
            finish_rows(&sums, (r0, tile_rows), (col0, cols), finish, c, ldc);
        }
    }
}

fn check(what: &'static str, len: usize, needed: usize) -> Result<(), QProductError> {
    if len < needed {
        Err(QProductError::Short { what, len, needed })
    } else {
        Ok(())
    }
}

/// The finish of one tile's integer sums into `c`, shared by every tier: scale, bias,
/// residual, floor, one f32 operation each, on whole 16-value rows (an edge panel's values
/// padded into a local row) so that the compiler vectorises them.
#[inline(always)]
fn finish_rows(
    sums: &IntSums,
    (r0, rows): (usize, usize),
    (col0, cols): (usize, usize),
    finish: QFinish<'_>,
    c: &mut [f32],
    ldc: usize,
) {
    let padded = |src: &[f32]| -> [f32; QNR] {
        let mut row = [0.0f32; QNR];
        row[..cols].copy_from_slice(&src[col0..][..cols]);
        row
    };
    let scale = padded(finish.scale);
    let bias = finish.bias.map(padded);
    for (r, row) in sums.iter().enumerate().take(rows) {
        let mut v = [0.0f32; QNR];
        for ((v, &s), &sc) in v.iter_mut().zip(row).zip(&scale) {
            *v = s as f32 * sc;
        }
        if let Some(bias) = &bias {
            for (v, &b) in v.iter_mut().zip(bias) {
                *v += b;
            }
        }
        if let Some((res, ld)) = finish.residual {
            let mut add = [0.0f32; QNR];
            add[..cols].copy_from_slice(&res[(r0 + r) * ld + col0..][..cols]);
            for (v, &x) in v.iter_mut().zip(&add) {
                *v += x;
            }
        }
        if let Some(f) = finish.floor {
            for v in &mut v {
                *v = floor(*v, f);
            }
        }
        c[(r0 + r) * ldc + col0..][..cols].copy_from_slice(&v[..cols]);
    }
}
