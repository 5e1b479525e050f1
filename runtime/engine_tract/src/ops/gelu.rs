//! The Swin MLPs' tanh GELU as one native op: one pass over the activations, split over the
//! engine's pool.
//!
//! The ONNX export spells `GELU(approximate="tanh")` as ten elementwise nodes: `y = half * (x *
//! (one + tanh(beta * (x + kappa * (x * x²)))))`. tract 0.23.9 runs them as six ops (`Square`,
//! three fused binary chains, `Tanh`, one more chain), each a pass over the tensor, the unary
//! ones on one thread: ~5 ms of `nano`'s 110 ms satellite encoder on one thread, where the one
//! pass here takes 2 ms (bound by memory: 2.5 M values read and written once).
//! [`fuse_tanh_gelus`] rewrites each such chain of a decluttered graph into a [`TanhGelu`],
//! which computes a block of values through the same steps: the same f32 operations in the
//! same order (each a single IEEE rounding, whose operands commute exactly), and tract-linalg's
//! own tanh kernel, the one tract's `Tanh` runs (elementwise, so a block gives each value the
//! bits the whole tensor does). Bit for bit, so no output and no pinned digest moves; blocks
//! never depend on the thread count. The constants are read from the graph, not assumed.

use tract_linalg::routines::Func;
use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::element_wise::ElementWiseOp;

use crate::graph::matching::{bin_inputs, const_operand, only_successor, replace_with_op};
use crate::pool;

/// Values a task computes at once: its tanh inputs stay in L1 between the three steps.
const BLOCK_VALUES: usize = 1024;

/// The tanh GELU's constants, as the graph holds them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeluConsts {
    /// The cube's factor (0.044715).
    pub kappa: f32,
    /// The tanh argument's factor (`sqrt(2 / pi)`).
    pub beta: f32,
    /// Added to the tanh (1).
    pub one: f32,
    /// The final factor (0.5).
    pub half: f32,
}

/// `half * (x * (one + tanh(beta * (x + kappa * (x * x²)))))` over an f32 tensor of any shape.
#[derive(Clone, Debug, PartialEq)]
pub struct TanhGelu {
    /// The constants of the rewritten chain.
    pub consts: GeluConsts,
}

// Constants compared by their bits: the op is hashed and compared when tract dedupes nodes.
impl Eq for TanhGelu {}
impl std::hash::Hash for TanhGelu {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        let c = self.consts;
        [c.kappa, c.beta, c.one, c.half]
            .map(f32::to_bits)
            .hash(state);
    }
}

impl TanhGelu {
    /// One block in place: the tanh argument into `arg`, tract's tanh over it, the product.
    fn block(&self, xs: &mut [f32], arg: &mut [f32], tanh: &ElementWiseF32) -> bool {
        let GeluConsts {
            kappa,
            beta,
            one,
            half,
        } = self.consts;
        let arg = &mut arg[..xs.len()];
        for (a, &x) in arg.iter_mut().zip(xs.iter()) {
            let cube = x * (x * x);
            *a = (x + cube * kappa) * beta;
        }
        if tanh.run(arg).is_err() {
            return false;
        }
        // tract's AVX-512 tanh leaves the vector registers dirty: the loop below (baseline SSE)
        // ran several times slower after it (`vector_state`).
        crate::vector_state::clear_upper();
        for (x, &t) in xs.iter_mut().zip(arg.iter()) {
            *x = (*x * (t + one)) * half;
        }
        true
    }
}

/// tract-linalg's f32 elementwise kernels.
type ElementWiseF32 = dyn tract_linalg::element_wise::ElementWise<f32>;

impl Op for TanhGelu {
    fn name(&self) -> StaticName {
        "TanhGelu".into()
    }
    op_as_typed_op!();
}

impl EvalOp for TanhGelu {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let x = args_1!(inputs);
        ensure!(
            x.datum_type() == f32::datum_type(),
            "TanhGelu of {:?}",
            x.datum_type()
        );
        // In place when the plan hands over its only reference (tract copies otherwise).
        let mut y = x.into_tensor();
        let tanh = Func::Tanh.ew_f32()?;
        let mut plain = y.try_as_plain_ram_mut()?;
        let values = plain.as_slice_mut::<f32>()?;
        let parallel = pool::worth_threads(values.len() * 16);
        let done = pool::on_threads(parallel, values, 4 * BLOCK_VALUES, |_, chunk| {
            let mut arg = [0.0f32; BLOCK_VALUES];
            chunk
                .chunks_mut(BLOCK_VALUES)
                .all(|block| self.block(block, &mut arg, &*tanh))
        });
        ensure!(done, "tanh kernel failed");
        Ok(tvec!(y.into_tvalue()))
    }
}

impl TypedOp for TanhGelu {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 1 && inputs[0].datum_type == f32::datum_type());
        Ok(tvec!(inputs[0].without_value()))
    }

    as_op!();
}

