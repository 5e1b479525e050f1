//! Stage graphs from a bundle's bytes to tract's typed model: the NNEF graph of a compiled
//! bundle (its f16 form given the arithmetic this core has), or with the `onnx` feature the ONNX
//! file of a folder bundle; inputs and outputs bound by name and checked against the manifest.

use tract_nnef::framework::Nnef;
use tract_nnef::prelude::*;

use satmap_bundle::graph_check::{GraphCheckError, MAX_TENSOR_ELEMENTS, check_nnef_stage};
use satmap_bundle::{BundleError, DType, Precision, StageEntry, TensorSpec};
use satmap_core::engine::Stage;

pub(crate) fn datum(dtype: DType) -> DatumType {
    match dtype {
        DType::U8 => DatumType::U8,
        DType::I64 => DatumType::I64,
        DType::F32 => DatumType::F32,
    }
}

/// tract's error for `stage`, with its whole context chain.
pub fn engine_error(stage: Stage) -> impl Fn(TractError) -> BundleError + Copy {
    move |e| BundleError::Engine {
        stage: stage.name(),
        message: format!("{e:#}"),
    }
}

/// Where an f16 bundle's arithmetic runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum HalfArithmetic {
    /// In f16, for a core with f16 arithmetic (Armv8.2-A FEAT_FP16: Cortex-A55/A75 and later,
    /// every listed ECU application core but the A72): the stored graph runs as it is, with a
    /// cast at each float input and output, so the runtime's buffers stay f32. tract then picks
    /// its fp16 kernels (twice the lanes of f32 per NEON instruction), yet retired more
    /// instructions than f32 on `test`'s encoders (docs/perf.md, "On ARM").
    Native,
    /// Widened to f32 at load: f16-rounded weights, f32 arithmetic, f32 RAM (the widened
    /// constants fold into f32 ones when the plan is optimised). Where the core has no f16
    /// arithmetic (x86 here, where tract's f16 kernels are portable fallbacks tens of times
    /// slower than f32) and wherever f32 arithmetic is wanted. The default.
    #[default]
    Widened,
}

impl HalfArithmetic {
    /// [`Native`](Self::Native) where tract finds f16 arithmetic on this core (on Linux it reads
    /// `/proc/cpuinfo`'s `asimdhp`; on an OS without it, such as QNX, this answers `Widened`),
    /// [`Widened`](Self::Widened) elsewhere.
    #[must_use]
    pub fn of_this_core() -> Self {
        if tract_linalg::has_fp16() {
            Self::Native
        } else {
            Self::Widened
        }
    }

    /// `native` or `widened`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Native => "native",
            Self::Widened => "widened",
        }
    }
}

/// The typed model of a compiled stage: its NNEF tar read through tract-core's registry, names
/// bound, and an f16 graph run as `half` says (an f16 bundle is half the flash of the f32 one:
/// 57% of the f32 file on `test`), with the arithmetic it got: a stage with index arithmetic
/// runs [`HalfArithmetic::Widened`] whatever was asked; `None` for an f32 or int8 graph.
pub fn nnef_model(
    stage: Stage,
    nnef: &Nnef,
    bytes: &[u8],
    entry: &StageEntry,
    precision: Precision,
    half: HalfArithmetic,
) -> Result<(TypedModel, Option<HalfArithmetic>), BundleError> {
    use tract_nnef::tract_core::floats::FloatPrecisionTranslator;
    use tract_nnef::tract_core::transform::ModelTransform as _;
    let engine_err = engine_error(stage);
    let model = checked_model(stage, nnef, bytes)?;
    check_io_names(stage, &graph_io_names(&model)?, entry)?;
    if precision != Precision::F16 {
        return Ok((model, None));
    }
    let (f16, f32) = (f16::datum_type(), f32::datum_type());
    // A stage with index arithmetic runs widened whole (see `has_index_arithmetic`).
    let got = match half {
        HalfArithmetic::Native if !has_index_arithmetic(&model) => HalfArithmetic::Native,
        _ => HalfArithmetic::Widened,
    };
    let translator = match got {
        // The translator always turns sources to f32 and casts the graph's outputs back to
        // f32; a filter that translates no other node keeps every operator in f16.
        HalfArithmetic::Native => FloatPrecisionTranslator::with_filter(f16, f32, |_| false),
        HalfArithmetic::Widened => FloatPrecisionTranslator::new(f16, f32),
    };
    translator
        .transform_into(model)
        .map(|m| (m, Some(got)))
        .map_err(engine_err)
}

/// What the engine does with a compiled stage's bytes before it builds a plan: the structural
/// check, tract's parse and the tensor-size check, with a tract panic caught and named (for
/// tools and the fuzz harness; [`TractEngine::load`](crate::TractEngine::load) does the same on the way to a plan).
///
/// # Errors
/// [`BundleError::Graph`] for a rule broken, [`BundleError::Engine`] for tract's refusal or
/// panic.
pub fn parse_stage_graph(stage: Stage, bytes: &[u8]) -> Result<(), BundleError> {
    confined(stage, || {
        checked_model(stage, &tract_nnef::nnef(), bytes).map(drop)
    })
}

