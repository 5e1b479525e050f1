//! LayerNorm over the last axis as one native op: one pass a row, rows split over the engine's
//! pool.
//!
//! tract 0.23.9 declutters an ONNX `LayerNormalization` into `Reduce<Sum>` over the last axis,
//! a `Mul` by `1 / C` (the mean), `x - mean`, its `RmsNorm` and the affine `Mul` and `Add`:
//! four to five passes over the activations, two of them on one thread, and per-op costs that
//! dominate small graphs (`test`'s `bev_encoder`, two LayerNorms of `[3200, 32]`, ran 1.05 ms
//! against onnxruntime's 0.66). [`fuse_layer_norms`] rewrites each such chain into a
//! [`LayerNorm`], which computes every row through tract's own steps: the row sum by
//! tract-linalg's `ReduceSum` kernel on the input row itself (the same slice at the same
//! address, so the kernel splits it as tract's `Reduce` does; a plain sum below 4 values, as
//! tract's), the mean as one f32 product, the difference, tract-linalg's `rms_norm` kernel on
//! the row, then the scale and the shift, each one f32 rounding. Bit for bit, so no output and
//! no pinned digest moves; rows never span threads.

use tract_linalg::routines::Func;
use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::nn::{Reduce, Reducer, RmsNorm};

use crate::gemm;
use crate::graph::matching::{bin_inputs as bin, const_operand, only_successor, replace_with_op};
use crate::pool;

/// Rows a task normalises at least (the pool's dispatch against a row of a few dozen values).
const ROWS_PER_TASK: usize = 64;

/// `((x - sum(x) * recip) normalised by tract's RmsNorm) * gamma + beta` over the last axis of
/// an f32 tensor.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerNorm {
    /// The mean's factor as the graph holds it (`1 / C`).
    pub recip: f32,
    /// The RmsNorm's epsilon.
    pub eps: f32,
    /// The scale, one a channel.
    pub gamma: Vec<f32>,
    /// The shift, one a channel.
    pub beta: Vec<f32>,
}

// Compared and hashed by bits: tract dedupes equal nodes.
impl Eq for LayerNorm {}
impl std::hash::Hash for LayerNorm {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        [self.recip, self.eps].map(f32::to_bits).hash(state);
        for v in self.gamma.iter().chain(&self.beta) {
            v.to_bits().hash(state);
        }
    }
}

impl LayerNorm {
    /// Normalise `rows` of `x` into `y` (both `rows * C` values).
    fn rows(
        &self,
        x: &[f32],
        y: &mut [f32],
        sum: &dyn tract_linalg::reduce::Reduce<f32>,
        rms: fn(&mut [f32], f32),
    ) -> bool {
        let c = self.gamma.len();
        for (xr, yr) in x.chunks_exact(c).zip(y.chunks_exact_mut(c)) {
            // tract's `Reduce<Sum>` takes its kernel from 4 values a row on.
            let s = if c >= 4 {
                match sum.run_with_params(xr, ()) {
                    Ok(s) => s,
                    Err(_) => return false,
                }
            } else {
                xr.iter().copied().sum::<f32>()
            };
            let mean = s * self.recip;
            for (v, &xv) in yr.iter_mut().zip(xr) {
                *v = xv - mean;
            }
            rms(yr, self.eps);
            // tract's kernels here are AVX-512 and leave the upper bits dirty (`vector_state`).
            crate::vector_state::clear_upper();
            for ((v, &g), &b) in yr.iter_mut().zip(&self.gamma).zip(&self.beta) {
                *v = *v * g + b;
            }
        }
        true
    }
}

impl Op for LayerNorm {
    fn name(&self) -> StaticName {
        "LayerNorm".into()
    }
    op_as_typed_op!();
}

impl EvalOp for LayerNorm {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let x = args_1!(inputs);
        let c = self.gamma.len();
        ensure!(
            x.datum_type() == f32::datum_type()
                && x.rank() >= 1
                && x.shape()[x.rank() - 1] == c
                && self.beta.len() == c
                && c > 0,
            "LayerNorm of {:?} {:?} over {c} channels",
            x.datum_type(),
            x.shape()
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let mut out = gemm::output_tensor(x.shape())?;
        let mut po = out.try_as_plain_ram_mut()?;
        let ys = po.as_slice_mut::<f32>()?;
        if ys.is_empty() {
            return Ok(tvec!(out.into_tvalue()));
        }
        let sum = Func::ReduceSum.reduce_f32()?;
        let rms = tract_linalg::routines::rms_norm_f32()?;
        let parallel = pool::worth_threads(ys.len() * 8);
        let chunk = ROWS_PER_TASK * c;
        let done = pool::on_threads(parallel, ys, chunk, |t, y| {
            self.rows(&xs[t * chunk..][..y.len()], y, &*sum, rms)
        });
        ensure!(done, "LayerNorm: tract's sum kernel failed");
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for LayerNorm {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 1 && inputs[0].datum_type == f32::datum_type());
        Ok(tvec!(inputs[0].without_value()))
    }

