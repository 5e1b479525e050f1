//! Products of two activations (attention's scores `Q K^T` and weighted values `P V`, per head
//! and window) as the native product.
//!
//! After decluttering they are `EinSum`s of two non-constant f32 operands with one summed
//! axis, one axis of each operand kept in the output and any number of batch axes (heads,
//! windows). [`native_batched`] rewrites each into a [`BatchedProduct`]: per batch, both
//! operands packed from their strided layout and [`gemm::product`] writing straight into the
//! output, whose last axis must be one operand's kept axis (the product's columns). tract plans
//! these with a run-time packing of the `[heads, 2000, 2000]` probabilities that cost as much as
//! the product (docs/perf.md). Bit for bit with tract's plan (its kernels sum `k` in one chain
//! from zero for these shapes; this module's tests, on products built here and on every stage of
//! the committed default bundle). On the AVX-512 tier only, as [`gemm`].

use tract_nnef::internal::*;

use crate::gemm::{self, MR, NR, pack};
use crate::ops::linear::f32_einsum;
use crate::pool;

/// Rows from which a product runs natively (fewer: tract's matrix-vector kernels, another sum
/// order).
pub const MIN_ROWS: usize = 8;

/// Columns from which a product runs natively: narrower (`test`'s 8-wide heads) leaves most of
/// the kernel's 32 columns empty, and tract's plan was faster.
pub const MIN_COLS: usize = 16;

/// One axis's extent and its element stride in A, B and the output (0 where absent).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct AxisStrides {
    /// Extent.
    pub len: usize,
    /// Stride in A.
    pub a: usize,
    /// Stride in B.
    pub b: usize,
    /// Stride in the output.
    pub c: usize,
}

/// `C[batch.., m, n] = sum_k A[batch.., m, k] B[batch.., k, n]` over operands and output laid
/// out with the strides recorded here (`n` contiguous in the output).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BatchedProduct {
    /// The op's input that is A (the other is B).
    pub a_input: usize,
    /// The two inputs' shapes, in input order.
    pub inputs: [TVec<usize>; 2],
    /// The output's shape.
    pub output: TVec<usize>,
    /// Batch axes.
    pub batch: TVec<AxisStrides>,
    /// Rows (in A and the output).
    pub m: AxisStrides,
    /// Columns (in B and the output, stride 1 there).
    pub n: AxisStrides,
    /// The summed axis (in A and B).
    pub k: AxisStrides,
}

impl Op for BatchedProduct {
    fn info(&self) -> TractResult<Vec<String>> {
        let batches: usize = self.batch.iter().map(|b| b.len).product();
        let (m, k, n) = (self.m.len, self.k.len, self.n.len);
        Ok(vec![format!(
            "Mult: {batches}x m:{m} k:{k} n:{n} with [native]"
        )])
    }

    fn name(&self) -> StaticName {
        "BatchedProduct".into()
    }
    op_as_typed_op!();
}

impl EvalOp for BatchedProduct {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let (x, y) = args_2!(inputs);
        ensure!(
            x.shape() == &*self.inputs[0] && y.shape() == &*self.inputs[1],
            "BatchedProduct inputs {:?} {:?}",
            x.shape(),
            y.shape()
        );
        let (px, py) = (x.try_as_plain_ram()?, y.try_as_plain_ram()?);
        let (xs, ys) = (px.as_slice::<f32>()?, py.as_slice::<f32>()?);
        let (a_all, b_all) = if self.a_input == 0 {
            (xs, ys)
        } else {
            (ys, xs)
        };
        let mut out = gemm::output_tensor(&self.output)?;
        let mut po = out.try_as_plain_ram_mut()?;
        let c_all = po.as_slice_mut::<f32>()?;
        let (m, n, k) = (self.m.len, self.n.len, self.k.len);
        let batches: usize = self.batch.iter().map(|b| b.len).product();
        let done = if pool::worth_threads(m * n * k) || !pool::worth_threads(batches * m * n * k) {
            // Large products split within; tiny ones in all stay on this thread.
            (0..batches).all(|index| {
                let [oa, ob, oc] = self.offsets(index);
                let c = &mut c_all[oc..][..self.c_len()];
                self.one(&a_all[oa..], &b_all[ob..], c, self.m.c)
            })
        } else {
            // Many small ones (the Swin windows): batches split over the pool, each into a C of
            // its own scattered into place (batches' rows may interleave in the output).
            let shared = std::sync::Mutex::new(&mut *c_all);
            pool::on_pool(batches, |index| {
                let [oa, ob, oc] = self.offsets(index);
                pack::with_scratch(m * n, |local| {
                    if !self.one(&a_all[oa..], &b_all[ob..], local, n) {
                        return false;
                    }
                    let Ok(mut c) = shared.lock() else {
                        return false;
                    };
                    for (r, row) in local.chunks_exact(n).enumerate() {
                        c[oc + r * self.m.c..][..n].copy_from_slice(row);
                    }
                    true
                })
            })
        };
        ensure!(
            done,
            "native product refused (AVX-512 missing or operands mis-sized)"
        );
        Ok(tvec!(out.into_tvalue()))
    }
}

