//! The engine's load-time rewrites of one stage's graph, in the one order they run, and the
//! record of what they did.
//!
//! On the decluttered graph first (their patterns are tract's decluttered ops): the deformable
//! samplers' `Mul -> Reduce<Sum>` corner sums ([`weighted_sum`]), those sums with the pixel
//! arithmetic that feeds them ([`bilinear`], which needs the corner sums already fused), the
//! softmaxes ([`softmax`]), the max poolings ([`max_pool`]), the tanh GELUs ([`gelu`]), the
//! LayerNorms ([`layer_norm`]), on the AVX-512 kernel tier the convolutions of 8 channels or
//! more ([`conv_unfold`]), the linear layers ([`linear`]) and the 1x1 convolutions of
//! channel-first maps ([`pointwise`]) on the native product ([`gemm`]), the ReLU and ResNet
//! shortcut `Add` after those convolutions taken into them ([`epilogue`]), and (on the other
//! tiers) the wide image stems, planned with im2col where tract would run them direct spatial
//! ([`conv_direct`]). Then tract's optimiser. On the optimised plan last: the
//! outlets that depend on the weights alone, computed once ([`fold`]), and the binary ops
//! optimisation left on tract's generic path ([`broadcast`], after the fold so that no folded op
//! is rewritten for nothing), and the constants re-laid with natural strides
//! ([`natural_consts`]). Every rewrite computes its graph's values bit for bit (each module's
//! tests) but on the stems tract would run direct spatial: [`conv_direct`], and [`conv_unfold`]
//! on the AVX-512 tier, sum the same products in tract's im2col order instead.

use tract_nnef::prelude::*;
use tract_nnef::tract_core::ops::binary::TypedBinOp;

use crate::engine_tract::{
    attention, batched, bilinear, broadcast, contraction, conv_direct, conv_unfold, epilogue, fold,
    gelu, gemm, layer_norm, linear, max_pool, natural_consts, pointwise, softmax, weighted_sum,
};

/// How many native ops the load-time rewrites put into one stage ([`optimise`]); serialised
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
    /// product ([`conv_unfold::unfold_convs`]; on the AVX-512 tier only).
    pub unfolded_convs: usize,
    /// Linear layers run as [`linear::PackedLinear`] ([`linear::native_linears`]; on the
    /// AVX-512 tier only).
    pub native_linears: usize,
    /// 1x1 convolutions of channel-first maps run as [`pointwise::PointwiseConv`]
    /// ([`pointwise::native_pointwise_convs`]; on the AVX-512 tier only).
    pub pointwise_convs: usize,
    /// Native convolutions that took the shortcut `Add` and/or the `ReLU` after them
    /// ([`epilogue::fuse_epilogues`]; on the AVX-512 tier only).
    pub epilogues: usize,
    /// Products of two activations (attention) run as [`batched::BatchedProduct`]
    /// ([`batched::native_batched`]; on the AVX-512 tier only).
    pub native_batched: usize,
    /// `scores -> softmax -> values` chains run as [`attention::FusedAttention`]
    /// ([`attention::fuse_attention`]; on the AVX-512 tier only).
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

/// Wire `op` (named `name`) on `inputs` of `model` in place of outlet 0 of node `replaced`: the
/// one patch every rewrite into a single native op applies.
///
/// # Errors
/// tract refusing the patch (an inconsistent model).
pub(crate) fn replace_with_op(
    model: &mut TypedModel,
    inputs: &[OutletId],
    replaced: usize,
    name: String,
    op: impl Into<Box<dyn TypedOp>>,
) -> TractResult<()> {
    let mut patch = TypedModelPatch::default();
    let taps: TVec<OutletId> = inputs
        .iter()
        .map(|&o| patch.tap_model(model, o))
        .collect::<TractResult<_>>()?;
    let y = patch.wire_node(name, op, &taps)?[0];
    patch.shunt_outside(model, OutletId::new(replaced, 0), y)?;
    patch.apply(model)
}

/// The one consumer of outlet 0 of node `id`, if it has exactly one and is not a model output:
/// the test every fused chain makes of its inner nodes.
///
/// # Errors
/// tract failing to list the model's outputs.
pub(crate) fn only_successor(model: &TypedModel, id: usize) -> TractResult<Option<usize>> {
    let outlet = &model.node(id).outputs[0];
    if outlet.successors.len() != 1 || model.output_outlets()?.contains(&OutletId::new(id, 0)) {
        return Ok(None);
    }
    Ok(Some(outlet.successors[0].node))
}

/// Node `id`'s two inputs if it is the binary op `name` (`Add`, `Mul`, `Sub`) without a
/// quantised output.
pub(crate) fn bin_inputs(model: &TypedModel, id: usize, name: &str) -> Option<[OutletId; 2]> {
    let node = model.node(id);
    let is = node
        .op_as::<TypedBinOp>()
        .is_some_and(|b| b.0.name() == name && b.1.is_none());
    (is && node.inputs.len() == 2).then(|| [node.inputs[0], node.inputs[1]])
}

/// If node `id` is the binary op `name` ([`bin_inputs`]) with exactly one constant operand: the
/// other operand and the constant (a bias, a scale, a GELU or LayerNorm factor).
///
/// # Errors
/// tract failing to give an operand's fact.
pub(crate) fn const_operand(
    model: &TypedModel,
    id: usize,
    name: &str,
) -> TractResult<Option<(OutletId, Arc<Tensor>)>> {
    let Some([i0, i1]) = bin_inputs(model, id, name) else {
        return Ok(None);
    };
    let (k0, k1) = (
        model.outlet_fact(i0)?.konst.clone(),
        model.outlet_fact(i1)?.konst.clone(),
    );
    Ok(match (k0, k1) {
        (None, Some(k)) => Some((i0, k)),
        (Some(k), None) => Some((i1, k)),
        _ => None,
    })
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

/// A decluttered stage through every rewrite and tract's optimiser: the graph the engine plans.
pub(crate) fn optimise(model: TypedModel) -> TractResult<(TypedModel, Rewrites)> {
    optimise_before(model, None)
}

/// A decluttered stage through the rewrites that run before `stop` (all with `None`): the graph
/// `stop` sees at load, so a test can compare that one rewrite against its input. Optimised
/// when `stop` comes after tract's optimiser, decluttered otherwise.
pub(crate) fn optimise_before(
    mut model: TypedModel,
    stop: Option<Pass>,
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
