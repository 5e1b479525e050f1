//! An int8 bundle's weights widened once at load, for the int8 passes.
//!
//! An int8 bundle stores each weight as int8 and a scale, widened in the graph:
//! `mul(cast(w_int8), scale)` (`satmap_translate::int8_weights`). tract folds that widening at
//! load only while the f32 weight stays under its 4 MiB constant-folding budget; a larger
//! weight (`nano`'s deepest convolutions, its Swin MLPs) is widened again every step, and its
//! layer then has no constant weight for the int8 passes (nor for the native f32 passes) to
//! take. With calibrated ranges, [`fold_widened_weights`] evaluates those widenings once (the
//! cast, the scale and any axis change after them, through tract's own ops, so the f32 values
//! are the ones a step would compute), leaving constants the int8 passes quantise back to the
//! stored int8 values. It runs only for an int8 load with ranges or a calibration
//! ([`super::rewrite::Quantisation`]): the W8A32 load keeps the int8 weights in RAM, by design.

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::binary::TypedBinOp;
use tract_nnef::tract_core::ops::cast::Cast;
use tract_nnef::tract_core::ops::change_axes::AxisOp;
use tract_nnef::tract_core::ops::konst::Const;

use super::fold::evaluate;

/// Replace each widening of an int8 constant (a `Cast` of an int8 constant, then `Mul`s by
/// constants and axis changes) that tract left in `model` by the f32 constant it evaluates to;
/// returns the model and the number of weights widened.
///
/// # Errors
/// tract failing to run the widening, or refusing the patch (an inconsistent model).
pub fn fold_widened_weights(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let order = model.eval_order()?;
    let is_const = |id: usize| model.node(id).op_is::<Const>();
    let mut widened = vec![false; model.nodes().len()];
    for &id in &order {
        let node = model.node(id);
        let reads = |ok: &dyn Fn(usize) -> bool| {
            !node.inputs.is_empty() && node.inputs.iter().all(|i| ok(i.node))
        };
        widened[id] = if node.op_is::<Cast>() {
            reads(&|i| {
                is_const(i)
                    && model
                        .outlet_fact(OutletId::new(i, 0))
                        .is_ok_and(|f| f.datum_type == i8::datum_type())
            })
        } else if node
            .op_as::<TypedBinOp>()
            .is_some_and(|b| b.0.name() == "Mul" && b.1.is_none())
            || node.op_is::<AxisOp>()
        {
            reads(&|i| is_const(i) || widened[i]) && node.inputs.iter().any(|i| widened[i.node])
        } else {
            false
        };
    }
    let frontier: Vec<OutletId> = order
        .iter()
        .filter(|&&id| {
            widened[id]
                && model.node(id).outputs[0]
                    .successors
                    .iter()
                    .any(|s| !widened[s.node])
        })
        .map(|&id| OutletId::new(id, 0))
        .collect();
    if frontier.is_empty() {
        return Ok((model, 0));
    }
    let values = evaluate(&model, &frontier)?;
    let mut patch = TypedModelPatch::default();
    for (&outlet, value) in frontier.iter().zip(values) {
        let name = format!("{}.widened", model.node(outlet.node).name);
        let wire = patch.add_const(name, value.into_tensor())?;
        patch.shunt_outside(&model, outlet, wire)?;
    }
    patch.apply(&mut model)?;
    Ok((model.into_compact()?, frontier.len()))
}
