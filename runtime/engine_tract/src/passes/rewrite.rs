//! The engine's load-time rewrites of one stage's graph, in the one order they run, and the
//! record of what they did.
//!
//! On the decluttered graph first (their patterns are tract's decluttered ops): the deformable
//! samplers' `Mul -> Reduce<Sum>` corner sums ([`weighted_sum`]), those sums with the pixel
//! arithmetic that feeds them ([`bilinear`], which needs the corner sums already fused), the
//! softmaxes ([`softmax`]), the max poolings ([`max_pool`]), the tanh GELUs ([`gelu`]), the
//! LayerNorms ([`layer_norm`]), with an int8 bundle the int8 convolutions and linear layers
//! ([`quant_conv`], [`quant_linear`]; every target), where a native product tier runs (AVX-512F by default:
//! [`gemm::tier`]) the convolutions of 8 channels or more ([`conv_unfold`]), the linear layers ([`linear`]) and the 1x1 convolutions of
//! channel-first maps ([`pointwise`]) on the native product ([`gemm`]), the ReLU and ResNet
//! shortcut `Add` after those convolutions taken into them ([`epilogue`]), and (without a native
//! tier) the wide image stems, planned with im2col where tract would run them direct spatial
//! ([`conv_direct`]). Then tract's optimiser. On the optimised plan last: the
//! outlets that depend on the weights alone, computed once ([`fold`]), and the binary ops
//! optimisation left on tract's generic path ([`broadcast`], after the fold so that no folded op
//! is rewritten for nothing), and the constants re-laid with natural strides
//! ([`natural_consts`]). Every rewrite computes its graph's values bit for bit (each module's
//! tests) but on the stems tract would run direct spatial: [`conv_direct`], and [`conv_unfold`]
//! on a native tier, sum the same products in tract's im2col order instead. The matching
//! helpers the passes share are in [`crate::graph::matching`]: this driver imports the passes, the
//! passes never import it (their tests do, to stop before them).

use tract_nnef::prelude::*;

use super::{contraction, conv_direct, epilogue, fold, natural_consts, widened_weights};
use crate::gemm;
use crate::ops::{
    attention, batched, bilinear, broadcast, conv_unfold, gelu, layer_norm, linear, max_pool,
    pointwise, quant_conv, quant_linear, range_probe, softmax, weighted_sum,
};

/// How many native ops the load-time rewrites put into one stage (`optimise`); serialised
/// field by field (`satmap-sim bench-stages` reports it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Rewrites {
    /// `Mul -> Reduce<Sum>` pairs rewritten into [`weighted_sum::WeightedAxisSum`] (the
    /// deformable samplers' corner sums).
    pub weighted_sums: usize,
    /// Deformable samplers run whole as [`bilinear::BilinearCornerSum`] (their corner sums
    /// among `weighted_sums`).
    pub bilinear_samplers: usize,
    /// Softmaxes run as [`softmax::RowSoftmax`] (0 on a host whose softmax kernel it does not
    /// model).
    pub row_softmaxes: usize,
    /// Max poolings run as [`max_pool::MaxPool2d`] (the ResNet stems'; every tier).
    pub max_pools: usize,
    /// Tanh GELU chains run as [`gelu::TanhGelu`] (the Swin MLPs'; every tier).
    pub tanh_gelus: usize,
    /// LayerNorm chains run as [`layer_norm::LayerNorm`] (every tier).
    pub layer_norms: usize,
    /// Convolutions of 8 outputs or more run as [`conv_unfold::UnfoldConv`] on the native
    /// product ([`conv_unfold::unfold_convs`]; on a native product tier only).
    pub unfolded_convs: usize,
    /// An int8 bundle's weights tract leaves widened every step, widened once at load for the
    /// int8 passes ([`widened_weights::fold_widened_weights`]; with calibrated ranges only).
    pub widened_weights: usize,
    /// Convolutions run in int8 as [`quant_conv::QuantConv`] (an int8 bundle with calibrated
    /// ranges; every target).
    pub int8_convs: usize,
    /// Linear layers run in int8 as [`quant_linear::QuantLinear`] (an int8 bundle with
    /// calibrated ranges; every target).
    pub int8_linears: usize,
    /// Range probes a calibration load put before convolutions and linear layers
    /// ([`quant_conv::probe_convs`], [`quant_linear::probe_linears`]).
    pub range_probes: usize,
    /// Linear layers run as [`linear::PackedLinear`] ([`linear::native_linears`]; on a
    /// native product tier only).
    pub native_linears: usize,
    /// 1x1 convolutions of channel-first maps run as [`pointwise::PointwiseConv`]
    /// ([`pointwise::native_pointwise_convs`]; on a native product tier only).
    pub pointwise_convs: usize,
    /// Native convolutions that took the shortcut `Add` and/or the `ReLU` after them
    /// ([`epilogue::fuse_epilogues`]; on a native product tier only).
    pub epilogues: usize,
    /// Products of two activations (attention) run as [`batched::BatchedProduct`]
    /// ([`batched::native_batched`]; on a native product tier only).
    pub native_batched: usize,
    /// `scores -> softmax -> values` chains run as [`attention::FusedAttention`]
    /// ([`attention::fuse_attention`]; on a native product tier only).
    pub fused_attentions: usize,
    /// Convolutions tract would run direct spatial planned with im2col and its matmul instead
    /// ([`conv_direct::im2col_wide_stems`]: the image stems of 64 channels or more).
    pub im2col_stems: usize,
    /// Outlets of the optimised plan that depend on the weights alone, computed at load.
    pub folded_outlets: usize,
    /// `Add`, `Sub` and `Mul` left on tract's generic path, run as
    /// [`broadcast::BroadcastBinary`].
    pub broadcast_binaries: usize,
}