impl BatchedProduct {
    /// Offsets of batch `index` in A, B and the output (last batch axis fastest).
    pub(crate) fn offsets(&self, index: usize) -> [usize; 3] {
        let (mut rest, mut off) = (index, [0usize; 3]);
        for ax in self.batch.iter().rev() {
            let i = rest % ax.len;
            rest /= ax.len;
            off[0] += i * ax.a;
            off[1] += i * ax.b;
            off[2] += i * ax.c;
        }
        off
    }

    /// Values one batch's C spans in the output.
    pub(crate) fn c_len(&self) -> usize {
        (self.m.len - 1) * self.m.c + self.n.len
    }

    /// Scratch values [`Self::pack_a`] fills.
    pub(crate) fn a_len(&self) -> usize {
        gemm::panels(self.m.len, MR) * MR * self.k.len
    }

    /// Scratch values [`Self::pack_b`] fills.
    pub(crate) fn b_len(&self) -> usize {
        gemm::panels(self.n.len, NR) * NR * self.k.len
    }

    /// One batch's A read from `src` (at its offset) into `dst` ([`Self::a_len`] values).
    pub(crate) fn pack_a(&self, parallel: bool, src: &[f32], dst: &mut [f32]) {
        let (m, k) = (self.m.len, self.k.len);
        pool::on_threads(parallel, dst, MR * k, |i, panel| {
            pack::pack_a_panel_strided(src, (m, k), (self.m.a, self.k.a), i, panel);
            true
        });
    }

    /// One batch's B read from `src` (at its offset) into `dst` ([`Self::b_len`] values).
    pub(crate) fn pack_b(&self, parallel: bool, src: &[f32], dst: &mut [f32]) {
        let (k, n) = (self.k.len, self.n.len);
        pool::on_threads(parallel, dst, NR * k, |j, panel| {
            pack::pack_b_panel_strided(src, (k, n), (self.k.b, self.n.b), j, panel);
            true
        });
    }

    /// One batch: both operands packed from `a_src` and `b_src`, the product into `c` (rows
    /// `ldc` apart).
    fn one(&self, a_src: &[f32], b_src: &[f32], c: &mut [f32], ldc: usize) -> bool {
        let (m, n, k) = (self.m.len, self.n.len, self.k.len);
        let parallel = pool::worth_threads(m * n * k);
        let a_len = self.a_len();
        pack::with_scratch(a_len + self.b_len(), |scratch| {
            let (a, b) = scratch.split_at_mut(a_len);
            self.pack_a(parallel, a_src, a);
            self.pack_b(parallel, b_src, b);
            let ops = gemm::Operands {
                a,
                b: gemm::BSource::Packed(b),
                m,
                n,
                k,
                ldc,
            };
            gemm::product(&ops, &mut c[..ops.c_len()], gemm::Bias::None)
        })
    }
}

impl TypedOp for BatchedProduct {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 2 && inputs.iter().all(|f| f.datum_type == f32::datum_type()));
        Ok(tvec!(f32::fact(&*self.output)))
    }

    fn cost(&self, _inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let batches: usize = self.batch.iter().map(|b| b.len).product();
        let fma = batches * self.m.len * self.n.len * self.k.len;
        Ok(tvec!((Cost::FMA(f32::datum_type()), fma.to_dim())))
    }

    as_op!();
}

/// Row-major element strides of `shape`.
fn strides(shape: &[usize]) -> TVec<usize> {
    let mut s: TVec<usize> = tvec![1; shape.len()];
    for i in (0..shape.len().saturating_sub(1)).rev() {
        s[i] = s[i + 1] * shape[i + 1];
    }
    s
}

