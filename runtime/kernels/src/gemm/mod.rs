//! The f32 product's micro-kernel: one [`MR`] x [`NR`] tile of C over one block of `k`, from
//! packed panels ([`pack`]), per tier ([`crate::Tier`]).
//!
//! The bits, which `generic.rs` defines: each output is `acc = fma(a[k], b[k], acc)` for `k`
//! ascending, `acc` starting at zero in the first block and at the stored partial sum after it
//! (an f32 store and load is exact), the chain tract's f32 kernels compute whatever the
//! blocking; after the last block the finish ([`TileFinish`]) adds the bias, then the
//! residual, then takes the floor, each one f32 operation. A vector tier computes the same
//! chain lane by lane (a fused multiply-add is one rounding on every instruction set), so it
//! gives the same bits.
//!
//! The tiers: `x86_64_avx512.rs` keeps the whole tile in 24 registers with masked edges; the
//! AVX2 and NEON tiers, with 16 and 32 registers, walk the tile in sub-tiles over the same
//! panels and finish through `finish_into` (the finish is a few hundred scalar operations a
//! tile against `kc x 384` multiply-adds).

pub mod pack;

#[cfg(target_arch = "aarch64")]
mod aarch64_neon;
mod generic;
#[cfg(target_arch = "x86_64")]
mod x86_64_avx2;
#[cfg(target_arch = "x86_64")]
mod x86_64_avx512;

pub use pack::{AlignedBuf, MR, NR, PackedA, PackedB, panels};

use crate::Tier;

/// What the tile adds to the finished sums (last block only), after the sum as tract does.
#[derive(Clone, Copy, Debug)]
pub enum TileBias<'a> {
    /// Nothing.
    None,
    /// One value a row: the tile's [`MR`] rows (fewer at the edge).
    PerRow(&'a [f32]),
    /// One value a column: the tile's [`NR`] columns (fewer at the edge).
    PerCol(&'a [f32]),
}

/// What a tile does to its finished sums (after its last block of `k`), in the order tract's
/// graph computes them: the convolution's or linear layer's bias, then a residual (`Add` of
/// another tensor of C's shape), then a floor (`Max` with a scalar: ReLU), each one f32 step.
#[derive(Clone, Copy, Debug)]
pub struct TileFinish<'a> {
    /// The bias.
    pub bias: TileBias<'a>,
    /// Values added after the bias, from the tile's first (row `r` at `r * ld`): `(values, ld)`.
    pub residual: Option<(&'a [f32], usize)>,
    /// `max(v, floor)` last, with [`floor`]'s bits.
    pub floor: Option<f32>,
}

impl TileFinish<'_> {
    /// Nothing after the sums.
    pub const NONE: TileFinish<'static> = TileFinish {
        bias: TileBias::None,
        residual: None,
        floor: None,
    };
}

/// `v.max(s)` with the bits of LLVM's x86 lowering of `f32::max` (tract's by-scalar `Max` on
/// x86, which the rewrites replace): `s` for a NaN `v`, else `s > v ? s : v` (so `v` for equal
/// zeros). Every tier's floor computes this, on every instruction set.
#[must_use]
#[inline(always)]
pub fn floor(v: f32, s: f32) -> f32 {
    if v.is_nan() || s > v { s } else { v }
}

/// One tile's place in C and its block of `k`.
pub struct Tile<'a> {
    /// `kc x MR` packed values of A.
    pub a: &'a [f32],
    /// `kc x NR` packed values of B.
    pub b: &'a [f32],
    /// C from the tile's first value: row `r` at `r * ldc`, at least `rows` rows of `cols`.
    pub c: &'a mut [f32],
    /// C's row stride.
    pub ldc: usize,
    /// Valid rows (`1..=MR`).
    pub rows: usize,
    /// Valid columns (`1..=NR`).
    pub cols: usize,
    /// Continue the sums stored in C (every block of `k` but the first).
    pub accumulate: bool,
    /// Applied after the last block ([`TileFinish::NONE`] on the others).
    pub finish: TileFinish<'a>,
}

impl Tile<'_> {
    /// Whether every slice covers the sizes the tile names.
    fn sized(&self) -> bool {
        let Self {
            a,
            b,
            c,
            ldc,
            rows,
            cols,
            finish,
            ..
        } = self;
        let kc = a.len() / MR;
        (1..=MR).contains(rows)
            && (1..=NR).contains(cols)
            && b.len() >= kc * NR
            && c.len() >= (rows - 1) * ldc + cols
            && match finish.bias {
                TileBias::None => true,
                TileBias::PerRow(v) => v.len() >= *rows,
                TileBias::PerCol(v) => v.len() >= *cols,
            }
            && finish
                .residual
                .is_none_or(|(v, ld)| ld >= *cols && v.len() >= (rows - 1) * ld + cols)
    }
}

/// The sums of one tile, row by row, in registers' stead for the tiers that finish through
/// [`finish_into`].
pub(crate) type Sums = [[f32; NR]; MR];

/// Run one tile on `tier`. Returns `false` (C untouched) for a tier whose instructions this CPU
/// lacks or a tile whose slices are too short for its sizes: callers choose the tier with
/// [`Tier::runs_here`] and size the slices, so that is a bug, never input.
pub fn run(tier: Tier, tile: Tile<'_>) -> bool {
    if !tile.sized() || !tier.runs_here() {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    if tier == Tier::X86_64Avx512f {
        // SAFETY: AVX-512F is present (`runs_here`) and the slices cover the tile (`sized`).
        unsafe { x86_64_avx512::run(tile) };
        return true;
    }
    let Tile {
        a,
        b,
        c,
        ldc,
        rows,
        cols,
        accumulate,
        finish,
    } = tile;
    let mut sums: Sums = [[0.0; NR]; MR];
    if accumulate {
        for (r, row) in sums.iter_mut().enumerate().take(rows) {
            row[..cols].copy_from_slice(&c[r * ldc..][..cols]);
        }
    }
    match tier {
        Tier::Generic => generic::tile(a, b, &mut sums, rows),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX2 and FMA are present (`runs_here`); `b` holds `kc` steps (`sized`).
        Tier::X86_64Avx2Fma => unsafe { x86_64_avx2::tile(a, b, &mut sums, (rows, cols)) },
        #[cfg(target_arch = "aarch64")]
        // SAFETY: NEON is present (`runs_here`); `b` holds `kc` steps (`sized`).
        Tier::Aarch64Neon => unsafe { aarch64_neon::tile(a, b, &mut sums, (rows, cols)) },
        // AVX-512F ran above; tiers of another architecture never run here (`runs_here`).
        _ => return false,
    }
    finish_into(&sums, c, (ldc, rows, cols), finish);
    true
}

/// Store the finished `sums` of a `rows x cols` tile into `c` (row `r` at `r * ldc`): the
/// bias, the residual and the floor, in that order, one f32 operation each.
fn finish_into(
    sums: &Sums,
    c: &mut [f32],
    (ldc, rows, cols): (usize, usize, usize),
    finish: TileFinish<'_>,
) {
    for (r, row) in sums.iter().enumerate().take(rows) {
        let out = &mut c[r * ldc..][..cols];
        for (col, (o, &sum)) in out.iter_mut().zip(&row[..cols]).enumerate() {
            let mut v = match finish.bias {
                TileBias::None => sum,
                TileBias::PerRow(b) => sum + b[r],
                TileBias::PerCol(b) => sum + b[col],
            };
            if let Some((res, ld)) = finish.residual {
                v += res[r * ld + col];
            }
            *o = match finish.floor {
                Some(s) => floor(v, s),
                None => v,
            };
        }
    }
}
