//! How [`super::product`] walks C: blocks of `k` and of B's column panels, and the split of
//! the blocks over the engine's threads (by row panels, by column panels, or rows outermost
//! for a deep product of few columns), each tile handed to the micro-kernel of the tier.

use rayon::prelude::*;
use satmap_kernels::gemm::Tile;
use tract_linalg::multithread::{Executor, current_tract_executor};

use super::{
    BSource, Bias, FILL_PANELS, FillPanels, Finish, KC, MR, NC_PANELS, NR, Operands, TileBias,
    TileFinish, pack, panels, tier,
};
use crate::pool::{DisjointParts, as_task, in_task, on_pool, on_threads, threads, worth_threads};

/// [`super::product`]'s blocks, B's filled into `scratch` where it is filled.
///
/// On the pool, a B that is filled (a convolution's patches) splits by columns: each task
/// fills and multiplies its own column panels for every row, into a C of its own copied into
/// place at the end, with no step in common (filled blocks need one per block otherwise). So
/// does a packed B with fewer row panels than column panels (the Swin's last stages: 28 tokens
/// against 3072 x 768 weights, where each thread then reads its share of the weights only).
/// Otherwise (a linear layer over many tokens) the rows of C split.
pub(super) fn blocks(
    ops: &Operands<'_>,
    c: &mut [f32],
    finish: Finish<'_>,
    scratch: &mut [f32],
) -> bool {
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

/// Values of B (every panel over all of `k`) that `rows_outer` keeps whole: 1.5 MiB of the
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
    // Each task copies its block into place through the shared pointer, without a lock (under
    // one, the tasks' copies ran one after the other).
    let shared = DisjointParts(c.as_mut_ptr());
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
