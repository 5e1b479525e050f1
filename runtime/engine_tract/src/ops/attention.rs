//! Self-attention (`softmax(Q K^T) V`, per head) as one op, the probabilities never laid out.
//!
//! The decoder's live self-attention is, after the earlier rewrites, a product of two
//! activations into `[heads, queries, keys]` scores, a [`RowSoftmax`] over the keys and a
//! product of those probabilities with the values: on `nano` a 64 MB scores tensor written,
//! read by the softmax, then read and packed again for the second product. [`fuse_attention`]
//! rewrites such a chain into [`FusedAttention`], which walks the queries in panels of
//! [`gemm::MR`]: the panel's scores (`MR x keys`, in L2) by [`gemm::product`], the softmax of
//! those rows by the [`RowSoftmax`] code itself, the rows packed as the A panel of the second
//! product, whose result lands in the output. Panels go to the engine's threads.
//!
//! Bit for bit with the unfused chain: each score and each output value is the same fused
//! multiply-add chain ([`gemm`]), and a softmax row is computed by the same function over a
//! row at the same 64-byte alignment (rows of a multiple of 16 keys only), whose exp is
//! elementwise and whose sum order depends on the row alone ([`crate::ops::softmax`]). This module's
//! tests compare with the unfused chain and with every stage of the committed default bundle.

use tract_linalg::routines::Func;
use tract_nnef::internal::*;

use crate::gemm::{self, MR, pack};
use crate::graph::matching::replace_with_op;
use crate::ops::batched::{BatchedProduct, as_batched};
use crate::ops::softmax::{RowSoftmax, SumOrder, softmax_block};
use crate::pool;

/// `softmax(scores) . v` with `scores = q . k` over the last axis, per batch (head).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct FusedAttention {
    /// The scores product (inputs 0 and 1 of this op).
    pub scores: BatchedProduct,
    /// The weighted values product, its A the probabilities (input 2 of this op its B).
    pub values: BatchedProduct,
    order: SumOrder,
}

impl Op for FusedAttention {
    fn name(&self) -> StaticName {
        "FusedAttention".into()
    }
    op_as_typed_op!();
}

impl EvalOp for FusedAttention {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let (x0, x1, v) = args_3!(inputs);
        let (s, p) = (&self.scores, &self.values);
        let v_shape = &p.inputs[1 - p.a_input];
        ensure!(
            x0.shape() == &*s.inputs[0] && x1.shape() == &*s.inputs[1] && v.shape() == &**v_shape,
            "FusedAttention inputs {:?} {:?} {:?}",
            x0.shape(),
            x1.shape(),
            v.shape()
        );
        let (p0, p1, pv) = (
            x0.try_as_plain_ram()?,
            x1.try_as_plain_ram()?,
            v.try_as_plain_ram()?,
        );
        let (xs0, xs1) = (p0.as_slice::<f32>()?, p1.as_slice::<f32>()?);
        let vs = pv.as_slice::<f32>()?;
        let (q_all, k_all) = if s.a_input == 0 {
            (xs0, xs1)
        } else {
            (xs1, xs0)
        };
        let mut out = gemm::output_tensor(&p.output)?;
        let mut po = out.try_as_plain_ram_mut()?;
        let c_all = po.as_slice_mut::<f32>()?;
        let exp = Func::Softmax2.map_reduce_f32()?;
        // Queries, head width, keys, value width.
        let (m, d, keys, dv) = (s.m.len, s.k.len, s.n.len, p.n.len);
        let ldc = p.m.c;
        let batches: usize = s.batch.iter().map(|b| b.len).product();
        for index in 0..batches {
            // The scores' batch offsets in Q and K, the values' in V and the output (the
            // two products' batch axes are the same, checked at the rewrite).
            let [oq, ok, _] = s.offsets(index);
            let [_, ov, oc] = p.offsets(index);
            let q = &q_all[oq..];
            let kt_len = s.b_len();
            let c = &mut c_all[oc..][..p.c_len()];
            let done = pack::with_scratch(kt_len + p.b_len(), |scratch| {
                let (kt, vp) = scratch.split_at_mut(kt_len);
                s.pack_b(true, &k_all[ok..], kt);
                p.pack_b(true, &vs[ov..], vp);
                // One task per query panel: its rows of the output.
                pool::on_threads(true, c, MR * ldc, |i, rows| {
                    let here = MR.min(m - i * MR);
                    pack::with_scratch(2 * MR * keys + MR * d, |buf| {
                        // The probabilities first: their rows start on 64-byte lines, as the
                        // scores tensor's rows do (the softmax's sum order follows alignment).
                        let (probs, rest) = buf.split_at_mut(MR * keys);
                        let (pp, qp) = rest.split_at_mut(MR * keys);
                        let probs = &mut probs[..here * keys];
                        pack::pack_a_panel_strided(q, (m, d), (s.m.a, s.k.a), i, qp);
                        let scores = gemm::Operands {
                            a: qp,
                            b: gemm::BSource::Packed(kt),
                            m: here,
                            n: keys,
                            k: d,
                            ldc: keys,
                        };
                        if !gemm::product(&scores, probs, gemm::Bias::None)
                            || softmax_block(probs, keys, &*exp, self.order).is_err()
                        {
                            return false;
                        }
                        pack::pack_a_panel(probs, here, keys, keys, 0, pp);
                        let weighted = gemm::Operands {
                            a: pp,
                            b: gemm::BSource::Packed(vp),
                            m: here,
                            n: dv,
                            k: keys,
                            ldc,
                        };
                        let c_rows = (here - 1) * ldc + dv;
                        gemm::product(&weighted, &mut rows[..c_rows], gemm::Bias::None)
                    })
                })
            });
            ensure!(
                done,
                "fused attention refused (AVX-512 missing or operands mis-sized)"
            );
        }
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for FusedAttention {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 3 && inputs.iter().all(|f| f.datum_type == f32::datum_type()));
        Ok(tvec!(f32::fact(&*self.values.output)))
    }

    as_op!();
}

