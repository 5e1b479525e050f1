//! The convolutions of 8 output channels or more as the native product of their weights and
//! their input's patches.
//!
//! tract 0.23.9 runs these with lazy im2col (the product gathers its image operand panel by
//! panel: 2-5x the bare product on the wide ones), eager im2col (its `Im2col` op spends ~2 ns a
//! value), or a direct spatial kernel, and its matrix product at 53-57% of an AVX-512 core's
//! peak (docs/perf.md). [`unfold_convs`] rewrites each such convolution into one
//! [`UnfoldConv`]: the weights packed once at load for [`gemm::product`], the patches
//! ([`Unfold`]: one row per input channel and tap, a shifted copy of the input rows with zeros
//! in the padding) gathered straight into the product's packed blocks as it goes (no `[k, n]`
//! matrix is ever laid out: the scratch is one block of [`gemm::KC`] x 1,024 values, or the
//! whole B of a deep product of few columns, [`gemm::WHOLE_B_MAX`] values at most), the bias
//! added to the finished sums. Narrower convolutions keep tract's plan (the product's 12-row
//! tiles would be mostly empty); a 1x1 convolution is a product after decluttering
//! ([`crate::ops::pointwise`] for channel-first maps).
//!
//! Bit for bit with tract's im2col: the product sums `k` in the order of tract's own im2col and
//! of the OIHW weights (input channel, then kernel row, then kernel column) in one fused
//! multiply-add chain from zero, and adds the bias after the sum, as tract's convolution does
//! on its im2col paths; this module's tests check the bits against tract's plan of the same
//! convolution and of every stage of the committed default bundle. The one convolution tract
//! would run otherwise, `test`'s 8-channel stem (tract's direct spatial kernel, which sums in
//! another order), now runs here too: 1.1-1.3 ms against tract's 2.9 (its image encoder 4.6 ->
//! 2.7 ms, onnxruntime's 2.95), so on the AVX-512 tier the default bundle's pinned digests
//! (the demo drive's, the C example's) are those of tract's im2col order; the tests compare
//! that stem against tract's plan with its direct spatial path off
//! (`TRACT_DISABLE_DIRECT_SPATIAL`). On the AVX-512 tier only ([`gemm`]).

use tract_nnef::internal::*;

use crate::gemm::{self, PackedA};
use crate::graph::matching::replace_with_op;
use crate::ops::conv_layer::conv_layer_at;
use crate::ops::finish::Epilogue;
use crate::ops::unfold::{Unfold, with_batch};

/// A convolution as the native product ([`gemm::product`]) of its weights, packed at load, and
/// its input's patches ([`Unfold`]), gathered straight into the product's packed blocks; the
/// bias added to the finished sums.
#[derive(Clone, Debug)]
pub struct UnfoldConv {
    /// The patches.
    pub unfold: Unfold,
    /// Output channels.
    pub out_channels: usize,
    /// Whether input and output carry a batch axis of 1 (NCHW; CHW otherwise).
    pub batch_axis: bool,
    /// The shortcut and ReLU after the bias ([`crate::passes::epilogue`]).
    pub epilogue: Epilogue,
    weights: Arc<PackedA>,
    bias: Arc<Vec<f32>>,
}

impl PartialEq for UnfoldConv {
    fn eq(&self, other: &Self) -> bool {
        self.unfold == other.unfold
            && self.out_channels == other.out_channels
            && self.batch_axis == other.batch_axis
            && self.epilogue == other.epilogue
            && Arc::ptr_eq(&self.weights, &other.weights)
            && Arc::ptr_eq(&self.bias, &other.bias)
    }
}
impl Eq for UnfoldConv {}

impl Op for UnfoldConv {
    fn info(&self) -> TractResult<Vec<String>> {
        let [oh, ow] = self.unfold.output;
        let (m, k, n) = (self.out_channels, self.unfold.depth(), oh * ow);
        Ok(vec![format!("Mult: m:{m} k:{k} n:{n} with [native]")])
    }

    fn name(&self) -> StaticName {
        "UnfoldConv".into()
    }
    op_as_typed_op!();
}

impl UnfoldConv {
    /// The convolution over `unfold`'s patches with `out_channels` x (channels x taps) weights
    /// `weights` (row-major) and one bias an output channel, no epilogue.
    #[must_use]
    pub fn new(unfold: Unfold, batch_axis: bool, weights: &[f32], bias: Vec<f32>) -> Self {
        let out_channels = bias.len();
        let k = unfold.depth();
        Self {
            unfold,
            out_channels,
            batch_axis,
            epilogue: Epilogue::default(),
            weights: Arc::new(PackedA::from_row_major(weights, out_channels, k)),
            bias: Arc::new(bias),
        }
    }

