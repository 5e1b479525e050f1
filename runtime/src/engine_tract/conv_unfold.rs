//! The mid-width convolutions as a native unfold and tract's own matrix product.
//!
//! With tract's AVX-512 kernels, the 3x3 convolutions of 64 to 255 output channels (ResNet's
//! layer1 and layer2, the 7x7 stem) run lazy im2col: the product gathers its image operand panel
//! by panel, and in `nano`'s image encoder the gather cost about as much as the product (layer1's
//! `m 64, k 576, n 3840` at 41 GFLOP/s). tract's eager `Im2col` op, which [`conv_im2col`] uses
//! for the wider ones, spends ~2 ns a value on these shapes and lost. [`unfold_convs`] instead
//! rewrites such a convolution into [`Unfold`] (the patches as a plain `[k, n]` matrix: one row
//! per input channel and tap, a shifted copy of the input rows with zeros in the padding, ~0.5 ns
//! a value) and an `mk,kn->mn` einsum with the weights and the bias, which tract's optimiser
//! plans as its own matmul with a packed operand. `nano`'s image encoder, per-node profile: its
//! matmuls 82.4 -> 57-60 ms, plus 7-9 ms of unfold and 5-7 ms of packing, the stage 93 -> 76-84 ms
//! (docs/perf.md). Wider convolutions are [`conv_im2col`]'s (or lost: layer4 with 512 channels
//! over 6 x 10 ran slower unfolded), narrower ones keep tract's plan.
//!
//! Bit for bit: the product runs tract's micro-kernel over the same `k` order (input channel,
//! then kernel row, then kernel column, the order of tract's own im2col and of the OIHW weights)
//! and adds the bias after the sum, as tract's convolution does; this module's tests check the
//! bits against tract's plan of the same convolution, and a 2-frame `nano` drive gives run
//! digest `a44dec433bc04144` with and without the pass. Measured on `amd-avx512f` only, so the
//! pass runs on the AVX-512 tier ([`conv_im2col::pays_off`]).
//!
//! [`conv_im2col`]: super::conv_im2col
//! [`conv_im2col::pays_off`]: super::conv_im2col::pays_off

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::cnn::Conv;
use tract_nnef::tract_core::ops::einsum::EinSum;
use tract_nnef::tract_core::ops::math;
use tract_nnef::tract_core::ops::nn::DataFormat;

/// `[1, C, H, W]` -> `[C * kh * kw, OH * OW]`: the patches of a 2-D convolution, row
/// `(c * kh + ky) * kw + kx`, zeros where a tap falls in the padding.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Unfold {
    /// Input channels, rows, columns.
    pub input: [usize; 3],
    /// Kernel rows, columns.
    pub kernel: [usize; 2],
    /// Strides (rows, columns).
    pub strides: [usize; 2],
    /// Dilations (rows, columns).
    pub dilations: [usize; 2],
    /// Padding before (rows, columns).
    pub pad_before: [usize; 2],
    /// Output rows, columns.
    pub output: [usize; 2],
}

impl Op for Unfold {
    fn name(&self) -> StaticName {
        "Unfold".into()
    }
    op_as_typed_op!();
}

impl EvalOp for Unfold {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let x = args_1!(inputs);
        let [c_n, h, w] = self.input;
        let [kh, kw] = self.kernel;
        let [oh, ow] = self.output;
        ensure!(x.shape() == [1, c_n, h, w], "Unfold input {:?}", x.shape());
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let n = oh * ow;
        let mut out = Tensor::zero::<f32>(&[c_n * kh * kw, n])?;
        let mut po = out.try_as_plain_ram_mut()?;
        let y = po.as_slice_mut::<f32>()?;
        let [sy, sx] = self.strides;
        let [dy, dx] = self.dilations;
        let [pt, pl] = self.pad_before;
        for (row, dst) in y.chunks_exact_mut(n).enumerate() {
            let kx = row % kw;
            let ky = (row / kw) % kh;
            let c = row / (kw * kh);
            let plane = &xs[c * h * w..][..h * w];
            for oy in 0..oh {
                let iy = (oy * sy + ky * dy) as isize - pt as isize;
                if iy < 0 || iy >= h as isize {
                    continue;
                }
                let src = &plane[iy as usize * w..][..w];
                let d = &mut dst[oy * ow..][..ow];
                let off = (kx * dx) as isize - pl as isize;
                if sx == 1 {
                    // Contiguous: the run of ox whose ix = ox + off is inside the row.
                    let lo = (-off).max(0) as usize;
                    let hi = ((w as isize - off).min(ow as isize)).max(0) as usize;
                    if lo < hi {
                        let s = (lo as isize + off) as usize;
                        d[lo..hi].copy_from_slice(&src[s..s + (hi - lo)]);
                    }
                } else {
                    for (ox, v) in d.iter_mut().enumerate() {
                        let ix = (ox * sx) as isize + off;
                        if ix >= 0 && ix < w as isize {
                            *v = src[ix as usize];
                        }
                    }
                }
            }
        }
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for Unfold {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 1 && inputs[0].datum_type == f32::datum_type());
        let [c, _, _] = self.input;
        let [kh, kw] = self.kernel;
        let [oh, ow] = self.output;
        Ok(tvec!(f32::fact([c * kh * kw, oh * ow])))
    }

    as_op!();
}