/// The structural check, tract's parse, and (before decluttering folds constants, the step
/// where a huge `tile` or reshape would be materialised) every tensor of the parsed graph
/// static and within the size limit.
fn checked_model(stage: Stage, nnef: &Nnef, bytes: &[u8]) -> Result<TypedModel, BundleError> {
    let refused = |source| BundleError::Graph {
        stage: stage.name(),
        source,
    };
    check_nnef_stage(bytes).map_err(refused)?;
    let model = nnef
        .model_for_read(&mut &bytes[..])
        .map_err(engine_error(stage))?;
    check_tensor_sizes(&model).map_err(refused)?;
    Ok(model)
}

/// `f`, with a panic inside tract (some graphs it cannot run make it panic, not err) turned
/// into [`BundleError::Engine`] naming `stage`.
pub(crate) fn confined<T>(
    stage: Stage,
    f: impl FnOnce() -> Result<T, BundleError>,
) -> Result<T, BundleError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|panic| {
        Err(BundleError::Engine {
            stage: stage.name(),
            message: format!("tract panicked: {}", crate::panic_message(&*panic)),
        })
    })
}

/// Every output of every node of `model` has a concrete shape of at most
/// [`MAX_TENSOR_ELEMENTS`] elements.
fn check_tensor_sizes(model: &TypedModel) -> Result<(), GraphCheckError> {
    for node in &model.nodes {
        for output in &node.outputs {
            let elements = output.fact.shape.as_concrete().map(|dims| {
                dims.iter()
                    .try_fold(1u64, |n, &d| n.checked_mul(d as u64))
                    .unwrap_or(u64::MAX)
            });
            match elements {
                Some(n) if n <= MAX_TENSOR_ELEMENTS => {}
                _ => {
                    return Err(GraphCheckError::TensorSize {
                        node: node.name.clone(),
                        shape: format!("{:?}", output.fact.shape),
                    });
                }
            }
        }
    }
    Ok(())
}

/// Whether any operator of `model` turns a float into something else (a cast to an index, a
/// comparison): index arithmetic. f16 holds integers exactly only up to 2048, and `test`'s
/// `bev_query` (bilinear sampling: floor, clamp, flat index) gathered past its table in f16, a
/// panic inside tract. Keeping only that arithmetic in f32 (the float cone above each such
/// operator, through tract's translator filter) still gathered past the table, for a reason not
/// found; a whole stage widened is the rule that holds.
fn has_index_arithmetic(model: &TypedModel) -> bool {
    let is_float = |o: &OutletId| model.outlet_fact(*o).is_ok_and(|f| f.datum_type.is_float());
    model.nodes.iter().any(|n| {
        n.inputs.iter().any(is_float)
            && !(0..n.outputs.len()).any(|i| is_float(&OutletId::new(n.id, i)))
    })
}

/// The typed model of an ONNX stage: parsed, names bound, static input facts from the manifest.
#[cfg(feature = "onnx")]
pub fn onnx_model(
    stage: Stage,
    bytes: &[u8],
    entry: &StageEntry,
) -> Result<TypedModel, BundleError> {
    use tract_onnx::prelude::{Framework as _, InferenceFact, InferenceModelExt as _};
    let engine_err = engine_error(stage);
    let mut model = tract_onnx::onnx()
        .model_for_read(&mut &bytes[..])
        .map_err(engine_err)?;
    check_io_names(stage, &graph_io_names(&model)?, entry)?;
    for (ix, spec) in entry.inputs.iter().enumerate() {
        model = model
            .with_input_fact(ix, InferenceFact::dt_shape(datum(spec.dtype), &spec.shape))
            .map_err(engine_err)?;
    }
    model.into_typed().map_err(engine_err)
}

/// Without the ONNX front end (the ECU build) a folder bundle is refused, not guessed at.
#[cfg(not(feature = "onnx"))]
pub fn onnx_model(stage: Stage, _: &[u8], _: &StageEntry) -> Result<TypedModel, BundleError> {
    Err(BundleError::Format {
        path: stage.name().into(),
        format: satmap_bundle::GraphFormat::Onnx,
        needs: "the `onnx` feature; compile them with `satmap-sim compile` for this engine",
    })
}

/// The names of a graph's inputs (their source nodes) and outputs (their labels), in order.
fn graph_io_names<F, O>(model: &Graph<F, O>) -> Result<(Vec<String>, Vec<String>), BundleError>
where
    F: Fact + Clone + 'static,
    O: std::fmt::Debug + std::fmt::Display + AsRef<dyn Op> + AsMut<dyn Op> + Clone + 'static,
{
    let inputs = model
        .inputs
        .iter()
        .map(|o| model.node(o.node).name.clone())
        .collect();
    let outputs = model
        .outputs
        .iter()
        .map(|&o| {
            model
                .outlet_label(o)
                .unwrap_or(model.node(o.node).name.as_str())
                .to_owned()
        })
        .collect();
    Ok((inputs, outputs))
}

