//! Products of an activation and a constant that contract several axes at once, reshaped into
//! the one-axis linear layers [`crate::ops::linear`] takes.
//!
//! The attention output projections contract heads and head width together: the decoder's
//! `mak,nak->mn` (`[2000, 8, 32]` against `[256, 8, 32]` in `nano`), bev_query's `mbak,nbk->mn`
//! (a unit axis between the two), the Swin's `cmbk,bkn->camn` (a unit axis added to the
//! output). tract ran them with its own kernel (the decoder's 9 of 193 ms in `nano`).
//! [`merge_contracted_axes`] rewrites each into `x` reshaped (its unit axes that only it has
//! removed, the contracted axes, which must be its trailing ones, merged into one), the
//! constant reshaped the same way (the contracted axes next to each other there, in the same
//! order), a two-axis einsum, and the output's unit axes put back. The merged axis runs in
//! memory order, which is the order tract's optimiser merges such axes in before its own
//! product (`merge_consecutive_same_role_axes`), and a unit axis adds nothing to a sum: the
//! stages compute their bits (the tests).

use tract_nnef::internal::*;
use tract_nnef::tract_core::axes::AxesMapping;
use tract_nnef::tract_core::ops::change_axes::AxisOp;
use tract_nnef::tract_core::ops::einsum::EinSum;

use crate::ops::linear::f32_einsum;

/// What one einsum becomes: the activation's input, its reshapes, the constant, the product.
struct Plan {
    /// The constant's input slot.
    wi: usize,
    /// Activation axes to remove (units only it has), highest first.
    x_removed: Vec<usize>,
    /// Where the contracted axes start in the activation after those removals, and their dims.
    merged: (usize, TVec<usize>),
    /// The constant reshaped to two axes.
    w: Tensor,
    /// The two-axis product's expression, inputs in the einsum's order.
    expr: String,
    /// Output axes to add back (units only the output has), lowest first.
    out_added: Vec<usize>,
}

/// The node `id` as such a product, if it is one (module doc) and not already one-axis.
fn plan(model: &TypedModel, id: usize) -> TractResult<Option<Plan>> {
    let node = model.node(id);
    let Some(es) = f32_einsum(node) else {
        return Ok(None);
    };
    let facts = model.node_input_facts(id)?;
    let Some(wi) = (0..2).find(|&i| facts[i].konst.is_some()) else {
        return Ok(None);
    };
    let xi = 1 - wi;
    let (Some(xs), Some(w)) = (facts[xi].shape.as_concrete(), facts[wi].konst.clone()) else {
        return Ok(None);
    };
    let Some(out) = node.outputs[0].fact.shape.as_concrete() else {
        return Ok(None);
    };
    if facts[xi].konst.is_some() || w.datum_type() != f32::datum_type() {
        return Ok(None);
    }
    // Sort every axis by role; one position at most per operand.
    let (mut kept, mut contracted, mut x_units, mut out_units) = (vec![], vec![], vec![], vec![]);
    let mut n_axis = None;
    for axis in es.axes.iter_all_axes() {
        let (ix, iw, io) = (&axis.inputs[xi], &axis.inputs[wi], &axis.outputs[0]);
        if ix.len() > 1 || iw.len() > 1 || io.len() > 1 {
            return Ok(None);
        }
        match (ix.first(), iw.first(), io.first()) {
            (Some(&px), None, Some(&po)) => kept.push((px, po, axis.repr)),
            (Some(&px), Some(&pw), None) => contracted.push((px, pw, axis.repr)),
            (None, Some(&pw), Some(&po)) if n_axis.is_none() => n_axis = Some((pw, po, axis.repr)),
            (Some(&px), None, None) if xs[px] == 1 => x_units.push(px),
            (None, None, Some(&po)) if out[po] == 1 => out_units.push(po),
            _ => return Ok(None),
        }
    }
    let Some((n_w, _, n_repr)) = n_axis else {
        return Ok(None);
    };
    if contracted.len() < 2 && x_units.is_empty() && out_units.is_empty() {
        return Ok(None);
    }
    // The activation without its units: kept axes in output order, then the contracted ones.
    let x_pos = |p: usize| p - x_units.iter().filter(|&&u| u < p).count();
    kept.sort_unstable();
    contracted.sort_unstable();
    let kept_in_order = kept.windows(2).all(|p| p[0].1 < p[1].1);
    let layout_ok = kept.iter().enumerate().all(|(i, k)| x_pos(k.0) == i)
        && contracted
            .iter()
            .enumerate()
            .all(|(i, c)| x_pos(c.0) == kept.len() + i);
    // In the constant: the contracted axes together, in the activation's order.
    let w_consecutive = contracted.windows(2).all(|p| p[1].1 == p[0].1 + 1);
    let n_first = n_w == 0;
    let w_rank_ok = w.rank() == contracted.len() + 1
        && (n_first || n_w == contracted.len())
        && contracted
            .first()
            .is_some_and(|c| c.1 == usize::from(n_first));
    if !kept_in_order || !layout_ok || !w_consecutive || !w_rank_ok {
        return Ok(None);
    }
    let k_dims: TVec<usize> = contracted.iter().map(|c| xs[c.0]).collect();
    let k: usize = k_dims.iter().product();
    let n = w.shape()[n_w];
    let w2 = w
        .into_tensor()
        .into_shape(&if n_first { [n, k] } else { [k, n] })?;
    let k_repr = contracted[contracted.len() - 1].2;
    let kept_reprs: String = kept.iter().map(|k| k.2).collect();
    let x_term = format!("{kept_reprs}{k_repr}");
    let w_term: String = if n_first {
        [n_repr, k_repr].iter().collect()
    } else {
        [k_repr, n_repr].iter().collect()
    };
    let out_term = format!("{kept_reprs}{n_repr}");
    let expr = if xi == 0 {
        format!("{x_term},{w_term}->{out_term}")
    } else {
        format!("{w_term},{x_term}->{out_term}")
    };
    let mut x_removed = x_units;
    x_removed.sort_unstable_by(|a, b| b.cmp(a));
    out_units.sort_unstable();
    Ok(Some(Plan {
        wi,
        x_removed,
        merged: (kept.len(), k_dims),
        w: w2,
        expr,
        out_added: out_units,
    }))
}

