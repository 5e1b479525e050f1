//! Matching and patching helpers every load-time rewrite uses: the one patch that wires a
//! native op in place of a node, and the tests a fused chain makes of its nodes. A leaf: the
//! driver ([`crate::passes::rewrite`]) imports the passes, the passes import this.

use tract_nnef::prelude::*;
use tract_nnef::tract_core::ops::binary::TypedBinOp;

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
