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

use rayon::prelude::*;
use satmap_kernels::gemm::Tile;
use satmap_kernels::{Tier, TierError};
use tract_linalg::multithread::{Executor, current_tract_executor};

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
    pack::with_scratch(scratch_len, |scratch| blocks(ops, c, finish, scratch))
}

/// [`product`]'s blocks, B's filled into `scratch` where it is filled.
///
/// On the pool, a B that is filled (a convolution's patches) splits by columns: each task
/// fills and multiplies its own column panels for every row, into a C of its own copied into
/// place at the end, with no step in common (filled blocks need one per block otherwise). So
/// does a packed B with fewer row panels than column panels (the Swin's last stages: 28 tokens
/// against 3072 x 768 weights, where each thread then reads its share of the weights only).
/// Otherwise (a linear layer over many tokens) the rows of C split.
fn blocks(ops: &Operands<'_>, c: &mut [f32], finish: Finish<'_>, scratch: &mut [f32]) -> bool {
    let Operands { a, b, m, n, k, ldc } = *ops;
    let n_panels = panels(n, NR);
    // Inside a pool task already (an op's own split): the product stays on that thread.
    let parallel = worth_threads(m * n * k) && !in_task();
    let tasks = 2 * threads();
    if k > KC && n_panels * k * NR <= WHOLE_B_MAX {
        return rows_outer(ops, c, finish, parallel, tasks);
    }
    let few_rows = panels(m, MR) < n_panels;
    if parallel && n_panels >= tasks && (matches!(b, BSource::Fill(_)) || few_rows) {
        return column_split(ops, c, finish, n_panels.div_ceil(tasks).min(NC_PANELS));
    }
    let rows_per_task = MR * panels(m, MR).div_ceil(tasks).max(1);
    for jc in (0..n_panels).step_by(NC_PANELS) {
        let js = jc..(jc + NC_PANELS).min(n_panels);
        for pc in (0..k).step_by(KC) {
            let kc = KC.min(k - pc);
            let block = Block {
                js: js.clone(),
                c_first: 0,
                pc,
                kc,
                b: match b {
                    BSource::Packed(all) => BlockB::Whole(all, k),
                    BSource::Fill(fill) => {
                        let dst = &mut scratch[..js.len() * kc * NR];
                        let filled =
                            on_threads(parallel, dst, FILL_PANELS * kc * NR, |t, panels| {
                                fill(jc + t * FILL_PANELS, pc, kc, panels);
                                true
                            });
                        if !filled {
                            return false;
                        }
                        BlockB::Block(dst)
                    }
                },
            };
            let done = on_threads(parallel, &mut c[..], rows_per_task * ldc, |t, rows| {
                let rows_here = (rows.len() + ldc - n) / ldc;
                block.tiles(
                    a,
                    (t * rows_per_task / MR, rows_here, rows),
                    (n, k, ldc),
                    finish,
                )
            });
            if !done {
                return false;
            }
        }
    }
    true
}

/// Values of B (every panel over all of `k`) that [`rows_outer`] keeps whole: 1.5 MiB of the
/// core's 2 MiB L2.
pub const WHOLE_B_MAX: usize = 384 * 1024;