    as_op!();
}

/// If node `id` is the binary op `name` of node `from`'s output and an f32 constant of `len`
/// values whose dims are all 1 but the last: that constant's values.
fn channel_operand(
    model: &TypedModel,
    id: usize,
    name: &str,
    (from, len): (usize, usize),
) -> TractResult<Option<Vec<f32>>> {
    let Some((other, k)) = const_operand(model, id, name)? else {
        return Ok(None);
    };
    let shape = k.shape();
    let ones = !shape.is_empty() && shape[..shape.len() - 1].iter().all(|&d| d == 1);
    if other.node != from || k.datum_type() != f32::datum_type() || k.len() != len || !ones {
        return Ok(None);
    }
    Ok(Some(k.try_as_plain_ram()?.as_slice::<f32>()?.to_vec()))
}

/// The LayerNorm chain that starts with `Reduce<Sum>` node `reduce`, if it is one (module
/// doc): its input, last node and op.
fn layer_norm_at(
    model: &TypedModel,
    reduce: usize,
) -> TractResult<Option<(OutletId, usize, LayerNorm)>> {
    let node = model.node(reduce);
    let x = node.inputs[0];
    let fact = model.outlet_fact(x)?;
    let rank = fact.rank();
    let Some(&c) = fact.shape.as_concrete().and_then(|s| s.last()) else {
        return Ok(None);
    };
    let reduces_last = node
        .op_as::<Reduce>()
        .is_some_and(|r| r.reducer == Reducer::Sum && *r.axes == [rank - 1]);
    if !reduces_last || fact.datum_type != f32::datum_type() || c == 0 {
        return Ok(None);
    }
    // Reduce -> Mul(recip) -> Sub(x, mean) -> RmsNorm -> Mul(gamma) -> Add(beta).
    let Some(mean) = only_successor(model, reduce)? else {
        return Ok(None);
    };
    let Some(recip) = channel_operand(model, mean, "Mul", (reduce, 1))? else {
        return Ok(None);
    };
    let Some(diff) = only_successor(model, mean)? else {
        return Ok(None);
    };
    // x - mean, in that order.
    let Some([minuend, subtrahend]) = bin(model, diff, "Sub") else {
        return Ok(None);
    };
    if minuend != x || subtrahend.node != mean {
        return Ok(None);
    }
    let Some(norm) = only_successor(model, diff)? else {
        return Ok(None);
    };
    let Some(rms) = model.node(norm).op_as::<RmsNorm>() else {
        return Ok(None);
    };
    if rms.axis != rank - 1 || rms.eps.len() != 1 {
        return Ok(None);
    }
    let eps = rms.eps.cast_to_scalar::<f32>()?;
    let Some(scale) = only_successor(model, norm)? else {
        return Ok(None);
    };
    let Some(gamma) = channel_operand(model, scale, "Mul", (norm, c))? else {
        return Ok(None);
    };
    let Some(shift) = only_successor(model, scale)? else {
        return Ok(None);
    };
    let Some(beta) = channel_operand(model, shift, "Add", (scale, c))? else {
        return Ok(None);
    };
    // No step may broadcast the activations to another shape.
    for id in [diff, norm, scale, shift] {
        if model.outlet_fact(OutletId::new(id, 0))?.shape != fact.shape {
            return Ok(None);
        }
    }
    let op = LayerNorm {
        recip: recip[0],
        eps,
        gamma,
        beta,
    };
    Ok(Some((x, shift, op)))
}

/// Rewrite every LayerNorm chain of a decluttered `model` (module doc) into a [`LayerNorm`];
/// returns the model and the number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn fuse_layer_norms(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let reduces: Vec<String> = model
        .nodes()
        .iter()
        .filter(|n| n.op_is::<Reduce>())
        .map(|n| n.name.clone())
        .collect();
    let mut done = 0;
    for name in reduces {
        let id = model.node_id_by_name(&name)?;
        let Some((x, last, op)) = layer_norm_at(&model, id)? else {
            continue;
        };
        let name = format!("{}.layer_norm", model.node(last).name);
        replace_with_op(&mut model, &[x], last, name, op)?;
        done += 1;
    }
    Ok((model.into_compact()?, done))
}

