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
//! A widened weight no int8 pass takes (a layer without a range, a grouped convolution) stays
//! an f32 constant: more RAM than W8A32's, and a step without its widening.

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

#[cfg(test)]
mod tests {
    //! A widening as an int8 bundle stores it (`Cast` of an int8 constant, `Mul` by its scales,
    //! an axis change) evaluated once into the constant a step computed, bit for bit.
    use super::*;
    use crate::test_support::{bits, run_plain};
    use tract_nnef::tract_core::ops::math;

    #[test]
    fn a_widening_becomes_the_constant_a_step_computed() {
        // Over tract's 4 MiB fold budget once widened (smaller, tract folds it as it wires).
        let (o, i) = (1100, 1024);
        let mut model = TypedModel::default();
        let x = model.add_source("x", f32::fact([i, o])).unwrap();
        let q: Vec<i8> = (0..o * i).map(|v| ((v * 37) % 255) as u8 as i8).collect();
        let q = Tensor::from_shape(&[o, i], &q).unwrap();
        let q = model.add_const("w_int8", q).unwrap();
        let wide = model
            .wire_node("wide", Cast::new(f32::datum_type()), &[q])
            .unwrap()[0];
        let scales: Vec<f32> = (0..o).map(|c| 1e-3 * (1 + c % 7) as f32).collect();
        let s = Tensor::from_shape(&[o, 1], &scales).unwrap();
        let s = model.add_const("scale", s).unwrap();
        let w = model.wire_node("w", math::mul(), &[wide, s]).unwrap()[0];
        let wt = model.wire_node("wt", AxisOp::Move(0, 1), &[w]).unwrap()[0];
        let y = model.wire_node("y", math::add(), &[x, wt]).unwrap();
        model.select_output_outlets(&y).unwrap();
        let input = tvec![
            Tensor::from_shape(&[i, o], &vec![1.0f32; i * o])
                .unwrap()
                .into_tvalue()
        ];
        let want = run_plain(model.clone(), &input);
        let (folded, n) = fold_widened_weights(model).unwrap();
        assert_eq!(n, 1, "the chain's last outlet, read by the step");
        assert!(!folded.nodes().iter().any(|n| n.op_is::<Cast>()));
        let got = run_plain(folded, &input);
        assert_eq!(bits(&got[0]), bits(&want[0]));
    }

    #[test]
    fn a_model_without_int8_constants_is_left_alone() {
        let mut model = TypedModel::default();
        let x = model.add_source("x", f32::fact([4])).unwrap();
        let c = model
            .add_const("c", Tensor::from_shape(&[4], &[1.0f32; 4]).unwrap())
            .unwrap();
        let y = model.wire_node("y", math::mul(), &[x, c]).unwrap();
        model.select_output_outlets(&y).unwrap();
        let (_, n) = fold_widened_weights(model).unwrap();
        assert_eq!(n, 0);
    }
}
