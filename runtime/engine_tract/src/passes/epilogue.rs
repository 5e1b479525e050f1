//! What a native product does to its finished sums besides the bias: a ResNet block's
//! shortcut `Add` or a transformer layer's residual `Add`, and the `ReLU` after it, taken into
//! the product's last store.
//!
//! After decluttering, ResNet's `conv -> ReLU` is a convolution followed by `Max` with a scalar
//! zero, and a block's `conv -> Add(shortcut) -> ReLU` an `Add` of the shortcut and that `Max`.
//! Run as tract ops they are passes of their own over the whole map (`paper`'s image encoder:
//! `OptBinChain(Add+Max)` 28 ms and `OptMaxByScalar` 13 ms of 614 ms on one thread, on maps
//! that left L2 between the convolution and them, and on one thread while the products ran
//! on all); so are the feed-forward layers' ReLUs and residual `Add`s after a [`PackedLinear`]
//! (`nano`'s BEV encoder: 1.7 of 19.9 ms). [`fuse_epilogues`] takes them into the
//! [`UnfoldConv`], [`PointwiseConv`], [`PackedLinear`], [`QuantLinear`] or [`QuantConv`] before them: the product's
//! micro-kernel adds the shortcut and applies the floor to each tile while it is still in
//! registers ([`crate::gemm::Finish`]).
//!
//! Bit for bit: the graph computes `((sum + bias) + shortcut).max(0)`, one f32 step each, and
//! so does the kernel, in that order; the `max` with tract's bits (its by-scalar `Max` is
//! Rust's `f32::max` compiled for x86: [`crate::gemm::floor`], a NaN giving the floor). This module's
//! tests check ResNet blocks and feed-forward layers built here and every stage of the
//! committed default bundle against the engine's plan before the pass. (tract's own plan of a
//! linear layer fuses a `Max` into its product kernel, where a NaN stays NaN; the engine ran
//! the `Max` as tract's by-scalar op after its native product before this pass, and still
//! computes those bits.)

use tract_nnef::internal::*;

use crate::graph::matching::{bin_inputs, only_successor, replace_with_op};
use crate::ops::conv_unfold::UnfoldConv;
use crate::ops::finish::Epilogue;
use crate::ops::linear::PackedLinear;
use crate::ops::pointwise::PointwiseConv;
use crate::ops::quant_conv::QuantConv;
use crate::ops::quant_linear::QuantLinear;