    /// This convolution with `epilogue` after its bias.
    #[must_use]
    pub fn with_epilogue(&self, epilogue: Epilogue) -> Self {
        Self {
            epilogue,
            ..self.clone()
        }
    }

    /// `[1, C, H, W]` or `[C, H, W]`.
    fn input_shape(&self) -> TVec<usize> {
        let [c, h, w] = self.unfold.input;
        with_batch(self.batch_axis, [c, h, w])
    }

    /// `[1, C_out, OH, OW]` or `[C_out, OH, OW]`.
    fn output_shape(&self) -> TVec<usize> {
        let [oh, ow] = self.unfold.output;
        with_batch(self.batch_axis, [self.out_channels, oh, ow])
    }
}

impl EvalOp for UnfoldConv {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let out_shape = self.output_shape();
        let shortcut = self.epilogue.shortcut(&inputs, &out_shape)?;
        let x = &inputs[0];
        let [oh, ow] = self.unfold.output;
        ensure!(
            x.shape() == &*self.input_shape(),
            "UnfoldConv input {:?}, expected {:?}",
            x.shape(),
            self.input_shape()
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let co = self.out_channels;
        let mut out = gemm::output_tensor(&out_shape)?;
        let mut po = out.try_as_plain_ram_mut()?;
        let fill = |j: usize, pc: usize, kc: usize, dst: &mut [f32]| {
            self.unfold.fill_panels(xs, (j, pc, kc), dst);
        };
        let ops = gemm::Operands {
            a: self.weights.as_slice(),
            b: gemm::BSource::Fill(&fill),
            m: co,
            n: oh * ow,
            k: self.unfold.depth(),
            ldc: oh * ow,
        };
        let finish = self
            .epilogue
            .finish(gemm::Bias::PerRow(&self.bias), shortcut);
        ensure!(
            gemm::product_then(&ops, po.as_slice_mut::<f32>()?, finish),
            "native product refused (AVX-512 missing or operands mis-sized)"
        );
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for UnfoldConv {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        self.epilogue.output_facts(inputs, &self.output_shape())
    }

    fn cost(&self, _inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let [oh, ow] = self.unfold.output;
        let fma = self.out_channels * self.unfold.depth() * oh * ow;
        Ok(tvec!((Cost::FMA(f32::datum_type()), fma.to_dim())))
    }

    as_op!();
}

/// Output channels from which a convolution is unfolded (below, the product's 12-row tiles are
/// mostly empty and tract's plan is kept). `test`'s 8-channel convolutions, two thirds of a
/// tile: 0.3 ms against tract's 1.1.
pub const MIN_OUTPUT_CHANNELS: usize = 8;

/// Rewrite every f32 convolution of a decluttered `model` with one group, NCHW over two
/// spatial axes (or CHW, the batch axis decluttered away), batch 1, constant weights and bias and at least [`MIN_OUTPUT_CHANNELS`]
/// outputs into an [`UnfoldConv`]; returns the model and the number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn unfold_convs(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let names: Vec<String> = model.nodes().iter().map(|n| n.name.clone()).collect();
    let mut done = 0;
    for name in names {
        let id = model.node_id_by_name(&name)?;
        let Some(conv) = conv_layer_at(&model, id)? else {
            continue;
        };
        if conv.out_channels() < MIN_OUTPUT_CHANNELS {
            continue;
        }
        let kernel_plain = conv.kernel.try_as_plain_ram()?;
        let op = UnfoldConv::new(
            conv.unfold.clone(),
            conv.batch_axis,
            kernel_plain.as_slice::<f32>()?,
            conv.bias.clone(),
        );
        replace_with_op(&mut model, &[conv.x], id, format!("{name}.unfold_conv"), op)?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The pass against tract's own plan of the same convolution, bit for bit: on ResNet shapes
    //! (rewritten), on narrow and wide ones (left alone), and on every stage of the committed
    //! default bundle.
    use super::*;
    use crate::passes::conv_direct;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        ConvShape, assert_same_bits, bits, committed_stage_before, conv_model, inputs_of,
        run_optimized,
    };
    use satmap_core::engine::Stage;
    use tract_nnef::tract_core::tract_data::knobs::KnobScope;

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn resnet_shapes_run_unfolded_with_tracts_bits() {
        let cases = [
            // `nano`'s layer1 (64 -> 64 over 48 x 80), a layer2 entry (stride 2), the stem
            // (7x7, stride 2, padding 3), a dilated one, odd maps that leave border pixels,
            // layer3 and layer4 widths (a 1x1 convolution is a matmul after decluttering), and
            // a satellite FPN convolution and patch embedding without the batch axis.
            ConvShape::new(64, 64, [48, 80], 3, 1, 1),
            ConvShape::new(64, 128, [48, 80], 3, 2, 1),
            ConvShape::new(3, 64, [96, 160], 7, 2, 3),
            ConvShape {
                dilation: 2,
                ..ConvShape::new(32, 64, [13, 17], 3, 1, 2)
            },
            ConvShape::new(16, 96, [11, 9], 3, 2, 0),
            ConvShape::new(16, 32, [23, 40], 3, 1, 1),
            ConvShape::new(128, 256, [12, 20], 3, 1, 1),
            ConvShape::new(300, 512, [6, 10], 3, 1, 1),
            ConvShape {
                batch: false,
                ..ConvShape::new(256, 256, [25, 13], 3, 1, 1)
            },
            ConvShape {
                batch: false,
                ..ConvShape::new(3, 96, [40, 24], 4, 4, 0)
            },
        ];
        for s in cases {
            let (model, inputs) = conv_model(&s);
            let (unfolded, n) = unfold_convs(model.clone()).unwrap();
            assert_eq!(n, 1, "{} -> {}", s.ci, s.co);
            assert!(unfolded.nodes().iter().any(|n| n.op_is::<UnfoldConv>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(unfolded, &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{} -> {}", s.ci, s.co);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{} -> {}", s.ci, s.co);
        }
    }

    #[test]
    fn narrow_convolutions_keep_tracts_plan() {
        // 4 outputs: a third of the product's 12-row tiles.
        let (model, _) = conv_model(&ConvShape::new(64, 4, [24, 40], 3, 1, 1));
        let (same, n) = unfold_convs(model).unwrap();
        assert_eq!(n, 0);
        assert!(
            same.nodes()
                .iter()
                .any(|n| n.op_is::<tract_nnef::tract_core::ops::cnn::Conv>())
        );
    }

    /// tract's direct spatial path off, as [`super::conv_direct`] scopes it: tract's im2col.
    fn without_direct_spatial<R>(f: impl FnOnce() -> R) -> R {
        KnobScope::new([("TRACT_DISABLE_DIRECT_SPATIAL", "1")])
            .expect("knob")
            .enter(f)
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn direct_spatial_stems_run_unfolded_with_tracts_im2col_bits() {
        // `test`'s 8-channel stem and a 16-channel one, both run direct spatial by tract.
        for s in [
            ConvShape::new(3, 8, [180, 320], 7, 2, 3),
            ConvShape::new(3, 16, [256, 320], 7, 2, 3),
        ] {
            let (model, inputs) = conv_model(&s);
            let direct = model.clone().into_optimized().unwrap();
            assert!(conv_direct::has_op(&direct, conv_direct::DIRECT_SPATIAL_OP));
            let (unfolded, n) = unfold_convs(model.clone()).unwrap();
            assert_eq!(n, 1, "{} -> {}", s.ci, s.co);
            let want = without_direct_spatial(|| run_optimized(model, &inputs));
            let got = run_optimized(unfolded, &inputs);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{} -> {}", s.ci, s.co);
        }
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let unfold = Unfold {
            input: [2, 4, 4],
            kernel: [3, 3],
            strides: [1, 1],
            dilations: [1, 1],
            pad_before: [1, 1],
            output: [4, 4],
        };
        let op = UnfoldConv {
            unfold,
            out_channels: 1,
            batch_axis: true,
            epilogue: Epilogue::default(),
            weights: Arc::new(PackedA::from_row_major(&[0.5; 18], 1, 18)),
            bias: Arc::new(vec![0.0]),
        };
        let x = Tensor::zero::<f32>(&[1, 3, 4, 4]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        // Every stage as tract's plan computes it with im2col (`test`'s stem is direct spatial
        // in tract's own plan; every other convolution takes im2col anyway).
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::UnfoldConvs);
            let inputs = inputs_of(&plain);
            let (unfolded, _) = unfold_convs(plain.clone()).expect("rewrite");
            let want = without_direct_spatial(|| run_optimized(plain, &inputs));
            let got = run_optimized(unfolded, &inputs);
            assert_same_bits(stage, &want, &got);
        }
    }
}