/// Whether node `id` is the elementwise op `name` (`Square`, `Tanh`).
fn is_unary(model: &TypedModel, id: usize, name: &str) -> bool {
    model
        .node(id)
        .op_as::<ElementWiseOp>()
        .is_some_and(|e| e.0.name() == name && e.1.is_none())
}

/// Binary node `id`'s operands as (the one that is `from`'s output, the other).
fn operands(model: &TypedModel, id: usize, from: usize) -> Option<(OutletId, OutletId)> {
    let inputs = &model.node(id).inputs;
    match (inputs[0].node == from, inputs[1].node == from) {
        (true, false) => Some((inputs[0], inputs[1])),
        (false, true) => Some((inputs[1], inputs[0])),
        _ => None,
    }
}

/// If node `id` is the binary op `name` of one activation and a one-value f32 constant: the
/// activation and the value.
fn scalar_operand(
    model: &TypedModel,
    id: usize,
    name: &str,
) -> TractResult<Option<(OutletId, f32)>> {
    let Some((other, k)) = const_operand(model, id, name)? else {
        return Ok(None);
    };
    if k.datum_type() != f32::datum_type() || k.len() != 1 {
        return Ok(None);
    }
    Ok(Some((other, k.try_as_plain_ram()?.as_slice::<f32>()?[0])))
}

/// The chain ending in `Tanh` node `tanh`, if it is a tanh GELU of one input wholly inside it:
/// the input, the chain's last node and its constants.
fn gelu_at(model: &TypedModel, tanh: usize) -> TractResult<Option<(OutletId, usize, GeluConsts)>> {
    // Backwards: tanh <- Mul(arg, beta) <- Add(x, k) <- Mul(cube, kappa) <- Mul(x, Square(x)).
    let arg = model.node(tanh).inputs[0].node;
    let Some((sum, beta)) = scalar_operand(model, arg, "Mul")? else {
        return Ok(None);
    };
    let sum = sum.node;
    let Some(ins) = bin_inputs(model, sum, "Add") else {
        return Ok(None);
    };
    // The sum's two operands: x itself and `kappa * cube`; try both ways round.
    for (x, k) in [(ins[0], ins[1]), (ins[1], ins[0])] {
        if let Some(found) = gelu_from(model, tanh, [arg, sum], x, k.node, beta)? {
            return Ok(Some(found));
        }
    }
    Ok(None)
}

/// [`gelu_at`] once `x` and the `kappa * cube` node `k` are chosen.
fn gelu_from(
    model: &TypedModel,
    tanh: usize,
    [arg, sum]: [usize; 2],
    x: OutletId,
    k: usize,
    beta: f32,
) -> TractResult<Option<(OutletId, usize, GeluConsts)>> {
    if x.slot != 0 {
        return Ok(None);
    }
    let Some((cube, kappa)) = scalar_operand(model, k, "Mul")? else {
        return Ok(None);
    };
    let cube = cube.node;
    if bin_inputs(model, cube, "Mul").is_none() {
        return Ok(None);
    }
    let Some((square, _)) = operands(model, cube, x.node)
        .map(|(_, other)| (other.node, other))
        .filter(|(s, _)| is_unary(model, *s, "Square") && model.node(*s).inputs[0] == x)
    else {
        return Ok(None);
    };
    // Forwards: tanh -> Add(t, one) -> Mul(x, p) -> Mul(q, half).
    let Some(plus) = only_successor(model, tanh)? else {
        return Ok(None);
    };
    let Some((t, one)) = scalar_operand(model, plus, "Add")? else {
        return Ok(None);
    };
    let Some(times_x) = only_successor(model, plus)? else {
        return Ok(None);
    };
    let x_times = bin_inputs(model, times_x, "Mul").is_some()
        && operands(model, times_x, plus).map(|o| o.1) == Some(x);
    let Some(last) = only_successor(model, times_x)? else {
        return Ok(None);
    };
    let Some((q, half)) = scalar_operand(model, last, "Mul")? else {
        return Ok(None);
    };
    if t.node != tanh || !x_times || q.node != times_x {
        return Ok(None);
    }
    // Every inner value feeds the chain alone, and no node broadcasts x to another shape.
    for id in [square, cube, k, sum, arg] {
        if only_successor(model, id)?.is_none() {
            return Ok(None);
        }
    }
    let shape = &model.outlet_fact(x)?.shape;
    for id in [square, cube, k, sum, arg, tanh, plus, times_x, last] {
        if model.outlet_fact(OutletId::new(id, 0))?.shape != *shape {
            return Ok(None);
        }
    }
    if model.outlet_fact(x)?.datum_type != f32::datum_type() {
        return Ok(None);
    }
    let consts = GeluConsts {
        kappa,
        beta,
        one,
        half,
    };
    Ok(Some((x, last, consts)))
}

