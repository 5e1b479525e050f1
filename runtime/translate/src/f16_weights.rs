//! The f16 form of a stage graph: the graph translated to f16, so its weights are stored as f16.
//!
//! tract's NNEF writer folds every cast of a constant before it writes (`prop_consts`), so an
//! f16 weight can reach the file only as the input of an f16 operator: the stored graph is the
//! whole f32 graph translated to f16 (tract's `FloatPrecisionTranslator`; sources, constants
//! and float operators), half the flash of the f32 form. On a core with f16 arithmetic
//! (ARMv8.2-A and later) that graph can run as it is; where there is none (x86 here), the engine
//! translates it back to f32 at load (`engine_tract::graph::load::nnef_model`), and tract's optimiser folds each
//! widened constant, so the target runs f32 kernels on f16-rounded weights.
//!
//! A weight outside f16's range would become an infinity and poison every activation it meets,
//! so the translation refuses a graph with any constant that is finite in f32 and not in f16.

use tract_nnef::internal::*;
use tract_nnef::tract_core::floats::FloatPrecisionTranslator;
use tract_nnef::tract_core::ops::konst::Const;
use tract_nnef::tract_core::transform::ModelTransform;

/// Elements at which a constant counts as a weight in [`f32_weight_bytes`].
pub const MIN_WEIGHT_ELEMENTS: usize = 64;

/// `model` translated to f16 (see the module documentation).
///
/// # Errors
/// tract's translation error, or the name of a constant f16 cannot hold.
pub fn to_f16(model: &TypedModel) -> TractResult<TypedModel> {
    // The writer's own rewrites (matmul forms, then constant folding) done here in f32 first:
    // after them in f16, tract folds the new constant matmuls with its portable f16 kernels
    // (40 s for map_decoder) and rounds every partial sum to f16.
    let mut wide = model.clone();
    tract_nnef::ser::rewrite_model(&mut wide)?;
    let mut half =
        FloatPrecisionTranslator::new(f32::datum_type(), f16::datum_type()).transform_into(wide)?;
    // What the NNEF writer will store: casts of constants folded into f16 constants.
    half.prop_consts()?;
    for node in &half.nodes {
        if let Some(konst) = node.op_as::<Const>() {
            let value = konst.val();
            if value.datum_type() == f16::datum_type() && value.is_plain_ram() {
                let values = value.try_as_plain_ram()?;
                let values = values.as_slice::<f16>()?;
                if let Some(v) = values.iter().find(|v| v.is_infinite()) {
                    bail!(
                        "constant {} holds {v} in f16 (outside f16's range)",
                        node.name
                    );
                }
            }
        }
    }
    Ok(half)
}

/// Bytes of f32 weights `model` holds in constants of at least [`MIN_WEIGHT_ELEMENTS`] elements.
#[must_use]
pub fn f32_weight_bytes(model: &TypedModel) -> usize {
    model
        .nodes
        .iter()
        .filter_map(|n| n.op_as::<Const>())
        .map(Const::val)
        .filter(|v| v.datum_type() == f32::datum_type() && v.len() >= MIN_WEIGHT_ELEMENTS)
        .map(|v| v.len() * 4)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::super::test_graphs::{dat_sizes, model_adding};
    use super::*;

    fn weights() -> Vec<f32> {
        (0..64).map(|i| 0.1 + i as f32 / 3.0).collect()
    }

    /// x + w: the NNEF form stores w as f16 (bytes of its tensor file), reads back and, widened,
    /// computes x + f16(w) in f32, bit for bit.
    #[test]
    fn weights_are_stored_as_f16_and_widened_at_load() -> TractResult<()> {
        let w = weights();
        let half = to_f16(&model_adding(tensor1(&w))?)?;
        let nnef = tract_nnef::nnef();
        let tar = nnef.write_to_tar_with_config(&half, Vec::new(), false, true)?;
        // One tensor file: a 128-byte header and 64 two-byte elements.
        assert_eq!(dat_sizes(&tar)?, [128 + 64 * 2]);
        let back = nnef.model_for_read(&mut tar.as_slice())?;
        let widened = FloatPrecisionTranslator::new(f16::datum_type(), f32::datum_type())
            .transform_into(back)?;
        let plan = widened.into_optimized()?.into_runnable()?;
        let out = plan.run(tvec![tensor1(&[0f32; 64]).into_tvalue()])?;
        let got = out[0].try_as_plain_ram()?.as_slice::<f32>()?;
        for (i, (g, w)) in got.iter().zip(&w).enumerate() {
            let want = f16::from_f32(*w).to_f32();
            assert_eq!(g.to_bits(), want.to_bits(), "element {i}");
        }
        Ok(())
    }

    /// A weight beyond f16's largest finite value (65504) is refused by name.
    #[test]
    fn a_weight_outside_f16_range_is_refused() -> TractResult<()> {
        let mut w = weights();
        w[7] = 1e6;
        let err = to_f16(&model_adding(tensor1(&w))?).unwrap_err().to_string();
        assert!(err.contains("constant w"), "{err}");
        Ok(())
    }
}