/// The chain `scores EinSum -> RowSoftmax -> values EinSum` from the scores node `id`, as a
/// [`FusedAttention`] with the values node and the value input.
fn as_attention(
    model: &TypedModel,
    id: usize,
) -> TractResult<Option<(FusedAttention, usize, OutletId)>> {
    let single = |n: usize| {
        let succ = &model.node(n).outputs[0].successors;
        (succ.len() == 1).then(|| succ[0])
    };
    let Some(scores) = as_batched(model, id)? else {
        return Ok(None);
    };
    let Some(sm_in) = single(id) else {
        return Ok(None);
    };
    let sm = model.node(sm_in.node);
    let Some(softmax) = sm.op_as::<RowSoftmax>() else {
        return Ok(None);
    };
    let Some(pv_in) = single(sm.id) else {
        return Ok(None);
    };
    let Some(values) = as_batched(model, pv_in.node)? else {
        return Ok(None);
    };
    let outputs = model.output_outlets()?;
    let fits = softmax.trailing == 1
        // Scores laid out [batch.., queries, keys], the softmax over the keys.
        && scores.n.c == 1
        && scores.m.c == scores.n.len
        && scores.n.len % 16 == 0
        && scores.m.len >= crate::ops::batched::MIN_ROWS
        // The probabilities are the values product's A: rows the queries, depth the keys.
        && values.a_input == pv_in.slot
        && values.m.len == scores.m.len
        && values.k.len == scores.n.len
        && values.batch.len() == scores.batch.len()
        && values.batch.iter().zip(&scores.batch).all(|(p, s)| p.len == s.len && p.a == s.c)
        && values.m.a == scores.m.c
        && values.k.a == 1
        && !outputs.contains(&OutletId::new(id, 0))
        && !outputs.contains(&OutletId::new(sm.id, 0));
    if !fits {
        return Ok(None);
    }
    let v = model.node(pv_in.node).inputs[1 - pv_in.slot];
    let attention = FusedAttention {
        scores,
        values,
        order: softmax.order,
    };
    Ok(Some((attention, pv_in.node, v)))
}

