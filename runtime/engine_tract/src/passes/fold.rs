//! Load-time evaluation of the parts of a stage that depend on its weights alone.
//!
//! MapTR's first decoder layer attends among its learned queries: `map_decoder`'s layer-0
//! self-attention (two matmuls around a softmax over a `[heads, queries, queries]` score
//! tensor, 4x2000x2000 on `nano`) reads no input. tract's constant propagation leaves it in the
//! graph, because its rule keeps a fold's output within the size of the fold's inputs and the
//! scores are much larger than the weights they come from; so every step recomputed it (on
//! `nano`, ~300 of the decoder's ~780 ms on an AVX2 EPYC). [`fold_input_independent`] runs
//! every such subgraph of the *optimised* model once, at load, through a plan of its own (the
//! same ops and kernels the step's plan runs, so the values are bit for bit a step's), and
//! replaces its frontier (the outlets an input-dependent node or a model output reads) with
//! constants. The large intermediates (the scores) are then gone from the step altogether.
//!
//! Only numeric outlets of plain tensors are folded (not tract's packed operands), and only while all the
//! constants it adds stay within [`FOLD_BUDGET_BYTES`]: a bound on what folding may add to the
//! resident weights.

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::konst::Const;
use tract_nnef::tract_core::ops::source::TypedSource;

/// Bytes the folded constants of one stage may take in all.
pub const FOLD_BUDGET_BYTES: usize = 16 << 20;

/// Replace the frontier of every input-independent subgraph of `model` by the constant it
/// evaluates to; returns the model and the number of outlets folded.
///
/// # Errors
/// tract failing to plan or run the subgraph, or refusing the patch (an inconsistent model).
pub fn fold_input_independent(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let order = model.eval_order()?;
    // A node is input-independent when it is a constant, or has inputs and reads only
    // input-independent outlets. A node without inputs that is not a constant (a source, a
    // generator) is not.
    let mut independent = vec![false; model.nodes().len()];
    for &id in &order {
        let node = model.node(id);
        independent[id] = node.op_is::<Const>()
            || (!node.op_is::<TypedSource>()
                && !node.inputs.is_empty()
                && node.inputs.iter().all(|i| independent[i.node]));
    }
    let outputs = model.output_outlets()?.to_vec();
    let mut frontier = Vec::new();
    let mut bytes = 0usize;
    for &id in &order {
        let node = model.node(id);
        if !independent[id] || node.op_is::<Const>() {
            continue;
        }
        for (slot, out) in node.outputs.iter().enumerate() {
            let outlet = OutletId::new(id, slot);
            let read_by_a_step =
                outputs.contains(&outlet) || out.successors.iter().any(|s| !independent[s.node]);
            let Some(size) = out
                .fact
                .shape
                .as_concrete()
                .map(|s| s.iter().product::<usize>() * out.fact.datum_type.size_of())
            else {
                continue;
            };
            // A packed operand (an exotic fact: `nano`'s int8 kernels over tract's 4 MiB fold
            // budget, packed by `OptMatMulPack` every step) is not a plain tensor: tract
            // refuses a constant in its place.
            if read_by_a_step
                && out.fact.datum_type.is_number()
                && out.fact.exotic_fact.is_none()
                && bytes + size <= FOLD_BUDGET_BYTES
            {
                bytes += size;
                frontier.push(outlet);
            }
        }
    }
    if frontier.is_empty() {
        return Ok((model, 0));
    }
    let values = evaluate(&model, &frontier)?;
    let mut patch = TypedModelPatch::default();
    for (&outlet, value) in frontier.iter().zip(values) {
        let name = format!("{}.folded.{}", model.node(outlet.node).name, outlet.slot);
        let wire = patch.add_const(name, value.into_tensor())?;
        patch.shunt_outside(&model, outlet, wire)?;
    }
    patch.apply(&mut model)?;
    Ok((model.into_compact()?, frontier.len()))
}

/// The values of `outlets` (input-independent) through a plan of `model` computing only them.
/// The model's inputs are fed zeros: no node the plan runs reads them.
pub(crate) fn evaluate(model: &TypedModel, outlets: &[OutletId]) -> TractResult<TVec<TValue>> {
    let inputs = model
        .input_outlets()?
        .iter()
        .map(|&i| {
            let fact = model.outlet_fact(i)?;
            let shape = fact
                .shape
                .as_concrete()
                .context("an input of symbolic shape")?;
            Ok(Tensor::zero_dt(fact.datum_type, shape)?.into_tvalue())
        })
        .collect::<TractResult<TVec<_>>>()?;
    model
        .clone()
        .with_output_outlets(outlets)?
        .into_runnable()?
        .run(inputs)
}

#[cfg(test)]
mod tests {
    //! The folded plan against the plan as optimised, bit for bit, on every stage of the
    //! committed default bundle.

    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        assert_same_bits, committed_rewrites, committed_stage_before, inputs_of, run_plain,
    };
    use satmap_core::engine::Stage;

    #[test]
    fn folded_stages_compute_what_they_computed_bit_for_bit() {
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::Fold);
            let inputs = inputs_of(&plain);
            let (folded, n) = fold_input_independent(plain.clone()).expect("fold");
            assert_eq!(n, committed_rewrites(stage).folded_outlets, "{stage}");
            assert_eq!(
                folded.nodes().len() < plain.nodes().len(),
                n > 0,
                "{stage}: the folded nodes left the plan"
            );
            let (a, b) = (run_plain(plain, &inputs), run_plain(folded, &inputs));
            assert_same_bits(stage, &a, &b);
        }
    }
}
