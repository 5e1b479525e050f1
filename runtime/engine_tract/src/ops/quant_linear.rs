//! Linear layers in integer arithmetic (W8A8), and the probes a calibration run reads their
//! activations' ranges with.
//!
//! [`QuantLinear`]: the activation quantised per tensor with the scale its calibrated range
//! gives (symmetric int8, [`satmap_kernels::qgemm::quantize`]), the weights per output column
//! at load (an int8 bundle's weights come back as the int8 values it stores), the product
//! summed in i32 on the integer tier this CPU has ([`IntTier`]) and finished in the same store:
//! `sum * (activation scale * column scale) + bias`. Every integer tier gives the same bits.
//!
//! [`probe_linears`]: a [`crate::ops::range_probe::RangeProbe`] before each layer
//! [`quantise_linears`] would take: what `satmap-sim compile --calibrate` records over frames
//! of the training split.
//!
//! Both passes choose layers with the same rule (`layer_at`): every linear layer the native f32
//! product would take (`Layer::is_native`), keyed by its `EinSum` node's name in the
//! decluttered graph, which is the same in every load of the same stage.

use std::collections::BTreeMap;

use satmap_kernels::qgemm::{self, IntTier, PackedQB, QFinish, padded_k, quantize};
use tract_nnef::internal::*;

use crate::graph::matching::replace_with_op;
use crate::ops::finish::Epilogue;
use crate::ops::linear::{Layer, as_layer};
use crate::ops::range_probe::{RangeLog, probe_inputs};
use crate::pool;

/// Rows of the activation quantised and multiplied as one task (a thread's share).
const BAND_ROWS: usize = 64;

/// `x [.., k] . W [k, n] (+ bias [n]) -> [.., n]` in int8 with i32 sums.
#[derive(Clone, Debug)]
pub struct QuantLinear {
    /// The activation's shape (its last axis `k`).
    pub input: TVec<usize>,
    /// Outputs a token.
    pub n: usize,
    /// The residual `Add` and ReLU after the bias ([`crate::passes::epilogue`]).
    pub epilogue: Epilogue,
    /// `1 / activation scale`.
    inv_scale: f32,
    /// The activation's scale times each column's weight scale.
    col_scale: Arc<Vec<f32>>,
    weights: Arc<PackedQB>,
    bias: Option<Arc<Vec<f32>>>,
    tier: IntTier,
}

impl PartialEq for QuantLinear {
    fn eq(&self, other: &Self) -> bool {
        self.input == other.input
            && self.n == other.n
            && self.epilogue == other.epilogue
            && self.inv_scale.to_bits() == other.inv_scale.to_bits()
            && self.tier == other.tier
            && Arc::ptr_eq(&self.weights, &other.weights)
            && Arc::ptr_eq(&self.col_scale, &other.col_scale)
    }
}
impl Eq for QuantLinear {}