/// The node `id` as a [`BatchedProduct`]: an f32 `EinSum` of two non-constant operands of
/// concrete shapes, every axis a batch axis (in both operands and the output), a kept axis of
/// one operand, or the one summed axis (in both operands only), with one kept axis each and
/// the output's last axis one of them.
pub(crate) fn as_batched(model: &TypedModel, id: usize) -> TractResult<Option<BatchedProduct>> {
    let node = model.node(id);
    let Some(es) = f32_einsum(node) else {
        return Ok(None);
    };
    let facts = model.node_input_facts(id)?;
    let out_fact = model.outlet_fact(OutletId::new(id, 0))?;
    let plain = |f: &TypedFact| f.datum_type == f32::datum_type() && f.konst.is_none();
    if !facts.iter().all(|f| plain(f)) {
        return Ok(None);
    }
    let (Some(s0), Some(s1), Some(so)) = (
        facts[0].shape.as_concrete(),
        facts[1].shape.as_concrete(),
        out_fact.shape.as_concrete(),
    ) else {
        return Ok(None);
    };
    let st = [strides(s0), strides(s1), strides(so)];
    let (mut batch, mut kept, mut summed) = (tvec![], [None, None], None);
    for axis in es.axes.iter_all_axes() {
        let (i0, i1, o) = (&axis.inputs[0], &axis.inputs[1], &axis.outputs[0]);
        if i0.len() > 1 || i1.len() > 1 || o.len() > 1 {
            return Ok(None);
        }
        let at = |which: usize, pos: Option<&usize>| pos.map_or(0, |&p| st[which][p]);
        let len = i0
            .first()
            .map(|&p| s0[p])
            .or(i1.first().map(|&p| s1[p]))
            .or(o.first().map(|&p| so[p]))
            .unwrap_or(1);
        // Strides as (input 0, input 1, output) for now; ordered as A, B below.
        let strides = AxisStrides {
            len,
            a: at(0, i0.first()),
            b: at(1, i1.first()),
            c: at(2, o.first()),
        };
        match (i0.first(), i1.first(), o.first()) {
            (Some(_), Some(_), Some(_)) => batch.push(strides),
            (Some(_), None, Some(&po)) if kept[0].is_none() => kept[0] = Some((strides, po)),
            (None, Some(_), Some(&po)) if kept[1].is_none() => kept[1] = Some((strides, po)),
            (Some(_), Some(_), None) if summed.is_none() => summed = Some(strides),
            _ => return Ok(None),
        }
    }
    let (Some(k0), Some(k1), Some(k)) = (kept[0], kept[1], summed) else {
        return Ok(None);
    };
    // B is the operand whose kept axis is the output's last (the product's columns).
    let last = so.len() - 1;
    let swap = |s: AxisStrides| AxisStrides {
        a: s.b,
        b: s.a,
        ..s
    };
    let (a_input, m, n, k, batch) = if k1.1 == last {
        (0, k0.0, k1.0, k, batch)
    } else if k0.1 == last {
        (
            1,
            swap(k1.0),
            swap(k0.0),
            swap(k),
            batch.into_iter().map(swap).collect(),
        )
    } else {
        return Ok(None);
    };
    Ok(Some(BatchedProduct {
        a_input,
        inputs: [s0.into(), s1.into()],
        output: so.into(),
        batch,
        m,
        n,
        k,
    }))
}

