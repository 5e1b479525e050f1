//! The native f32 `Add`, `Sub` and `Mul` over broadcast operands.
//!
//! tract's optimiser turns most binary ops into its vector kernels (by a scalar, row by row,
//! fused into a matmul's epilogue), but an operand broadcast along inner axes, such as
//! `bev_query`'s `[3200, 8, 2, 4, 2] + [3200, 1, 1, 1, 2]` or the image normalisation's
//! `[1, 3, H, W] - [1, 3, 1, 1]`, stays on its generic path: an ndarray zip at ~20 ns a value
//! (9 ms for that one `Add` on an AVX2 EPYC). After optimisation, [`fuse_broadcast_binaries`]
//! rewrites what is left of those three ops into [`BroadcastBinary`], which walks the output
//! by runs of trailing axes merged where both operands allow, each operand read contiguously or
//! as one value; a short run whose operand repeats along the next axis out (the `[N, 8] + [1, 8]`
//! of a bias, the `[H, W, 3] - [1, 1, 3]` of a normalisation) is first laid out as many rows in
//! a scratch, so the loop runs over long rows instead of short ones.
//!
//! Bit for bit: each output value is the one IEEE operation on the same two values, whatever
//! the walk (`Div` is left to tract, whose kernels may multiply by a reciprocal).

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::binary::TypedBinOp;

/// The operation of a [`BroadcastBinary`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BinaryKind {
    /// `a + b`.
    Add,
    /// `a - b`.
    Sub,
    /// `a * b`.
    Mul,
}

impl BinaryKind {
    /// The kind of tract's binary op named `name`, if it is one of the three.
    fn of(name: &str) -> Option<Self> {
        match name {
            "Add" => Some(Self::Add),
            "Sub" => Some(Self::Sub),
            "Mul" => Some(Self::Mul),
            _ => None,
        }
    }
}

/// `a (op) b` over f32 operands of one rank that broadcast to the output shape.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BroadcastBinary {
    /// The operation.
    pub kind: BinaryKind,
}

impl Op for BroadcastBinary {
    fn name(&self) -> StaticName {
        "BroadcastBinary".into()
    }
    op_as_typed_op!();
}

impl EvalOp for BroadcastBinary {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let (a, b) = args_2!(inputs);
        Ok(tvec!(self.apply(&a, &b)?.into_tvalue()))
    }
}

impl BroadcastBinary {
    fn apply(&self, a: &Tensor, b: &Tensor) -> TractResult<Tensor> {
        // One walk per operation, so that each inner loop is a single instruction's.
        match self.kind {
            BinaryKind::Add => walk(a, b, |p, q| p + q),
            BinaryKind::Sub => walk(a, b, |p, q| p - q),
            BinaryKind::Mul => walk(a, b, |p, q| p * q),
        }
    }
}

