//! The packed operand formats of the native product, and the packing into them.
//!
//! A is packed in panels of [`MR`] rows: panel `i` holds, for each `k` ascending, the [`MR`]
//! values `A[i * MR + r][k]` side by side (zeros past the last row). B is packed in panels of
//! [`NR`] columns: panel `j` holds, for each `k`, `B[k][j * NR + c]` (zeros past the last
//! column). A panel is whole in `k`, so a block of `k` is a contiguous slice of it and the
//! engine's blocking of the product needs no format of its own. Every panel starts on a 64-byte
//! line ([`AlignedBuf`]): the kernel's vector loads never split a cache line.

/// Rows of an A panel (the broadcast side of the kernel).
pub const MR: usize = 12;
/// Columns of a B panel (two 16-lane vectors, four 8-lane, eight 4-lane).
pub const NR: usize = 32;

/// Values per 64-byte line.
const LINE: usize = 16;

/// An f32 buffer whose first value sits on a 64-byte boundary.
#[derive(Clone, Debug, Default)]
pub struct AlignedBuf {
    raw: Vec<f32>,
    start: usize,
    len: usize,
}

impl AlignedBuf {
    /// `len` zeros.
    #[must_use]
    pub fn zeros(len: usize) -> Self {
        let raw = vec![0.0f32; len + LINE];
        let start = raw.as_ptr().align_offset(LINE * size_of::<f32>()).min(LINE);
        Self { raw, start, len }
    }

    /// The values.
    #[must_use]
    pub fn as_slice(&self) -> &[f32] {
        &self.raw[self.start..][..self.len]
    }

    /// The values, writable.
    pub fn as_mut_slice(&mut self) -> &mut [f32] {
        &mut self.raw[self.start..][..self.len]
    }
}

