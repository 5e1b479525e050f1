//! The native softmax over trailing axes, for the short rows the samplers' attention weights have.
//!
//! tract 0.23.9 runs a float softmax row by row on x86 (no row kernel there): three dynamic
//! kernel calls per row (max, exp-and-sum, scale), each staging a partial vector through scratch
//! memory. A row of 4 (`bev_query`'s `[3200, 8, 2, 4]` sampling weights) then costs ~200-400 ns,
//! 22 of `test`'s 71 ms `bev_query` on an AVX-512 Xeon; the GKT kernel weights `[3200, 4, 15]`
//! another 8 ms. At load, [`fuse_softmaxes`] rewrites every f32 `Softmax` over trailing axes
//! into [`RowSoftmax`], which works on blocks of rows: the row maxima are subtracted, one call of
//! tract-linalg's own exp kernel covers the whole block, and each row is summed and scaled.
//!
//! Contract: **bit-identical to tract's own softmax** on the same host, so the rewrite changes no
//! output and no pinned digest. Per row `x`: `m = max(x)` (exact in any order); `e[i] =
//! exp(x[i] - m)` by tract-linalg's `Softmax2` kernel (elementwise, so a block call gives each
//! value the bits a row call gives it); the sum `s` is added in exactly the lanes and the order
//! tract's row call adds it ([`SumOrder`], in `satmap-kernels`: the map-reduce driver's split of the row at the
//! kernel's alignment, the kernel's accumulators and its horizontal fold); `y[i] = e[i] * (1 /
//! s)`, as tract's scale kernel multiplies. The order is known per kernel, by name; on a host
//! whose kernel is not one of them, or whose kernel disagrees with the model on a probe at load
//! (`sum_order_here`), nothing is rewritten. Rows never span threads, so the result is the
//! same for any thread count. A row holding NaN comes out all NaN, as tract's does (the NaN
//! payloads are not pinned).

use tract_linalg::reduce::MapReduce;
use tract_linalg::routines::Func;
use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::nn::{Softmax, SoftmaxKind};

pub(crate) use satmap_kernels::softmax::SumOrder;
use satmap_kernels::softmax::row_max;

/// Rows are processed in blocks of at least this many values: one exp-kernel call per block
/// amortises its set-up over short rows, and a block stays in L1.
const BLOCK_VALUES: usize = 1024;

/// Softmax of an f32 tensor over its last `trailing` axes (their product is the row length).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct RowSoftmax {
    /// How many trailing axes one row spans (at least one).
    pub trailing: usize,
    /// How this host's tract softmax adds up a row ([`sum_order_here`]).
    pub(crate) order: SumOrder,
}

impl Op for RowSoftmax {
    fn name(&self) -> StaticName {
        "RowSoftmax".into()
    }
    op_as_typed_op!();
}

impl EvalOp for RowSoftmax {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let input = args_1!(inputs);
        Ok(tvec!(self.softmax(input.into_tensor())?.into_tvalue()))
    }
}

impl RowSoftmax {
    /// The softmax of `t`, in place (the module doc's contract).
    fn softmax(&self, mut t: Tensor) -> TractResult<Tensor> {
        ensure!(
            self.trailing >= 1 && self.trailing <= t.rank(),
            "RowSoftmax over {} trailing axes of a rank-{} tensor",
            self.trailing,
            t.rank()
        );
        let row_len: usize = t.shape()[t.rank() - self.trailing..].iter().product();
        if row_len == 0 || t.len() == 0 {
            return Ok(t);
        }
        let exp = Func::Softmax2.map_reduce_f32()?;
        let order = self.order;
        let mut plain = t.try_as_plain_ram_mut()?;
        let data = plain.as_slice_mut::<f32>()?;
        let total = data.len();
        let rows_per_block = (BLOCK_VALUES / row_len).max(1);
        tract_linalg::multithread::par_chunks_mut(data, row_len, total, |_, chunk| {
            for block in chunk.chunks_mut(rows_per_block * row_len) {
                softmax_block(block, row_len, &*exp, order)?;
            }
            Ok(())
        })?;
        Ok(t)
    }
}

/// The contract of the module doc over `block` (whole rows of `row_len`), in place.
pub(crate) fn softmax_block(
    block: &mut [f32],
    row_len: usize,
    exp: &dyn MapReduce<f32, f32>,
    order: SumOrder,
) -> TractResult<()> {
    for row in block.chunks_exact_mut(row_len) {
        let m = row_max(row);
        for x in row.iter_mut() {
            *x -= m;
        }
    }
    // The kernel writes exp(x - 0) = exp(x) in place (x - 0 is x, bit for bit, as tract's
    // in-kernel x - m is our x - m); the block total it returns is not used.
    exp.run_with_params(block, 0.0)?;
    for row in block.chunks_exact_mut(row_len) {
        let r = order.row_sum(row).recip();
        for x in row.iter_mut() {
            *x *= r;
        }
    }
    Ok(())
}

