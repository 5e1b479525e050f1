//! The plan's constants re-laid with tract's natural strides.
//!
//! tract's `Tensor::insert_axis` gives a new axis of length 1 the stride of the axis after it,
//! so a LayerNorm's `[C]` scale, broadcast to `[1, C]` when the graph is decluttered, holds
//! strides `[1, 1]` where tract's natural ones are `[C, 1]`: the same bytes in the same order.
//! tract's element-wise kernels (`OptBinChain`, `par_bin`) compare strides, not layouts, and
//! send such an operand to the generic ndarray path at ~8 ns a value: the three
//! `x * scale + shift` chains of `test`'s `bev_encoder` took 3 of its 5 ms on an AVX2 EPYC.
//! [`naturalise_consts`] (the last load-time rewrite) gives every such constant the same bytes
//! with natural strides, so those ops take their vector kernels.
//!
//! Bit for bit: a constant's values do not change, and an element-wise op computes each output
//! value by the same IEEE operations on either path (this module's test runs every stage of the
//! committed default bundle both ways).

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::konst::Const;

/// Replace every plain constant of `model` whose strides are not tract's natural ones, but whose
/// bytes are in natural order (only its length-1 axes differ), by the same bytes with natural
/// strides; returns the model and how many constants were re-laid.
///
/// # Errors
/// tract refusing a re-laid tensor (it does not, for a plain copyable one).
pub fn naturalise_consts(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in 0..model.nodes().len() {
        let Some(konst) = model.node(id).op_as::<Const>() else {
            continue;
        };
        if konst.exotic_fact().is_some() {
            continue;
        }
        let Some(natural) = relaid(konst.val())? else {
            continue;
        };
        let natural = Arc::new(natural);
        let node = model.node_mut(id);
        node.op = Box::new(Const::new(Arc::clone(&natural))?);
        if let Some(fact) = node.outputs.first_mut()
            && fact.fact.konst.is_some()
        {
            fact.fact.konst = Some(natural);
        }
        done += 1;
    }
    Ok((model, done))
}

/// `t` with natural strides, if its strides are not natural but its bytes are in natural order.
fn relaid(t: &Tensor) -> TractResult<Option<Tensor>> {
    if !t.datum_type().is_copy() || !t.has_plain_ram_storage() {
        return Ok(None);
    }
    let natural = Tensor::natural_strides(t.shape());
    if t.strides() == &*natural {
        return Ok(None);
    }
    let same_order = t
        .shape()
        .iter()
        .zip(t.strides().iter().zip(natural.iter()))
        .all(|(&dim, (s, n))| dim == 1 || s == n);
    if !same_order {
        return Ok(None);
    }
    // SAFETY: the bytes are `t`'s own plain storage, of its datum type and element count.
    let bytes = t.as_bytes();
    Ok(Some(unsafe {
        Tensor::from_raw_dt(t.datum_type(), t.shape(), bytes)
    }?))
}

#[cfg(test)]
mod tests {
    //! Constants of an `insert_axis` re-laid with the same values; every stage of the committed
    //! default bundle, compiled (NNEF) and as exported (ONNX), run with and without the pass,
    //! bit for bit.

    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        assert_same_bits, bits, committed_stage_before, inputs_of, run_plain,
    };
    use satmap_core::engine::Stage;

    #[test]
    fn an_inserted_axis_is_relaid_with_the_same_values() {
        let mut t = Tensor::from_shape(&[4], &[1.5f32, -2.0, 3.25, 0.0]).expect("tensor");
        t.insert_axis(0).expect("axis");
        assert_ne!(t.strides(), &*Tensor::natural_strides(t.shape()));
        let natural = relaid(&t).expect("relaid").expect("not natural");
        assert_eq!(natural.strides(), &*Tensor::natural_strides(&[1, 4]));
        assert_eq!(bits(&natural), bits(&t));
        // Natural already: nothing to do.
        assert!(relaid(&natural).expect("relaid").is_none());
    }

    /// `plain` and `plain` through the pass, run on the same inputs: the same bits, and no
    /// constant left to re-lay. Returns how many were re-laid.
    fn relaid_bit_for_bit(stage: Stage, plain: TypedModel) -> usize {
        let inputs = inputs_of(&plain);
        let (relaid, n) = naturalise_consts(plain.clone()).expect("rewrite");
        let (_, left) = naturalise_consts(relaid.clone()).expect("again");
        assert_eq!(left, 0, "{stage}: a constant kept unnatural strides");
        let (a, b) = (run_plain(plain, &inputs), run_plain(relaid, &inputs));
        assert_same_bits(stage, &a, &b);
        n
    }

    #[test]
    fn compiled_stages_compute_what_they_computed_bit_for_bit() {
        for stage in Stage::ALL {
            relaid_bit_for_bit(stage, committed_stage_before(stage, Pass::NaturalConsts));
        }
    }

    /// The exported ONNX stages: tract's ONNX LayerNorm import is where the `[1, C]` scales
    /// and shifts with unnatural strides come from (the compiled NNEF stages hold few). Through
    /// tract's optimiser alone: the engine's `layer_norm` pass takes those LayerNorms whole (so
    /// on our own graphs this pass now finds nothing), and this pass stays for the ones it
    /// does not match.
    #[cfg(feature = "onnx")]
    #[test]
    fn exported_stages_compute_what_they_computed_bit_for_bit() {
        use crate::{onnx_model, test_support::root};
        use satmap_bundle::Bundle;
        let bundle = Bundle::open(root().join("models/bundles/test")).expect("bundle");
        for stage in Stage::ALL {
            let bytes = bundle.read_stage(stage).expect("stage bytes");
            let entry = bundle.manifest().stage(stage).expect("entry");
            let model = onnx_model(stage, &bytes, entry)
                .expect("model")
                .into_decluttered()
                .expect("declutter");
            let plain = model.into_optimized().expect("optimise");
            let n = relaid_bit_for_bit(stage, plain);
            // `bev_encoder`'s two LayerNorms: a scale and a shift each, at least.
            if stage == Stage::BevEncoder {
                assert!(n >= 4, "{stage}: {n} constants re-laid");
            }
        }
    }
}
