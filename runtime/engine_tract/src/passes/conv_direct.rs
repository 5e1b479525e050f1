//! The image stems: im2col and a matrix product where tract would run a direct spatial kernel.
//!
//! tract 0.23.9 runs an f32 convolution with at most 576 inputs per output point and output rows
//! of 128 points or more as a `DirectSpatialConv`, a register-blocked loop over the output row.
//! In our graphs that is the image encoders' stem (ResNet's 7x7, stride 2, over the RGB image).
//! With 64 output channels (`nano`, `paper`) the direct kernel took 16.6-17.4 ms of `nano`'s
//! image encoder where im2col and tract's matmul (m 64, k 147, n 15,360) take 7.7 ms, the stage
//! 105-113 -> 94.5 ms (`satmap-sim bench-stages --ops`, `amd-avx512f`, docs/perf.md); the same
//! knob for the whole run measured 11-22% on the stage with the AVX2 + FMA kernels and 15% with
//! Intel's AVX-512 ones. With `test`'s 8 stem channels the direct kernel wins (2.1 ms against
//! 2.5-3.7), an m the matmul tiles mostly waste: the pass takes convolutions of
//! [`MIN_OUTPUT_CHANNELS`] or more.
//!
//! On the AVX-512 tier [`conv_unfold`](crate::ops::conv_unfold) runs first and takes every stem
//! itself, `test`'s 8-channel one too (same summation order as this pass's im2col, faster there
//! than the direct kernel: 1.1-1.3 against 2.9 ms); this pass takes the wide ones on the other
//! tiers.
//!
//! [`im2col_wide_stems`] codegens each such convolution itself, before tract's optimiser, with
//! tract's `TRACT_DISABLE_DIRECT_SPATIAL` scoped to that one node; tract then picks its im2col
//! plan as it would for any other convolution. Unlike the other rewrites this one changes the
//! summation order of the convolutions it takes (a sum of the same products in another order):
//! its values are tract's direct ones within float rounding (this module's tests), and the
//! stages it touches are compared with the PyTorch reference at the stage tolerance like every
//! other. `test`, the bundle whose digests are pinned, has no such convolution of 64 channels
//! (its AVX-512 digests follow `conv_unfold`'s im2col order for its stem).

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::cnn::Conv;
use tract_nnef::tract_core::tract_data::knobs::KnobScope;

/// Output channels from which a convolution tract would run direct spatial runs im2col instead
/// (measured: 64 wins ~2x, 8 loses 20-75%).
pub const MIN_OUTPUT_CHANNELS: usize = 64;

/// The name of tract's direct spatial convolution op (the op type is private).
pub(crate) const DIRECT_SPATIAL_OP: &str = "DirectSpatialConv";

/// Codegen every convolution of a decluttered `model` that tract would run direct spatial and
/// that has [`MIN_OUTPUT_CHANNELS`] outputs or more with im2col instead; returns the model and
/// the number of convolutions so planned.
///
/// # Errors
/// tract refusing a convolution's codegen or its patch (an inconsistent model).
pub fn im2col_wide_stems(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let no_direct = KnobScope::new([("TRACT_DISABLE_DIRECT_SPATIAL", "1")])?;
    let candidates: Vec<String> = model
        .nodes()
        .iter()
        .filter(|node| {
            node.op_as::<Conv>()
                .is_some_and(|conv| conv.output_channels() >= MIN_OUTPUT_CHANNELS)
        })
        .map(|node| node.name.clone())
        .collect();
    let mut done = 0;
    for name in candidates {
        let id = model.node_id_by_name(&name)?;
        let node = model.node(id);
        // tract's own plan first: a convolution it would not run direct spatial is not this
        // pass's business.
        let direct = node
            .op
            .codegen(&model, node)?
            .is_some_and(|patch| has_op(&patch.model, DIRECT_SPATIAL_OP));
        if !direct {
            continue;
        }
        let Some(patch) = no_direct.enter(|| node.op.codegen(&model, node))? else {
            continue;
        };
        if has_op(&patch.model, DIRECT_SPATIAL_OP) {
            continue;
        }
        patch.apply(&mut model)?;
        done += 1;
    }
    Ok((model, done))
}

/// Whether `model` has a node of the op named `op` (tract's conv ops are private types).
pub(crate) fn has_op(model: &TypedModel, op: &str) -> bool {
    model.nodes().iter().any(|n| n.op.name() == op)
}

#[cfg(test)]
mod tests {
    //! The pass on ResNet stems of `nano` (rewritten, values within rounding of tract's direct
    //! kernel) and `test` (left alone).
    use super::*;
    use crate::test_support::{ConvShape, bits, conv_model, run_optimized, run_plain};

    /// A ResNet stem (7x7, stride 2, padding 3) `3 -> co` over `3 x 192 x 320` (the image
    /// encoders' input), decluttered, and its input.
    fn stem_model(co: usize) -> (TypedModel, TVec<TValue>) {
        conv_model(&ConvShape::new(3, co, [192, 320], 7, 2, 3))
    }

    #[test]
    fn a_64_channel_stem_runs_im2col_within_rounding_of_the_direct_kernel() {
        let (model, inputs) = stem_model(64);
        let direct = model.clone().into_optimized().unwrap();
        let (rewritten, n) = im2col_wide_stems(model.clone()).unwrap();
        // Where tract runs AMX (64 inputs a point at most) the stem is im2col already.
        assert_eq!(n, usize::from(has_op(&direct, DIRECT_SPATIAL_OP)));
        if n == 0 {
            // Said, not silent: the comparison below needs tract's direct kernel here.
            eprintln!("skipped: tract runs this 64-channel stem as im2col on this CPU already");
            return;
        }
        let rewritten = rewritten.into_optimized().unwrap();
        assert!(!has_op(&rewritten, DIRECT_SPATIAL_OP));
        assert!(rewritten.nodes().iter().any(|n| n.op.name() == "OptMatMul"));
        let want = run_optimized(model, &inputs);
        let got = run_plain(rewritten, &inputs);
        let (want, got) = (bits(&want[0]), bits(&got[0]));
        let (want, got): (Vec<f32>, Vec<f32>) = (
            want.into_iter().map(f32::from_bits).collect(),
            got.into_iter().map(f32::from_bits).collect(),
        );
        assert_eq!(want.len(), 64 * 96 * 160);
        // 147 products of values below 0.5 a point, summed in another order: a few ulps of
        // sums of order 1 (1.3e-6 measured); 1e-5 is 10x below the stage tolerance.
        let worst = want
            .iter()
            .zip(&got)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(worst <= 1e-5, "largest difference {worst}");
    }

    #[test]
    fn a_narrow_stem_keeps_the_direct_kernel() {
        // `test`'s stem: 8 output channels.
        let (model, _) = stem_model(8);
        let (same, n) = im2col_wide_stems(model).unwrap();
        assert_eq!(n, 0);
        assert!(has_op(&same.into_optimized().unwrap(), DIRECT_SPATIAL_OP));
    }
}