/// `op` over `a` and `b` broadcast to their common shape.
fn walk(a: &Tensor, b: &Tensor, op: impl Fn(f32, f32) -> f32) -> TractResult<Tensor> {
    ensure!(
        a.rank() == b.rank(),
        "BroadcastBinary over ranks {} and {}",
        a.rank(),
        b.rank()
    );
    let shape = tract_nnef::tract_core::broadcast::multi_broadcast(&[a.shape(), b.shape()])
        .context("operands that do not broadcast")?;
    let groups = merged_axes(&shape, &steps(a.shape(), &shape), &steps(b.shape(), &shape));
    let mut out = Tensor::zero::<f32>(&shape)?;
    let (pa, pb) = (a.try_as_plain_ram()?, b.try_as_plain_ram()?);
    let (xa, xb) = (pa.as_slice::<f32>()?, pb.as_slice::<f32>()?);
    let mut po = out.try_as_plain_ram_mut()?;
    let y = po.as_slice_mut::<f32>()?;
    if y.is_empty() {
        return Ok(out);
    }
    let Some((&inner, outer)) = groups.split_last() else {
        // Every axis of length 1: one value.
        y[0] = op(xa[0], xb[0]);
        return Ok(out);
    };
    // A short inner run with, just outside it, an axis along which one operand repeats: the
    // repeated run is laid out once in a scratch of many rows, so the loop runs long.
    let tiled = match outer.last() {
        Some(&next) if inner.len < TILE_BELOW => Tile::of(inner, next),
        _ => None,
    };
    let (outer, block) = match tiled {
        Some(t) => (&outer[..outer.len() - 1], inner.len * t.rows),
        None => (outer, inner.len),
    };
    let dims: Vec<usize> = outer.iter().map(|g| g.len).collect();
    let step_a: Vec<usize> = outer.iter().map(|g| g.step[0]).collect();
    let step_b: Vec<usize> = outer.iter().map(|g| g.step[1]).collect();
    let mut idx = vec![0usize; outer.len()];
    let mut at = [0usize; 2];
    // A tiled block is walked in chunks of whole rows, the repeated run laid out for one chunk.
    let chunk = tiled.map_or(0, |t| {
        (TILE_VALUES / inner.len).clamp(1, t.rows) * inner.len
    });
    let mut scratch: Vec<f32> = Vec::new();
    let mut scratch_of = None;
    for out_block in y.chunks_exact_mut(block) {
        let [ia, ib] = at;
        match tiled {
            None => run(out_block, inner, &xa[ia..], &xb[ib..], &op),
            Some(t) => {
                let (runs_on, repeated, at_rep) = if t.repeats_b {
                    (&xa[ia..], &xb[ib..], ib)
                } else {
                    (&xb[ib..], &xa[ia..], ia)
                };
                if scratch_of != Some(at_rep) {
                    repeat_into(&mut scratch, &repeated[..inner.len], chunk);
                    scratch_of = Some(at_rep);
                }
                run_tiled(out_block, runs_on, &scratch, chunk, t.repeats_b, &op);
            }
        }
        advance(&mut idx, &dims, [&step_a, &step_b], &mut at);
    }
    Ok(out)
}

/// `scratch` as `n` values of `row` repeated: the run once, then doubled, so a few copies
/// however short the run.
fn repeat_into(scratch: &mut Vec<f32>, row: &[f32], n: usize) {
    scratch.resize(n, 0.0);
    scratch[..row.len()].copy_from_slice(row);
    let mut filled = row.len();
    while filled < n {
        let more = filled.min(n - filled);
        scratch.copy_within(..more, filled);
        filled += more;
    }
}

/// One tiled block: `y` against the contiguous operand `runs_on` and the repeated one laid out
/// in `scratch`, chunk by chunk; `repeats_b` says which side of `op` the repeated one is.
fn run_tiled(
    y: &mut [f32],
    runs_on: &[f32],
    scratch: &[f32],
    chunk: usize,
    repeats_b: bool,
    op: &impl Fn(f32, f32) -> f32,
) {
    for (out, from) in y.chunks_mut(chunk).zip(runs_on.chunks(chunk)) {
        let rep = &scratch[..out.len()];
        if repeats_b {
            for ((o, &p), &q) in out.iter_mut().zip(from).zip(rep) {
                *o = op(p, q);
            }
        } else {
            for ((o, &q), &p) in out.iter_mut().zip(from).zip(rep) {
                *o = op(p, q);
            }
        }
    }
}

/// One inner run of `inner.len` outputs, each operand read contiguously from its slice's start
/// or as its first value.
fn run(y: &mut [f32], inner: Axis, xa: &[f32], xb: &[f32], op: &impl Fn(f32, f32) -> f32) {
    let n = y.len();
    match inner.step {
        [1, 1] => {
            for ((o, &p), &q) in y.iter_mut().zip(&xa[..n]).zip(&xb[..n]) {
                *o = op(p, q);
            }
        }
        [1, 0] => {
            let q = xb[0];
            for (o, &p) in y.iter_mut().zip(&xa[..n]) {
                *o = op(p, q);
            }
        }
        [0, 1] => {
            let p = xa[0];
            for (o, &q) in y.iter_mut().zip(&xb[..n]) {
                *o = op(p, q);
            }
        }
        [sa, sb] => {
            // Not reached by `merged_axes` (an inner group steps by 0 or 1); kept total.
            for (j, o) in y.iter_mut().enumerate() {
                *o = op(xa[j * sa], xb[j * sb]);
            }
        }
    }
}

/// One output axis, or several adjacent ones walked as one: its length and each operand's
/// step along it (0 where the operand is broadcast).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Axis {
    len: usize,
    step: [usize; 2],
}

