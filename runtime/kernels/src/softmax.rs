//! The row reductions of the engine's softmax (`RowSoftmax`): the row maximum, and a row's sum
//! in exactly the order one of tract-linalg 0.23.9's `Softmax2` kernels adds it ([`SumOrder`]),
//! so that the engine's softmax gives tract's bits. Portable Rust, one implementation: the
//! order is the contract, and the compiler vectorises the lanes (no per-ISA tier: a tier would
//! have to keep the same lanes and add nothing).

/// The order in which tract's softmax adds up one row's exponentials, per tract-linalg
/// `Softmax2` kernel (read off tract-linalg 0.23.9's `x86_64/softmax.rs`, `generic/reduce.rs`
/// and `frame/element_wise_helper.rs`).
///
/// The driver splits a row at the kernel's alignment: the values before the first aligned
/// address (the prefix), the aligned whole kernel widths (the body), the rest (the suffix). The
/// prefix and the suffix are each staged at the start of a scratch vector padded with values
/// whose exponential is +0, the body runs in place, and the three kernel results are added in
/// that order onto 0. One kernel call keeps `accumulators` vectors of `lanes` lanes: value `i`
/// of the call lands in lane `i % lanes` of accumulator `(i / lanes) % accumulators`; at the end
/// the accumulators are added pairwise (`(a0 + a1) + (a2 + a3)`) and the lanes are folded. A
/// padding value adds +0 to a lane, which changes no sum of non-negative values, so it is left
/// out here.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SumOrder {
    /// `SSoftMaxL2Accurate`: one 4-lane accumulator, lanes folded as `(l0 + l1) + (l2 + l3)`;
    /// 16-byte alignment.
    Generic4,
    /// `x86_64_fma_softmax2_f32_32n`: four 8-lane accumulators, lanes folded by halves (upper
    /// half onto lower: 8 -> 4 -> 2 -> 1); 32-byte alignment.
    Fma8x4,
    /// `x86_64_avx512_softmax2_f32_64n`: four 16-lane accumulators, lanes folded by halves
    /// (`_mm512_reduce_add_ps`: 16 -> 8 -> 4 -> 2 -> 1); 64-byte alignment.
    Avx512x16x4,
}

impl SumOrder {
    /// The order of the kernel tract-linalg names `name`, if it is one this module knows.
    #[must_use]
    pub fn of_kernel(name: &str) -> Option<Self> {
        match name {
            "SSoftMaxL2Accurate" => Some(Self::Generic4),
            "x86_64_fma_softmax2_f32_32n" => Some(Self::Fma8x4),
            "x86_64_avx512_softmax2_f32_64n" => Some(Self::Avx512x16x4),
            _ => None,
        }
    }

    /// The kernel's alignment, in bytes (where the driver splits a row).
    #[must_use]
    #[inline]
    pub const fn align_bytes(self) -> usize {
        match self {
            Self::Generic4 => 16,
            Self::Fma8x4 => 32,
            Self::Avx512x16x4 => 64,
        }
    }

    /// Values one kernel step takes (the body is a whole number of them).
    #[must_use]
    #[inline]
    pub const fn nr(self) -> usize {
        match self {
            Self::Generic4 => 4,
            Self::Fma8x4 => 32,
            Self::Avx512x16x4 => 64,
        }
    }

    /// The sum of `row` (already exponentiated, at its real address: the split depends on it)
    /// in tract's order.
    #[must_use]
    #[inline]
    pub fn row_sum(self, row: &[f32]) -> f32 {
        let nr = self.nr();
        let prefix = row.as_ptr().align_offset(self.align_bytes()).min(row.len());
        let body = (row.len() - prefix) / nr * nr;
        let mut s = 0.0f32;
        if prefix > 0 {
            s += self.call(&row[..prefix]);
        }
        if body > 0 {
            s += self.call(&row[prefix..prefix + body]);
        }
        if prefix + body < row.len() {
            s += self.call(&row[prefix + body..]);
        }
        s
    }

    /// One kernel call's sum over `values` (a whole number of steps, or a staged part of one).
    #[inline]
    fn call(self, values: &[f32]) -> f32 {
        match self {
            Self::Generic4 => {
                let l = accumulate::<4, 1>(values)[0];
                (l[0] + l[1]) + (l[2] + l[3])
            }
            Self::Fma8x4 => fold_halves(pairwise(accumulate::<8, 4>(values))),
            Self::Avx512x16x4 => fold_halves(pairwise(accumulate::<16, 4>(values))),
        }
    }
}

/// The largest value of `row` (exact in any order; NaNs are skipped; `-inf` for an empty row).
/// Written as compare and select, which compiles to vector max instructions (`f32::max` does
/// not, for its NaN rule).
#[must_use]
#[inline]
pub fn row_max(row: &[f32]) -> f32 {
    let pick = |m: f32, x: f32| if x > m { x } else { m };
    let mut lanes = [f32::NEG_INFINITY; 8];
    let chunks = row.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (l, &x) in lanes.iter_mut().zip(c) {
            *l = pick(*l, x);
        }
    }
    rest.iter()
        .fold(lanes.into_iter().fold(f32::NEG_INFINITY, pick), |m, &x| {
            pick(m, x)
        })
}

