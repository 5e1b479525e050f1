//! The im2col path of the wide convolutions: eager where tract would gather lazily.
//!
//! tract 0.23.9 runs every f32 convolution with a 3x3 (or larger) kernel that is not a direct
//! spatial one through *lazy* im2col: the matrix product gathers its image operand panel by
//! panel from the padded input. With tract's AVX-512 kernels, on the wide convolutions of `nano`
//! and `paper` (256 output channels or more over 128 to a few thousand pixels: ResNet's layer3,
//! the satellite FPN), that gather cost 2-5x the product itself; *eager* im2col (the whole
//! `[k, n]` operand packed once, then the same product) ran them 2.3-3.7x faster, and lost on
//! narrower convolutions, on tiny maps and where the scratch is large. With the AVX2 + FMA
//! kernels lazy im2col costs 1.1-1.3x the product and eager loses on every shape by 5-15%
//! (`runtime/benches/tract_conv.rs`, docs/perf.md), so the pass runs on the AVX-512 tier only
//! ([`pays_off`]). The paths feed one micro-kernel the same packed panels in the same k order,
//! so the two compute the same bits (this module's tests): where it runs does not move a digest.
//!
//! [`eager_wide_convs`] codegens each such convolution itself, before tract's optimiser, with
//! tract's lazy-im2col knobs scoped to that one node: a convolution tract would run another way
//! (direct spatial, a matmul) keeps tract's choice.

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::cnn::Conv;
use tract_nnef::tract_core::ops::cnn::conv::Im2Col;
use tract_nnef::tract_core::tract_data::knobs::KnobScope;

/// Output channels from which a convolution's im2col is eager (the benchmark's crossover on
/// AVX-512: 256 wins 2.3-3.7x, 128 and 64 lose).
pub const MIN_OUTPUT_CHANNELS: usize = 256;

/// Output pixels from which a convolution's im2col is eager: on ResNet-18's layer4 map (6 x 10)
/// lazy im2col was 20-25% faster in three runs of the benchmark, from 12 x 20 eager 3x.
pub const MIN_OUTPUT_PIXELS: usize = 128;

/// The largest eager im2col scratch (`k x n` f32) this pass asks for: above it (the map
/// decoder's 4608 x 3200 input projection, 59 MB) lazy im2col was faster, and the scratch
/// would be RAM on top of the stage's.
pub const MAX_SCRATCH_BYTES: usize = 16 << 20;

/// Whether eager im2col runs faster than lazy on a host of kernel `family`
/// ([`kernel_family`](crate::engine_tract::kernel_family)): on the AVX-512 tier (measured on
/// `intel-avx512f`; `amd-avx512f` runs the same AVX-512 kernels, not measured on its own). Not
/// on `amd-fma`, where eager lost on every benchmarked shape; not on tiers never measured.
#[must_use]
pub fn pays_off(family: &str) -> bool {
    family.ends_with("-avx512f")
}

/// Codegen every wide f32 convolution of a decluttered `model` with eager im2col; returns the
/// model and the number of convolutions so planned.
///
/// # Errors
/// tract refusing a convolution's codegen or its patch (an inconsistent model).
pub fn eager_wide_convs(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    // Thresholds no convolution reaches: tract's `should_use_lazy` then says eager, for the
    // one node planned inside the scope.
    let eager = KnobScope::new([
        ("TRACT_LAZY_IM2COL_MIN_KERNEL", "1000000000"),
        ("TRACT_LAZY_IM2COL_MAX_EAGER_BYTES", "1000000000000"),
    ])?;
    let wide: Vec<String> = model
        .nodes()
        .iter()
        .filter(|node| is_wide(&model, node))
        .map(|node| node.name.clone())
        .collect();
    let mut done = 0;
    for name in wide {
        let id = model.node_id_by_name(&name)?;
        let node = model.node(id);
        let Some(patch) = eager.enter(|| node.op.codegen(&model, node))? else {
            continue;
        };
        // Only an im2col plan is this pass's business; any other (direct spatial) is tract's
        // own choice, left to its optimiser.
        if !patch.model.nodes().iter().any(|n| n.op_is::<Im2Col>()) {
            continue;
        }
        patch.apply(&mut model)?;
        done += 1;
    }
    Ok((model, done))
}