/// The output axes, outermost first, without those of length 1 and with adjacent axes merged
/// where each operand steps over both as over one (broadcast along both, or contiguous across
/// them): the innermost group then steps each operand by 0 or 1.
fn merged_axes(shape: &[usize], sa: &[usize], sb: &[usize]) -> Vec<Axis> {
    let mut groups: Vec<Axis> = Vec::with_capacity(shape.len());
    for ax in (0..shape.len()).rev() {
        if shape[ax] == 1 {
            continue;
        }
        let axis = Axis {
            len: shape[ax],
            step: [sa[ax], sb[ax]],
        };
        match groups.last_mut() {
            Some(inner)
                if (0..2).all(|k| {
                    (axis.step[k] == 0 && inner.step[k] == 0)
                        || (axis.step[k] != 0 && axis.step[k] == inner.step[k] * inner.len)
                }) =>
            {
                inner.len *= axis.len;
            }
            _ => groups.push(axis),
        }
    }
    groups.reverse();
    groups
}

/// An inner run of both operands contiguous and, outside it, `rows` repeats of one operand's
/// run along which the other goes on contiguously.
#[derive(Clone, Copy, Debug)]
struct Tile {
    rows: usize,
    /// `b` repeats (else `a`).
    repeats_b: bool,
}

impl Tile {
    fn of(inner: Axis, next: Axis) -> Option<Self> {
        if inner.step != [1, 1] {
            return None;
        }
        match next.step {
            [s, 0] if s == inner.len => Some(Self {
                rows: next.len,
                repeats_b: true,
            }),
            [0, s] if s == inner.len => Some(Self {
                rows: next.len,
                repeats_b: false,
            }),
            _ => None,
        }
    }
}

/// One step of an odometer over `dims` (last axis fastest): `idx` moves to the next index and
/// each `offsets[k]` by what `steps[k]` says that move costs.
fn advance<const K: usize>(
    idx: &mut [usize],
    dims: &[usize],
    steps: [&[usize]; K],
    offsets: &mut [usize; K],
) {
    for ax in (0..idx.len()).rev() {
        idx[ax] += 1;
        for (off, st) in offsets.iter_mut().zip(steps) {
            *off += st[ax];
        }
        if idx[ax] < dims[ax] {
            return;
        }
        for (off, st) in offsets.iter_mut().zip(steps) {
            *off -= st[ax] * dims[ax];
        }
        idx[ax] = 0;
    }
}

/// Inner runs shorter than this many values are tiled ([`Tile`]) where the axes allow.
const TILE_BELOW: usize = 64;
/// Values of one tiled chunk (the repeated operand's scratch): it stays in L1.
const TILE_VALUES: usize = 1024;

/// An operand's step per output axis: its natural stride, or 0 along an axis it broadcasts.
fn steps(shape: &[usize], out: &[usize]) -> Vec<usize> {
    let mut s = vec![0usize; shape.len()];
    let mut stride = 1;
    for ax in (0..shape.len()).rev() {
        s[ax] = if shape[ax] == 1 && out[ax] != 1 {
            0
        } else {
            stride
        };
        stride *= shape[ax];
    }
    s
}

impl TypedOp for BroadcastBinary {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 2);
        ensure!(inputs.iter().all(|f| f.datum_type == f32::datum_type()));
        let shape = tract_nnef::tract_core::broadcast::multi_broadcast(&[
            inputs[0].shape.to_tvec(),
            inputs[1].shape.to_tvec(),
        ])
        .context("operands that do not broadcast")?;
        Ok(tvec!(f32::fact(shape)))
    }

    as_op!();
}

/// Rewrite every f32 `Add`, `Sub` and `Mul` left on tract's generic path of an optimised
/// `model`, whose operands have one rank and concrete shapes, into [`BroadcastBinary`]; returns
/// the model and the number rewritten.
///
/// # Errors
/// tract refusing the patch (an inconsistent model).
pub fn fuse_broadcast_binaries(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut fused = 0;
    for id in model.eval_order()? {
        let node = model.node(id);
        let Some(bin) = node.op_as::<TypedBinOp>() else {
            continue;
        };
        let Some(kind) = BinaryKind::of(bin.0.name()) else {
            continue;
        };
        let plain = |f: &TypedFact| {
            f.datum_type == f32::datum_type() && f.shape.as_concrete().is_some() && !f.is_exotic()
        };
        let eligible = {
            let facts = model.node_input_facts(id)?;
            bin.1.is_none()
                && facts.len() == 2
                && facts.iter().all(|f| plain(f))
                && plain(model.outlet_fact(OutletId::new(id, 0))?)
                && facts[0].rank() == facts[1].rank()
        };
        if !eligible {
            continue;
        }
        let patch = TypedModelPatch::replace_single_op(
            &model,
            node,
            &node.inputs,
            BroadcastBinary { kind },
        )?;
        patch.apply(&mut model)?;
        fused += 1;
    }
    Ok((model, fused))
}

