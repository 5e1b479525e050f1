//! The native softmax over trailing axes, for the short rows the samplers' attention weights have.
//!
//! tract 0.23.9 runs a float softmax row by row on x86 (no row kernel there): three dynamic
//! kernel calls per row (max, exp-and-sum, scale), each staging a partial vector through scratch
//! memory. A row of 4 (`bev_query`'s `[3200, 8, 2, 4]` sampling weights) then costs ~430 ns, 22
//! of `test`'s 71 ms `bev_query`; the GKT kernel weights `[3200, 4, 15]` another 8 ms. At load,
//! [`fuse_softmaxes`] rewrites every f32 `Softmax` over trailing axes into [`RowSoftmax`], which
//! works on blocks of rows: the row maxima are subtracted, one call of tract-linalg's own exp
//! kernel (the one tract's softmax uses: same polynomial, same host dispatch) covers the whole
//! block, and each row is summed and scaled.
//!
//! Contract, per row `x` of `n` values: `m = max(x)`; `e[i] = exp(x[i] - m)` by tract-linalg's
//! `Softmax2` kernel (elementwise: independent of where a block starts or ends); the sum `s` in a
//! fixed order: eight lane sums, lane `j` adding `e[j], e[j + 8], ...` over the whole eights in
//! ascending order, combined as `((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7))`, then the
//! remaining `n % 8` values added in ascending order; `y[i] = e[i] * (1 / s)`. Rows never span
//! threads, so the result is the same for any thread count. Only the order of the row sum
//! differs from tract's (which sums in its kernel's vector lanes), so values move by an ulp or
//! so, well inside every parity tolerance.

use tract_linalg::reduce::MapReduce;
use tract_linalg::routines::Func;
use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::nn::{Softmax, SoftmaxKind};

/// Rows are processed in blocks of at least this many values: one exp-kernel call per block
/// amortises its set-up over short rows, and a block stays in L1.
const BLOCK_VALUES: usize = 1024;

/// Softmax of an f32 tensor over its last `trailing` axes (their product is the row length).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct RowSoftmax {
    /// How many trailing axes one row spans (at least one).
    pub trailing: usize,
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
        ensure!(
            self.trailing >= 1 && self.trailing <= input.rank(),
            "RowSoftmax over {} trailing axes of a rank-{} tensor",
            self.trailing,
            input.rank()
        );
        let row_len: usize = input.shape()[input.rank() - self.trailing..]
            .iter()
            .product();
        let mut output = input.into_tensor();
        if row_len == 0 || output.len() == 0 {
            return Ok(tvec!(output.into_tvalue()));
        }
        let exp = Func::Softmax2.map_reduce_f32()?;
        let mut plain = output.try_as_plain_ram_mut()?;
        let data = plain.as_slice_mut::<f32>()?;
        let total = data.len();
        let rows_per_block = (BLOCK_VALUES / row_len).max(1);
        tract_linalg::multithread::par_chunks_mut(data, row_len, total, |_, chunk| {
            for block in chunk.chunks_mut(rows_per_block * row_len) {
                softmax_block(block, row_len, &*exp)?;
            }
            Ok(())
        })?;
        Ok(tvec!(output.into_tvalue()))
    }
}

/// The contract of the module doc over `block` (whole rows of `row_len`), in place.
fn softmax_block(
    block: &mut [f32],
    row_len: usize,
    exp: &dyn MapReduce<f32, f32>,
) -> TractResult<()> {
    for row in block.chunks_exact_mut(row_len) {
        let m = row_max(row);
        for x in row.iter_mut() {
            *x -= m;
        }
    }
    // The kernel writes exp(x - 0) = exp(x) in place; the block total it returns is not used.
    exp.run_with_params(block, 0.0)?;
    for row in block.chunks_exact_mut(row_len) {
        let r = row_sum(row).recip();
        for x in row.iter_mut() {
            *x *= r;
        }
    }
    Ok(())
}

/// The largest value of `row` (exact in any order; NaNs are skipped). Written as compare and
/// select, which compiles to vector max instructions (`f32::max` does not, for its NaN rule).
fn row_max(row: &[f32]) -> f32 {
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

/// The sum of `row` in the module doc's fixed order.
pub(crate) fn row_sum(row: &[f32]) -> f32 {
    let mut l = [0.0f32; 8];
    let chunks = row.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (s, &x) in l.iter_mut().zip(c) {
            *s += x;
        }
    }
    let mut s = ((l[0] + l[1]) + (l[2] + l[3])) + ((l[4] + l[5]) + (l[6] + l[7]));
    for &x in rest {
        s += x;
    }
    s
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
/// into [`RowSoftmax`]; returns the model and the number rewritten.
///
/// # Errors
/// tract refusing the patch (an inconsistent model).
pub fn fuse_softmaxes(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
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
        };
        let patch = TypedModelPatch::replace_single_op(&model, node, &node.inputs, op)?;
        patch.apply(&mut model)?;
        fused += 1;
    }
    Ok((model.into_compact()?, fused))
}

#[cfg(test)]
mod tests {
    //! The kernel against an f64 softmax, the sum order against a scalar loop, and the rewrite
    //! through the engine's own load path.

    use super::*;

    fn run(shape: &[usize], trailing: usize, values: &[f32]) -> Vec<f32> {
        let t = Tensor::from_shape(shape, values).expect("tensor");
        let out = RowSoftmax { trailing }
            .eval_out_of_plan(tvec!(t.into_tvalue()))
            .expect("eval")
            .expect("an out-of-plan result");
        out[0]
            .try_as_plain_ram()
            .expect("plain")
            .as_slice::<f32>()
            .expect("f32")
            .to_vec()
    }

    fn values(n: usize, seed: u32) -> Vec<f32> {
        // A fixed pseudo-random spread over [-12, 12): a spread wide enough that the row maxima
        // matter, no crate needed for a few hundred values.
        (0..n as u32)
            .map(|i| {
                let h = (i.wrapping_mul(2_654_435_761) ^ seed).wrapping_mul(2_246_822_519);
                (h >> 8) as f32 / (1u32 << 24) as f32 * 24.0 - 12.0
            })
            .collect()
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
            let x = values(n, 7);
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

    #[test]
    fn the_row_sum_has_the_documented_order() {
        let row = [1e8f32, 1.0, -1e8, 3.0, 0.5, 0.25, 7.0, 1e-3, 2.0, 1e7, 5.0];
        let mut l = [0.0f32; 8];
        for (j, s) in l.iter_mut().enumerate() {
            *s = row[j];
        }
        let mut want = ((l[0] + l[1]) + (l[2] + l[3])) + ((l[4] + l[5]) + (l[6] + l[7]));
        for &x in &row[8..] {
            want += x;
        }
        assert_eq!(row_sum(&row).to_bits(), want.to_bits());
        // Another order gives another value for these magnitudes: the order is observable.
        let sequential = row.iter().fold(0.0f32, |s, &x| s + x);
        assert_ne!(sequential.to_bits(), want.to_bits());
    }

    #[test]
    fn blocks_do_not_change_the_result() {
        // 600 rows of 4 span several blocks; each row alone must give the same bits.
        let x = values(2400, 3);
        let all = run(&[600, 4], 1, &x);
        for (i, row) in x.chunks(4).enumerate() {
            let one = run(&[1, 4], 1, row);
            assert_eq!(
                one.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                all[i * 4..][..4]
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            );
        }
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
