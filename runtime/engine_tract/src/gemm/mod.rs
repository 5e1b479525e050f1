//! The native f32 matrix product the engine runs its large products on, over the micro-kernel
//! tiers of `satmap-kernels` ([`tier`]).
//!
//! `C[m, n] = A[m, k] B[k, n]`, then a bias per row or column, with the operands packed into
//! panels ([`pack`]) and `k` taken in blocks of [`KC`] so that a block of an A panel stays in
//! L1 while the B panels of a column block ([`NC_PANELS`]) stream from L2; the micro-kernel
//! (`satmap_kernels::gemm::run`) computes one 12 x 32 tile of C. tract 0.23.9 runs these products
//! with a 16 x 12 tile over the whole of `k` (one load per multiply-add, panels streamed from
//! L2 or beyond) at 53-57% of this core's peak (docs/perf.md).
//!
//! Bits: every output is one fused multiply-add chain over `k` ascending from zero, and the
//! bias is added to the finished sum: what tract's f32 kernels compute (their tiles hold one
//! accumulator per output and start from zero; each rewrite's tests compare with tract's plan
//! bit for bit), on every tier alike. The threads split C in whole row panels or column panels
//! ([`product`]); an output's arithmetic does not depend on which thread computes it, so the
//! bits hold for any thread count.

mod blocks;

pub use blocks::WHOLE_B_MAX;

use satmap_kernels::{Tier, TierError};

pub use satmap_kernels::gemm::pack;
pub use satmap_kernels::gemm::{
    AlignedBuf, MR, NR, PackedA, PackedB, TileBias, TileFinish, floor, panels,
};

/// The tier this process runs the native products on: `SATMAP_KERNEL_TIER`'s, or AVX-512F
/// where the CPU has it (`None`: tract's products stay, and the rewrites that plan this product
/// do not run).
///
/// # Errors
/// `SATMAP_KERNEL_TIER` naming no tier, or one this CPU lacks: the engine refuses to load.
pub fn chosen_tier() -> Result<Option<Tier>, TierError> {
    Tier::chosen()
}

/// [`chosen_tier`] where the variable was good (the engine loaded).
#[must_use]
pub fn tier() -> Option<Tier> {
    Tier::chosen().ok().flatten()
}

/// `k` a block: 12 x 256 f32 of an A panel (12 KiB) stay in L1 across a column block.
pub const KC: usize = 256;
/// B panels a column block: 256 x 1024 f32 (1 MiB) stay in L2 across the A panels.
pub const NC_PANELS: usize = 32;

/// Panels a [`BSource::Fill`] call fills at most (256 columns: one gather of a patch row
/// serves 8 panels).
pub const FILL_PANELS: usize = 8;

/// What the product adds to the finished sums.
#[derive(Clone, Copy, Debug)]
pub enum Bias<'a> {
    /// Nothing.
    None,
    /// `m` values, one a row of C (a convolution's output channels).
    PerRow(&'a [f32]),
    /// `n` values, one a column of C (a linear layer's outputs).
    PerCol(&'a [f32]),
}

/// What the product does to its finished sums, in tract's order ([`TileFinish`]): the bias,
/// then a residual, then a floor.
#[derive(Clone, Copy, Debug)]
pub struct Finish<'a> {
    /// The bias.
    pub bias: Bias<'a>,
    /// A dense `m x n` tensor (row stride `n`) added after the bias: a ResNet block's shortcut.
    pub residual: Option<&'a [f32]>,
    /// `max(v, floor)` last (ReLU), as tract's by-scalar `Max` computes it.
    pub floor: Option<f32>,
}

impl<'a> From<Bias<'a>> for Finish<'a> {
    fn from(bias: Bias<'a>) -> Self {
        Self {
            bias,
            residual: None,
            floor: None,
        }
    }
}

impl Finish<'_> {
    /// The finish of one value: `sum` at row `r`, column `col` of an `n`-column product.
    fn scalar(&self, sum: f32, (r, col, n): (usize, usize, usize)) -> f32 {
        let mut v = match self.bias {
            Bias::None => sum,
            Bias::PerRow(b) => sum + b[r],
            Bias::PerCol(b) => sum + b[col],
        };
        if let Some(res) = self.residual {
            v += res[r * n + col];
        }
        match self.floor {
            Some(s) => floor(v, s),
            None => v,
        }
    }
}

/// `fill(j, pc, kc, dst)` of [`BSource::Fill`].
pub type FillPanels<'a> = dyn Fn(usize, usize, usize, &mut [f32]) + Sync + 'a;

