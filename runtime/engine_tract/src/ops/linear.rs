//! The linear layers (products with a constant weight matrix) as the native product.
//!
//! After decluttering, a linear layer is an [`EinSum`] of an activation `[.., k]` and a
//! constant `[k, n]` (or `[n, k]`) into `[.., n]`, usually followed by an `Add` of a constant
//! bias `[n]`. [`native_linears`] rewrites each into one [`PackedLinear`]: the weights packed
//! once at load ([`gemm::PackedB`]), the activation packed per run, the bias added to the
//! finished sums, as tract's own plan adds it (bit for bit: this module's tests, against tract's
//! plan of every stage of the committed default bundle). Rows of fewer than [`MIN_ROWS`]
//! tokens keep tract's plan: there tract runs its matrix-vector kernels, which sum `k` over four
//! accumulators, so the bits would differ. On the AVX-512 tier only, as [`gemm`].

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::einsum::EinSum;

use crate::gemm::{self, MR, PackedB};
use crate::graph::matching::{const_operand, only_successor, replace_with_op};
use crate::ops::finish::Epilogue;
use crate::pool;

/// Tokens (rows of the product) from which a linear layer runs natively.
pub const MIN_ROWS: usize = 8;

/// `x [.., k] . W [k, n] (+ bias [n]) -> [.., n]` with `W` packed at load.
#[derive(Clone, Debug)]
pub struct PackedLinear {
    /// The activation's shape (its last axis `k`).
    pub input: TVec<usize>,
    /// Outputs a token.
    pub n: usize,
    /// The residual `Add` and ReLU after the bias ([`crate::passes::epilogue`]).
    pub epilogue: Epilogue,
    weights: Arc<PackedB>,
    bias: Option<Arc<Vec<f32>>>,
}

impl PartialEq for PackedLinear {
    fn eq(&self, other: &Self) -> bool {
        self.input == other.input
            && self.n == other.n
            && self.epilogue == other.epilogue
            && Arc::ptr_eq(&self.weights, &other.weights)
            && match (&self.bias, &other.bias) {
                (None, None) => true,
                (Some(a), Some(b)) => Arc::ptr_eq(a, b),
                _ => false,
            }
    }
}
impl Eq for PackedLinear {}

impl PackedLinear {
    /// This layer with `epilogue` after its bias.
    #[must_use]
    pub fn with_epilogue(&self, epilogue: Epilogue) -> Self {
        Self {
            epilogue,
            ..self.clone()
        }
    }

    fn k(&self) -> usize {
        self.input.last().copied().unwrap_or(0)
    }

    fn output_shape(&self) -> TVec<usize> {
        let mut s = self.input.clone();
        if let Some(last) = s.last_mut() {
            *last = self.n;
        }
        s
    }
}

impl Op for PackedLinear {
    fn info(&self) -> TractResult<Vec<String>> {
        let m = self.input.iter().product::<usize>() / self.k().max(1);
        Ok(vec![format!(
            "Mult: m:{m} k:{} n:{} with [native]",
            self.k(),
            self.n
        )])
    }

    fn name(&self) -> StaticName {
        "PackedLinear".into()
    }
    op_as_typed_op!();
}

impl EvalOp for PackedLinear {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let out_shape = self.output_shape();
        let residual = self.epilogue.shortcut(&inputs, &out_shape)?;
        let x = &inputs[0];
        ensure!(
            x.shape() == &*self.input,
            "PackedLinear input {:?}",
            x.shape()
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let k = self.k();
        let m = xs.len() / k.max(1);
        let mut out = gemm::output_tensor(&out_shape)?;
        let mut po = out.try_as_plain_ram_mut()?;
        let c = po.as_slice_mut::<f32>()?;
        let bias = match &self.bias {
            Some(b) => gemm::Bias::PerCol(b),
            None => gemm::Bias::None,
        };
        let n = self.n;
        let done = gemm::pack::with_scratch(gemm::panels(m, MR) * MR * k, |a| {
            pool::on_threads(pool::worth_threads(m * k * n), a, MR * k, |i, panel| {
                gemm::pack::pack_a_panel(xs, m, k, k, i, panel);
                true
            });
            let ops = gemm::Operands {
                a,
                b: gemm::BSource::Packed(self.weights.as_slice()),
                m,
                n,
                k,
                ldc: n,
            };
            gemm::product_then(&ops, c, self.epilogue.finish(bias, residual))
        });
        ensure!(
            done,
            "native product refused (AVX-512 missing or operands mis-sized)"
        );
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for PackedLinear {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        self.epilogue.output_facts(inputs, &self.output_shape())
    }

    fn cost(&self, _inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let fma = self.input.iter().product::<usize>() * self.n;
        Ok(tvec!((Cost::FMA(f32::datum_type()), fma.to_dim())))
    }

    as_op!();
}

/// What an [`EinSum`] node is when it is a linear layer.
pub(crate) struct Layer {
    /// The activation.
    pub x: OutletId,
    /// Its concrete shape.
    pub input: TVec<usize>,
    /// The weights as `[k, n]`, row-major.
    pub w: Tensor,
    /// Outputs a token.
    pub n: usize,
}

impl Layer {
    /// Whether the native product takes this layer: at least [`MIN_ROWS`] tokens, two outputs
    /// and a non-empty `k` (the rule [`native_linears`] and the int8 layers share).
    pub(crate) fn is_native(&self) -> bool {
        let k = self.input.last().copied().unwrap_or(0);
        let rows = self.input.iter().product::<usize>() / k.max(1);
        rows >= MIN_ROWS && self.n >= 2 && k > 0
    }