/// [`blocks`] for a B of few columns and a deep `k` (ResNet's last stage: 60 pixels against
/// 512 x 4,608 weights): B is laid out whole once (filled where it is filled), then each task
/// takes its A panels one after the other, every block of `k` of a panel in turn, so that A
/// streams once and in address order. Ordered by blocks of `k` first, the A blocks of one
/// depth lie a whole panel (221 KiB there) apart and each is read from L3 at a stride the
/// prefetchers do not follow (the stage ran its three 4,608-deep convolutions at 85 GFLOP/s).
fn rows_outer(
    ops: &Operands<'_>,
    c: &mut [f32],
    finish: Finish<'_>,
    parallel: bool,
    tasks: usize,
) -> bool {
    let Operands { a, b, m, n, k, ldc } = *ops;
    let n_panels = panels(n, NR);
    let rows_per_task = MR * panels(m, MR).div_ceil(tasks).max(1);
    let run = |whole: &[f32], c: &mut [f32]| {
        on_threads(parallel, c, rows_per_task * ldc, |t, rows| {
            let rows_here = (rows.len() + ldc - n) / ldc;
            (0..rows_here.div_ceil(MR)).all(|ii| {
                let panel_rows = &mut rows[ii * MR * ldc..];
                let first = t * rows_per_task / MR + ii;
                (0..k).step_by(KC).all(|pc| {
                    let block = Block {
                        js: 0..n_panels,
                        c_first: 0,
                        pc,
                        kc: KC.min(k - pc),
                        b: BlockB::Whole(whole, k),
                    };
                    let here = MR.min(rows_here - ii * MR);
                    block.tiles(a, (first, here, &mut *panel_rows), (n, k, ldc), finish)
                })
            })
        })
    };
    match b {
        BSource::Packed(all) => run(all, c),
        BSource::Fill(fill) => pack::with_scratch(n_panels * k * NR, |whole| {
            fill_whole(fill, whole, (n_panels, k), parallel.then_some(tasks));
            run(whole, c)
        }),
    }
}

/// B whole (`n_panels` panels of depth `k`) filled into `whole`, split over `tasks` on the
/// pool where given: by panel and, with fewer panels than tasks, by depth within a panel
/// (ResNet's last stage has 2 panels of 4,608 rows: filled by panel, half the threads
/// waited).
fn fill_whole(
    fill: &FillPanels<'_>,
    whole: &mut [f32],
    (n_panels, k): (usize, usize),
    tasks: Option<usize>,
) {
    let parts = tasks.map_or(1, |t| t.div_ceil(n_panels));
    let depth = k.div_ceil(parts);
    let mut pieces: Vec<(usize, usize, &mut [f32])> = Vec::with_capacity(n_panels * parts);
    for (j, panel) in whole.chunks_mut(k * NR).enumerate() {
        for (q, dst) in panel.chunks_mut(depth * NR).enumerate() {
            pieces.push((j, q * depth, dst));
        }
    }
    let one = |(j, pc, dst): (usize, usize, &mut [f32])| fill(j, pc, dst.len() / NR, dst);
    match current_tract_executor() {
        Executor::MultiThread(pool) if tasks.is_some() => pool.install(|| {
            pieces
                .into_par_iter()
                .for_each(|piece| as_task(|| one(piece)));
        }),
        _ => pieces.into_iter().for_each(one),
    }
}

/// [`blocks`] split by columns: tasks of `per_task` B panels on the pool.
fn column_split(ops: &Operands<'_>, c: &mut [f32], finish: Finish<'_>, per_task: usize) -> bool {
    let Operands { a, b, m, n, k, ldc } = *ops;
    let n_panels = panels(n, NR);
    if c.len() < ops.c_len() {
        return false;
    }
    let shared = DisjointColumns(c.as_mut_ptr());
    let task = |t: usize| -> bool {
        let js = t * per_task..((t + 1) * per_task).min(n_panels);
        let col0 = js.start * NR;
        let cols = n.min(js.end * NR) - col0;
        let fill_len = match b {
            BSource::Fill(_) => js.len() * KC.min(k) * NR,
            BSource::Packed(_) => 0,
        };
        pack::with_scratch(m * cols + fill_len, |buf| {
            let (local, fill_buf) = buf.split_at_mut(m * cols);
            for pc in (0..k).step_by(KC) {
                let kc = KC.min(k - pc);
                let block = Block {
                    js: js.clone(),
                    c_first: js.start,
                    pc,
                    kc,
                    b: match b {
                        BSource::Packed(all) => BlockB::Whole(all, k),
                        BSource::Fill(fill) => {
                            let dst = &mut fill_buf[..js.len() * kc * NR];
                            for (f, panels) in dst.chunks_mut(FILL_PANELS * kc * NR).enumerate() {
                                fill(js.start + f * FILL_PANELS, pc, kc, panels);
                            }
                            BlockB::Block(dst)
                        }
                    },
                };
                if !block.tiles(a, (0, m, &mut local[..]), (n, k, cols), finish) {
                    return false;
                }
            }
            for (r, row) in local.chunks_exact(cols).enumerate() {
                // SAFETY: `c` spans `c_len()` values (checked above) and stays mutably
                // borrowed by this function until every task has returned; row `r`'s columns
                // `col0..col0 + cols` lie inside it (`r < m`, `col0 + cols <= n <= ldc`), and
                // no other task writes them (tasks own disjoint column panels) or reads C.
                unsafe {
                    std::ptr::copy_nonoverlapping(row.as_ptr(), shared.at(r * ldc + col0), cols);
                }
            }
            true
        })
    };
    on_pool(n_panels.div_ceil(per_task), task)
}