/// Rewrite every product of two activations of a decluttered `model` with at least
/// [`MIN_ROWS`] rows and [`MIN_COLS`] columns into a [`BatchedProduct`]; returns the model and the
/// number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn native_batched(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let Some(op) = as_batched(&model, id)? else {
            continue;
        };
        if op.m.len < MIN_ROWS || op.n.len < MIN_COLS || op.k.len == 0 {
            continue;
        }
        let node = model.node(id);
        let patch = TypedModelPatch::replace_single_op(&model, node, &node.inputs, op)?;
        patch.apply(&mut model)?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The pass against tract's own plan, bit for bit: on the attention products of `nano`'s
    //! decoder and the Swin windows (shapes shrunk), and on every stage of the committed
    //! default bundle.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, on_two_threads, run_optimized};
    use tract_nnef::tract_core::ops::einsum::EinSum;

    fn values(len: usize, seed: usize) -> Vec<f32> {
        (0..len)
            .map(|i| ((i * 7919 + seed * 104_729) % 1013) as f32 / 500.0 - 1.0)
            .collect()
    }

    /// `x . y` as the einsum `expr` over operands of shapes `sx`, `sy`, and its inputs.
    fn product_model(expr: &str, sx: &[usize], sy: &[usize]) -> (TypedModel, TVec<TValue>) {
        let mut model = TypedModel::default();
        let x = model.add_source("x", f32::fact(sx)).unwrap();
        let y = model.add_source("y", f32::fact(sy)).unwrap();
        let es = EinSum {
            axes: expr.parse().unwrap(),
            operating_dt: f32::datum_type(),
            q_params: None,
        };
        let z = model.wire_node("mm", es, &[x, y]).unwrap();
        model.select_output_outlets(&z).unwrap();
        let lx: usize = sx.iter().product();
        let ly: usize = sy.iter().product();
        let inputs = tvec![
            Tensor::from_shape(sx, &values(lx, 1))
                .unwrap()
                .into_tvalue(),
            Tensor::from_shape(sy, &values(ly, 2))
                .unwrap()
                .into_tvalue(),
        ];
        (model.into_decluttered().unwrap(), inputs)
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn attention_products_run_natively_with_tracts_bits() {
        for (expr, sx, sy) in [
            // Decoder self-attention scores and weighted values (4 heads).
            ("mak,nak->amn", vec![200, 4, 64], vec![150, 4, 64]),
            ("amk,kan->man", vec![4, 200, 150], vec![150, 4, 64]),
            // Swin window attention: windows and heads as two batch axes.
            ("abmk,abnk->abmn", vec![3, 2, 49, 32], vec![3, 2, 49, 32]),
            ("abmk,abkn->ambn", vec![3, 2, 49, 49], vec![3, 2, 49, 32]),
            // The output's last axis from the first operand: the operands swap roles.
            ("kn,km->mn", vec![70, 40], vec![70, 30]),
        ] {
            let (model, inputs) = product_model(expr, &sx, &sy);
            let (native, done) = native_batched(model.clone()).unwrap();
            assert_eq!(done, 1, "{expr}");
            assert!(native.nodes().iter().any(|n| n.op_is::<BatchedProduct>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(native, &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{expr}");
            assert_eq!(bits(&got[0]), bits(&want[0]), "{expr}");
        }
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn batches_on_the_pool_keep_the_bits() {
        // 32 windows of 49 tokens: each product too small to split, the batches split.
        let (model, inputs) = product_model("abmk,abkn->ambn", &[8, 4, 49, 49], &[8, 4, 49, 32]);
        let want = run_optimized(model.clone(), &inputs);
        let native = native_batched(model).unwrap().0;
        let got = on_two_threads(|| run_optimized(native, &inputs));
        assert_eq!(bits(&got[0]), bits(&want[0]));
    }

    #[test]
    fn constant_operands_and_single_rows_keep_tracts_plan() {
        // One row: tract's matrix-vector kernels.
        let (model, _) = product_model("mk,kn->mn", &[1, 64], &[64, 64]);
        assert_eq!(native_batched(model).unwrap().1, 0);
        // A constant operand is a linear layer's (`linear`), not this pass's.
        let (mut model, _) = product_model("mk,kn->mn", &[64, 64], &[64, 64]);
        let w = model
            .add_const("w", Tensor::zero::<f32>(&[64, 64]).unwrap())
            .unwrap();
        let x = model.input_outlets().unwrap()[0];
        let es = EinSum {
            axes: "mk,kn->mn".parse().unwrap(),
            operating_dt: f32::datum_type(),
            q_params: None,
        };
        let z = model.wire_node("mm_const", es, &[x, w]).unwrap()[0];
        let first = model.output_outlets().unwrap()[0];
        model.select_output_outlets(&[first, z]).unwrap();
        let (_, done) = native_batched(model.into_decluttered().unwrap()).unwrap();
        assert_eq!(done, 1, "only the product of the two sources");
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let (model, _) = product_model("mk,kn->mn", &[16, 8], &[8, 4]);
        let id = model
            .nodes()
            .iter()
            .position(|n| n.op_is::<EinSum>())
            .unwrap();
        let op = as_batched(&model, id).unwrap().unwrap();
        let x = Tensor::zero::<f32>(&[16, 9]).unwrap().into_tvalue();
        let y = Tensor::zero::<f32>(&[9, 4]).unwrap().into_tvalue();
        assert!(op.eval_out_of_plan(tvec!(x, y)).is_err());
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::NativeBatched, native_batched);
    }
}