/// Where the product reads B.
#[derive(Clone, Copy)]
pub enum BSource<'a> {
    /// Packed once ([`PackedB::as_slice`]): panel `j` whole in `k`.
    Packed(&'a [f32]),
    /// Packed block by block as the product goes: `fill(j, pc, kc, dst)` writes depth rows
    /// `pc..pc + kc` of panels `j..j + dst.len() / (kc * NR)` into `dst`, one panel after the
    /// other (`NR` values a row, zeros past the last column). Called from the engine's threads
    /// with up to [`FILL_PANELS`] panels at a time.
    Fill(&'a FillPanels<'a>),
}

/// The operands of one product.
#[derive(Clone, Copy)]
pub struct Operands<'a> {
    /// A in panels of [`MR`] rows (panel `i` at `i * MR * k`).
    pub a: &'a [f32],
    /// B.
    pub b: BSource<'a>,
    /// Rows of C.
    pub m: usize,
    /// Columns of C.
    pub n: usize,
    /// Depth.
    pub k: usize,
    /// C's row stride (`n` for a dense C).
    pub ldc: usize,
}

impl Operands<'_> {
    /// Values C spans: `m` rows of `n` at `ldc` apart.
    #[must_use]
    pub fn c_len(&self) -> usize {
        if self.m == 0 {
            0
        } else {
            (self.m - 1) * self.ldc + self.n
        }
    }
}

/// The product into `c` (`m` rows of `n` values, row `r` at `r * ldc`, [`Operands::c_len`]
/// long; the values between rows untouched) on the engine's threads, split as `blocks`
/// says, `bias` added to the finished sums. `false` (C in an unspecified state)
/// for operands or a bias shorter than their sizes, or no native [`tier`]: the rewrites that
/// plan this product check both, so that is a bug, never input.
#[must_use]
pub fn product(ops: &Operands<'_>, c: &mut [f32], bias: Bias<'_>) -> bool {
    product_then(ops, c, bias.into())
}

/// [`product`] with a residual and a floor after the bias ([`Finish`]); `false` also for a
/// residual shorter than `m x n`.
#[must_use]
pub fn product_then(ops: &Operands<'_>, c: &mut [f32], finish: Finish<'_>) -> bool {
    let Operands { a, b, m, n, k, ldc } = *ops;
    let bias = finish.bias;
    let n_panels = panels(n, NR);
    let sized = a.len() >= panels(m, MR) * MR * k
        && match b {
            BSource::Packed(all) => all.len() >= n_panels * NR * k,
            BSource::Fill(_) => true,
        }
        && match bias {
            Bias::None => true,
            Bias::PerRow(v) => v.len() >= m,
            Bias::PerCol(v) => v.len() >= n,
        }
        && finish.residual.is_none_or(|res| res.len() >= m * n);
    if !sized || ldc < n || c.len() != ops.c_len() || tier().is_none() {
        return false;
    }
    if m == 0 || n == 0 {
        return true;
    }
    if k == 0 {
        for (r, row) in c.chunks_mut(ldc).enumerate() {
            for (col, v) in row[..n].iter_mut().enumerate() {
                *v = finish.scalar(0.0, (r, col, n));
            }
        }
        return true;
    }
    let scratch_len = match b {
        BSource::Fill(_) => NC_PANELS.min(n_panels) * KC.min(k) * NR,
        BSource::Packed(_) => 0,
    };
    pack::with_scratch(scratch_len, |scratch| {
        blocks::blocks(ops, c, finish, scratch)
    })
}

/// An f32 tensor of `shape` for products that write every one of its values (the rewrites'
/// ops: their products cover the output), left unwritten: zeroing the decoder's
/// `[4, 2000, 2000]` scores first cost a pass over 64 MB.
///
/// # Errors
/// tract refusing the shape (its size overflowing).
pub fn output_tensor(
    shape: &[usize],
) -> tract_nnef::prelude::TractResult<tract_nnef::prelude::Tensor> {
    // SAFETY: f32 has no invalid bit patterns, and each caller's products store every value
    // before the tensor leaves the op (on an error it is dropped unread).
    unsafe { tract_nnef::prelude::Tensor::uninitialized::<f32>(shape) }
}

#[cfg(test)]
mod tests {
    //! The product against a scalar fused multiply-add chain (`f32::mul_add`, `k` ascending
    //! from zero, the bias after), bit for bit, over shapes with edge tiles in every direction,
    //! `k` across block boundaries, and one and two threads.
    use super::*;
    use crate::gemm::pack::pack_a;
    use crate::test_support::on_two_threads;
    use tract_linalg::multithread::Executor;