/// The native products that take an [`Epilogue`].
enum Finishable<'a> {
    Unfold(&'a UnfoldConv),
    Pointwise(&'a PointwiseConv),
    Linear(&'a PackedLinear),
    Int8Linear(&'a QuantLinear),
    Int8Conv(&'a QuantConv),
}

impl Finishable<'_> {
    fn of(node: &TypedNode) -> Option<Finishable<'_>> {
        if let Some(op) = node.op_as::<UnfoldConv>() {
            Some(Finishable::Unfold(op))
        } else if let Some(op) = node.op_as::<PointwiseConv>() {
            Some(Finishable::Pointwise(op))
        } else if let Some(op) = node.op_as::<QuantLinear>() {
            Some(Finishable::Int8Linear(op))
        } else if let Some(op) = node.op_as::<QuantConv>() {
            Some(Finishable::Int8Conv(op))
        } else {
            node.op_as::<PackedLinear>().map(Finishable::Linear)
        }
    }

    fn epilogue(&self) -> Epilogue {
        match self {
            Finishable::Unfold(op) => op.epilogue,
            Finishable::Pointwise(op) => op.epilogue,
            Finishable::Linear(op) => op.epilogue,
            Finishable::Int8Linear(op) => op.epilogue,
            Finishable::Int8Conv(op) => op.epilogue,
        }
    }

    fn with(&self, epilogue: Epilogue) -> Box<dyn TypedOp> {
        match self {
            Finishable::Unfold(op) => Box::new(op.with_epilogue(epilogue)),
            Finishable::Pointwise(op) => Box::new(op.with_epilogue(epilogue)),
            Finishable::Linear(op) => Box::new(op.with_epilogue(epilogue)),
            Finishable::Int8Linear(op) => Box::new(op.with_epilogue(epilogue)),
            Finishable::Int8Conv(op) => Box::new(op.with_epilogue(epilogue)),
        }
    }
}

/// Take into each [`UnfoldConv`], [`PointwiseConv`] and [`PackedLinear`] of `model` without an
/// epilogue the `Add` of a non-constant f32 tensor of its output's shape that is its one
/// consumer, and then (or instead) the `Max` with a constant f32 scalar on the right that
/// consumes that; returns the model and the number of products that took one.
///
/// # Errors
/// tract refusing a patch or a fact (an inconsistent model).
pub fn fuse_epilogues(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let node = model.node(id);
        let Some(conv) = Finishable::of(node) else {
            continue;
        };
        if !conv.epilogue().is_empty() {
            continue;
        }
        let out = OutletId::new(id, 0);
        let Some(shape) = model.outlet_fact(out)?.shape.as_concrete().map(TVec::from) else {
            continue;
        };
        let mut epilogue = Epilogue::default();
        let mut inputs: TVec<OutletId> = node.inputs.iter().copied().collect();
        let mut last = out;
        // Whether node `id`'s output has the product's shape (no broadcast grew it).
        let keeps_shape = |id: usize| -> TractResult<bool> {
            Ok(model.outlet_fact(OutletId::new(id, 0))?.shape.as_concrete() == Some(&shape))
        };
        if let Some(next) = only_successor(&model, last.node)?
            && let Some([a, b]) = bin_inputs(&model, next, "Add")
            && let Some(other) = match (a == last, b == last) {
                (true, false) => Some(b),
                (false, true) => Some(a),
                _ => None,
            }
        {
            let fact = model.outlet_fact(other)?;
            if fact.konst.is_none()
                && fact.datum_type == f32::datum_type()
                && fact.shape.as_concrete() == Some(&shape)
                && keeps_shape(next)?
            {
                epilogue.residual = true;
                inputs.push(other);
                last = OutletId::new(next, 0);
            }
        }
        if let Some(next) = only_successor(&model, last.node)?
            && let Some([a, b]) = bin_inputs(&model, next, "Max")
            && a == last
            && let Some(k) = &model.outlet_fact(b)?.konst
            && k.datum_type() == f32::datum_type()
            && k.len() == 1
            && k.rank() <= shape.len()
            && keeps_shape(next)?
        {
            epilogue.floor = Some(k.cast_to_scalar::<f32>()?);
            last = OutletId::new(next, 0);
        }
        if epilogue.is_empty() {
            continue;
        }
        let op = conv.with(epilogue);
        let name = format!("{}.epilogue", model.node(last.node).name);
        replace_with_op(&mut model, &inputs, last.node, name, op)?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The pass against tract's plan, bit for bit: ResNet blocks and feed-forward layers built
    //! here (3x3 and 1x1 convolutions, linear layers, with and without the shortcut) and every
    //! stage of the committed default bundle.
    use super::*;
    use crate::gemm;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        ConvShape, assert_pass_keeps_stage_bits, bits, conv_model, linear_model, on_two_threads,
        run_optimized,
    };
    use crate::{ops::conv_unfold, ops::linear, ops::pointwise};
    use tract_nnef::tract_core::ops::math;

    /// `(model, inputs)` (one output) with, after its output, `Add(y, shortcut)` (the shortcut
    /// a second input) when `residual`, then `Max(_, floor)`.
    fn block(
        (mut model, mut inputs): (TypedModel, TVec<TValue>),
        residual: bool,
        floor: f32,
    ) -> (TypedModel, TVec<TValue>) {
        let mut y = model.output_outlets().unwrap()[0];
        let shape: TVec<usize> = model
            .outlet_fact(y)
            .unwrap()
            .shape
            .as_concrete()
            .unwrap()
            .into();
        if residual {
            let r = model.add_source("shortcut", f32::fact(&shape)).unwrap();
            y = model
                .wire_node("shortcut_add", math::add(), &[y, r])
                .unwrap()[0];
            // Shortcut values of both signs around the sums, a NaN among them.
            let mut v: Vec<f32> = (0..shape.iter().product::<usize>())
                .map(|i| ((i * 7919) % 101) as f32 / 25.0 - 2.0)
                .collect();
            v[3] = f32::NAN;
            inputs.push(Tensor::from_shape(&shape, &v).unwrap().into_tvalue());
        }
        let k = model
            .add_const(
                "floor",
                tensor0(floor).broadcast_into_rank(shape.len()).unwrap(),
            )
            .unwrap();
        y = model.wire_node("relu", math::max(), &[y, k]).unwrap()[0];
        model.select_output_outlets(&[y]).unwrap();
        (model, inputs)
    }

    /// The fused floor stands for tract's by-scalar `Max` (issue 40: a test per assumption on
    /// tract 0.23.9's internals): its plan of `Max(x, s)` gives `gemm::floor(x, s)` bit for bit,
    /// at every length (its kernel's body and tail) and on every tier, for NaN, signed zeros
    /// and subnormals; a tract whose ReLU picked the other of two equal zeros, or let a NaN
    /// through, fails here before any bundle digest moves.
    #[test]
    fn tracts_by_scalar_max_is_the_floor_bit_for_bit() {
        let specials = [
            f32::NAN,
            0.0,
            -0.0,
            1e-40,
            -1e-40,
            1.5,
            -1.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.5,
        ];
        for len in (1..=70).chain([129, 1000]) {
            let values: Vec<f32> = (0..len)
                .map(|i| specials[(i * 7) % specials.len()])
                .collect();
            for s in [0.0f32, -0.0, -0.5] {
                let mut model = TypedModel::default();
                let x = model.add_source("x", f32::fact([len])).unwrap();
                let k = model
                    .add_const("s", tensor0(s).broadcast_into_rank(1).unwrap())
                    .unwrap();
                let y = model.wire_node("relu", math::max(), &[x, k]).unwrap()[0];
                model.select_output_outlets(&[y]).unwrap();
                let input = Tensor::from_shape(&[len], &values).unwrap();
                let got = run_optimized(model, &tvec![input.into()]);
                let want: Vec<u32> = values
                    .iter()
                    .map(|&v| gemm::floor(v, s).to_bits())
                    .collect();
                assert_eq!(bits(&got[0]), want, "length {len}, floor {s}");
            }
        }
    }

    /// `block` through the native passes and this one against the engine's plan before this
    /// pass (the native product, then tract's `Add` and by-scalar `Max`), on one and two
    /// threads; `what` names it in failures. Not against tract's own plan of the whole block:
    /// for a linear layer tract fuses the `Max` into its product kernel, where a NaN stays NaN
    /// (its by-scalar `Max` gives the floor for it, as the engine always has).
    fn assert_block_fuses(base: (TypedModel, TVec<TValue>), what: &str) {
        for residual in [false, true] {
            for floor in [0.0, -0.5] {
                let (model, inputs) = block(base.clone(), residual, floor);
                let native = conv_unfold::unfold_convs(model).unwrap().0;
                let native = linear::native_linears(native).unwrap().0;
                let native = pointwise::native_pointwise_convs(native).unwrap().0;
                let (fused, n) = fuse_epilogues(native.clone()).unwrap();
                let what = format!("{what}, residual {residual}, floor {floor}");
                assert_eq!(n, 1, "{what}");
                assert!(
                    !fused.nodes().iter().any(|n| n.op.name() == "Max"),
                    "{what}"
                );
                let want = run_optimized(native, &inputs);
                let got = run_optimized(fused.clone(), &inputs);
                assert_same(&got[0], &want[0], &what);
                let two = on_two_threads(|| run_optimized(fused, &inputs));
                assert_same(&two[0], &want[0], &format!("{what} on two threads"));
            }
        }
    }

    /// `got` and `want` bit for bit, the first difference named.
    fn assert_same(got: &Tensor, want: &Tensor, what: &str) {
        let (g, w) = (bits(got), bits(want));
        assert_eq!(g.len(), w.len(), "{what}");
        if let Some(i) = g.iter().zip(&w).position(|(a, b)| a != b) {
            let (a, b) = (f32::from_bits(g[i]), f32::from_bits(w[i]));
            panic!("{what}: value {i} is {a:e}, tract's {b:e}");
        }
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn resnet_blocks_take_their_shortcut_and_relu_with_tracts_bits() {
        for s in [
            ConvShape::new(32, 64, [24, 40], 3, 1, 1),
            ConvShape::new(64, 128, [12, 20], 1, 1, 0),
            ConvShape::new(16, 13, [7, 9], 3, 1, 1),
        ] {
            assert_block_fuses(conv_model(&s), &format!("{} -> {} k{}", s.ci, s.co, s.k));
        }
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn linear_layers_take_their_residual_and_relu_with_tracts_bits() {
        // The BEV encoder's feed-forward layers (3200 tokens), a few tokens, no bias.
        for (lead, k, n, bias) in [(vec![3200], 256, 512, true), (vec![2, 9], 40, 33, false)] {
            let model = linear_model(&lead, k, n, false, bias);
            let mut shape = lead.clone();
            shape.push(k);
            let x: Vec<f32> = (0..shape.iter().product::<usize>())
                .map(|i| ((i * 31) % 97) as f32 / 48.0 - 1.0)
                .collect();
            let inputs = tvec![Tensor::from_shape(&shape, &x).unwrap().into_tvalue()];
            assert_block_fuses((model, inputs), &format!("{lead:?} x {k} -> {n}"));
        }
    }

    #[test]
    fn other_consumers_are_left_alone() {
        // The Max's constant on the left and a non-scalar floor: tract's plan stays.
        let s = ConvShape::new(32, 64, [24, 40], 3, 1, 1);
        let (mut model, _) = conv_model(&s);
        let y = model.output_outlets().unwrap()[0];
        let k = model
            .add_const("floor", tensor0(0.0f32).broadcast_into_rank(4).unwrap())
            .unwrap();
        let z = model.wire_node("relu", math::max(), &[k, y]).unwrap()[0];
        model.select_output_outlets(&[z]).unwrap();
        let native = conv_unfold::unfold_convs(model).unwrap().0;
        assert_eq!(fuse_epilogues(native).unwrap().1, 0);
    }

    #[test]
    fn a_missing_shortcut_is_an_error_value() {
        let e = Epilogue {
            residual: true,
            floor: Some(0.0),
        };
        let x = Tensor::zero::<f32>(&[1, 2, 3]).unwrap().into_tvalue();
        assert!(e.shortcut(std::slice::from_ref(&x), &[1, 2, 3]).is_err());
        let wrong = Tensor::zero::<f32>(&[1, 2, 4]).unwrap().into_tvalue();
        assert!(e.shortcut(&[x.clone(), wrong], &[1, 2, 3]).is_err());
        assert!(e.shortcut(&[x.clone(), x], &[1, 2, 3]).unwrap().is_some());
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::Epilogues, fuse_epilogues);
    }
}