/// C's first value, shared by the tasks of [`column_split`], each of which writes its own
/// columns only (so each copies its block into place without a lock: under one, the tasks'
/// copies ran one after the other).
struct DisjointColumns(*mut f32);

impl DisjointColumns {
    /// The pointer to value `i` of C (a method, so that a closure captures the whole `Sync`
    /// wrapper rather than its raw pointer field).
    ///
    /// # Safety
    /// `i` within C.
    unsafe fn at(&self, i: usize) -> *mut f32 {
        // SAFETY: the caller keeps `i` within C.
        unsafe { self.0.add(i) }
    }
}

// SAFETY: the pointer is only written through by `column_split`'s tasks, each at its own
// columns of C, while `column_split` holds C's mutable borrow.
unsafe impl Sync for DisjointColumns {}

/// `task(i)` for `i` in `0..tasks`, on the engine's pool where there is one; `false` when a
/// task returned it.
pub fn on_pool(tasks: usize, task: impl Fn(usize) -> bool + Sync + Send) -> bool {
    match current_tract_executor() {
        Executor::MultiThread(pool) => {
            pool.install(|| (0..tasks).into_par_iter().all(|t| as_task(|| task(t))))
        }
        // The engine never runs on rayon's global pool (see `TractEngine::set_threads`).
        _ => (0..tasks).all(task),
    }
}

/// One block of the product: B panels `js` over depth rows `pc..pc + kc`, into a C whose first
/// column is that of panel `c_first`.
struct Block<'a> {
    js: std::ops::Range<usize>,
    c_first: usize,
    pc: usize,
    kc: usize,
    b: BlockB<'a>,
}