    /// The constant bias the single `Add` after this layer's node `id` adds ([`bias_after`]),
    /// with that `Add`: `[n]`, or any rank up to the output's with ones before `n`.
    ///
    /// # Errors
    /// tract failing to give a fact.
    pub(crate) fn bias_after(
        &self,
        model: &TypedModel,
        id: usize,
    ) -> TractResult<Option<(usize, Vec<f32>)>> {
        let (rank, n) = (self.input.len(), self.n);
        bias_after(model, id, |shape| {
            shape.len() <= rank
                && shape.last() == Some(&n)
                && shape[..shape.len() - 1].iter().all(|&d| d == 1)
        })
    }
}

/// An f32 [`EinSum`] node of one activation (concrete shape) and one constant rank-2 matrix:
/// what a linear layer ([`as_layer`]) and a 1x1 convolution ([`crate::ops::pointwise`]) are before
/// their axes are read.
pub(crate) struct ConstProduct<'a> {
    /// The op.
    pub es: &'a EinSum,
    /// Which input is the activation (the other the matrix).
    pub xi: usize,
    /// The activation's shape.
    pub input: TVec<usize>,
    /// The matrix.
    pub w: Arc<Tensor>,
}

/// The node's op as a plain f32 [`EinSum`] of two inputs (no quantisation), the form every
/// native product rewrite starts from.
pub(crate) fn f32_einsum(node: &TypedNode) -> Option<&EinSum> {
    let es = node.op_as::<EinSum>()?;
    let plain = es.q_params.is_none() && es.operating_dt == f32::datum_type();
    (plain && node.inputs.len() == 2).then_some(es)
}

/// The node `id` as a [`ConstProduct`], if it is one.
pub(crate) fn const_product(
    model: &TypedModel,
    id: usize,
) -> TractResult<Option<ConstProduct<'_>>> {
    let node = model.node(id);
    let Some(es) = f32_einsum(node) else {
        return Ok(None);
    };
    let facts = model.node_input_facts(id)?;
    let Some(wi) = (0..2).find(|&i| facts[i].konst.is_some() && facts[i].rank() == 2) else {
        return Ok(None);
    };
    let xi = 1 - wi;
    let (xf, wf) = (facts[xi], facts[wi]);
    let Some(input) = xf.shape.as_concrete().map(TVec::from) else {
        return Ok(None);
    };
    let Some(w) = wf.konst.clone() else {
        return Ok(None);
    };
    if xf.konst.is_some()
        || xf.datum_type != f32::datum_type()
        || wf.datum_type != f32::datum_type()
    {
        return Ok(None);
    }
    Ok(Some(ConstProduct { es, xi, input, w }))
}

/// The node `id` as a linear layer: an f32 [`EinSum`] of one activation whose last axis is
/// summed against a constant rank-2 matrix, every other activation axis kept in place, the
/// matrix's other axis last in the output.
pub(crate) fn as_layer(model: &TypedModel, id: usize) -> TractResult<Option<Layer>> {
    let Some(ConstProduct { es, xi, input, w }) = const_product(model, id)? else {
        return Ok(None);
    };
    let wi = 1 - xi;
    let xr = input.len();
    let (mut k_pos, mut n_pos) = (None, None);
    for axis in es.axes.iter_all_axes() {
        let (ix, iw, out) = (&axis.inputs[xi], &axis.inputs[wi], &axis.outputs[0]);
        if ix.len() > 1 || iw.len() > 1 || out.len() > 1 {
            return Ok(None);
        }
        match (ix.first(), iw.first(), out.first()) {
            (Some(&px), Some(&pw), None) if px + 1 == xr => k_pos = Some(pw),
            (None, Some(&pw), Some(&po)) if po + 1 == xr => n_pos = Some(pw),
            (Some(&px), None, Some(&po)) if px == po && px + 1 < xr => {}
            _ => return Ok(None),
        }
    }
    let (Some(k_pos), Some(_)) = (k_pos, n_pos) else {
        return Ok(None);
    };
    let w = if k_pos == 0 {
        w.into_tensor()
    } else {
        w.into_tensor().permute_axes(&[1, 0])?
    };
    let n = w.shape()[1];
    Ok(Some(Layer {
        x: model.node(id).inputs[xi],
        input,
        w,
        n,
    }))
}