/// Output channels from which a convolution is unfolded (below, the product's m tiles are
/// mostly empty and tract's plan is kept).
pub const MIN_OUTPUT_CHANNELS: usize = 64;
/// Output channels from which a convolution is left to [`conv_im2col`](super::conv_im2col)
/// (unfolding layer4's 512 channels lost).
pub const MAX_OUTPUT_CHANNELS: usize = 256;
/// The largest unfolded operand (`k x n` f32), as [`conv_im2col::MAX_SCRATCH_BYTES`]: RAM on
/// top of the stage's.
///
/// [`conv_im2col::MAX_SCRATCH_BYTES`]: super::conv_im2col::MAX_SCRATCH_BYTES
pub const MAX_SCRATCH_BYTES: usize = super::conv_im2col::MAX_SCRATCH_BYTES;

/// Rewrite every f32 convolution of a decluttered `model` with one group, NCHW over two
/// spatial axes, batch 1, constant weights and bias, more than one tap, [`MIN_OUTPUT_CHANNELS`]
/// to [`MAX_OUTPUT_CHANNELS`] (excluded) outputs and an unfolded operand within
/// [`MAX_SCRATCH_BYTES`] into [`Unfold`] and a matmul; returns the model and the number
/// rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn unfold_convs(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let (lo, hi) = (MIN_OUTPUT_CHANNELS, MAX_OUTPUT_CHANNELS);
    let names: Vec<String> = model.nodes().iter().map(|n| n.name.clone()).collect();
    let mut done = 0;
    for name in names {
        let id = model.node_id_by_name(&name)?;
        let node = model.node(id);
        let Some(conv) = node.op_as::<Conv>() else {
            continue;
        };
        if conv.q_params.is_some()
            || conv.group != 1
            || conv.pool_spec.data_format != DataFormat::NCHW
            || conv.pool_spec.kernel_shape.len() != 2
            || conv.output_channels() < lo
            || conv.output_channels() >= hi
        {
            continue;
        }
        let facts: Vec<TypedFact> = model.node_input_facts(id)?.into_iter().cloned().collect();
        if facts.len() != 3 || facts[0].datum_type != f32::datum_type() {
            continue;
        }
        let Some(xs) = facts[0].shape.as_concrete() else {
            continue;
        };
        let (Some(kernel), Some(bias)) = (facts[1].konst.clone(), facts[2].konst.clone()) else {
            continue;
        };
        if xs.len() != 4 || xs[0] != 1 {
            continue;
        }
        let (ci, h, w) = (xs[1], xs[2], xs[3]);
        let co = conv.output_channels();
        let ks = &conv.pool_spec.kernel_shape;
        let (kh, kw) = (ks[0], ks[1]);
        if kh * kw < 2 || kernel.shape() != [co, ci, kh, kw] {
            continue;
        }
        let pads = conv.pool_spec.computed_padding(&[h, w]);
        let (oh, ow) = (pads[0].convoluted, pads[1].convoluted);
        let k = ci * kh * kw;
        if k * oh * ow * size_of::<f32>() > MAX_SCRATCH_BYTES || oh * ow == 0 {
            continue;
        }
        let strides = conv.pool_spec.strides();
        let dil = conv.pool_spec.dilations();
        let unfold = Unfold {
            input: [ci, h, w],
            kernel: [kh, kw],
            strides: [strides[0], strides[1]],
            dilations: [dil[0], dil[1]],
            pad_before: [pads[0].pad_before, pads[1].pad_before],
            output: [oh, ow],
        };
        let bias_plain = bias.try_as_plain_ram()?;
        let bias_all = bias_plain.as_slice::<f32>()?;
        let bias_vals: Vec<f32> = if bias.rank() == 0 {
            vec![bias_all[0]; co]
        } else if bias.shape() == [co] {
            bias_all.to_vec()
        } else {
            continue;
        };
        let mut patch = TypedModelPatch::default();
        let x = patch.tap_model(&model, node.inputs[0])?;
        let cols = patch.wire_node(format!("{name}.unfold"), unfold, &[x])?[0];
        let wk = kernel.into_tensor().into_shape(&[co, k])?;
        let wk = patch.add_const(format!("{name}.unfold_weights"), wk)?;
        let mm = patch.wire_node(
            format!("{name}.unfold_mm"),
            EinSum {
                axes: "mk,kn->mn".parse()?,
                operating_dt: f32::datum_type(),
                q_params: None,
            },
            &[wk, cols],
        )?[0];
        let b = patch.add_const(
            format!("{name}.unfold_bias"),
            Tensor::from_shape(&[co, 1], &bias_vals)?,
        )?;
        let y = patch.wire_node(format!("{name}.unfold_bias_add"), math::add(), &[mm, b])?[0];
        let y = patch.wire_node(
            format!("{name}.unfold_shape"),
            AxisOp::Reshape(
                0,
                tvec![co.to_dim(), (oh * ow).to_dim()],
                tvec![1.to_dim(), co.to_dim(), oh.to_dim(), ow.to_dim()],
            ),
            &[y],
        )?[0];
        patch.shunt_outside(&model, OutletId::new(id, 0), y)?;
        patch.apply(&mut model)?;
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
    use crate::engine::Stage;
    use crate::engine_tract::rewrite::Pass;
    use crate::engine_tract::test_support::{
        ConvShape, assert_same_bits, bits, committed_stage_before, conv_model, inputs_of,
        run_optimized,
    };

    #[test]
    fn resnet_shapes_run_unfolded_with_tracts_bits() {
        let cases = [
            // `nano`'s layer1 (64 -> 64 over 48 x 80), a layer2 entry (stride 2), the stem
            // (7x7, stride 2, padding 3), a dilated one, and odd maps that leave border pixels.
            ConvShape::new(64, 64, [48, 80], 3, 1, 1),
            ConvShape::new(64, 128, [48, 80], 3, 2, 1),
            ConvShape::new(3, 64, [96, 160], 7, 2, 3),
            ConvShape {
                dilation: 2,
                ..ConvShape::new(32, 64, [13, 17], 3, 1, 2)
            },
            ConvShape::new(16, 96, [11, 9], 3, 2, 0),
        ];
        for s in cases {
            let (model, inputs) = conv_model(&s);
            let (unfolded, n) = unfold_convs(model.clone()).unwrap();
            assert_eq!(n, 1, "{} -> {}", s.ci, s.co);
            assert!(unfolded.nodes().iter().any(|n| n.op_is::<Unfold>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(unfolded, &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{} -> {}", s.ci, s.co);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{} -> {}", s.ci, s.co);
        }
    }

    #[test]
    fn narrow_and_wide_convolutions_keep_tracts_plan() {
        // 32 outputs (below the product's useful m); 256 (conv_im2col's).
        for s in [
            ConvShape::new(64, 32, [24, 40], 3, 1, 1),
            ConvShape::new(128, 256, [12, 20], 3, 1, 1),
        ] {
            let (model, _) = conv_model(&s);
            let (same, n) = unfold_convs(model).unwrap();
            assert_eq!(n, 0, "{} -> {}", s.ci, s.co);
            assert!(same.nodes().iter().any(|n| n.op_is::<Conv>()));
        }
        // A 1x1 convolution (one tap) is a matmul already.
        let (model, _) = conv_model(&ConvShape::new(64, 64, [24, 40], 1, 1, 0));
        assert_eq!(unfold_convs(model).unwrap().1, 0);
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = Unfold {
            input: [2, 4, 4],
            kernel: [3, 3],
            strides: [1, 1],
            dilations: [1, 1],
            pad_before: [1, 1],
            output: [4, 4],
        };
        let x = Tensor::zero::<f32>(&[1, 3, 4, 4]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }

    #[test]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::UnfoldConvs);
            let inputs = inputs_of(&plain);
            let (unfolded, _) = unfold_convs(plain.clone()).expect("rewrite");
            let (a, b) = (
                run_optimized(plain, &inputs),
                run_optimized(unfolded, &inputs),
            );
            assert_same_bits(stage, &a, &b);
        }
    }
}