impl QuantLinear {
    /// The layer `w [k][n]` (row-major f32) with `bias`, its activation of largest magnitude
    /// `abs_max`, on `tier`.
    ///
    /// # Errors
    /// Weights that do not pack (`k` over the exact limit, a size mismatch).
    pub fn new(
        input: TVec<usize>,
        w: &[f32],
        n: usize,
        bias: Option<Vec<f32>>,
        abs_max: f32,
        tier: IntTier,
    ) -> TractResult<Self> {
        let k = input.last().copied().unwrap_or(0);
        let (q, w_scales) = quantize::weights_per_column(w, k, n);
        let weights = PackedQB::pack(&q, k, n)?;
        let a_scale = quantize::scale_for(abs_max);
        Ok(Self {
            input,
            n,
            epilogue: Epilogue::default(),
            inv_scale: 1.0 / a_scale,
            col_scale: Arc::new(w_scales.iter().map(|&s| a_scale * s).collect()),
            weights: Arc::new(weights),
            bias: bias.map(Arc::new),
            tier,
        })
    }

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

std::thread_local! {
    /// The quantised rows of this thread's band, kept between runs (it only grows, so a step
    /// allocates here only the first time a thread meets its widest layer).
    static ROWS: std::cell::RefCell<Vec<i8>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl Op for QuantLinear {
    fn info(&self) -> TractResult<Vec<String>> {
        let m = self.input.iter().product::<usize>() / self.k().max(1);
        Ok(vec![format!(
            "Mult: m:{m} k:{} n:{} int8 on {}",
            self.k(),
            self.n,
            self.tier
        )])
    }

    fn name(&self) -> StaticName {
        "QuantLinear".into()
    }
    op_as_typed_op!();
}

impl EvalOp for QuantLinear {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let out_shape = self.output_shape();
        let residual = self.epilogue.shortcut(&inputs, &out_shape)?;
        let x = &inputs[0];
        ensure!(
            x.shape() == &*self.input,
            "QuantLinear input {:?}",
            x.shape()
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let (k, n) = (self.k(), self.n);
        let m = xs.len() / k.max(1);
        let kp = padded_k(k);
        let mut out = crate::gemm::output_tensor(&out_shape)?;
        let mut po = out.try_as_plain_ram_mut()?;
        let c = po.as_slice_mut::<f32>()?;
        let parallel = pool::worth_threads(m * k * n);
        let done = pool::on_threads(parallel, c, BAND_ROWS * n.max(1), |i, band| {
            let r0 = i * BAND_ROWS;
            let rows = band.len() / n.max(1);
            let x = &xs[r0 * k..(r0 + rows) * k];
            let finish = QFinish {
                scale: &self.col_scale,
                bias: self.bias.as_deref().map(Vec::as_slice),
                residual: residual.map(|r| (&r[r0 * n..], n)),
                floor: self.epilogue.floor,
            };
            ROWS.with(|buf| {
                let mut buf = buf.borrow_mut();
                if buf.len() < rows * kp {
                    buf.resize(rows * kp, 0);
                }
                let a = &mut buf[..rows * kp];
                quantize::activations(x, rows, k, self.inv_scale, a)
                    && qgemm::product(self.tier, a, rows, &self.weights, finish, band, n).is_ok()
            })
        });
        ensure!(done, "integer product refused (operands mis-sized)");
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for QuantLinear {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        self.epilogue.output_facts(inputs, &self.output_shape())
    }

    fn cost(&self, _inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let macs = self.input.iter().product::<usize>() * self.n;
        Ok(tvec!((Cost::FMA(i8::datum_type()), macs.to_dim())))
    }

    as_op!();
}

/// Node `id` as a layer the int8 passes take.
fn layer_at(model: &TypedModel, id: usize) -> TractResult<Option<Layer>> {
    Ok(as_layer(model, id)?.filter(Layer::is_native))
}

/// Replace every layer `layer_at` takes that has a range in `ranges` by a [`QuantLinear`] on
/// `tier`, its bias `Add` taken in; returns the model and the number replaced.
///
/// # Errors
/// tract refusing a patch, or weights that do not pack.
pub fn quantise_linears(
    mut model: TypedModel,
    ranges: &BTreeMap<String, f32>,
    tier: IntTier,
) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    // Ids stay valid while patching (a patch appends nodes and leaves the old ones dead), and
    // each layer is read when it is reached: a patch before it may have rewired its input.
    for id in model.eval_order()? {
        let name = model.node(id).name.clone();
        let Some(&abs_max) = ranges.get(&name) else {
            continue;
        };
        let Some(layer) = layer_at(&model, id)? else {
            continue;
        };
        let n = layer.n;
        let bias = layer.bias_after(&model, id)?;
        let w = layer.w.try_as_plain_ram()?;
        let op = QuantLinear::new(
            layer.input.clone(),
            w.as_slice::<f32>()?,
            n,
            bias.as_ref().map(|(_, b)| b.clone()),
            abs_max,
            tier,
        )?;
        let replaced = bias.map_or(id, |(add_id, _)| add_id);
        replace_with_op(&mut model, &[layer.x], replaced, format!("{name}.int8"), op)?;
        done += 1;
    }
    Ok((model, done))
}

/// Put a [`crate::ops::range_probe::RangeProbe`] into `log` before every layer `layer_at` takes in `stage`; returns the
/// model and the number of probes.
///
/// # Errors
/// tract refusing a patch.
pub fn probe_linears(
    model: TypedModel,
    log: &RangeLog,
    stage: &str,
) -> TractResult<(TypedModel, usize)> {
    probe_inputs(model, log, stage, |model, id| {
        Ok(layer_at(model, id)?.map(|layer| layer.x))
    })
}

#[cfg(test)]
mod tests {
    //! The int8 layer against the f32 layer it replaces (within the quantisation's bound, stated
    //! per case), bit for bit across every integer tier this CPU has, and the probes: the range
    //! they record is the input's largest magnitude, and the probed model computes the same bits.
    use super::*;
    use crate::test_support::{bits, linear_model, run_optimized};
    use satmap_kernels::qgemm::histogram::RangeMethod;

    fn input(shape: &[usize]) -> TVec<TValue> {
        let len: usize = shape.iter().product();
        let x: Vec<f32> = (0..len)
            .map(|i| ((i * 31) % 97) as f32 / 48.0 - 1.0)
            .collect();
        tvec![Tensor::from_shape(shape, &x).unwrap().into_tvalue()]
    }

    /// The name of the one layer of `model` the int8 passes take.
    fn layer_name(model: &TypedModel) -> String {
        let ids: Vec<usize> = model
            .eval_order()
            .unwrap()
            .into_iter()
            .filter(|&id| layer_at(model, id).unwrap().is_some())
            .collect();
        assert_eq!(ids.len(), 1);
        model.node(ids[0]).name.clone()
    }

    fn values(t: &TValue) -> Vec<f32> {
        t.try_as_plain_ram()
            .unwrap()
            .as_slice::<f32>()
            .unwrap()
            .to_vec()
    }

    #[test]
    fn int8_layers_stay_within_the_quantisation_bound_and_agree_on_every_tier() {
        for (lead, k, n, transposed, bias) in [
            (vec![300], 64, 48, false, true),
            (vec![2, 50], 130, 33, true, true),
            (vec![9], 7, 2, true, false),
        ] {
            let model = linear_model(&lead, k, n, transposed, bias);
            let mut shape = lead.clone();
            shape.push(k);
            let inputs = input(&shape);
            let want = values(&run_optimized(model.clone(), &inputs)[0]);
            // The input's range, as a calibration over this input would record it.
            let abs_max = quantize::abs_max(&values(&inputs[0]));
            let name = layer_name(&model);
            let ranges = BTreeMap::from([(name, abs_max)]);
            let mut first: Option<Vec<u32>> = None;
            for tier in IntTier::ALL.into_iter().filter(|t| t.runs_here()) {
                let (q, done) = quantise_linears(model.clone(), &ranges, tier).unwrap();
                assert_eq!(done, 1);
                assert!(q.nodes().iter().any(|n| n.op_is::<QuantLinear>()));
                let got = run_optimized(q, &inputs);
                // Bound: each of k products off by at most half a step of each operand
                // (|x| <= 1 and |w| <= 1 here): k * (s_x / 2 + s_w / 2 + s_x * s_w / 4).
                let (s_x, s_w) = (abs_max / 127.0, 1.0 / 127.0);
                let bound = k as f32 * (s_x / 2.0 + s_w / 2.0 + s_x * s_w / 4.0);
                let worst = values(&got[0])
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                assert!(
                    worst <= bound,
                    "{lead:?} x {k} -> {n} on {tier}: {worst} > {bound}"
                );
                assert!(
                    worst > 0.0,
                    "int8 that equals f32 bit for bit was not quantised"
                );
                let b = bits(&got[0]);
                match &first {
                    None => first = Some(b),
                    Some(f) => assert_eq!(&b, f, "{tier} differs from the first tier"),
                }
            }
        }
    }

    #[test]
    fn a_layer_without_a_range_stays_f32() {
        let model = linear_model(&[300], 64, 48, false, true);
        let (_, done) = quantise_linears(model, &BTreeMap::new(), IntTier::Generic).unwrap();
        assert_eq!(done, 0);
    }

    #[test]
    fn probes_record_each_layers_input_range_and_change_no_bit() {
        let model = linear_model(&[2, 50], 130, 33, true, true);
        let inputs = input(&[2, 50, 130]);
        let want = run_optimized(model.clone(), &inputs);
        let log = RangeLog::default();
        let (probed, done) = probe_linears(model.clone(), &log, "stage").unwrap();
        assert_eq!(done, 1);
        let got = run_optimized(probed, &inputs);
        assert_eq!(bits(&got[0]), bits(&want[0]));
        let ranges = log.ranges(RangeMethod::AbsMax);
        let name = layer_name(&model);
        assert_eq!(
            ranges.get(&("stage".to_owned(), name)),
            Some(&quantize::abs_max(&values(&inputs[0])))
        );
        assert_eq!(ranges.len(), 1);
    }

    #[test]
    fn the_fused_residual_and_floor_give_the_unfused_bits() {
        let (m, k, n) = (70, 40, 19);
        let w: Vec<f32> = (0..k * n)
            .map(|i| ((i * 13) % 29) as f32 / 14.0 - 1.0)
            .collect();
        let bias: Vec<f32> = (0..n).map(|i| i as f32 / 7.0 - 1.0).collect();
        let op =
            QuantLinear::new(tvec![m, k], &w, n, Some(bias), 1.0, IntTier::default_here()).unwrap();
        let x = input(&[m, k]);
        let res: Vec<f32> = (0..m * n)
            .map(|i| ((i * 7) % 11) as f32 / 5.0 - 1.0)
            .collect();
        let plain = values(&op.eval_out_of_plan(x.clone()).unwrap().unwrap()[0]);
        let want: Vec<u32> = plain
            .iter()
            .zip(&res)
            .map(|(&v, &r)| satmap_kernels::gemm::floor(v + r, 0.0).to_bits())
            .collect();
        let fused = op.with_epilogue(Epilogue {
            residual: true,
            floor: Some(0.0),
        });
        let mut inputs = x;
        inputs.push(Tensor::from_shape(&[m, n], &res).unwrap().into_tvalue());
        let got = fused.eval_out_of_plan(inputs).unwrap().unwrap();
        assert_eq!(bits(&got[0]), want);
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = QuantLinear::new(tvec![4, 3], &[1.0; 6], 2, None, 1.0, IntTier::Generic).unwrap();
        let x = Tensor::zero::<f32>(&[4, 2]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }
}