    /// Deterministic values in [-1, 1) with all mantissa bits in play.
    fn values(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 40) as f32 / (1u64 << 23) as f32 - 1.0
            })
            .collect()
    }

    fn chain(a: &[f32], b: &[f32], m: usize, n: usize, k: usize, finish: Finish<'_>) -> Vec<u32> {
        let mut out = Vec::with_capacity(m * n);
        for r in 0..m {
            for c in 0..n {
                let mut acc = 0.0f32;
                for kk in 0..k {
                    acc = a[r * k + kk].mul_add(b[kk * n + c], acc);
                }
                out.push(finish.scalar(acc, (r, c, n)).to_bits());
            }
        }
        out
    }

    fn run(m: usize, n: usize, k: usize, per_row: bool) -> (Vec<u32>, Vec<u32>) {
        let bias_v = values(m.max(n), 3);
        let bias = if per_row {
            Bias::PerRow(&bias_v)
        } else {
            Bias::PerCol(&bias_v)
        };
        run_then(m, n, k, bias.into())
    }

    /// The product of (m, n, k) with `finish` through every B source and a wider C, and the
    /// scalar chain's bits.
    fn run_then(m: usize, n: usize, k: usize, finish: Finish<'_>) -> (Vec<u32>, Vec<u32>) {
        let a = values(m * k, 1 + m as u64);
        let b = values(k * n, 2 + n as u64);
        let pa = PackedA::from_row_major(&a, m, k);
        let pb = PackedB::from_row_major(&b, k, n);
        let mut ops = Operands {
            a: pa.as_slice(),
            b: BSource::Packed(pb.as_slice()),
            m,
            n,
            k,
            ldc: n,
        };
        let mut c = vec![f32::NAN; m * n];
        assert!(product_then(&ops, &mut c, finish), "{m} x {n} x {k}");
        let got: Vec<u32> = c.iter().map(|v| v.to_bits()).collect();
        // B filled block by block gives the same bits.
        let fill = |j: usize, pc: usize, kc: usize, dst: &mut [f32]| {
            for (jl, panel) in dst.chunks_exact_mut(kc * NR).enumerate() {
                panel.copy_from_slice(&pb.as_slice()[((j + jl) * k + pc) * NR..][..kc * NR]);
            }
        };
        ops.b = BSource::Fill(&fill);
        let mut c2 = vec![f32::NAN; m * n];
        assert!(product_then(&ops, &mut c2, finish), "{m} x {n} x {k}");
        assert_eq!(got, c2.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
        // Into a wider C (row stride n + 5): the same values, the gaps untouched.
        ops.ldc = n + 5;
        let mut wide = vec![f32::NAN; ops.c_len()];
        assert!(product_then(&ops, &mut wide, finish), "{m} x {n} x {k}");
        for (r, row) in wide.chunks(n + 5).enumerate() {
            let want: Vec<u32> = got[r * n..][..n].to_vec();
            assert_eq!(
                row[..n].iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                want
            );
            assert!(row[n..].iter().all(|v| v.is_nan()));
        }
        (got, chain(&a, &b, m, n, k, finish))
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn finishes_add_the_residual_and_floor_after_the_bias_bit_for_bit() {
        // Every split: rows (few columns, deep), whole B (`rows_outer`), columns (filled B),
        // and edges in m and n.
        for (m, n, k) in [(25, 70, 257), (100, 70, 600), (30, 2100, 520), (13, 33, 7)] {
            let bias = values(m, 3);
            let mut residual = values(m * n, 4);
            // A NaN residual makes a NaN sum: the floor gives the floor for it.
            residual[n + 1] = f32::NAN;
            for floor in [Some(0.0), Some(-0.25), None] {
                let finish = Finish {
                    bias: Bias::PerRow(&bias),
                    residual: Some(&residual),
                    floor,
                };
                let (got, want) = run_then(m, n, k, finish);
                assert_eq!(got, want, "{m} x {n} x {k}, floor {floor:?}");
                let two = on_two_threads(|| run_then(m, n, k, finish).0);
                assert_eq!(two, want, "{m} x {n} x {k} on two threads");
                if floor == Some(0.0) && k > 0 {
                    assert_eq!(got[n + 1], 0.0f32.to_bits());
                    assert!(got.iter().all(|&v| f32::from_bits(v) >= 0.0));
                }
            }
        }
        // A residual shorter than m x n is refused.
        let pa = PackedA::from_row_major(&[1.0; 6], 3, 2);
        let pb = PackedB::from_row_major(&[1.0; 8], 2, 4);
        let ops = Operands {
            a: pa.as_slice(),
            b: BSource::Packed(pb.as_slice()),
            m: 3,
            n: 4,
            k: 2,
            ldc: 4,
        };
        let short = Finish {
            bias: Bias::None,
            residual: Some(&[0.0; 11]),
            floor: None,
        };
        assert!(!product_then(&ops, &mut [0.0; 12], short));
    }

    /// The native-tier tests above are ignored on a CPU without a native tier; this fails when
    /// they are ignored on a CPU that has one (or compiled in on one that lacks it), so a
    /// machine with a tier never reports them skipped.
    #[test]
    fn the_native_tier_tests_run_where_this_cpu_has_a_tier() {
        let here = Tier::default_here();
        assert_eq!(
            cfg!(satmap_native_tier_tests),
            here.is_some(),
            "the native-tier tests are built for a CPU {} a native tier, this one has {here:?}: \
             rebuild here",
            if cfg!(satmap_native_tier_tests) {
                "with"
            } else {
                "without"
            },
        );
        if cfg!(satmap_native_tier_tests) {
            // They run on the tier the variable forces, if any: never on none.
            assert!(
                tier().is_some(),
                "SATMAP_KERNEL_TIER={:?} leaves no native tier for the engine's tests",
                std::env::var("SATMAP_KERNEL_TIER")
            );
            eprintln!(
                "native products tested on the {} tier",
                tier().map_or("-", Tier::name)
            );
        }
    }

    #[test]
    fn the_floor_is_rusts_f32_max_on_this_target() {
        // tract's by-scalar Max is `v.max(s)` compiled for x86; `black_box` keeps LLVM from
        // folding it at compile time (its constant folder orders the zeros, the hardware does
        // not).
        let vs = [
            0.0,
            -0.0,
            1.5,
            -1.5,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e-40,
        ];
        for &v in &vs {
            for &s in &vs {
                let (bv, bs) = (std::hint::black_box(v), std::hint::black_box(s));
                assert_eq!(floor(v, s).to_bits(), bv.max(bs).to_bits(), "max({v}, {s})");
            }
        }
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn products_are_the_fma_chain_bit_for_bit() {
        // Edges in m (13, 25), n (33, 70), k across blocks (257, 600) and a whole multiple.
        for (m, n, k) in [
            (1, 1, 1),
            (13, 33, 7),
            (12, 32, 256),
            (25, 70, 257),
            (64, 96, 600),
            (7, 1100, 40),
            (30, 2100, 520),
        ] {
            for per_row in [true, false] {
                let (got, want) = run(m, n, k, per_row);
                assert_eq!(got, want, "{m} x {n} x {k}, per row {per_row}");
            }
        }
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn threads_split_rows_and_columns_without_moving_a_bit() {
        let pool = std::sync::Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap(),
        );
        // 3 column panels: rows split; 10: a filled B splits by columns (`run` checks both).
        for (m, n, k) in [(100, 70, 300), (100, 300, 300), (30, 2100, 520)] {
            let (single, want) = run(m, n, k, true);
            assert_eq!(single, want);
            let two = tract_linalg::multithread::multithread_tract_scope(
                Executor::MultiThread(pool.clone()),
                || run(m, n, k, true).0,
            );
            assert_eq!(two, want, "{m} x {n} x {k}");
            // As the engine runs a plan: on a worker of the pool itself.
            let inside = pool.install(|| {
                tract_linalg::multithread::multithread_tract_scope(
                    Executor::MultiThread(pool.clone()),
                    || run(m, n, k, true).0,
                )
            });
            assert_eq!(inside, want, "{m} x {n} x {k} from a worker");
        }
    }

    #[test]
    fn short_operands_are_refused() {
        let a = PackedA::from_row_major(&[1.0; 12], 3, 4);
        let b = PackedB::from_row_major(&[1.0; 8], 4, 2);
        let ops = Operands {
            a: a.as_slice(),
            b: BSource::Packed(b.as_slice()),
            m: 3,
            n: 2,
            k: 5,
            ldc: 2,
        };
        assert!(!product(&ops, &mut [0.0; 6], Bias::None));
        let ops = Operands { k: 4, ..ops };
        assert!(!product(&ops, &mut [0.0; 5], Bias::None));
        assert!(!product(&ops, &mut [0.0; 6], Bias::PerRow(&[1.0; 2])));
        // The A panel packer pads rows past `m` with zeros.
        let mut dst = vec![9.0; MR * 4];
        pack_a(&[1.0; 12], 3, 4, 4, &mut dst);
        assert!(dst.iter().filter(|&&v| v == 9.0).count() == 0);
    }
}