/// Rewrite every tanh GELU chain of a decluttered `model` (the module doc) into a
/// [`TanhGelu`]; returns the model and the number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn fuse_tanh_gelus(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let tanhs: Vec<String> = model
        .nodes()
        .iter()
        .filter(|n| is_unary(&model, n.id, "Tanh"))
        .map(|n| n.name.clone())
        .collect();
    let mut done = 0;
    for name in tanhs {
        let id = model.node_id_by_name(&name)?;
        let Some((x, last, consts)) = gelu_at(&model, id)? else {
            continue;
        };
        let name = format!("{}.gelu", model.node(last).name);
        replace_with_op(&mut model, &[x], last, name, TanhGelu { consts })?;
        done += 1;
    }
    Ok((model.into_compact()?, done))
}

#[cfg(test)]
mod tests {
    //! The op against tract's plan of the exported chain, bit for bit, over values from
    //! subnormal to past tanh's saturation, on one and two threads; chains it must leave alone;
    //! and every stage of the committed default bundle.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, on_two_threads, run_optimized};
    use tract_nnef::tract_core::ops::math;

    /// The chain as the ONNX export wires it, on `[rows, 37]` (a length no block divides);
    /// `twist` makes the final factor act on x instead of the product (not a GELU).
    fn chain(rows: usize, twist: bool) -> (TypedModel, TVec<TValue>) {
        let mut m = TypedModel::default();
        let shape = [rows, 37];
        let x = m.add_source("x", f32::fact(shape)).unwrap();
        let k =
            |m: &mut TypedModel, name: &str, v: f32| m.add_const(name, tensor2(&[[v]])).unwrap();
        let (kappa, beta, one, half) = (
            k(&mut m, "kappa", 0.044715),
            k(&mut m, "beta", 0.797_884_6),
            k(&mut m, "one", 1.0),
            k(&mut m, "half", 0.5),
        );
        let sq = m.wire_node("sq", math::square(), &[x]).unwrap()[0];
        let cube = m.wire_node("cube", math::mul(), &[x, sq]).unwrap()[0];
        let kc = m.wire_node("kc", math::mul(), &[cube, kappa]).unwrap()[0];
        let sum = m.wire_node("sum", math::add(), &[x, kc]).unwrap()[0];
        let arg = m.wire_node("arg", math::mul(), &[sum, beta]).unwrap()[0];
        let t = m.wire_node("t", math::tanh(), &[arg]).unwrap()[0];
        let p = m.wire_node("p", math::add(), &[t, one]).unwrap()[0];
        let q = if twist {
            m.wire_node("q", math::mul(), &[x, half]).unwrap()[0]
        } else {
            m.wire_node("q", math::mul(), &[x, p]).unwrap()[0]
        };
        let y = if twist {
            m.wire_node("y", math::mul(), &[q, p]).unwrap()[0]
        } else {
            m.wire_node("y", math::mul(), &[q, half]).unwrap()[0]
        };
        m.select_output_outlets(&[y]).unwrap();
        // Subnormal, tiny, ordinary, large and saturating values, both signs, zeros and a NaN.
        let values: Vec<f32> = (0..rows * 37)
            .map(|i| {
                let s = if i % 2 == 0 { 1.0 } else { -1.0 };
                match i % 11 {
                    0 => s * 1e-40,
                    1 => s * 0.0,
                    2 if i % 7 == 0 => f32::NAN,
                    3 => s * 30.0,
                    v => s * (i as f32 * 0.001_731 + v as f32 * 0.37).sin() * 4.0,
                }
            })
            .collect();
        let input = Tensor::from_shape(&shape, &values).unwrap();
        (m.into_decluttered().unwrap(), tvec![input.into()])
    }

    #[test]
    fn the_chain_computes_tracts_bits() {
        for rows in [1, 3, 200] {
            let (model, inputs) = chain(rows, false);
            let (fused, n) = fuse_tanh_gelus(model.clone()).unwrap();
            assert_eq!(n, 1, "{rows} rows");
            assert_eq!(
                fused
                    .nodes()
                    .iter()
                    .filter(|n| n.op_is::<TanhGelu>())
                    .count(),
                1
            );
            assert!(!fused.nodes().iter().any(|n| is_unary(&fused, n.id, "Tanh")));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(fused.clone(), &inputs);
            assert_eq!(bits(&got[0]), bits(&want[0]), "{rows} rows");
            let two = on_two_threads(|| run_optimized(fused, &inputs));
            assert_eq!(bits(&two[0]), bits(&want[0]), "{rows} rows, two threads");
        }
    }

    #[test]
    fn other_chains_are_left_alone() {
        let (model, _) = chain(3, true);
        assert_eq!(fuse_tanh_gelus(model).unwrap().1, 0);
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = TanhGelu {
            consts: GeluConsts {
                kappa: 0.044715,
                beta: 0.8,
                one: 1.0,
                half: 0.5,
            },
        };
        let x = Tensor::zero::<i32>(&[4, 2]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }

    #[test]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::TanhGelus, fuse_tanh_gelus);
    }
}
