//! The 1x1 convolutions of channel-first maps as the native product.
//!
//! After decluttering, a 1x1 convolution of a `[1, C, H, W]` (or `[C, H, W]`) map is an
//! `EinSum` of constant weights `[C_out, C]` and the map, contracting its channel axis,
//! usually followed by an `Add` of a constant bias `[C_out, 1, 1]`. [`crate::ops::linear`] takes
//! products whose contracted axis is last (tokens x features); these contract the channel axis,
//! so tract kept them: ResNet-50's bottleneck projections ran through tract's product at 28-60
//! GFLOP/s (`paper`'s image encoder: half of its 876 ms, with 86 ms of tract packing the map)
//! and the FPN laterals likewise. [`native_pointwise_convs`] rewrites each into one
//! [`PointwiseConv`]: `C[o, p] = W[o, c] X[c, p]`, the weights packed once at load as the
//! product's A, the map's channel rows copied into the product's B blocks as it goes, the bias
//! added per row to the finished sums.
//!
//! Bit for bit: each output is one fused multiply-add chain over the channels ascending from
//! zero, the bias added after, as tract's product computes it (this module's tests, against
//! tract's plan of 1x1 convolutions built here and of every stage of the committed default
//! bundle). Maps of fewer than [`MIN_PIXELS`] pixels keep tract's plan (its matrix-vector
//! kernels sum in another order). On the AVX-512 tier only, as [`gemm`].
//!
//! A strided 1x1 convolution (ResNet's shortcut projections) declutters into `Downsample`s of
//! the map (tract's copy of every other row and column, on one thread: 13 ms of `paper`'s
//! image encoder) and the product: it runs as an [`UnfoldConv`] of a 1x1 kernel at those
//! strides over the map before them, gathering the pixels as the product goes (the same
//! chain over the channels; without a bias it adds `0.0`, which leaves every sum as it is:
//! a chain from `+0.0` is never `-0.0`).

use tract_nnef::internal::*;

use tract_nnef::tract_core::ops::Downsample;

use crate::gemm::{self, NR, PackedA};
use crate::graph::matching::replace_with_op;
use crate::ops::conv_unfold::{MIN_OUTPUT_CHANNELS, UnfoldConv};
use crate::ops::finish::Epilogue;
use crate::ops::linear::{ConstProduct, bias_after, const_product};
use crate::ops::unfold::Unfold;

/// Pixels (columns of the product) from which a 1x1 convolution runs natively: one B panel.
pub const MIN_PIXELS: usize = NR;

/// `W [m, k] . X [k, n] (+ bias [m]) -> [m, n]` over a channel-first map (`k` channels of `n`
/// pixels in, `m` out), `W` packed at load.
#[derive(Clone, Debug)]
pub struct PointwiseConv {
    /// The map's shape (`[1.., k, spatial..]`).
    pub input: TVec<usize>,
    /// The output's shape (`[1.., m, spatial..]`).
    pub output: TVec<usize>,
    /// Output channels, input channels, pixels.
    pub mkn: [usize; 3],
    /// The shortcut and ReLU after the bias ([`crate::passes::epilogue`]).
    pub epilogue: Epilogue,
    weights: Arc<PackedA>,
    bias: Option<Arc<Vec<f32>>>,
}

impl PartialEq for PointwiseConv {
    fn eq(&self, other: &Self) -> bool {
        self.input == other.input
            && self.output == other.output
            && self.mkn == other.mkn
            && self.epilogue == other.epilogue
            && Arc::ptr_eq(&self.weights, &other.weights)
            && match (&self.bias, &other.bias) {
                (None, None) => true,
                (Some(a), Some(b)) => Arc::ptr_eq(a, b),
                _ => false,
            }
    }
}
impl Eq for PointwiseConv {}

impl Op for PointwiseConv {
    fn info(&self) -> TractResult<Vec<String>> {
        let [m, k, n] = self.mkn;
        Ok(vec![format!("Mult: m:{m} k:{k} n:{n} with [native]")])
    }

    fn name(&self) -> StaticName {
        "PointwiseConv".into()
    }
    op_as_typed_op!();
}

impl PointwiseConv {
    /// This convolution with `epilogue` after its bias.
    #[must_use]
    pub fn with_epilogue(&self, epilogue: Epilogue) -> Self {
        Self {
            epilogue,
            ..self.clone()
        }
    }
}

