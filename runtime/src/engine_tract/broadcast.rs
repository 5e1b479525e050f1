//! The native f32 `Add`, `Sub` and `Mul` over broadcast operands.
//!
//! tract's optimiser turns most binary ops into its vector kernels (by a scalar, row by row,
//! fused into a matmul's epilogue), but an operand broadcast along inner axes, such as
//! `bev_query`'s `[3200, 8, 2, 4, 2] + [3200, 1, 1, 1, 2]` or the image normalisation's
//! `[1, 3, H, W] - [1, 3, 1, 1]`, stays on its generic path: an ndarray zip at ~20 ns a value
//! (9 ms for that one `Add` on an AVX2 EPYC). After optimisation, [`fuse_broadcast_binaries`]
//! rewrites what is left of those three ops into [`BroadcastBinary`], which walks the output
//! by blocks of trailing axes, each operand read contiguously, as one value, or through a table
//! of its offsets within the block.
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
    let sa = steps(a.shape(), &shape);
    let sb = steps(b.shape(), &shape);
    let mut out = Tensor::zero::<f32>(&shape)?;
    let (pa, pb) = (a.try_as_plain_ram()?, b.try_as_plain_ram()?);
    let (xa, xb) = (pa.as_slice::<f32>()?, pb.as_slice::<f32>()?);
    let mut po = out.try_as_plain_ram_mut()?;
    let y = po.as_slice_mut::<f32>()?;
    if y.is_empty() {
        return Ok(out);
    }
    // The block: the trailing axes, until it holds BLOCK_VALUES values (at least the last
    // axis, at most BLOCK_MAX values beyond it). Each operand's offsets within it are
    // tabled once; the outer axes are walked by an odometer, once per block.
    let rank = shape.len();
    let mut inner = rank;
    let mut block = 1usize;
    while inner > 0
        && (inner == rank || (block < BLOCK_VALUES && block * shape[inner - 1] <= BLOCK_MAX))
    {
        inner -= 1;
        block *= shape[inner];
    }
    let table = |steps: &[usize]| -> Vec<usize> {
        let mut t = Vec::with_capacity(block);
        let mut idx = vec![0usize; rank - inner];
        let mut off = [0usize];
        for _ in 0..block {
            t.push(off[0]);
            advance(&mut idx, &shape[inner..], [&steps[inner..]], &mut off);
        }
        t
    };
    let (oa, ob) = (table(&sa), table(&sb));
    let (ta, tb) = (Operand::of(&oa), Operand::of(&ob));
    let mut idx = vec![0usize; inner];
    let mut at = [0usize; 2];
    for out_block in y.chunks_exact_mut(block) {
        let [ia, ib] = at;
        match (&ta, &tb) {
            (Operand::Contiguous, Operand::Contiguous) => {
                let (ar, br) = (&xa[ia..][..block], &xb[ib..][..block]);
                for ((o, &p), &q) in out_block.iter_mut().zip(ar).zip(br) {
                    *o = op(p, q);
                }
            }
            (Operand::Contiguous, Operand::Scalar) => {
                let q = xb[ib];
                for (o, &p) in out_block.iter_mut().zip(&xa[ia..][..block]) {
                    *o = op(p, q);
                }
            }
            (Operand::Scalar, Operand::Contiguous) => {
                let p = xa[ia];
                for (o, &q) in out_block.iter_mut().zip(&xb[ib..][..block]) {
                    *o = op(p, q);
                }
            }
            _ => {
                let (ar, br) = (&xa[ia..], &xb[ib..]);
                for ((o, &ja), &jb) in out_block.iter_mut().zip(&oa).zip(&ob) {
                    *o = op(ar[ja], br[jb]);
                }
            }
        }
        advance(
            &mut idx,
            &shape[..inner],
            [&sa[..inner], &sb[..inner]],
            &mut at,
        );
    }
    Ok(out)
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

/// Values of an output block (trailing axes) at least this many, where the axes allow.
const BLOCK_VALUES: usize = 256;
/// ... and at most this many (beyond the last axis alone): its offset tables stay in L1/L2.
const BLOCK_MAX: usize = 16384;

/// How an operand's values lie within one output block.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Operand {
    /// At offsets `0, 1, 2, ...`.
    Contiguous,
    /// One value for the whole block.
    Scalar,
    /// At the offsets of its table.
    Table,
}

impl Operand {
    fn of(table: &[usize]) -> Self {
        if table.iter().enumerate().all(|(j, &o)| o == j) {
            Self::Contiguous
        } else if table.iter().all(|&o| o == 0) {
            Self::Scalar
        } else {
            Self::Table
        }
    }
}

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
    use crate::engine::Stage;
    use crate::engine_tract::rewrite::Pass;
    use crate::engine_tract::test_support::{
        assert_same_bits, bits, committed_rewrites, committed_stage_before, inputs_of, run_plain,
    };
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
        let cases: [(&[usize], &[usize]); 6] = [
            (&[30, 8, 2, 4, 2], &[30, 1, 1, 1, 2]),
            (&[1, 3, 9, 7], &[1, 3, 1, 1]),
            (&[1, 3, 1, 1], &[2, 3, 5, 4]),
            (&[4, 1, 6], &[1, 5, 1]),
            (&[5, 7], &[5, 7]),
            (&[1], &[9]),
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