/// Where a block's B panels are.
enum BlockB<'a> {
    /// In the whole packed B of depth `.1`.
    Whole(&'a [f32], usize),
    /// In a block packed for it (panel `js.start` first).
    Block(&'a [f32]),
}

impl Block<'_> {
    /// The block's tiles over `rows_here` rows of C from A panel `first` (`rows`: those rows
    /// at `ldc` apart; `n` the product's columns).
    fn tiles(
        &self,
        a: &[f32],
        (first, rows_here, rows): (usize, usize, &mut [f32]),
        (n, k, ldc): (usize, usize, usize),
        finish: Finish<'_>,
    ) -> bool {
        let Self { pc, kc, .. } = *self;
        let Some(tier) = tier() else {
            return false;
        };
        let last = pc + kc == k;
        for ii in 0..rows_here.div_ceil(MR) {
            let i = first + ii;
            let a_blk = &a[(i * k + pc) * MR..][..kc * MR];
            for j in self.js.clone() {
                let b_blk = match self.b {
                    BlockB::Whole(all, depth) => &all[(j * depth + pc) * NR..][..kc * NR],
                    BlockB::Block(blk) => &blk[(j - self.js.start) * kc * NR..][..kc * NR],
                };
                let tile_finish = if last {
                    TileFinish {
                        bias: match finish.bias {
                            Bias::None => TileBias::None,
                            Bias::PerRow(v) => TileBias::PerRow(&v[i * MR..]),
                            Bias::PerCol(v) => TileBias::PerCol(&v[j * NR..]),
                        },
                        // The residual is dense and global: its tile at row i * MR, column
                        // j * NR, whatever part of C this block writes.
                        residual: finish.residual.map(|res| (&res[i * MR * n + j * NR..], n)),
                        floor: finish.floor,
                    }
                } else {
                    TileFinish::NONE
                };
                let done = satmap_kernels::gemm::run(
                    tier,
                    Tile {
                        a: a_blk,
                        b: b_blk,
                        c: &mut rows[ii * MR * ldc + (j - self.c_first) * NR..],
                        ldc,
                        rows: MR.min(rows_here - ii * MR),
                        cols: NR.min(n - j * NR),
                        accumulate: pc > 0,
                        finish: tile_finish,
                    },
                );
                if !done {
                    return false;
                }
            }
        }
        true
    }
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

std::thread_local! {
    /// Whether this thread is running one task of an op's split ([`as_task`]).
    static IN_TASK: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run one task of an op's split on a pool thread: the vector state cleared first (tract's
/// kernels may have left it dirty on this worker, see `vector_state`), and marked, so that a
/// product inside it stays on its thread ([`in_task`]). The plan itself runs on a worker of the
/// same pool (`on_engine_threads`), so being on a worker does not tell a task from the plan.
fn as_task<R>(task: impl FnOnce() -> R) -> R {
    super::vector_state::clear_upper();
    let outer = IN_TASK.replace(true);
    let result = task();
    IN_TASK.set(outer);
    result
}

/// Whether this thread is inside a task of an op's split (then it does not split again).
fn in_task() -> bool {
    IN_TASK.get()
}

/// Threads of the engine's pool (1 outside one).
fn threads() -> usize {
    match current_tract_executor() {
        Executor::MultiThread(pool) => pool.current_num_threads(),
        _ => 1,
    }
}

/// Multiply-adds from which a product is worth the pool's dispatch (a few microseconds a call):
/// the Swin windows' 49 x 49 x 32 products run on the calling thread.
pub const PARALLEL_MIN_MACS: usize = 1 << 20;

/// Whether a product of `macs` multiply-adds (and its packing) goes to the pool.
#[must_use]
pub fn worth_threads(macs: usize) -> bool {
    macs >= PARALLEL_MIN_MACS
}

/// `task(index, chunk)` over `data` in chunks of `chunk` values, on the engine's pool when
/// `parallel`, else on this thread; `false` when a task returned it.
pub fn on_threads<F>(parallel: bool, data: &mut [f32], chunk: usize, task: F) -> bool
where
    F: Fn(usize, &mut [f32]) -> bool + Sync,
{
    let chunk = chunk.max(1);
    match current_tract_executor() {
        Executor::MultiThread(pool) if parallel => pool.install(|| {
            data.par_chunks_mut(chunk)
                .enumerate()
                .all(|(i, c)| as_task(|| task(i, c)))
        }),
        // The engine never runs on rayon's global pool (see `TractEngine::set_threads`).
        _ => data.chunks_mut(chunk).enumerate().all(|(i, c)| task(i, c)),
    }
}

#[cfg(test)]
mod tests {
    //! The product against a scalar fused multiply-add chain (`f32::mul_add`, `k` ascending
    //! from zero, the bias after), bit for bit, over shapes with edge tiles in every direction,
    //! `k` across block boundaries, and one and two threads.
    use super::*;
    use crate::engine_tract::gemm::pack::pack_a;
    use crate::engine_tract::test_support::on_two_threads;

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
    fn tasks_are_marked_and_the_plan_thread_is_not() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let pool = std::sync::Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap(),
        );
        let marked = AtomicUsize::new(0);
        let plan_marked = pool.install(|| {
            tract_linalg::multithread::multithread_tract_scope(
                Executor::MultiThread(pool.clone()),
                || {
                    let before = in_task();
                    assert!(on_pool(8, |_| {
                        marked.fetch_add(usize::from(in_task()), Ordering::Relaxed);
                        true
                    }));
                    let mut data = [0.0f32; 64];
                    assert!(on_threads(true, &mut data, 8, |_, _| {
                        marked.fetch_add(usize::from(in_task()), Ordering::Relaxed);
                        true
                    }));
                    before || in_task()
                },
            )
        });
        // A product on the plan's thread may split; one inside a task stays on its thread.
        assert!(!plan_marked);
        assert_eq!(marked.load(Ordering::Relaxed), 16);
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
