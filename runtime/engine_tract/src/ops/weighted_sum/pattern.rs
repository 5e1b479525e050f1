//! The pattern [`fuse_weighted_sums`] recognises: a `Mul -> Reduce<Sum>` pair over one middle
//! axis (with the `Gather` of rows feeding it, where there is one), and the patch that replaces
//! it with one [`WeightedAxisSum`].

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::binary::TypedBinOp;
use tract_nnef::tract_core::ops::change_axes::AxisOp;
use tract_nnef::tract_core::ops::math::Mul;
use tract_nnef::tract_core::ops::nn::{Reduce, Reducer};

use super::WeightedAxisSum;

/// A `Mul -> Reduce<Sum>` pair to rewrite: the Reduce node, its axis and the fused op's inputs.
struct Fusion {
    reduce: usize,
    op: WeightedAxisSum,
    inputs: TVec<OutletId>,
}

/// True when `outlet` feeds exactly one node and is not a model output.
fn single_use(model: &TypedModel, outlet: OutletId) -> TractResult<bool> {
    Ok(model.node(outlet.node).outputs[outlet.slot]
        .successors
        .len()
        == 1
        && !model.output_outlets()?.contains(&outlet))
}

/// `outlet` as `Reshape(0, [M], dims)` of `Gather(axis 0)` of a `[R, dh]` f32 matrix by i64
/// indices, both single-use: the Gather's inputs and the operand's shape `dims` (ending in dh).
fn gathered_rows(
    model: &TypedModel,
    outlet: OutletId,
) -> TractResult<Option<(OutletId, OutletId, TVec<usize>)>> {
    let reshape = model.node(outlet.node);
    let Some(AxisOp::Reshape(0, from, _)) = reshape.op_as::<AxisOp>() else {
        return Ok(None);
    };
    if from.len() != 1 || !single_use(model, reshape.inputs[0])? {
        return Ok(None);
    }
    let gather = model.node(reshape.inputs[0].node);
    let is_row_gather = gather
        .op_as::<tract_nnef::tract_core::ops::array::Gather>()
        .is_some_and(|g| g.axis == 0 && g.output_type.is_none());
    if !is_row_gather {
        return Ok(None);
    }
    let (data, mut indices) = (gather.inputs[0], gather.inputs[1]);
    // Integer casts of f32 values upstream of the indices, through single-use order-keeping
    // reshapes, are folded in (tract loads ONNX's f32 -> int64 Cast as f32 -> TDim, then TDim ->
    // i64 before the Gather): the kernel reads the f32 values in the same row-major order and
    // converts them as those casts do (`as i64`).
    let mut o = indices;
    let mut casts = 0;
    loop {
        let n = model.node(o.node);
        if n.inputs.len() != 1 || !single_use(model, o)? {
            break;
        }
        let keeps_order = n
            .op_as::<AxisOp>()
            .is_some_and(|op| !matches!(op, AxisOp::Move(..)));
        let int_cast = n
            .op_as::<tract_nnef::tract_core::ops::cast::Cast>()
            .is_some_and(|c| c.to == i64::datum_type() || c.to == TDim::datum_type());
        if !keeps_order && !int_cast {
            break;
        }
        casts += usize::from(int_cast);
        o = n.inputs[0];
    }
    if casts > 0 && model.outlet_fact(o)?.datum_type == f32::datum_type() {
        indices = o;
    }
    let data_fact = model.outlet_fact(data)?;
    let index_fact = model.outlet_fact(indices)?;
    let Some(shape) = model
        .outlet_fact(outlet)?
        .shape
        .as_concrete()
        .map(TVec::from)
    else {
        return Ok(None);
    };
    let data_dims = data_fact.shape.as_concrete();
    let ok = data_fact.datum_type == f32::datum_type()
        && matches!(index_fact.datum_type, DatumType::I64 | DatumType::F32)
        && index_fact
            .shape
            .as_concrete()
            .map(|d| d.iter().product::<usize>())
            == model
                .outlet_fact(gather.inputs[1])?
                .shape
                .as_concrete()
                .map(|d| d.iter().product())
        && data_dims.is_some_and(|d| d.len() == 2 && shape.last() == Some(&d[1]));
    Ok(ok.then_some((data, indices, shape)))
}

/// The first `Mul -> Reduce<Sum>(one middle axis)` pair over f32 whose product feeds nothing
/// else; gathered when one operand is a row gather summed over its second-to-last axis.
fn find_pair(model: &TypedModel) -> TractResult<Option<Fusion>> {
    for &id in &model.eval_order()? {
        let node = model.node(id);
        let Some(reduce) = node.op_as::<Reduce>() else {
            continue;
        };
        if reduce.reducer != Reducer::Sum || reduce.axes.len() != 1 {
            continue;
        }
        let fact = model.outlet_fact(node.inputs[0])?;
        let axis = reduce.axes[0];
        if fact.datum_type != f32::datum_type() || axis + 1 >= fact.rank() {
            continue;
        }
        let mul = model.node(node.inputs[0].node);
        let is_mul = mul
            .op_as::<TypedBinOp>()
            .is_some_and(|b| b.0.is::<Mul>() && b.1.is_none());
        if !is_mul || !single_use(model, node.inputs[0])? {
            continue;
        }
        let ins = [mul.inputs[0], mul.inputs[1]];
        let mut all_f32 = true;
        for o in ins {
            all_f32 &= model.outlet_fact(o)?.datum_type == f32::datum_type();
        }
        if !all_f32 {
            continue;
        }
        for (a, b) in [(ins[0], ins[1]), (ins[1], ins[0])] {
            if axis + 2 == fact.rank()
                && single_use(model, a)?
                && let Some((data, indices, shape)) = gathered_rows(model, a)?
                && shape.len() == fact.rank()
            {
                return Ok(Some(Fusion {
                    reduce: id,
                    op: WeightedAxisSum {
                        axis,
                        gathered: Some(shape),
                    },
                    inputs: tvec![data, indices, b],
                }));
            }
        }
        return Ok(Some(Fusion {
            reduce: id,
            op: WeightedAxisSum {
                axis,
                gathered: None,
            },
            inputs: tvec![ins[0], ins[1]],
        }));
    }
    Ok(None)
}

/// Rewrite every fusable `Mul -> Reduce<Sum>` pair of a decluttered model into
/// [`WeightedAxisSum`] (reading a row gather in place where it feeds the pair); returns the
/// model and the number of pairs rewritten.
///
/// # Errors
/// tract refusing the patch (an inconsistent model).
pub fn fuse_weighted_sums(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut fused = 0;
    while let Some(f) = find_pair(&model)? {
        let name = model.node(f.reduce).name.clone();
        let mut patch = TypedModelPatch::default();
        let taps = patch.taps(&model, &f.inputs)?;
        let out = patch.wire_node(format!("{name}.weighted_axis_sum"), f.op, &taps)?;
        patch.shunt_outside(&model, f.reduce.into(), out[0])?;
        patch.apply(&mut model)?;
        // Drop the replaced nodes, so the search cannot find them again.
        model = model.into_compact()?;
        fused += 1;
    }
    Ok((model, fused))
}