/// The rewrites in the order [`optimise`] runs them (tract's optimiser between `Im2colStems`
/// and `Fold`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Pass {
    WeightedSums,
    BilinearSamplers,
    RowSoftmaxes,
    MaxPools,
    TanhGelus,
    LayerNorms,
    UnfoldConvs,
    NativeLinears,
    PointwiseConvs,
    Epilogues,
    FusedAttention,
    NativeBatched,
    Im2colStems,
    Fold,
    BroadcastBinaries,
    NaturalConsts,
}

/// What a load does with the convolutions and linear layers the int8 passes take.
#[derive(Clone, Debug, Default)]
pub enum Quantisation {
    /// Nothing: the f32 passes.
    #[default]
    None,
    /// Each layer with a range here (by its name) runs in int8 on this integer tier.
    Int8 {
        /// Largest activation magnitude per layer name (a stage's calibration).
        ranges: std::collections::BTreeMap<String, f32>,
        /// The integer tier.
        tier: satmap_kernels::qgemm::IntTier,
    },
    /// Every layer gets a range probe into this log (a calibration run).
    Observe {
        /// Where the ranges go.
        log: range_probe::RangeLog,
        /// The stage's name (the first half of each range's key).
        stage: &'static str,
    },
}

/// A decluttered stage through every rewrite and tract's optimiser: the graph the engine plans.
pub(crate) fn optimise(
    model: TypedModel,
    quantisation: &Quantisation,
) -> TractResult<(TypedModel, Rewrites)> {
    optimise_before(model, None, quantisation)
}

