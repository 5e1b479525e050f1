//! The pattern [`fuse_bilinear_samplers`] recognises: the export's ~30 element-wise nodes of
//! one bilinear sampler (corners, weights, bounds, flat indices) above a gathered
//! [`WeightedAxisSum`], matched node by node, and the patch that replaces them with one
//! [`BilinearCornerSum`].

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::change_axes::AxisOp;

use super::BilinearCornerSum;
use crate::ops::weighted_sum::WeightedAxisSum;

/// The node behind `o` when its op is named `name` (tract's op names: `Mul`, `Add`, `Floor`...).
fn node_named<'m>(model: &'m TypedModel, o: OutletId, name: &str) -> Option<&'m TypedNode> {
    let n = model.node(o.node);
    (o.slot == 0 && n.op().name() == name).then_some(n)
}

/// The two operands of a binary node named `name` behind `o`.
fn operands(model: &TypedModel, o: OutletId, name: &str) -> Option<[OutletId; 2]> {
    node_named(model, o, name)
        .filter(|n| n.inputs.len() == 2)
        .map(|n| [n.inputs[0], n.inputs[1]])
}

/// The value of a constant holding one f32 (any rank).
fn scalar(model: &TypedModel, o: OutletId) -> Option<f32> {
    let k = model.outlet_fact(o).ok()?.konst.clone()?;
    if k.len() != 1 || k.datum_type() != f32::datum_type() {
        return None;
    }
    k.try_as_plain_ram()
        .ok()?
        .as_slice::<f32>()
        .ok()?
        .first()
        .copied()
}

/// The variable operand of a binary `name` whose other operand is the scalar `c` (either side
/// when `commutes`, else on the right).
fn with_scalar(
    model: &TypedModel,
    o: OutletId,
    name: &str,
    c: Option<f32>,
    commutes: bool,
) -> Option<(OutletId, f32)> {
    let [a, b] = operands(model, o, name)?;
    let fits = |k: Option<f32>| k.filter(|&k| c.is_none_or(|c| c.to_bits() == k.to_bits()));
    if let Some(k) = fits(scalar(model, b)) {
        return Some((a, k));
    }
    if commutes && let Some(k) = fits(scalar(model, a)) {
        return Some((b, k));
    }
    None
}

/// The four inputs of a `Concat` over `axis` behind `o`.
fn concat4(model: &TypedModel, o: OutletId, axis: usize) -> Option<[OutletId; 4]> {
    let n = node_named(model, o, "Concat")?;
    let c = n.op_as::<tract_nnef::tract_core::ops::array::TypedConcat>()?;
    (c.axis == axis && n.inputs.len() == 4)
        .then(|| [n.inputs[0], n.inputs[1], n.inputs[2], n.inputs[3]])
}

/// `gx` as `1 - fx`, `fx` as `x - Floor(x)`: the axis, from `gx`.
fn axis_from_g(model: &TypedModel, gx: OutletId) -> Option<(OutletId, OutletId, OutletId)> {
    let [one, fx] = operands(model, gx, "Sub")?;
    (scalar(model, one)? == 1.0).then_some(())?;
    let [x, x0] = operands(model, fx, "Sub")?;
    let floor = node_named(model, x0, "Floor")?;
    (floor.inputs[0] == x).then_some((x, x0, fx))
}

/// `Concat(a, b, a, b)` (x) or `Concat(a, a, b, b)` (y) behind `o`, with `b = a + 1`: `a`.
fn corners_of(model: &TypedModel, o: OutletId, is_x: bool) -> Option<OutletId> {
    let c = concat4(model, o, 2)?;
    let (a, b) = (c[0], if is_x { c[1] } else { c[2] });
    let want = if is_x { [a, b, a, b] } else { [a, a, b, b] };
    let (base, _) = with_scalar(model, b, "Add", Some(1.0), true)?;
    (c == want && base == a).then_some(a)
}

/// `Min(Max(v, 0), hi)`: the clamped `v` and `hi`.
fn clamp_of(model: &TypedModel, o: OutletId) -> Option<(OutletId, f32)> {
    let (inner, hi) = with_scalar(model, o, "Min", None, true)?;
    let (v, _) = with_scalar(model, inner, "Max", Some(0.0), true)?;
    Some((v, hi))
}

/// The leaves of a tree of `And` nodes.
fn and_leaves(model: &TypedModel, o: OutletId, out: &mut Vec<OutletId>) {
    match operands(model, o, "And") {
        Some([a, b]) => {
            and_leaves(model, a, out);
            and_leaves(model, b, out);
        }
        None => out.push(o),
    }
}

/// A sampler to rewrite: the corner sum node and the fused op's inputs.
struct Sampler {
    sum: usize,
    op: BilinearCornerSum,
    inputs: [OutletId; 4],
}

/// The sampler subgraph above the gathered corner sum `id`, when it is exactly the export's.
fn match_sampler(model: &TypedModel, id: usize) -> TractResult<Option<Sampler>> {
    let node = model.node(id);
    let Some(was) = node.op_as::<WeightedAxisSum>() else {
        return Ok(None);
    };
    if was.gathered.is_none() || was.axis != 2 || node.inputs.len() != 3 {
        return Ok(None);
    }
    let [data, idx, w4] = [node.inputs[0], node.inputs[1], node.inputs[2]];
    if model.outlet_fact(idx)?.datum_type != f32::datum_type() {
        return Ok(None);
    }
    Ok(
        match_parts(model, data, idx, w4).map(|(op, inputs)| Sampler {
            sum: id,
            op,
            inputs,
        }),
    )
}