/// `A` accumulators of `W` lanes over `values`, value `i` into lane `i % W` of accumulator
/// `(i / W) % A`, in ascending order.
fn accumulate<const W: usize, const A: usize>(values: &[f32]) -> [[f32; W]; A] {
    let mut acc = [[0.0f32; W]; A];
    let steps = values.chunks_exact(W * A);
    let rest = steps.remainder();
    for step in steps {
        for (a, part) in acc.iter_mut().zip(step.chunks_exact(W)) {
            for (s, &v) in a.iter_mut().zip(part) {
                *s += v;
            }
        }
    }
    for (i, &v) in rest.iter().enumerate() {
        acc[i / W][i % W] += v;
    }
    acc
}

/// Four accumulators added lane by lane as `(a0 + a1) + (a2 + a3)`.
fn pairwise<const W: usize>(acc: [[f32; W]; 4]) -> [f32; W] {
    std::array::from_fn(|j| (acc[0][j] + acc[1][j]) + (acc[2][j] + acc[3][j]))
}

/// Lanes folded by halves: the upper half added onto the lower until one lane is left.
fn fold_halves<const W: usize>(mut lanes: [f32; W]) -> f32 {
    let mut w = W;
    while w > 1 {
        w /= 2;
        for j in 0..w {
            lanes[j] += lanes[j + w];
        }
    }
    lanes[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values whose sum depends on the order they are added in: 1 then many ulps of it.
    fn order_sensitive(n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| {
                if i % 7 == 0 {
                    1.0
                } else {
                    3.0e-8 * (i as f32 + 1.0)
                }
            })
            .collect()
    }

    #[test]
    fn a_call_adds_in_the_lanes_and_folds_the_kernel_names() {
        // Generic4 over 6 values: lanes [v0 + v4, v1 + v5, v2, v3], folded (l0 + l1) + (l2 + l3).
        let v = order_sensitive(6);
        let lanes = [v[0] + v[4], v[1] + v[5], v[2], v[3]];
        let want = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
        assert_eq!(SumOrder::Generic4.call(&v).to_bits(), want.to_bits());
        // Fma8x4 over 40 values: accumulator j holds values 8j..8j+8 of the first 32, then
        // values 32..40 land in accumulator 0 again.
        let v = order_sensitive(40);
        let mut acc = [[0.0f32; 8]; 4];
        for (i, &x) in v.iter().enumerate() {
            acc[(i / 8) % 4][i % 8] += x;
        }
        let lanes: [f32; 8] =
            std::array::from_fn(|j| (acc[0][j] + acc[1][j]) + (acc[2][j] + acc[3][j]));
        let l4: [f32; 4] = std::array::from_fn(|j| lanes[j] + lanes[j + 4]);
        let l2 = [l4[0] + l4[2], l4[1] + l4[3]];
        assert_eq!(
            SumOrder::Fma8x4.call(&v).to_bits(),
            (l2[0] + l2[1]).to_bits()
        );
    }

    #[test]
    fn a_row_splits_at_the_kernels_alignment() {
        // One buffer, rows starting at every offset: the sum is prefix + body + suffix.
        let buf = order_sensitive(300);
        for order in [SumOrder::Generic4, SumOrder::Fma8x4, SumOrder::Avx512x16x4] {
            for start in 0..20 {
                let row = &buf[start..start + 200];
                let prefix = row
                    .as_ptr()
                    .align_offset(order.align_bytes())
                    .min(row.len());
                let body = (row.len() - prefix) / order.nr() * order.nr();
                let want = order.call(&row[..prefix])
                    + order.call(&row[prefix..prefix + body])
                    + order.call(&row[prefix + body..]);
                let want = if prefix == 0 {
                    // No prefix call: 0 + body, not 0 + (sum of nothing) + body.
                    0.0 + order.call(&row[..body]) + order.call(&row[body..])
                } else {
                    want
                };
                assert_eq!(
                    order.row_sum(row).to_bits(),
                    want.to_bits(),
                    "{order:?} {start}"
                );
            }
        }
    }

    #[test]
    fn the_known_kernels_are_named_and_no_other() {
        assert_eq!(
            SumOrder::of_kernel("SSoftMaxL2Accurate"),
            Some(SumOrder::Generic4)
        );
        assert_eq!(
            SumOrder::of_kernel("x86_64_avx512_softmax2_f32_64n"),
            Some(SumOrder::Avx512x16x4)
        );
        assert_eq!(
            SumOrder::of_kernel("arm64simd_softmax2_fastcompact_f32_16n"),
            None
        );
    }

    #[test]
    fn the_row_maximum_skips_nans_and_keeps_infinities() {
        assert_eq!(row_max(&[]), f32::NEG_INFINITY);
        let mut row: Vec<f32> = (0..37).map(|i| (i as f32 * 0.7).sin()).collect();
        let want = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        assert_eq!(row_max(&row), want);
        row[3] = f32::NAN;
        row[36] = f32::NAN;
        assert_eq!(row_max(&row), want);
        row[20] = f32::INFINITY;
        assert_eq!(row_max(&row), f32::INFINITY);
    }
}