/// The order of this host's kernel, if known and if it reproduces tract's own softmax bit
/// for bit on a probe (rows of 1 to 80 values and of 1000, at every alignment the kernel
/// has); `None` leaves tract's softmax in place.
///
/// # Errors
/// tract-linalg having no `Softmax2` kernel, or tract's softmax failing on the probe.
pub(crate) fn sum_order_here() -> TractResult<Option<SumOrder>> {
    let Some(order) = SumOrder::of_kernel(Func::Softmax2.map_reduce_f32()?.name()) else {
        return Ok(None);
    };
    for row_len in (1..=80).chain([1000]) {
        let rows = 17;
        let x = probe_values(rows * row_len, row_len as u32);
        let t = Tensor::from_shape(&[rows, row_len], &x)?;
        let theirs = Softmax::new(tvec![1], None, SoftmaxKind::Softmax)
            .eval_out_of_plan(tvec!(t.clone().into_tvalue()))?
            .context("tract's softmax evaluates out of a plan")?;
        let ours = RowSoftmax { trailing: 1, order }.softmax(t)?;
        let a = theirs[0].try_as_plain_ram()?;
        let b = ours.try_as_plain_ram()?;
        let same = a
            .as_slice::<f32>()?
            .iter()
            .zip(b.as_slice::<f32>()?)
            .all(|(p, q)| p.to_bits() == q.to_bits());
        if !same {
            return Ok(None);
        }
    }
    Ok(Some(order))
}

/// A fixed pseudo-random spread over [-12, 12): wide enough that the row maxima and the order
/// of a row's sum both show in the last bits.
fn probe_values(n: usize, seed: u32) -> Vec<f32> {
    (0..n as u32)
        .map(|i| {
            let h = (i.wrapping_mul(2_654_435_761) ^ seed).wrapping_mul(2_246_822_519);
            (h >> 8) as f32 / (1u32 << 24) as f32 * 24.0 - 12.0
        })
        .collect()
}

impl TypedOp for RowSoftmax {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 1 && inputs[0].datum_type == f32::datum_type());
        ensure!(self.trailing >= 1 && self.trailing <= inputs[0].rank());
        Ok(tvec!(f32::fact(inputs[0].shape.clone())))
    }

    fn cost(&self, inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let n: TDim = inputs[0].shape.iter().product();
        Ok(tvec!((Cost::Div(f32::datum_type()), n)))
    }

    as_op!();
}

/// Rewrite every f32 `Softmax` (not `LogSoftmax`) whose axes are the trailing axes of its input
/// into [`RowSoftmax`]; returns the model and the number rewritten (0 on a host whose kernel
/// order is unknown or fails the probe of `sum_order_here`).
///
/// # Errors
/// tract refusing the patch (an inconsistent model).
pub fn fuse_softmaxes(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    // The probe runs once a process; a probe that fails to run counts as a mismatch (tract's
    // softmax stays, which is always right).
    static ORDER: std::sync::OnceLock<Option<SumOrder>> = std::sync::OnceLock::new();
    let Some(order) = *ORDER.get_or_init(|| sum_order_here().ok().flatten()) else {
        return Ok((model, 0));
    };
    let mut fused = 0;
    for id in model.eval_order()? {
        let node = model.node(id);
        let Some(sm) = node.op_as::<Softmax>() else {
            continue;
        };
        let fact = model.outlet_fact(node.inputs[0])?;
        let rank = fact.rank();
        let mut axes = sm.axes.clone();
        axes.sort_unstable();
        let trailing = !axes.is_empty()
            && axes
                .iter()
                .enumerate()
                .all(|(i, &a)| a + axes.len() == rank + i);
        if sm.kind != SoftmaxKind::Softmax
            || sm.quant_output_dt.is_some()
            || fact.datum_type != f32::datum_type()
            || !trailing
        {
            continue;
        }
        let op = RowSoftmax {
            trailing: axes.len(),
            order,
        };
        let patch = TypedModelPatch::replace_single_op(&model, node, &node.inputs, op)?;
        patch.apply(&mut model)?;
        fused += 1;
    }
    Ok((model.into_compact()?, fused))
}

