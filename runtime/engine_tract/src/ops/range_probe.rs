//! The probes a calibration run reads the int8 layers' activation ranges with: [`RangeProbe`],
//! an identity op that counts the magnitudes of its input into a [`RangeLog`] under its layer's
//! name, and [`probe_inputs`], which puts one before the activation of each layer an int8 pass
//! would take ([`crate::ops::quant_linear::probe_linears`], [`crate::ops::quant_conv::probe_convs`]).

use std::collections::BTreeMap;
use std::sync::Mutex;

use satmap_kernels::qgemm::histogram::{MagnitudeHistogram, RangeMethod};
use tract_nnef::internal::*;

/// The magnitudes seen per `(stage, layer name)`, shared by the probes of every stage of one
/// load (and of every load given the same log).
#[derive(Clone, Debug, Default)]
pub struct RangeLog(Arc<Mutex<BTreeMap<(String, String), MagnitudeHistogram>>>);

impl PartialEq for RangeLog {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl RangeLog {
    /// Count `values` under `key`.
    fn observe(&self, key: &(String, String), values: &[f32]) {
        // A poisoned log (a probe panicked mid-update) still holds valid counts.
        let mut map = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        map.entry(key.clone()).or_default().add(values);
    }

    /// The range `method` takes of each layer's values so far, by `(stage, layer name)`.
    #[must_use]
    pub fn ranges(&self, method: RangeMethod) -> BTreeMap<(String, String), f32> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .map(|(k, h)| (k.clone(), h.range(method)))
            .collect()
    }
}

/// An identity op that records its input's largest magnitude under `key`.
#[derive(Clone, Debug)]
pub struct RangeProbe {
    /// The stage's and the layer's name.
    pub key: (String, String),
    log: RangeLog,
}

impl PartialEq for RangeProbe {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key && Arc::ptr_eq(&self.log.0, &other.log.0)
    }
}
impl Eq for RangeProbe {}

impl Op for RangeProbe {
    fn name(&self) -> StaticName {
        "RangeProbe".into()
    }
    op_as_typed_op!();
}

impl EvalOp for RangeProbe {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        ensure!(inputs.len() == 1, "RangeProbe takes one input");
        let x = inputs[0].try_as_plain_ram()?;
        self.log.observe(&self.key, x.as_slice::<f32>()?);
        Ok(inputs)
    }
}

impl TypedOp for RangeProbe {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 1);
        Ok(tvec!(inputs[0].without_value()))
    }

    as_op!();
}

/// Put a [`RangeProbe`] into `log`, keyed `(stage, node name)`, on the activation `layer_x`
/// picks for each node it takes (`None`: no layer), node by node in evaluation order; returns
/// the model and the number of probes.
///
/// # Errors
/// tract refusing a patch, or `layer_x` naming an outlet that is not the node's input.
pub fn probe_inputs(
    mut model: TypedModel,
    log: &RangeLog,
    stage: &str,
    layer_x: impl Fn(&TypedModel, usize) -> TractResult<Option<OutletId>>,
) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    // Ids stay valid while patching (a patch appends nodes and leaves the old ones dead), and
    // each layer is read when it is reached: a patch before it may have rewired its input.
    for id in model.eval_order()? {
        let Some(x) = layer_x(&model, id)? else {
            continue;
        };
        let node = model.node(id).clone();
        let name = node.name.clone();
        let mut patch = TypedModelPatch::default();
        let mut taps: TVec<OutletId> = node
            .inputs
            .iter()
            .map(|&o| patch.tap_model(&model, o))
            .collect::<TractResult<_>>()?;
        let xi = node
            .inputs
            .iter()
            .position(|&o| o == x)
            .context("the layer's activation is one of its inputs")?;
        let probe = RangeProbe {
            key: (stage.to_owned(), name.clone()),
            log: log.clone(),
        };
        taps[xi] = patch.wire_node(format!("{name}.range_probe"), probe, &[taps[xi]])?[0];
        let y = patch.wire_node(format!("{name}.probed"), node.op.clone(), &taps)?[0];
        patch.shunt_outside(&model, OutletId::new(id, 0), y)?;
        patch.apply(&mut model)?;
        done += 1;
    }
    Ok((model, done))
}