std::thread_local! {
    /// Scratch buffers of this thread, one per nesting depth of [`with_scratch`], kept between
    /// products: a fresh buffer of a few MiB is a fresh mapping whose first touch page-faults on
    /// every run. Each only grows, so once every product has run on a thread, no later product
    /// allocates there (what lets a step's allocations end with the step).
    static SCRATCH: std::cell::RefCell<Vec<AlignedBuf>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Nesting depth of [`with_scratch`] on this thread.
    static DEPTH: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Restores the nesting depth when a scratch user returns or unwinds.
struct DepthGuard(usize);

impl Drop for DepthGuard {
    fn drop(&mut self) {
        DEPTH.set(self.0);
    }
}

/// `f` over a scratch of `len` values whose contents are unspecified (the caller writes every
/// value it reads), reused across calls on this thread; nested calls get distinct buffers.
pub fn with_scratch<R>(len: usize, f: impl FnOnce(&mut [f32]) -> R) -> R {
    let depth = DEPTH.get();
    let _restore = DepthGuard(depth);
    DEPTH.set(depth + 1);
    let mut buf = SCRATCH.with(|s| {
        s.borrow_mut()
            .get_mut(depth)
            .map(core::mem::take)
            .unwrap_or_default()
    });
    if buf.len < len {
        buf = AlignedBuf::zeros(len);
    }
    let out = f(&mut buf.as_mut_slice()[..len]);
    SCRATCH.with(|s| {
        let mut s = s.borrow_mut();
        if s.len() <= depth {
            s.resize_with(depth + 1, AlignedBuf::default);
        }
        s[depth] = buf;
    });
    out
}

/// Panels of `MR` (or `NR`) needed for `len` rows (columns).
#[must_use]
pub const fn panels(len: usize, width: usize) -> usize {
    len.div_ceil(width)
}

/// An `m x k` A operand packed once (the constant weights of a convolution).
#[derive(Clone, Debug)]
pub struct PackedA {
    /// Rows.
    pub m: usize,
    /// Depth.
    pub k: usize,
    buf: AlignedBuf,
}

impl PackedA {
    /// Pack the row-major `m x k` matrix `a` (row `r` at `a[r * k..]`).
    ///
    /// # Panics
    /// Never for `a.len() >= m * k`; shorter is a caller bug (checked by the rewrites).
    #[must_use]
    pub fn from_row_major(a: &[f32], m: usize, k: usize) -> Self {
        let mut buf = AlignedBuf::zeros(panels(m, MR) * MR * k);
        pack_a(a, m, k, k, buf.as_mut_slice());
        Self { m, k, buf }
    }

    /// Every panel, one after the other (panel `i` at `i * MR * k`).
    #[must_use]
    pub fn as_slice(&self) -> &[f32] {
        self.buf.as_slice()
    }
}

/// A `k x n` B operand packed once (the constant weights of a linear layer).
#[derive(Clone, Debug)]
pub struct PackedB {
    /// Depth.
    pub k: usize,
    /// Columns.
    pub n: usize,
    buf: AlignedBuf,
}

impl PackedB {
    /// Pack the row-major `k x n` matrix `b` (row `kk` at `b[kk * n..]`).
    #[must_use]
    pub fn from_row_major(b: &[f32], k: usize, n: usize) -> Self {
        let mut buf = AlignedBuf::zeros(panels(n, NR) * NR * k);
        for (kk, row) in b.chunks_exact(n.max(1)).take(k).enumerate() {
            pack_b_row(row, kk, k, buf.as_mut_slice());
        }
        Self { k, n, buf }
    }

    /// Every panel, one after the other.
    #[must_use]
    pub fn as_slice(&self) -> &[f32] {
        self.buf.as_slice()
    }
}

/// Pack the rows of `a` (row `r` of `k` values at `a[r * row_stride..]`) into `dst`, panels of
/// [`MR`] rows; `dst` holds `panels(m, MR) * MR * k` values, the padding rows already zero or
/// overwritten here.
pub fn pack_a(a: &[f32], m: usize, k: usize, row_stride: usize, dst: &mut [f32]) {
    for (i, panel) in dst.chunks_exact_mut(MR * k).enumerate() {
        pack_a_panel(a, m, k, row_stride, i, panel);
    }
}

/// Panel `i` of [`pack_a`] into `panel` (`MR * k` values).
pub fn pack_a_panel(a: &[f32], m: usize, k: usize, row_stride: usize, i: usize, panel: &mut [f32]) {
    // Step by step in `k`, each step's 12 values written together: the panel is written once
    // in order (row by row, it was written 12 times over at a 48-byte stride), the 12 rows
    // read as 12 sequential streams.
    let zeros = [0.0f32; 0];
    let rows: [&[f32]; MR] = std::array::from_fn(|r| {
        let row = i * MR + r;
        if row < m {
            &a[row * row_stride..][..k]
        } else {
            &zeros
        }
    });
    let full = rows.iter().all(|r| r.len() == k);
    for (kk, dst) in panel.chunks_exact_mut(MR).take(k).enumerate() {
        if full {
            for (d, row) in dst.iter_mut().zip(&rows) {
                *d = row[kk];
            }
        } else {
            for (d, row) in dst.iter_mut().zip(&rows) {
                *d = row.get(kk).copied().unwrap_or(0.0);
            }
        }
    }
}

/// Panel `i` of an A read with strides: element `(row, kk)` at `row * rs + kk * cs` of `src`
/// (`panel`: `MR * k` values, zeros past row `m`).
pub fn pack_a_panel_strided(
    src: &[f32],
    (m, k): (usize, usize),
    (rs, cs): (usize, usize),
    i: usize,
    panel: &mut [f32],
) {
    for r in 0..MR {
        let row = i * MR + r;
        for kk in 0..k {
            panel[kk * MR + r] = if row < m {
                src[row * rs + kk * cs]
            } else {
                0.0
            };
        }
    }
}

/// Panel `j` of a B read with strides: element `(kk, col)` at `kk * rs + col * cs` of `src`
/// (`panel`: `NR * k` values, zeros past column `n`).
pub fn pack_b_panel_strided(
    src: &[f32],
    (k, n): (usize, usize),
    (rs, cs): (usize, usize),
    j: usize,
    panel: &mut [f32],
) {
    let cols = NR.min(n - j * NR);
    for (kk, dst) in panel.chunks_exact_mut(NR).take(k).enumerate() {
        let row = &src[kk * rs + j * NR * cs..];
        if cs == 1 {
            dst[..cols].copy_from_slice(&row[..cols]);
        } else {
            for (c, v) in dst[..cols].iter_mut().enumerate() {
                *v = row[c * cs];
            }
        }
        dst[cols..].fill(0.0);
    }
}

/// Write row `kk` of B (its `n` values in `row`) into the packed buffer `dst` of depth `k`.
/// The padding columns of the last panel are left as they are (zero in a fresh buffer).
pub fn pack_b_row(row: &[f32], kk: usize, k: usize, dst: &mut [f32]) {
    for (j, chunk) in row.chunks(NR).enumerate() {
        dst[(j * k + kk) * NR..][..chunk.len()].copy_from_slice(chunk);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scratch_is_reused_and_nested_calls_get_their_own() {
        let first = with_scratch(100, |s| s.as_ptr() as usize);
        let (again, inner) = with_scratch(50, |outer| {
            outer.fill(1.0);
            let inner = with_scratch(50, |inner| {
                inner.fill(2.0);
                inner.as_ptr() as usize
            });
            assert!(outer.iter().all(|&v| v == 1.0));
            (outer.as_ptr() as usize, inner)
        });
        assert_eq!(first, again);
        assert_ne!(again, inner);
    }

    #[test]
    fn buffers_start_on_a_line() {
        for len in [1, 15, 16, 1000] {
            let b = AlignedBuf::zeros(len);
            assert_eq!(b.as_slice().as_ptr() as usize % 64, 0);
            assert_eq!(b.as_slice().len(), len);
        }
    }

    #[test]
    fn a_panels_hold_columns_of_rows_and_zero_padding() {
        let (m, k) = (14, 3);
        let a: Vec<f32> = (0..m * k).map(|v| v as f32).collect();
        let p = PackedA::from_row_major(&a, m, k);
        // Panel 0, k = 2: rows 0..12 of column 2.
        let want: Vec<f32> = (0..MR).map(|r| (r * k + 2) as f32).collect();
        assert_eq!(&p.as_slice()[2 * MR..][..MR], &want[..]);
        // Panel 1, k = 1: rows 12, 13, then zeros.
        let p1 = &p.as_slice()[(k + 1) * MR..][..MR];
        assert_eq!(p1[0], (12 * k + 1) as f32);
        assert_eq!(p1[1], (13 * k + 1) as f32);
        assert!(p1[2..].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn packed_b_matches_its_rows() {
        let (k, n) = (3, 33);
        let b: Vec<f32> = (0..k * n).map(|v| v as f32).collect();
        let p = PackedB::from_row_major(&b, k, n);
        let mut want = vec![0.0; panels(n, NR) * NR * k];
        for (kk, row) in b.chunks_exact(n).enumerate() {
            pack_b_row(row, kk, k, &mut want);
        }
        assert_eq!(p.as_slice(), &want[..]);
    }

    #[test]
    fn b_rows_land_in_their_panels() {
        let (k, n) = (2, 40);
        let mut dst = vec![0.0; panels(n, NR) * NR * k];
        let row: Vec<f32> = (0..n).map(|v| v as f32 + 100.0).collect();
        pack_b_row(&row, 1, k, &mut dst);
        assert_eq!(&dst[NR..2 * NR], &row[..NR]);
        assert_eq!(&dst[(k + 1) * NR..][..n - NR], &row[NR..]);
        assert!(dst[..NR].iter().all(|&v| v == 0.0));
    }
}