/// Rewrite every `scores -> RowSoftmax -> values` chain of a decluttered `model` (after
/// [`crate::ops::softmax::fuse_softmaxes`]) into a [`FusedAttention`]; returns the model and the
/// number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn fuse_attention(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let Some((op, values_node, v)) = as_attention(&model, id)? else {
            continue;
        };
        let name = format!("{}.fused_attention", model.node(id).name);
        let inputs = model.node(id).inputs.clone();
        replace_with_op(
            &mut model,
            &[inputs[0], inputs[1], v],
            values_node,
            name,
            op,
        )?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The fused op against the unfused chain tract and the earlier rewrites plan, bit for bit:
    //! on the decoder's attention layout (shrunk) and on every stage of the committed default
    //! bundle.
    use super::*;
    use crate::ops::softmax::fuse_softmaxes;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, run_optimized};
    use tract_nnef::tract_core::ops::einsum::EinSum;
    use tract_nnef::tract_core::ops::nn::{Softmax, SoftmaxKind};

    /// `softmax(q . k^T) . v` over `[queries, heads, width]` operands, as the decoder lays them
    /// out, with its softmax already native; and its inputs.
    fn attention_model(queries: usize, keys: usize) -> (TypedModel, TVec<TValue>) {
        let (heads, d) = (3, 16);
        let mut model = TypedModel::default();
        let q = model
            .add_source("q", f32::fact([queries, heads, d]))
            .unwrap();
        let k = model.add_source("k", f32::fact([keys, heads, d])).unwrap();
        let v = model.add_source("v", f32::fact([keys, heads, d])).unwrap();
        let einsum = |expr: &str| EinSum {
            axes: expr.parse().unwrap(),
            operating_dt: f32::datum_type(),
            q_params: None,
        };
        let s = model
            .wire_node("scores", einsum("mak,nak->amn"), &[q, k])
            .unwrap();
        let softmax = Softmax::new(tvec![2], None, SoftmaxKind::default());
        let p = model.wire_node("softmax", softmax, &s).unwrap();
        let o = model
            .wire_node("values", einsum("amk,kan->man"), &[p[0], v])
            .unwrap();
        model.select_output_outlets(&o).unwrap();
        let values = |len: usize, seed: usize| -> Vec<f32> {
            (0..len)
                .map(|i| ((i * 7919 + seed * 104_729) % 1013) as f32 / 250.0 - 2.0)
                .collect()
        };
        let inputs = tvec![
            Tensor::from_shape(&[queries, heads, d], &values(queries * heads * d, 1)).unwrap(),
            Tensor::from_shape(&[keys, heads, d], &values(keys * heads * d, 2)).unwrap(),
            Tensor::from_shape(&[keys, heads, d], &values(keys * heads * d, 3)).unwrap(),
        ];
        let model = fuse_softmaxes(model.into_decluttered().unwrap()).unwrap().0;
        (model, inputs.into_iter().map(|t| t.into_tvalue()).collect())
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn attention_runs_fused_with_the_unfused_bits() {
        // Query counts with an edge panel; key counts of one and several B panels.
        for (queries, keys) in [(40, 48), (29, 160), (100, 304)] {
            let (model, inputs) = attention_model(queries, keys);
            let (fused, done) = fuse_attention(model.clone()).unwrap();
            assert_eq!(done, 1, "{queries} x {keys}");
            assert!(fused.nodes().iter().any(|n| n.op_is::<FusedAttention>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(fused, &inputs);
            assert_eq!(got[0].shape(), want[0].shape());
            assert_eq!(bits(&got[0]), bits(&want[0]), "{queries} x {keys}");
        }
    }

    #[test]
    fn keys_off_the_line_keep_the_unfused_chain() {
        // 50 keys: softmax rows would start off 64-byte lines, so the sum order could differ.
        let (model, _) = attention_model(40, 50);
        assert_eq!(fuse_attention(model).unwrap().1, 0);
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let (model, inputs) = attention_model(40, 48);
        let (fused, _) = fuse_attention(model).unwrap();
        let op = fused
            .nodes()
            .iter()
            .find_map(|n| n.op_as::<FusedAttention>())
            .unwrap()
            .clone();
        let short = Tensor::zero::<f32>(&[47, 3, 16]).unwrap().into_tvalue();
        let bad = tvec![inputs[0].clone(), inputs[1].clone(), short];
        assert!(op.eval_out_of_plan(bad).is_err());
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::FusedAttention, fuse_attention);
    }
}