fn match_parts(
    model: &TypedModel,
    data: OutletId,
    idx: OutletId,
    w4: OutletId,
) -> Option<(BilinearCornerSum, [OutletId; 4])> {
    // Weights: AddAxis(Mul(Mul(Concat(corner weights), Tile(attn)), Cast(And(bounds)))).
    let add_axis = model.node(w4.node);
    if !matches!(add_axis.op_as::<AxisOp>(), Some(AxisOp::Add(3))) {
        return None;
    }
    let [a, b] = operands(model, add_axis.inputs[0], "Mul")?;
    let (wa, cast) = if node_named(model, b, "Cast").is_some() {
        (a, b)
    } else {
        (b, a)
    };
    let mask = node_named(model, cast, "Cast")?.inputs[0];
    let [a, b] = operands(model, wa, "Mul")?;
    let (wc, tile) = if node_named(model, b, "Tile").is_some() {
        (a, b)
    } else {
        (b, a)
    };
    let tile_node = node_named(model, tile, "Tile")?;
    let tile_op = tile_node.op_as::<tract_nnef::tract_core::ops::array::Tile>()?;
    if tile_op.multipliers.as_slice() != [1.to_dim(), 1.to_dim(), 4.to_dim()] {
        return None;
    }
    let attn = tile_node.inputs[0];
    let m = concat4(model, wc, 2)?;
    // m = [gx*gy, fx*gy, gx*fy, fx*fy]; products commute bit for bit, so either operand order.
    let pair = |o: OutletId| operands(model, o, "Mul");
    let (m0, m1, m2, m3) = (pair(m[0])?, pair(m[1])?, pair(m[2])?, pair(m[3])?);
    let (gx, gy) = if axis_from_g(model, m0[0]).is_some_and(|(_, _, f)| m3.contains(&f)) {
        (m0[0], m0[1])
    } else {
        (m0[1], m0[0])
    };
    let (x, x0, fx) = axis_from_g(model, gx)?;
    let (y, y0, fy) = axis_from_g(model, gy)?;
    let same = |p: [OutletId; 2], u: OutletId, v: OutletId| p == [u, v] || p == [v, u];
    if !(same(m1, fx, gy) && same(m2, gx, fy) && same(m3, fx, fy)) {
        return None;
    }
    // Indices: ((Clamp(ys) * W + Clamp(xs)) + head * H * W).
    let [s, hoff] = operands(model, idx, "Add")?;
    let (s, hoff) = if model.outlet_fact(hoff).ok()?.konst.is_some() {
        (s, hoff)
    } else {
        (hoff, s)
    };
    let [p, q] = operands(model, s, "Add")?;
    let (row_part, xi) = if node_named(model, p, "Mul").is_some() {
        (p, q)
    } else {
        (q, p)
    };
    let (yi, wf) = with_scalar(model, row_part, "Mul", None, true)?;
    let (xs, w_max) = clamp_of(model, xi)?;
    let (ys, h_max) = clamp_of(model, yi)?;
    if wf != w_max + 1.0 || w_max < 0.0 || h_max < 0.0 {
        return None;
    }
    let (w, h) = (wf as usize, h_max as usize + 1);
    if corners_of(model, xs, true)? != x0 || corners_of(model, ys, false)? != y0 {
        return None;
    }
    // Bounds: the And of xs >= 0, xs <= W - 1, ys >= 0, ys <= H - 1, in any order.
    let mut leaves = Vec::new();
    and_leaves(model, mask, &mut leaves);
    let mut want = vec![
        ("GTE", xs, 0.0),
        ("LTE", xs, w_max),
        ("GTE", ys, 0.0),
        ("LTE", ys, h_max),
    ];
    if leaves.len() != 4 {
        return None;
    }
    for leaf in leaves {
        let n = model.node(leaf.node);
        let name = n.op().name();
        let [v, k] = operands(model, leaf, &name)?;
        let k = scalar(model, k)?;
        let pos = want
            .iter()
            .position(|&(nm, o, c)| nm == name && o == v && c.to_bits() == k.to_bits())?;
        want.swap_remove(pos);
    }
    // Head offsets: [1, heads, 1] holding head * H * W.
    let k = model.outlet_fact(hoff).ok()?.konst.clone()?;
    let heads = model
        .outlet_fact(x)
        .ok()?
        .shape
        .as_concrete()?
        .get(1)
        .copied()?;
    let plain = k.try_as_plain_ram().ok()?;
    let offs = plain.as_slice::<f32>().ok()?;
    let plane = (h * w) as f32;
    if k.shape() != [1, heads, 1] || offs.iter().enumerate().any(|(i, &o)| o != i as f32 * plane) {
        return None;
    }
    let shape = model.outlet_fact(x).ok()?.shape.clone();
    let shapes_ok = [x, y, attn].iter().all(|&o| {
        model
            .outlet_fact(o)
            .is_ok_and(|f| f.datum_type == f32::datum_type() && f.shape == shape)
    });
    shapes_ok.then_some((BilinearCornerSum { h, w }, [data, x, y, attn]))
}

/// Rewrite every gathered corner sum whose weights and indices come from the export's bilinear
/// sampler into [`BilinearCornerSum`]; returns the model and the number rewritten.
///
/// # Errors
/// tract refusing the patch (an inconsistent model).
pub fn fuse_bilinear_samplers(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut found = Vec::new();
    for id in model.eval_order()? {
        if let Some(s) = match_sampler(&model, id)? {
            found.push(s);
        }
    }
    let fused = found.len();
    for s in found {
        let name = model.node(s.sum).name.clone();
        let mut patch = TypedModelPatch::default();
        let taps = patch.taps(&model, &s.inputs)?;
        let out = patch.wire_node(format!("{name}.bilinear"), s.op, &taps)?;
        patch.shunt_outside(&model, s.sum.into(), out[0])?;
        patch.apply(&mut model)?;
    }
    Ok((model.into_compact()?, fused))
}