impl EvalOp for PointwiseConv {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let shortcut = self.epilogue.shortcut(&inputs, &self.output)?;
        let x = &inputs[0];
        ensure!(
            x.shape() == &*self.input,
            "PointwiseConv input {:?}, expected {:?}",
            x.shape(),
            self.input
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let [m, k, n] = self.mkn;
        let mut out = gemm::output_tensor(&self.output)?;
        let mut po = out.try_as_plain_ram_mut()?;
        // B's rows are the map's channel rows: panel columns copied, zeros past the last pixel.
        let fill = |j: usize, pc: usize, kc: usize, dst: &mut [f32]| {
            for (jl, panel) in dst.chunks_exact_mut(kc * NR).enumerate() {
                let col0 = (j + jl) * NR;
                let cols = NR.min(n.saturating_sub(col0));
                for (r, row) in panel.chunks_exact_mut(NR).enumerate() {
                    row[..cols].copy_from_slice(&xs[(pc + r) * n + col0..][..cols]);
                    row[cols..].fill(0.0);
                }
            }
        };
        let ops = gemm::Operands {
            a: self.weights.as_slice(),
            b: gemm::BSource::Fill(&fill),
            m,
            n,
            k,
            ldc: n,
        };
        let bias = match &self.bias {
            Some(b) => gemm::Bias::PerRow(b),
            None => gemm::Bias::None,
        };
        ensure!(
            gemm::product_then(
                &ops,
                po.as_slice_mut::<f32>()?,
                self.epilogue.finish(bias, shortcut)
            ),
            "native product refused (AVX-512 missing or operands mis-sized)"
        );
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for PointwiseConv {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        self.epilogue.output_facts(inputs, &self.output)
    }

    fn cost(&self, _inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let [m, k, n] = self.mkn;
        Ok(tvec!((Cost::FMA(f32::datum_type()), (m * k * n).to_dim())))
    }

    as_op!();
}

/// What an `EinSum` node is when it is a 1x1 convolution of a channel-first map.
struct Pointwise {
    /// The map.
    x: OutletId,
    input: TVec<usize>,
    output: TVec<usize>,
    /// The channel axis of the map.
    x_channel: usize,
    /// The channel axis of the output.
    channel: usize,
    /// The weights as `[m, k]`, row-major.
    w: Tensor,
}

/// The node `id` as a 1x1 convolution: an f32 `EinSum` of a map and a constant rank-2
/// matrix, contracting one map axis (the channels) against the matrix, the matrix's other axis
/// the output's channels, the map's axes after its channels kept in order after the output's,
/// every other axis of length 1 (tract's decluttered 1x1 convolutions add or drop the batch
/// axis: `IHW,OI->NOHW`, `NIHW,OI->OHW`).
fn as_pointwise(model: &TypedModel, id: usize) -> TractResult<Option<Pointwise>> {
    let Some(ConstProduct { es, xi, input, w }) = const_product(model, id)? else {
        return Ok(None);
    };
    let wi = 1 - xi;
    let Some(output) = model.outlet_fact(OutletId::new(id, 0))?.shape.as_concrete() else {
        return Ok(None);
    };
    let output: TVec<usize> = output.into();
    let (mut k_at, mut m_at, mut kept) = (None, None, tvec![]);
    for axis in es.axes.iter_all_axes() {
        let (ix, iw, out) = (&axis.inputs[xi], &axis.inputs[wi], &axis.outputs[0]);
        if ix.len() > 1 || iw.len() > 1 || out.len() > 1 {
            return Ok(None);
        }
        match (ix.first(), iw.first(), out.first()) {
            (Some(&px), Some(&pw), None) => k_at = Some((px, pw)),
            (None, Some(&pw), Some(&po)) => m_at = Some((pw, po)),
            (Some(&px), None, Some(&po)) => kept.push((px, po)),
            // A unit axis of the map or of the output alone.
            (Some(&px), None, None) if input[px] == 1 => {}
            (None, None, Some(&po)) if output[po] == 1 => {}
            _ => return Ok(None),
        }
    }
    let (Some((x_channel, k_w)), Some((m_w, channel))) = (k_at, m_at) else {
        return Ok(None);
    };
    let in_order = kept.iter().all(|&(px, po)| {
        if px < x_channel || po < channel {
            input[px] == 1 && po < channel
        } else {
            px - x_channel == po - channel
        }
    });
    let spatial_kept = kept.iter().filter(|&&(px, _)| px > x_channel).count();
    if k_w == m_w
        || !in_order
        || spatial_kept != input.len() - x_channel - 1
        || output.len() - channel != input.len() - x_channel
        || input[..x_channel].iter().any(|&d| d != 1)
        || output[..channel].iter().any(|&d| d != 1)
    {
        return Ok(None);
    }
    let w = if m_w == 0 {
        w.into_tensor()
    } else {
        w.into_tensor().permute_axes(&[1, 0])?
    };
    if output[channel] != w.shape()[0] {
        return Ok(None);
    }
    Ok(Some(Pointwise {
        x: model.node(id).inputs[xi],
        input,
        output,
        x_channel,
        channel,
        w,
    }))
}

/// If `pw`'s map is every `s`-th pixel of another (a chain of `Downsample`s, offset 0, over its
/// two spatial axes: ResNet's strided shortcut projections), that map and the convolution as
/// the patches of a 1x1 kernel at those strides, with whether map and output keep the batch
/// axis. `None` for a map not downsampled, or downsampled otherwise.
fn strided_source(
    model: &TypedModel,
    pw: &Pointwise,
) -> TractResult<Option<(OutletId, Unfold, bool)>> {
    let (rank, c) = (pw.input.len(), pw.x_channel);
    if rank != c + 3 || pw.output.len() != rank || pw.channel != c || c > 1 {
        return Ok(None);
    }
    let mut strides = [1usize, 1];
    let mut src = pw.x;
    while let Some(ds) = model.node(src.node).op_as::<Downsample>() {
        let Some(i) = (ds.axis > c).then(|| ds.axis - c - 1).filter(|&i| i < 2) else {
            break;
        };
        if ds.modulo != 0 || ds.stride <= 0 {
            break;
        }
        strides[i] *= ds.stride.unsigned_abs();
        src = model.node(src.node).inputs[0];
    }
    if strides == [1, 1] {
        return Ok(None);
    }
    let Some(full) = model.outlet_fact(src)?.shape.as_concrete().map(TVec::from) else {
        return Ok(None);
    };
    let [oh, ow] = [pw.input[c + 1], pw.input[c + 2]];
    let [h, w] = [full[c + 1], full[c + 2]];
    if full.len() != rank
        || full[..=c] != pw.input[..=c]
        || h.div_ceil(strides[0]) != oh
        || w.div_ceil(strides[1]) != ow
    {
        return Ok(None);
    }
    let unfold = Unfold {
        input: [pw.input[c], h, w],
        kernel: [1, 1],
        strides,
        dilations: [1, 1],
        pad_before: [0, 0],
        output: [oh, ow],
    };
    Ok(Some((src, unfold, c == 1)))
}

/// Rewrite every 1x1 convolution of a decluttered `model` (see `as_pointwise`) with at least
/// [`MIN_OUTPUT_CHANNELS`] outputs and [`MIN_PIXELS`] pixels into a [`PointwiseConv`], its bias
/// `Add` taken in; returns the model and the number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn native_pointwise_convs(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let Some(pw) = as_pointwise(&model, id)? else {
            continue;
        };
        let (m, k) = (pw.w.shape()[0], pw.w.shape()[1]);
        let n: usize = pw.input[pw.x_channel + 1..].iter().product();
        if m < MIN_OUTPUT_CHANNELS || n < MIN_PIXELS || k == 0 || pw.input[pw.x_channel] != k {
            continue;
        }
        // `[m]` laid along the output's channel axis, every other axis of length 1.
        let (output, channel) = (&pw.output, pw.channel);
        let bias = bias_after(&model, id, |shape| {
            shape.len() == output.len()
                && shape
                    .iter()
                    .enumerate()
                    .all(|(i, &d)| d == if i == channel { output[channel] } else { 1 })
        })?;
        let w_plain = pw.w.try_as_plain_ram()?;
        let replaced = bias.as_ref().map_or(id, |(add_id, _)| *add_id);
        let name = format!("{}.pointwise_conv", model.node(id).name);
        if let Some((src, unfold, batch_axis)) = strided_source(&model, &pw)? {
            // The map's pixels at a stride: a 1x1 convolution over the patches of the map
            // before its `Downsample`s, gathered as the product goes.
            let bias = bias.map_or_else(|| vec![0.0; m], |(_, b)| b);
            let op = UnfoldConv::new(unfold, batch_axis, w_plain.as_slice::<f32>()?, bias);
            replace_with_op(&mut model, &[src], replaced, name, op)?;
            done += 1;
            continue;
        }
        let op = PointwiseConv {
            input: pw.input.clone(),
            output: pw.output.clone(),
            mkn: [m, k, n],
            epilogue: Epilogue::default(),
            weights: Arc::new(PackedA::from_row_major(w_plain.as_slice::<f32>()?, m, k)),
            bias: bias.as_ref().map(|(_, b)| Arc::new(b.clone())),
        };
        replace_with_op(&mut model, &[pw.x], replaced, name, op)?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The pass against tract's own plan, bit for bit: on 1x1 convolutions built here (with
    //! and without the batch axis, with a bias, wide and narrow maps) and on every stage of the
    //! committed default bundle.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        ConvShape, assert_pass_keeps_stage_bits, bits, conv_model, run_optimized,
    };

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn pointwise_convolutions_run_natively_with_tracts_bits() {
        for s in [
            // ResNet-50's bottleneck projections (`paper`'s layer1, smaller maps), an FPN
            // lateral without the batch axis, odd sizes off the tiles.
            ConvShape::new(64, 256, [48, 80], 1, 1, 0),
            ConvShape::new(256, 64, [24, 40], 1, 1, 0),
            ConvShape {
                batch: false,
                ..ConvShape::new(96, 256, [50, 25], 1, 1, 0)
            },
            ConvShape::new(13, 21, [7, 9], 1, 1, 0),
        ] {
            let (model, inputs) = conv_model(&s);
            let (native, n) = native_pointwise_convs(model.clone()).unwrap();
            assert_eq!(n, 1, "{} -> {}", s.ci, s.co);
            assert!(native.nodes().iter().any(|n| n.op_is::<PointwiseConv>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(native, &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{} -> {}", s.ci, s.co);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{} -> {}", s.ci, s.co);
        }
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn strided_projections_gather_the_map_they_were_downsampled_from() {
        // ResNet's shortcut projections (stride 2, odd and even maps), with and without the
        // batch axis.
        for s in [
            ConvShape::new(64, 128, [24, 40], 1, 2, 0),
            ConvShape::new(32, 16, [15, 9], 1, 2, 0),
            ConvShape {
                batch: false,
                ..ConvShape::new(16, 24, [12, 20], 1, 2, 0)
            },
        ] {
            let (model, inputs) = conv_model(&s);
            assert!(model.nodes().iter().any(|n| n.op_is::<Downsample>()));
            let (native, n) = native_pointwise_convs(model.clone()).unwrap();
            assert_eq!(n, 1, "{} -> {}", s.ci, s.co);
            let native = native.into_decluttered().unwrap();
            assert!(native.nodes().iter().any(|n| n.op_is::<UnfoldConv>()));
            assert!(!native.nodes().iter().any(|n| n.op_is::<Downsample>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(native, &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{} -> {}", s.ci, s.co);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{} -> {}", s.ci, s.co);
        }
    }

    #[test]
    fn small_maps_and_narrow_outputs_keep_tracts_plan() {
        for s in [
            ConvShape::new(64, 256, [4, 5], 1, 1, 0),
            ConvShape::new(64, 4, [48, 80], 1, 1, 0),
        ] {
            let (model, _) = conv_model(&s);
            assert_eq!(native_pointwise_convs(model).unwrap().1, 0);
        }
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = PointwiseConv {
            input: tvec![1, 2, 4, 8],
            output: tvec![1, 3, 4, 8],
            mkn: [3, 2, 32],
            epilogue: Epilogue::default(),
            weights: Arc::new(PackedA::from_row_major(&[0.5; 6], 3, 2)),
            bias: None,
        };
        let x = Tensor::zero::<f32>(&[1, 3, 4, 8]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::PointwiseConvs, native_pointwise_convs);
    }
}
