//! The whole bilinear deformable sampler as one native kernel: corners, weights, bounds, flat
//! indices and the weighted corner sum, from the sampling coordinates.
//!
//! `satmap_ref.sampling.bilinear_gather_sum` exports as ~30 element-wise nodes over
//! `[N, heads, 4 x points]` (four-way concats of the corners, clamps, comparisons, a tile of the
//! attention weights, casts) that end in the corner sum [`super::weighted_sum`] already runs
//! natively. tract runs each of them as a separate pass over a fresh tensor: 30 of `test`'s 40
//! ms `bev_query` after the row softmax. At load, [`fuse_bilinear_samplers`] recognises that
//! subgraph above every gathered [`WeightedAxisSum`] and replaces it with [`BilinearCornerSum`],
//! which reads `x`, `y` (pixel coordinates, `loc * size - 0.5`) and the attention weights once
//! per point and keeps every corner in registers.
//!
//! The kernel performs, per query, head and corner-major sample `k = corner * points + point`,
//! the same f32 operations in the same order as the graph it replaces, so its outputs are bit
//! for bit those of the unfused graph (a test asserts it on the committed bundle):
//! `x0 = floor(x)`, `x1 = x0 + 1`, `fx = x - x0`, `gx = 1 - fx` (and the same in y); corner
//! weights `gx * gy, fx * gy, gx * fy, fx * fy`; `w = (corner_weight * attn) * inside` with
//! `inside` 1.0 when `0 <= xs <= W - 1` and `0 <= ys <= H - 1`, else 0.0; the row
//! `((clamp(ys) * W + clamp(xs)) + head * H * W) as i64`; then the corner sum's
//! `acc = acc + row[d] * w`, `k` ascending. Queries are independent, so on the engine's pool
//! of N threads they are split between threads by fixed blocks: the same bits on any N (the
//! engine's thread test asserts the digests on 1 and 2).

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::change_axes::AxisOp;

use rayon::prelude::*;
use tract_linalg::multithread::{Executor, current_tract_executor};

use super::weighted_sum::WeightedAxisSum;

/// Queries one task of [`BilinearCornerSum`] samples: `bev_query`'s 3,200 make 50 tasks, a
/// decoder layer's fewer; enough to keep two to a few threads busy, few enough that a task's
/// setup (one points buffer) does not count.
const QUERIES_PER_TASK: usize = 64;

/// `out[n, h, 0, :] = sum over k of data[row(n, h, k), :] * w(n, h, k)`, all of the module doc's
/// sampling math done in place; inputs `(data [heads * H * W, dh], x, y, attn [N, heads, P])`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BilinearCornerSum {
    /// Height of the sampled map, in rows.
    pub h: usize,
    /// Width of the sampled map, in columns.
    pub w: usize,
}

impl Op for BilinearCornerSum {
    fn name(&self) -> StaticName {
        "BilinearCornerSum".into()
    }
    op_as_typed_op!();
}

impl EvalOp for BilinearCornerSum {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        ensure!(inputs.len() == 4, "BilinearCornerSum takes four inputs");
        let shape = inputs[1].shape();
        ensure!(
            shape.len() == 3,
            "sampling coordinates are [N, heads, points]"
        );
        ensure!(
            inputs[2].shape() == shape && inputs[3].shape() == shape,
            "x, y and the attention weights differ in shape"
        );
        let (n, heads, points) = (shape[0], shape[1], shape[2]);
        let data_plain = inputs[0].try_as_plain_ram()?;
        let data = data_plain.as_slice::<f32>()?;
        ensure!(inputs[0].rank() == 2, "the sampled map is [rows, dh]");
        let (rows, dh) = (inputs[0].shape()[0], inputs[0].shape()[1]);
        ensure!(
            rows == heads * self.h * self.w,
            "the map has {rows} rows, not heads x H x W"
        );
        let xp = inputs[1].try_as_plain_ram()?;
        let yp = inputs[2].try_as_plain_ram()?;
        let ap = inputs[3].try_as_plain_ram()?;
        let (xs, ys, attn) = (
            xp.as_slice::<f32>()?,
            yp.as_slice::<f32>()?,
            ap.as_slice::<f32>()?,
        );
        let wf = self.w as f32;
        let (w_max, h_max) = ((self.w - 1) as f32, (self.h - 1) as f32);
        let plane = (self.h * self.w) as f32;
        let mut out = vec![0.0f32; n * heads * dh];
        let query_len = heads * dh;
        // One task: QUERIES_PER_TASK queries, each written by its own arithmetic alone, so the
        // split (and the thread count) cannot change a bit.
        let task = |(t, chunk): (usize, &mut [f32])| -> TractResult<()> {
            // Per point: x0, x1, y0, y1, gx, fx, gy, fy, attn (reused by the four corners).
            let mut pts = vec![[0.0f32; 9]; points];
            for (i, acc_q) in chunk.chunks_exact_mut(query_len).enumerate() {
                let q = t * QUERIES_PER_TASK + i;
                for (head, acc) in acc_q.chunks_exact_mut(dh).enumerate() {
                    let base = (q * heads + head) * points;
                    let head_off = head as f32 * plane;
                    for (p, pt) in pts.iter_mut().enumerate() {
                        let (x, y) = (xs[base + p], ys[base + p]);
                        let (x0, y0) = (x.floor(), y.floor());
                        let (fx, fy) = (x - x0, y - y0);
                        *pt = [
                            x0,
                            x0 + 1.0,
                            y0,
                            y0 + 1.0,
                            1.0 - fx,
                            fx,
                            1.0 - fy,
                            fy,
                            attn[base + p],
                        ];
                    }
                    for corner in 0..4 {
                        // Corner order of the export: (x0, y0), (x1, y0), (x0, y1), (x1, y1).
                        let (cx, cy) = (corner & 1, corner >> 1);
                        for pt in &pts {
                            let (xc, yc) = (pt[cx], pt[2 + cy]);
                            let wx = if cx == 0 { pt[4] } else { pt[5] };
                            let wy = if cy == 0 { pt[6] } else { pt[7] };
                            let inside = xc >= 0.0 && xc <= w_max && yc >= 0.0 && yc <= h_max;
                            let wt = ((wx * wy) * pt[8]) * if inside { 1.0 } else { 0.0 };
                            let xi = xc.max(0.0).min(w_max);
                            let yi = yc.max(0.0).min(h_max);
                            let row = ((yi * wf + xi) + head_off) as i64;
                            ensure!(
                                (0..rows as i64).contains(&row),
                                "sample row {row} out of range (0..{rows})"
                            );
                            let r = &data[row as usize * dh..][..dh];
                            for (s, v) in acc.iter_mut().zip(r) {
                                *s += *v * wt;
                            }
                        }
                    }
                }
            }
            Ok(())
        };
        if query_len > 0 {
            let chunk_len = QUERIES_PER_TASK * query_len;
            match current_tract_executor() {
                Executor::MultiThread(pool) => pool.install(|| {
                    out.par_chunks_mut(chunk_len)
                        .enumerate()
                        .try_for_each(|(i, chunk)| {
                            super::vector_state::clear_upper();
                            task((i, chunk))
                        })
                })?,
                // The engine never runs on rayon's global pool (see `TractEngine::set_threads`).
                _ => out.chunks_mut(chunk_len).enumerate().try_for_each(task)?,
            }
        }
        Ok(tvec!(
            Tensor::from_shape(&[n, heads, 1, dh], &out)?.into_tvalue()
        ))
    }
}