/// Rewrite every product of a decluttered `model` that contracts several trailing activation
/// axes against a constant (module doc) into reshapes around a one-axis einsum; returns the
/// model and how many were rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn merge_contracted_axes(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let Some(p) = plan(&model, id)? else {
            continue;
        };
        let node = model.node(id);
        let name = node.name.clone();
        let Some(es) = node.op_as::<EinSum>().cloned() else {
            continue;
        };
        let wi = p.wi;
        let mut patch = TypedModelPatch::default();
        let mut x = patch.tap_model(&model, node.inputs[1 - wi])?;
        for (i, &axis) in p.x_removed.iter().enumerate() {
            x = patch.wire_node(format!("{name}.unit{i}"), AxisOp::Rm(axis), &[x])?[0];
        }
        let (start, dims) = p.merged;
        let k: usize = dims.iter().product();
        let reshape = AxisOp::Reshape(
            start,
            dims.iter().map(|&d| d.to_dim()).collect(),
            tvec![k.to_dim()],
        );
        x = patch.wire_node(format!("{name}.merge_k"), reshape, &[x])?[0];
        let w = patch.add_const(format!("{name}.w2"), p.w)?;
        let op = EinSum {
            axes: p.expr.parse::<AxesMapping>()?,
            ..es
        };
        let inputs = if wi == 0 { [w, x] } else { [x, w] };
        let mut y = patch.wire_node(format!("{name}.merged"), op, &inputs)?[0];
        for (i, &axis) in p.out_added.iter().enumerate() {
            y = patch.wire_node(format!("{name}.out_unit{i}"), AxisOp::Add(axis), &[y])?[0];
        }
        patch.shunt_outside(&model, OutletId::new(id, 0), y)?;
        patch.apply(&mut model)?;
        done += 1;
    }
    Ok((model.into_compact()?, done))
}

#[cfg(test)]
mod tests {
    //! The rewrite against tract's plan of the same product, bit for bit, on the three forms
    //! of our graphs and on every stage of the committed default bundle; forms it must leave.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, run_optimized};

    fn product(expr: &str, x: &[usize], w: &[usize]) -> (TypedModel, TVec<TValue>) {
        let mut m = TypedModel::default();
        let xs = m.add_source("x", f32::fact(x)).unwrap();
        let wv: Vec<f32> = (0..w.iter().product::<usize>())
            .map(|i| ((i * 7919 % 113) as f32 - 56.0) * 0.0173)
            .collect();
        let wc = m
            .add_const("w", Tensor::from_shape(w, &wv).unwrap())
            .unwrap();
        let op = EinSum::new(expr.parse().unwrap(), f32::datum_type());
        let y = m.wire_node("p", op, &[xs, wc]).unwrap();
        m.select_output_outlets(&y).unwrap();
        let xv: Vec<f32> = (0..x.iter().product::<usize>())
            .map(|i| ((i * 104_729 % 997) as f32 - 498.0) * 0.0021)
            .collect();
        let input = Tensor::from_shape(x, &xv).unwrap();
        (m.into_decluttered().unwrap(), tvec![input.into()])
    }

    #[test]
    fn merged_products_compute_tracts_bits() {
        for (expr, x, w) in [
            ("mak,nak->mn", vec![40, 8, 32], vec![24, 8, 32]),
            ("mbak,nbk->mn", vec![30, 8, 1, 4], vec![32, 8, 4]),
            ("cmbk,bkn->camn", vec![2, 49, 2, 16], vec![2, 16, 32]),
        ] {
            let (model, inputs) = product(expr, &x, &w);
            let (merged, n) = merge_contracted_axes(model.clone()).unwrap();
            assert_eq!(n, 1, "{expr}");
            let want = run_optimized(model, &inputs);
            let got = run_optimized(merged.clone(), &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{expr}");
            assert_eq!(bits(&got[0]), bits(&want[0]), "{expr}");
            // And then the linear layer pass takes it.
            let (linear, taken) = crate::ops::linear::native_linears(merged).unwrap();
            if crate::gemm::tier().is_some() {
                assert_eq!(taken, 1, "{expr}");
                let native = run_optimized(linear, &inputs);
                assert_eq!(bits(&native[0]), bits(&want[0]), "{expr} native");
            } else {
                assert_eq!(
                    taken, 0,
                    "{expr}: no native tier here, the product stays tract's"
                );
            }
        }
    }

    #[test]
    fn other_products_are_left_alone() {
        for (expr, x, w) in [
            // Already one contracted axis; contracted axes not trailing; apart in the constant.
            ("mk,nk->mn", vec![40, 32], vec![24, 32]),
            ("akm,nak->mn", vec![8, 32, 40], vec![24, 8, 32]),
            ("mak,ank->mn", vec![40, 8, 32], vec![8, 24, 32]),
        ] {
            let (model, _) = product(expr, &x, &w);
            assert_eq!(merge_contracted_axes(model).unwrap().1, 0, "{expr}");
        }
    }

    #[test]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::NativeLinears, merge_contracted_axes);
    }
}
