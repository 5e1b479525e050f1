//! The packed int8 weight format of the integer product.
//!
//! The weights `W [k][n]` are packed in panels of [`QNR`] columns; a panel is `padded_k(k) / 4`
//! lines of 64 bytes ([`Line`]), line `g` holding, for each of the panel's columns `c` in turn,
//! the four values `W[4g..4g + 4][c]` (zeros past `k` and past `n`). That is the operand of one
//! 4-way dot-product instruction per 4 columns (`vpdpbusd`, `sdot`): a line is one 16-lane
//! AVX-512 vector, two AVX2 vectors, four NEON vectors. Activations are rows of `padded_k(k)`
//! bytes (zeros past `k`), read four at a time.

use super::{MAX_K, QNR};

/// Bytes of a line: four `k` values of each of a panel's columns.
pub const LINE: usize = 4 * QNR;

/// One 64-byte line of a panel, on a 64-byte boundary.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct Line(pub [i8; LINE]);

/// `k` rounded up to a whole number of 4-value groups: an activation row's stride.
#[must_use]
pub const fn padded_k(k: usize) -> usize {
    k.div_ceil(4) * 4
}

/// Int8 weights packed for the integer product, with each column's sum.
#[derive(Clone, Debug)]
pub struct PackedQB {
    k: usize,
    n: usize,
    lines: Vec<Line>,
    col_sums: Vec<i32>,
}

/// Weights that cannot be packed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PackError {
    /// `w` does not hold `k x n` values.
    #[error("int8 weights: {len} values for {k} x {n}")]
    Size {
        /// Values given.
        len: usize,
        /// Rows (the summed axis).
        k: usize,
        /// Columns.
        n: usize,
    },
    /// The summed axis is longer than an i32 sum is exact for.
    #[error("int8 weights: k = {k} over the exact limit {MAX_K}")]
    TooLong {
        /// The summed axis.
        k: usize,
    },
}

impl PackedQB {
    /// Pack `w`, row-major `[k][n]`.
    ///
    /// # Errors
    /// `w` not `k x n`, or `k` over [`MAX_K`].
    pub fn pack(w: &[i8], k: usize, n: usize) -> Result<Self, PackError> {
        if k.checked_mul(n) != Some(w.len()) {
            return Err(PackError::Size { len: w.len(), k, n });
        }
        if k > MAX_K {
            return Err(PackError::TooLong { k });
        }
        let groups = padded_k(k) / 4;
        let panels = n.div_ceil(QNR);
        let mut lines = vec![Line([0; LINE]); panels * groups];
        let mut col_sums = vec![0i32; panels * QNR];
        for (kk, row) in w.chunks_exact(n.max(1)).enumerate().take(k) {
            for (col, &v) in row.iter().enumerate() {
                let (p, c) = (col / QNR, col % QNR);
                lines[p * groups + kk / 4].0[4 * c + kk % 4] = v;
                col_sums[col] += i32::from(v);
            }
        }
        Ok(Self {
            k,
            n,
            lines,
            col_sums,
        })
    }

    /// The summed axis.
    #[must_use]
    pub fn k(&self) -> usize {
        self.k
    }

    /// Output columns.
    #[must_use]
    pub fn n(&self) -> usize {
        self.n
    }

    /// Panels of [`QNR`] columns.
    #[must_use]
    pub fn panels(&self) -> usize {
        self.n.div_ceil(QNR)
    }

    /// Panel `p`'s lines (`padded_k(k) / 4` of them).
    pub(crate) fn panel(&self, p: usize) -> &[Line] {
        let groups = padded_k(self.k) / 4;
        &self.lines[p * groups..][..groups]
    }

    /// Each column's sum of weights, [`QNR`] a panel (zeros past `n`).
    #[must_use]
    pub fn col_sums(&self) -> &[i32] {
        &self.col_sums
    }

    /// Bytes the packed weights take.
    #[must_use]
    pub fn bytes(&self) -> usize {
        self.lines.len() * LINE + self.col_sums.len() * 4
    }
}