/// A decluttered stage through the rewrites that run before `stop` (all with `None`): the graph
/// `stop` sees at load, so a test can compare that one rewrite against its input. Optimised
/// when `stop` comes after tract's optimiser, decluttered otherwise.
pub(crate) fn optimise_before(
    mut model: TypedModel,
    stop: Option<Pass>,
    quantisation: &Quantisation,
) -> TractResult<(TypedModel, Rewrites)> {
    let runs = |pass: Pass| stop.is_none_or(|s| pass < s);
    let mut done = Rewrites::default();
    if runs(Pass::WeightedSums) {
        (model, done.weighted_sums) = weighted_sum::fuse_weighted_sums(model)?;
    }
    if runs(Pass::BilinearSamplers) {
        (model, done.bilinear_samplers) = bilinear::fuse_bilinear_samplers(model)?;
    }
    if runs(Pass::RowSoftmaxes) {
        (model, done.row_softmaxes) = softmax::fuse_softmaxes(model)?;
    }
    if runs(Pass::MaxPools) {
        (model, done.max_pools) = max_pool::native_max_pools(model)?;
    }
    if runs(Pass::TanhGelus) {
        (model, done.tanh_gelus) = gelu::fuse_tanh_gelus(model)?;
    }
    if runs(Pass::LayerNorms) {
        (model, done.layer_norms) = layer_norm::fuse_layer_norms(model)?;
    }
    // The int8 convolutions (or the calibration's probes) on every target, before the f32
    // convolutions take them; first the weights tract left widened every step made constants.
    let quantising = match quantisation {
        Quantisation::None => false,
        Quantisation::Int8 { ranges, .. } => !ranges.is_empty(),
        Quantisation::Observe { .. } => true,
    };
    if runs(Pass::UnfoldConvs) && quantising {
        (model, done.widened_weights) = widened_weights::fold_widened_weights(model)?;
    }
    if runs(Pass::UnfoldConvs) {
        match quantisation {
            Quantisation::None => {}
            Quantisation::Int8 { ranges, tier } => {
                (model, done.int8_convs) = quant_conv::quantise_convs(model, ranges, *tier)?;
            }
            Quantisation::Observe { log, stage } => {
                (model, done.range_probes) = quant_conv::probe_convs(model, log, stage)?;
            }
        }
    }
    // The native product runs on a tier of satmap-kernels (AVX-512F by default, another when
    // `SATMAP_KERNEL_TIER` forces it); without one, or with `tract` forced, tract's stay.
    let native = gemm::chosen_tier()?.is_some();
    if runs(Pass::UnfoldConvs) && native {
        (model, done.unfolded_convs) = conv_unfold::unfold_convs(model)?;
    }
    if runs(Pass::NativeLinears) && native {
        // Products over several axes at once reshaped into linear layers first (a layout
        // change, not counted).
        (model, _) = contraction::merge_contracted_axes(model)?;
    }
    // Before the f32 linear layers take them: the int8 layers (or the calibration's probes)
    // on every target, whether or not the f32 product is native here.
    match quantisation {
        Quantisation::None => {}
        Quantisation::Int8 { ranges, tier } => {
            (model, done.int8_linears) = quant_linear::quantise_linears(model, ranges, *tier)?;
        }
        Quantisation::Observe { log, stage } => {
            let (probed, probes) = quant_linear::probe_linears(model, log, stage)?;
            (model, done.range_probes) = (probed, done.range_probes + probes);
        }
    }
    if runs(Pass::NativeLinears) && native {
        (model, done.native_linears) = linear::native_linears(model)?;
    }
    if runs(Pass::PointwiseConvs) && native {
        (model, done.pointwise_convs) = pointwise::native_pointwise_convs(model)?;
    }
    if runs(Pass::Epilogues) && native {
        (model, done.epilogues) = epilogue::fuse_epilogues(model)?;
    }
    if runs(Pass::FusedAttention) && native {
        (model, done.fused_attentions) = attention::fuse_attention(model)?;
    }
    if runs(Pass::NativeBatched) && native {
        (model, done.native_batched) = batched::native_batched(model)?;
    }
    if runs(Pass::Im2colStems) {
        (model, done.im2col_stems) = conv_direct::im2col_wide_stems(model)?;
    }
    if stop.is_none_or(|s| s > Pass::Im2colStems) {
        model = model.into_optimized()?;
    }
    if runs(Pass::Fold) {
        (model, done.folded_outlets) = fold::fold_input_independent(model)?;
    }
    if runs(Pass::BroadcastBinaries) {
        (model, done.broadcast_binaries) = broadcast::fuse_broadcast_binaries(model)?;
    }
    if runs(Pass::NaturalConsts) {
        // A layout change, not a native op: not counted in `Rewrites`.
        (model, _) = natural_consts::naturalise_consts(model)?;
    }
    Ok((model, done))
}