/// The constant bias that the single `Add` after node `id` (not a model output) adds, with
/// that `Add` node: f32, of a shape `accepts` takes, the `Add` not broadcasting the sum.
pub(crate) fn bias_after(
    model: &TypedModel,
    id: usize,
    accepts: impl Fn(&[usize]) -> bool,
) -> TractResult<Option<(usize, Vec<f32>)>> {
    let Some(add_id) = only_successor(model, id)? else {
        return Ok(None);
    };
    let Some((sum, b)) = const_operand(model, add_id, "Add")? else {
        return Ok(None);
    };
    let bias_like = b.datum_type() == f32::datum_type() && accepts(b.shape());
    let same_shape =
        model.outlet_fact(OutletId::new(add_id, 0))?.shape == model.outlet_fact(sum)?.shape;
    if sum.node != id || !bias_like || !same_shape {
        return Ok(None);
    }
    let plain = b.try_as_plain_ram()?;
    Ok(Some((add_id, plain.as_slice::<f32>()?.to_vec())))
}

/// Rewrite every linear layer of a decluttered `model` with at least [`MIN_ROWS`] tokens and
/// at least two outputs into a [`PackedLinear`], its bias `Add` taken in; returns the model and
/// the number rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn native_linears(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let Some(layer) = as_layer(&model, id)? else {
            continue;
        };
        if !layer.is_native() {
            continue;
        }
        let k = *layer.input.last().unwrap_or(&0);
        let bias = layer.bias_after(&model, id)?;
        let w_plain = layer.w.try_as_plain_ram()?;
        let op = PackedLinear {
            input: layer.input.clone(),
            n: layer.n,
            epilogue: Epilogue::default(),
            weights: Arc::new(PackedB::from_row_major(
                w_plain.as_slice::<f32>()?,
                k,
                layer.n,
            )),
            bias: bias.as_ref().map(|(_, b)| Arc::new(b.clone())),
        };
        let replaced = bias.map_or(id, |(add_id, _)| add_id);
        let name = format!("{}.packed_linear", model.node(id).name);
        replace_with_op(&mut model, &[layer.x], replaced, name, op)?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The pass against tract's own plan, bit for bit: on linear layers built here (weights
    //! either way round, with and without a bias, one and two leading axes) and on every stage
    //! of the committed default bundle.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, linear_model, run_optimized};
    use tract_nnef::tract_core::ops::binary::TypedBinOp;

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn linear_layers_run_natively_with_tracts_bits() {
        for (lead, k, n, transposed, bias) in [
            (vec![3200], 256, 256, false, true),
            (vec![1, 2000], 64, 130, true, true),
            (vec![4, 50], 300, 33, false, false),
            (vec![9], 7, 2, true, false),
        ] {
            let model = linear_model(&lead, k, n, transposed, bias);
            let (native, done) = native_linears(model.clone()).unwrap();
            assert_eq!(done, 1, "{lead:?} x {k} -> {n}");
            assert!(native.nodes().iter().any(|n| n.op_is::<PackedLinear>()));
            // The bias add went into the op.
            let adds = native
                .eval_order()
                .unwrap()
                .into_iter()
                .filter(|&i| native.node(i).op_is::<TypedBinOp>())
                .count();
            assert_eq!(adds, 0, "{lead:?} x {k} -> {n}");
            let mut shape = lead.clone();
            shape.push(k);
            let len: usize = shape.iter().product();
            let x: Vec<f32> = (0..len)
                .map(|i| ((i * 31) % 97) as f32 / 48.0 - 1.0)
                .collect();
            let inputs = tvec![Tensor::from_shape(&shape, &x).unwrap().into_tvalue()];
            let want = run_optimized(model, &inputs);
            let got = run_optimized(native, &inputs);
            assert_eq!(got[0].shape(), want[0].shape());
            assert_eq!(bits(&got[0]), bits(&want[0]), "{lead:?} x {k} -> {n}");
        }
    }

    #[test]
    fn single_tokens_keep_tracts_plan() {
        // One token: tract's matrix-vector kernels sum k in another order.
        let model = linear_model(&[1], 64, 64, false, true);
        assert_eq!(native_linears(model).unwrap().1, 0);
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = PackedLinear {
            input: tvec![4, 3],
            n: 2,
            epilogue: Epilogue::default(),
            weights: Arc::new(PackedB::from_row_major(&[1.0; 6], 3, 2)),
            bias: None,
        };
        let x = Tensor::zero::<f32>(&[4, 2]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }

    #[test]
    #[cfg_attr(
        not(satmap_native_tier_tests),
        ignore = "needs the default native product tier (AVX-512F): not on this CPU"
    )]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::NativeLinears, native_linears);
    }
}