/// Bind by name: the graph's inputs and outputs must carry the manifest's names in the
/// manifest's order (which [`satmap_bundle::StageEntry::check_interface`] has checked is the
/// runtime's). Two same-shape tensors swapped in the graph would otherwise load and run with
/// each buffer fed to the other's place.
fn check_io_names(
    stage: Stage,
    (input_names, output_names): &(Vec<String>, Vec<String>),
    entry: &StageEntry,
) -> Result<(), BundleError> {
    for (what, names, specs) in [
        ("input", input_names, &entry.inputs),
        ("output", output_names, &entry.outputs),
    ] {
        if names.len() != specs.len() {
            return Err(BundleError::Interface {
                stage: stage.name(),
                what,
                tensor: "*".into(),
                found: format!("{} tensors in the graph", names.len()),
                expected: format!("{} tensors", specs.len()),
            });
        }
        for (ix, (name, spec)) in names.iter().zip(specs).enumerate() {
            if *name != spec.name {
                return Err(BundleError::Interface {
                    stage: stage.name(),
                    what,
                    tensor: spec.name.clone(),
                    found: format!("graph {what} {ix} named `{name}`"),
                    expected: format!("`{}` at position {ix}", spec.name),
                });
            }
        }
    }
    Ok(())
}

/// Check a typed model's input and output facts against the manifest.
pub fn check_graph_io(
    stage: Stage,
    model: &TypedModel,
    inputs: &[TensorSpec],
    outputs: &[TensorSpec],
) -> Result<(), BundleError> {
    let check = |what: &'static str, facts: Vec<TractResult<&TypedFact>>, specs: &[TensorSpec]| {
        if facts.len() != specs.len() {
            return Err(BundleError::Interface {
                stage: stage.name(),
                what,
                tensor: "*".into(),
                found: format!("{} tensors in the graph", facts.len()),
                expected: format!("{} tensors", specs.len()),
            });
        }
        for (fact, spec) in facts.into_iter().zip(specs) {
            let fact = fact.map_err(engine_error(stage))?;
            let shape: Option<Vec<usize>> = fact.shape.as_concrete().map(<[usize]>::to_vec);
            if fact.datum_type != datum(spec.dtype) || shape.as_deref() != Some(&spec.shape[..]) {
                return Err(BundleError::Interface {
                    stage: stage.name(),
                    what,
                    tensor: spec.name.clone(),
                    found: format!("{:?} {:?}", fact.datum_type, fact.shape),
                    expected: format!("{:?} {:?}", spec.dtype, spec.shape),
                });
            }
        }
        Ok(())
    };
    check(
        "input",
        (0..model.inputs.len())
            .map(|i| model.input_fact(i))
            .collect(),
        inputs,
    )?;
    check(
        "output",
        (0..model.outputs.len())
            .map(|i| model.output_fact(i))
            .collect(),
        outputs,
    )
}

#[cfg(test)]
mod tests {
    //! What the f16 load relies on in tract 0.23.9's precision translator (issue 40: a test per
    //! assumption on tract's internals): a filter that translates nothing keeps the operators in
    //! f16 (native half arithmetic), the plain translator widens them to f32.
    use tract_nnef::tract_core::floats::FloatPrecisionTranslator;
    use tract_nnef::tract_core::ops::math;
    use tract_nnef::tract_core::transform::ModelTransform as _;

    use super::*;

    /// The element type of the first node whose op is `op`'s.
    fn type_of(model: &TypedModel, op: &str) -> DatumType {
        let node = model
            .nodes()
            .iter()
            .find(|n| n.op.name() == op)
            .unwrap_or_else(|| panic!("no {op} node"));
        model
            .outlet_fact(OutletId::new(node.id, 0))
            .unwrap()
            .datum_type
    }

    #[test]
    fn the_native_filter_keeps_operators_in_f16_and_the_plain_one_widens_them() {
        let (f16, f32) = (f16::datum_type(), f32::datum_type());
        let mut model = TypedModel::default();
        let x = model.add_source("x", f16::fact([4])).unwrap();
        let y = model.wire_node("square", math::mul(), &[x, x]).unwrap()[0];
        let z = model.wire_node("sum", math::add(), &[y, x]).unwrap()[0];
        model.select_output_outlets(&[z]).unwrap();
        let native = FloatPrecisionTranslator::with_filter(f16, f32, |_| false)
            .transform_into(model.clone())
            .unwrap();
        assert_eq!(type_of(&native, "Mul"), f16);
        assert_eq!(type_of(&native, "Add"), f16);
        let widened = FloatPrecisionTranslator::new(f16, f32)
            .transform_into(model)
            .unwrap();
        assert_eq!(type_of(&widened, "Mul"), f32);
        assert_eq!(type_of(&widened, "Add"), f32);
    }
}