#[cfg(test)]
mod tests {
    //! The op against tract's own softmax (bit for bit) and an f64 softmax, the sum orders
    //! against their documented folds, and the rewrite's selection.

    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        assert_same_bits, committed_rewrites, committed_stage_before, inputs_of, run_optimized,
    };
    use satmap_core::engine::Stage;

    fn order() -> SumOrder {
        sum_order_here()
            .expect("probe")
            .expect("this host's Softmax2 kernel has a known order that passes the probe")
    }

    fn f32s(t: &Tensor) -> Vec<f32> {
        t.try_as_plain_ram()
            .expect("plain")
            .as_slice::<f32>()
            .expect("f32")
            .to_vec()
    }

    fn run(shape: &[usize], trailing: usize, values: &[f32]) -> Vec<f32> {
        let t = Tensor::from_shape(shape, values).expect("tensor");
        let out = RowSoftmax {
            trailing,
            order: order(),
        }
        .eval_out_of_plan(tvec!(t.into_tvalue()))
        .expect("eval")
        .expect("an out-of-plan result");
        f32s(&out[0])
    }

    /// tract's own softmax over the last `trailing` axes.
    fn tracts(shape: &[usize], trailing: usize, values: &[f32]) -> Vec<f32> {
        let t = Tensor::from_shape(shape, values).expect("tensor");
        let axes = (shape.len() - trailing..shape.len()).collect();
        let out = Softmax::new(axes, None, SoftmaxKind::Softmax)
            .eval_out_of_plan(tvec!(t.into_tvalue()))
            .expect("eval")
            .expect("an out-of-plan result");
        f32s(&out[0])
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn every_stage_of_the_default_bundle_computes_its_unfused_graph_bit_for_bit() {
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::RowSoftmaxes);
            let (fused, n) = fuse_softmaxes(plain.clone()).expect("fuse");
            assert_eq!(n, committed_rewrites(stage).row_softmaxes, "{stage}");
            let left = fused
                .nodes()
                .iter()
                .filter(|n| n.op_is::<Softmax>())
                .count();
            assert_eq!(left, 0, "{stage}: a softmax was left to tract");
            let inputs = inputs_of(&plain);
            let (a, b) = (run_optimized(plain, &inputs), run_optimized(fused, &inputs));
            assert_same_bits(stage, &a, &b);
        }
    }

    #[test]
    fn this_hosts_kernel_is_known_and_passes_the_probe() {
        let name = Func::Softmax2.map_reduce_f32().expect("kernel").name();
        assert_eq!(SumOrder::of_kernel(name), Some(order()), "{name}");
    }

    #[test]
    fn rows_are_tracts_softmax_bit_for_bit() {
        // Every row length up to 130 (every split of a row at the kernel's alignment, several
        // whole kernel steps), the samplers' rows, the decoder's, and two trailing axes; rows
        // with -inf entries (masked keys) among them.
        let mut shapes: Vec<(Vec<usize>, usize)> = (1..=130).map(|n| (vec![9, n], 1)).collect();
        shapes.extend([
            (vec![40, 8, 2, 4], 1),
            (vec![30, 4, 15], 1),
            (vec![2, 3, 1000], 1),
            (vec![2, 2000], 1),
            (vec![2, 3, 3, 7], 2),
            (vec![5, 6, 11], 2),
        ]);
        for (shape, trailing) in shapes {
            let n: usize = shape.iter().product();
            let mut x = probe_values(n, n as u32);
            for v in x.iter_mut().step_by(7) {
                *v = f32::NEG_INFINITY;
            }
            x[0] = 11.0;
            assert_eq!(
                bits(&run(&shape, trailing, &x)),
                bits(&tracts(&shape, trailing, &x)),
                "{shape:?} over {trailing}"
            );
        }
    }

    #[test]
    fn rows_match_an_f64_softmax() {
        for (shape, trailing) in [
            (vec![3, 5, 4], 1),
            (vec![7, 15], 1),
            (vec![2, 3, 3, 7], 2),
            (vec![300, 4], 1),
            (vec![2, 1000], 1),
            (vec![5, 1], 1),
        ] {
            let n: usize = shape.iter().product();
            let x = probe_values(n, 7);
            let y = run(&shape, trailing, &x);
            let row: usize = shape[shape.len() - trailing..].iter().product();
            for (xr, yr) in x.chunks(row).zip(y.chunks(row)) {
                let m = xr
                    .iter()
                    .fold(f64::NEG_INFINITY, |m, &v| m.max(f64::from(v)));
                let s: f64 = xr.iter().map(|&v| (f64::from(v) - m).exp()).sum();
                for (&xv, &yv) in xr.iter().zip(yr) {
                    let want = (f64::from(xv) - m).exp() / s;
                    let err = (f64::from(yv) - want).abs();
                    assert!(err <= 2e-6 * want + 1e-9, "{shape:?}: {yv} vs {want}");
                }
            }
        }
    }

    /// `n` values at an address `offset` floats past a 64-byte boundary.
    fn at_offset(values: &[f32], offset: usize) -> (Tensor, std::ops::Range<usize>) {
        let mut t = Tensor::zero_aligned::<f32>(&[values.len() + offset], 64).expect("tensor");
        t.try_as_plain_ram_mut()
            .expect("plain")
            .as_slice_mut::<f32>()
            .expect("f32")[offset..]
            .copy_from_slice(values);
        (t, offset..offset + values.len())
    }

    #[test]
    fn the_sum_orders_have_their_documented_folds() {
        // Magnitudes far apart, so that every order of the additions gives other bits.
        let e = [
            1e8f32, 5.0, 3.0, 3e7, 13.0, 0.125, 0.125, 1e8, 5.0, 13.0, 1e-3, 0.25,
        ];
        let (t, r) = at_offset(&e[..4], 0);
        let plain = t.try_as_plain_ram().expect("plain");
        let row = &plain.as_slice::<f32>().expect("f32")[r];
        // Four values in the lanes 0-3 of one staged step.
        let halves = (e[0] + e[2]) + (e[1] + e[3]);
        let adjacent = (e[0] + e[1]) + (e[2] + e[3]);
        assert_ne!(halves.to_bits(), adjacent.to_bits());
        assert_eq!(SumOrder::Fma8x4.row_sum(row).to_bits(), halves.to_bits());
        assert_eq!(
            SumOrder::Avx512x16x4.row_sum(row).to_bits(),
            halves.to_bits()
        );
        assert_eq!(
            SumOrder::Generic4.row_sum(row).to_bits(),
            adjacent.to_bits()
        );
        // Twelve values starting one float past a 32-byte boundary: the FMA order stages the
        // seven before the boundary (lanes 0-6), then the five after it (lanes 0-4), and adds
        // the two onto 0; the AVX-512 order (64-byte boundary) stages all twelve at once.
        let (t, r) = at_offset(&e, 1);
        let plain = t.try_as_plain_ram().expect("plain");
        let row = &plain.as_slice::<f32>().expect("f32")[r];
        let fold8 = |l: &[f32]| {
            let mut v = [0.0f32; 8];
            v[..l.len()].copy_from_slice(l);
            let h = [v[0] + v[4], v[1] + v[5], v[2] + v[6], v[3] + v[7]];
            (h[0] + h[2]) + (h[1] + h[3])
        };
        let fma = (0.0 + fold8(&e[..7])) + fold8(&e[7..]);
        assert_eq!(SumOrder::Fma8x4.row_sum(row).to_bits(), fma.to_bits());
        let mut v = [0.0f32; 16];
        v[..12].copy_from_slice(&e);
        let h8: Vec<f32> = (0..8).map(|j| v[j] + v[j + 8]).collect();
        let h4: Vec<f32> = (0..4).map(|j| h8[j] + h8[j + 4]).collect();
        let avx = (h4[0] + h4[2]) + (h4[1] + h4[3]);
        assert_eq!(SumOrder::Avx512x16x4.row_sum(row).to_bits(), avx.to_bits());
        assert_ne!(fma.to_bits(), avx.to_bits());
    }

    #[test]
    fn the_rewrite_takes_trailing_softmaxes_only() {
        let mut model = TypedModel::default();
        let x = model.add_source("x", f32::fact([6, 4, 5])).expect("source");
        let last = model
            .wire_node(
                "last",
                Softmax::new(tvec![2], None, SoftmaxKind::Softmax),
                &[x],
            )
            .expect("wire")[0];
        let middle = model
            .wire_node(
                "middle",
                Softmax::new(tvec![1], None, SoftmaxKind::Softmax),
                &[last],
            )
            .expect("wire")[0];
        let log = model
            .wire_node(
                "log",
                Softmax::new(tvec![2], None, SoftmaxKind::LogSoftmax),
                &[middle],
            )
            .expect("wire")[0];
        model.select_output_outlets(&[log]).expect("outputs");
        let (model, fused) = fuse_softmaxes(model).expect("fuse");
        assert_eq!(fused, 1);
        let kinds: Vec<String> = model
            .nodes()
            .iter()
            .map(|n| n.op().name().into_owned())
            .collect();
        assert!(kinds.contains(&"RowSoftmax".to_string()), "{kinds:?}");
        assert_eq!(kinds.iter().filter(|k| *k == "Softmax").count(), 1);
        assert_eq!(kinds.iter().filter(|k| *k == "LogSoftmax").count(), 1);
    }
}