#[cfg(test)]
mod tests {
    //! The op against tract's own binary ops, and the rewrite against the plan as optimised on
    //! every stage of the committed default bundle, both bit for bit.

    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        assert_same_bits, bits, committed_rewrites, committed_stage_before, inputs_of, run_plain,
    };
    use satmap_core::engine::Stage;
    use tract_nnef::tract_core::ops::math;

    fn tensor(shape: &[usize], seed: u32) -> Tensor {
        let n: usize = shape.iter().product();
        let v: Vec<f32> = (0..n as u32)
            .map(|i| {
                let h = (i.wrapping_mul(2_654_435_761) ^ seed).wrapping_mul(2_246_822_519);
                (h >> 8) as f32 / (1u32 << 24) as f32 * 6.0 - 3.0
            })
            .collect();
        Tensor::from_shape(shape, &v).expect("tensor")
    }

    #[test]
    fn values_are_tracts_bit_for_bit() {
        // The stages' shapes (scaled down) and the walk's corner cases: tiled runs with the
        // repeated operand on either side and fixed or moving along an outer axis, a tile of
        // rows that is not a multiple of its chunk, runs too long to tile, no axis at all.
        let cases: [(&[usize], &[usize]); 14] = [
            (&[30, 8, 2, 4, 2], &[30, 1, 1, 1, 2]),
            (&[30, 8, 2, 4, 2], &[1, 1, 1, 1, 2]),
            (&[1, 3, 9, 7], &[1, 3, 1, 1]),
            (&[1, 3, 1, 1], &[2, 3, 5, 4]),
            (&[4, 1, 6], &[1, 5, 1]),
            (&[5, 7], &[5, 7]),
            (&[1], &[9]),
            (&[1, 1], &[1, 1]),
            (&[1250, 8], &[1, 8]),
            (&[1, 8], &[1250, 8]),
            (&[180, 32, 3], &[1, 1, 3]),
            (&[7, 1, 3], &[7, 700, 3]),
            (&[8, 49, 49], &[1, 49, 49]),
            (&[5, 1], &[1, 7]),
        ];
        for (sa, sb) in cases {
            let (a, b) = (tensor(sa, 1), tensor(sb, 2));
            for (kind, theirs) in [
                (BinaryKind::Add, math::add()),
                (BinaryKind::Sub, math::sub()),
                (BinaryKind::Mul, math::mul()),
            ] {
                let want = theirs
                    .eval_out_of_plan(tvec!(a.clone().into_tvalue(), b.clone().into_tvalue()))
                    .expect("tract")
                    .expect("out of plan");
                let got = BroadcastBinary { kind }.apply(&a, &b).expect("ours");
                assert_eq!(got.shape(), want[0].shape(), "{kind:?} {sa:?} {sb:?}");
                assert_eq!(bits(&got), bits(&want[0]), "{kind:?} {sa:?} {sb:?}");
            }
        }
        // Operands that do not broadcast are an error value.
        let err = BroadcastBinary {
            kind: BinaryKind::Add,
        }
        .apply(&tensor(&[2, 3], 1), &tensor(&[3, 3], 2));
        assert!(err.is_err());
    }

    #[test]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::BroadcastBinaries);
            let inputs = inputs_of(&plain);
            let (fused, n) = fuse_broadcast_binaries(plain.clone()).expect("rewrite");
            assert_eq!(n, committed_rewrites(stage).broadcast_binaries, "{stage}");
            let (_, left) = fuse_broadcast_binaries(fused.clone()).expect("again");
            assert_eq!(left, 0, "{stage}: a binary op was left on the generic path");
            let (a, b) = (run_plain(plain, &inputs), run_plain(fused, &inputs));
            assert_same_bits(stage, &a, &b);
        }
    }
}