/// An f32 convolution of one group with at least [`MIN_OUTPUT_CHANNELS`] outputs over at least
/// [`MIN_OUTPUT_PIXELS`] pixels, a kernel of more than one tap and an eager scratch within
/// [`MAX_SCRATCH_BYTES`].
fn is_wide(model: &TypedModel, node: &TypedNode) -> bool {
    let Some(conv) = node.op_as::<Conv>() else {
        return false;
    };
    let (Some(input), Ok(output)) = (node.inputs.first(), model.outlet_fact(node.id.into())) else {
        return false;
    };
    let Ok(input) = model.outlet_fact(*input) else {
        return false;
    };
    let Some(out_shape) = output.shape.as_concrete() else {
        return false;
    };
    let taps: usize = conv.pool_spec.kernel_shape.iter().product();
    let k = conv.input_channels() * taps;
    let n = out_shape.iter().product::<usize>() / conv.output_channels().max(1);
    conv.q_params.is_none()
        && conv.group == 1
        && input.datum_type == f32::datum_type()
        && taps > 1
        && conv.output_channels() >= MIN_OUTPUT_CHANNELS
        && n >= MIN_OUTPUT_PIXELS
        && k * n * size_of::<f32>() <= MAX_SCRATCH_BYTES
}

#[cfg(test)]
mod tests {
    //! The pass against tract's own plan of the same convolution, bit for bit, on a wide one
    //! (rewritten); narrow, tiny-map and large-scratch ones left alone.
    use super::*;
    use crate::engine_tract::conv_direct::has_op;
    use crate::engine_tract::test_support::{ConvShape, bits, conv_model, run_optimized};

    /// A decluttered 3x3 same-padded convolution `ci -> co` over `h x w`, and its input.
    fn conv3x3(ci: usize, co: usize, h: usize, w: usize) -> (TypedModel, TVec<TValue>) {
        conv_model(&ConvShape::new(ci, co, [h, w], 3, 1, 1))
    }

    #[test]
    fn eager_im2col_runs_on_the_avx512_tier_only() {
        assert!(pays_off("intel-avx512f") && pays_off("amd-avx512f"));
        assert!(!pays_off("amd-fma") && !pays_off("intel-fma") && !pays_off("generic"));
    }

    #[test]
    fn a_wide_convolution_runs_eager_im2col_with_tracts_bits() {
        // ResNet-18's layer3 on `nano` (256 channels over 12 x 20).
        let (model, inputs) = conv3x3(256, 256, 12, 20);
        let lazy = model.clone().into_optimized().unwrap();
        assert!(has_op(&lazy, "LazyIm2col") && !has_op(&lazy, "Im2col"));
        let (eager, n) = eager_wide_convs(model.clone()).unwrap();
        assert_eq!(n, 1);
        let eager = eager.into_optimized().unwrap();
        assert!(has_op(&eager, "Im2col") && !has_op(&eager, "LazyIm2col"));
        let want = run_optimized(model, &inputs);
        let got = run_optimized(eager, &inputs);
        assert_eq!(bits(&got[0]), bits(&want[0]));
    }

    #[test]
    fn narrow_or_large_convolutions_keep_tracts_plan() {
        // 128 output channels; 60 output pixels (ResNet-18's layer4 on `nano`); a scratch of
        // 4608 x 3200 f32 (the map decoder's projection on `nano`, 59 MB).
        for (ci, co, h, w) in [(128, 128, 23, 40), (512, 512, 6, 10), (512, 256, 80, 40)] {
            let (model, _) = conv3x3(ci, co, h, w);
            let (same, n) = eager_wide_convs(model).unwrap();
            assert_eq!(n, 0, "{ci} -> {co}");
            assert!(has_op(&same, "Conv"));
        }
    }
}