impl TypedOp for BilinearCornerSum {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 4);
        ensure!(inputs.iter().all(|f| f.datum_type == f32::datum_type()));
        ensure!(inputs[0].rank() == 2 && inputs[1].rank() == 3);
        let s = &inputs[1].shape;
        Ok(tvec!(f32::fact([
            s[0].clone(),
            s[1].clone(),
            1.to_dim(),
            inputs[0].shape[1].clone()
        ])))
    }

    fn cost(&self, inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let n: TDim = inputs[1].shape.iter().product::<TDim>() * 4 * inputs[0].shape[1].clone();
        Ok(tvec!((Cost::FMA(f32::datum_type()), n)))
    }

    as_op!();
}

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

#[cfg(test)]
mod tests {
    //! The kernel against `satmap_ref.sampling.bilinear_corner_sum` (committed vectors), and the
    //! rewrite against the unfused graph of the committed default bundle, both bit for bit.

    use super::*;
    use crate::engine::Stage;
    use crate::engine_tract::rewrite::Pass;
    use crate::engine_tract::test_support::{
        assert_same_bits, bits, committed_rewrites, committed_stage_before, golden_tensor,
        inputs_of, kernel_golden, run_optimized,
    };

    #[test]
    fn the_kernel_is_the_python_reference_bit_for_bit() {
        let bytes = kernel_golden();
        let st = safetensors::SafeTensors::deserialize(&bytes).expect("safetensors");
        let inputs: TVec<TValue> = ["sampler_rows", "sampler_x", "sampler_y", "sampler_attn"]
            .iter()
            .map(|n| golden_tensor(&st, n).into_tvalue())
            .collect();
        let op = BilinearCornerSum { h: 5, w: 4 };
        let out = op
            .eval_out_of_plan(inputs.clone())
            .expect("eval")
            .expect("out of plan");
        let want = golden_tensor(&st, "sampler_out");
        assert_eq!(out[0].shape(), want.shape());
        assert_eq!(bits(&out[0]), bits(&want));
        // A map of the wrong size is an error value, not a panic or a wrong read.
        let err = BilinearCornerSum { h: 6, w: 4 }
            .eval_out_of_plan(inputs)
            .unwrap_err();
        assert!(format!("{err:#}").contains("rows"), "{err:#}");
    }

    #[test]
    fn fused_samplers_compute_the_unfused_graph_bit_for_bit() {
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::BilinearSamplers);
            let (fused, n) = fuse_bilinear_samplers(plain.clone()).expect("fuse");
            assert_eq!(n, committed_rewrites(stage).bilinear_samplers, "{stage}");
            let left = fused
                .nodes()
                .iter()
                .filter(|n| n.op_is::<WeightedAxisSum>())
                .count();
            assert_eq!(
                left, 0,
                "{stage}: every corner sum is inside a fused sampler"
            );
            let inputs = inputs_of(&plain);
            let (a, b) = (run_optimized(plain, &inputs), run_optimized(fused, &inputs));
            assert_same_bits(stage, &a, &b);
        }
    }
}