#[cfg(test)]
mod tests {
    //! The op against tract's plan of the exported chain, bit for bit, over rows of several
    //! widths (below tract's kernel threshold; odd ones, whose rows start at every offset from
    //! the kernel's alignment; wide), on one and two threads; chains it must leave alone; and every
    //! stage of the committed default bundle.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, on_two_threads, run_optimized};
    use tract_nnef::tract_core::ops::math;

    /// The chain as tract declutters an exported LayerNorm over `[rows, c]`; `swap` subtracts
    /// the other way round (not a LayerNorm).
    fn chain(rows: usize, c: usize, swap: bool) -> (TypedModel, TVec<TValue>) {
        let mut m = TypedModel::default();
        let x = m.add_source("x", f32::fact([rows, c])).unwrap();
        let recip = m.add_const("recip", tensor2(&[[1.0 / c as f32]])).unwrap();
        let gamma: Vec<f32> = (0..c).map(|i| 0.5 + i as f32 * 0.037).collect();
        let beta: Vec<f32> = (0..c).map(|i| (i as f32 * 0.3).sin() * 0.1).collect();
        let gamma = m
            .add_const("gamma", Tensor::from_shape(&[1, c], &gamma).unwrap())
            .unwrap();
        let beta = m
            .add_const("beta", Tensor::from_shape(&[1, c], &beta).unwrap())
            .unwrap();
        let s = m
            .wire_node("sum", Reduce::new(tvec!(1), Reducer::Sum), &[x])
            .unwrap()[0];
        let mean = m.wire_node("mean", math::mul(), &[s, recip]).unwrap()[0];
        let d = if swap {
            m.wire_node("d", math::sub(), &[mean, x]).unwrap()[0]
        } else {
            m.wire_node("d", math::sub(), &[x, mean]).unwrap()[0]
        };
        let eps = Arc::new(tensor0(1e-5f32));
        let n = m.wire_node("n", RmsNorm { axis: 1, eps }, &[d]).unwrap()[0];
        let g = m.wire_node("g", math::mul(), &[n, gamma]).unwrap()[0];
        let y = m.wire_node("y", math::add(), &[g, beta]).unwrap()[0];
        m.select_output_outlets(&[y]).unwrap();
        let values: Vec<f32> = (0..rows * c)
            .map(|i| match i % 17 {
                0 => 1e-40,
                1 => -0.0,
                v => ((i as f32) * 0.0123).sin() * (v as f32) + 0.25,
            })
            .collect();
        let input = Tensor::from_shape(&[rows, c], &values).unwrap();
        (m, tvec![input.into()])
    }

    #[test]
    fn the_chain_computes_tracts_bits() {
        // Below the kernel threshold, at it (tract 0.23.9 sums rows of 4 or more with its
        // ReduceSum kernel, shorter ones in a loop: issue 40 pins that), odd, one AVX-512 step
        // and a tail, the decoder's width.
        for (rows, c) in [
            (5, 3),
            (6, 4),
            (9, 5),
            (7, 31),
            (300, 32),
            (130, 67),
            (64, 256),
        ] {
            let (model, inputs) = chain(rows, c, false);
            let model = model.into_decluttered().unwrap();
            let (fused, n) = fuse_layer_norms(model.clone()).unwrap();
            assert_eq!(n, 1, "{rows} x {c}");
            assert!(fused.nodes().iter().any(|n| n.op_is::<LayerNorm>()));
            assert!(!fused.nodes().iter().any(|n| n.op_is::<RmsNorm>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(fused.clone(), &inputs);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{rows} x {c}");
            let two = on_two_threads(|| run_optimized(fused, &inputs));
            assert_eq!(bits(&two[0]), bits(&want[0]), "{rows} x {c}, two threads");
        }
    }

    #[test]
    fn other_chains_are_left_alone() {
        let (model, _) = chain(8, 32, true);
        let model = model.into_decluttered().unwrap();
        assert_eq!(fuse_layer_norms(model).unwrap().1, 0);
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = LayerNorm {
            recip: 0.25,
            eps: 1e-5,
            gamma: vec![1.0; 4],
            beta: vec![0.0; 4],
        };
        for x in [
            Tensor::zero::<f32>(&[3, 5]).unwrap(),
            Tensor::zero::<i32>(&[3, 4]).unwrap(),
        ] {
            assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
        }
    }

    #[test]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::LayerNorms, fuse_layer_norms);
    }
}
