//! The tract graph engine: runs a bundle's stages over the runtime's fixed buffers (std only).
//!
//! Each stage is loaded once from ONNX with its static input facts, optimised, turned into a
//! plan, and given one reused state for the life of the engine (optimisation dominates load
//! time, so the plan is never rebuilt). Inputs are held in reference-counted tensors that are
//! overwritten in place every run, so feeding a stage copies the runtime buffer into tract's
//! memory once and allocates nothing on our side; tract's own intermediate tensors are the
//! graph engine's allocations.
//!
//! Threads: tract runs single-threaded here (the `multithread-mm` feature of `tract-linalg` is
//! off), which keeps every matmul's summation order fixed and the outputs bit-identical across
//! runs. Turning that feature on and passing a multithread executor in the run options splits
//! matmuls across threads; tract's kernels partition output tiles, not reductions, so results
//! stay bit-identical, but we have measured only a 1.24x gain on 2 cores and keep it off.

use std::rc::Rc;

use tract_onnx::prelude::*;

use crate::bundle::{Bundle, BundleError, DType, TensorSpec};
use crate::engine::{Engine, EngineError, EngineErrorKind, Stage};
use crate::model_dims::ModelDims;

/// One loaded stage: its plan's reused state and its input tensors.
struct StageRunner {
    stage: Stage,
    state: TypedSimpleState,
    inputs: Vec<Rc<Tensor>>,
    output_lens: Vec<usize>,
}

impl StageRunner {
    fn load(bundle: &Bundle, stage: Stage) -> Result<Self, BundleError> {
        let entry = bundle.manifest().stage(stage)?;
        let path = bundle.stage_path(stage)?;
        let engine_err = |e: TractError| BundleError::Engine {
            stage: stage.name(),
            message: format!("{e:#}"),
        };
        let mut model = tract_onnx::onnx().model_for_path(&path).map_err(engine_err)?;
        for (ix, spec) in entry.inputs.iter().enumerate() {
            model = model
                .with_input_fact(ix, InferenceFact::dt_shape(datum(spec.dtype), &spec.shape))
                .map_err(engine_err)?;
        }
        let plan = model
            .into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(engine_err)?;
        check_graph_io(stage, &plan, entry.inputs.as_slice(), entry.outputs.as_slice())?;
        let state = plan.spawn().map_err(engine_err)?;
        let inputs = entry
            .inputs
            .iter()
            .map(|spec| Tensor::zero_dt(datum(spec.dtype), &spec.shape).map(Rc::new))
            .collect::<TractResult<Vec<_>>>()
            .map_err(engine_err)?;
        let output_lens = entry.outputs.iter().map(|s| s.shape.iter().product()).collect();
        Ok(Self {
            stage,
            state,
            inputs,
            output_lens,
        })
    }

    fn err(&self, kind: EngineErrorKind) -> EngineError {
        EngineError {
            stage: self.stage,
            kind,
        }
    }

    /// Mutable view of input `ix` as `T`. The state drops its references to the inputs at the
    /// end of every run, so the tensor is uniquely owned here.
    fn input_mut<T: Datum>(&mut self, ix: usize) -> Result<&mut [T], EngineError> {
        let stage = self.stage;
        let err = EngineError {
            stage,
            kind: EngineErrorKind::ShapeMismatch,
        };
        let tensor = self.inputs.get_mut(ix).ok_or(err)?;
        let tensor = Rc::get_mut(tensor).ok_or(EngineError {
            stage,
            kind: EngineErrorKind::Backend(BACKEND_INPUT_SHARED),
        })?;
        tensor.as_slice_mut::<T>().map_err(|_| err)
    }

    fn write_input<T: Datum + Copy>(&mut self, ix: usize, src: &[T]) -> Result<(), EngineError> {
        let dst = self.input_mut::<T>(ix)?;
        if dst.len() != src.len() {
            return Err(self.err(EngineErrorKind::ShapeMismatch));
        }
        dst.copy_from_slice(src);
        Ok(())
    }

    /// Run the stage and copy each f32 output into the matching buffer of `outs`.
    fn run(&mut self, outs: &mut [&mut [f32]]) -> Result<(), EngineError> {
        if outs.len() != self.output_lens.len()
            || outs.iter().zip(&self.output_lens).any(|(o, &n)| o.len() != n)
        {
            return Err(self.err(EngineErrorKind::ShapeMismatch));
        }
        let inputs: TVec<TValue> = self.inputs.iter().map(|t| TValue::Var(Rc::clone(t))).collect();
        let results = self
            .state
            .run(inputs)
            .map_err(|_| self.err(EngineErrorKind::Backend(BACKEND_RUN_FAILED)))?;
        if results.len() != outs.len() {
            return Err(self.err(EngineErrorKind::ShapeMismatch));
        }
        for (value, out) in results.iter().zip(outs.iter_mut()) {
            let src = value
                .as_slice::<f32>()
                .map_err(|_| self.err(EngineErrorKind::ShapeMismatch))?;
            if src.len() != out.len() {
                return Err(self.err(EngineErrorKind::ShapeMismatch));
            }
            out.copy_from_slice(src);
        }
        Ok(())
    }
}

/// Backend code: an input tensor was still shared when the next run wanted to write it.
pub const BACKEND_INPUT_SHARED: u32 = 1;
/// Backend code: tract returned an error while running the plan.
pub const BACKEND_RUN_FAILED: u32 = 2;

fn datum(dtype: DType) -> DatumType {
    match dtype {
        DType::U8 => DatumType::U8,
        DType::I64 => DatumType::I64,
        DType::F32 => DatumType::F32,
    }
}

/// Check the optimised plan's input and output facts against the manifest.
fn check_graph_io(
    stage: Stage,
    plan: &TypedSimplePlan,
    inputs: &[TensorSpec],
    outputs: &[TensorSpec],
) -> Result<(), BundleError> {
    let model = plan.model();
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
            let fact = fact.map_err(|e| BundleError::Engine {
                stage: stage.name(),
                message: format!("{e:#}"),
            })?;
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
        (0..model.inputs.len()).map(|i| model.input_fact(i)).collect(),
        inputs,
    )?;
    check(
        "output",
        (0..model.outputs.len()).map(|i| model.output_fact(i)).collect(),
        outputs,
    )
}

/// All five stages of a bundle, loaded into tract, implementing [`Engine`].
pub struct TractEngine {
    dims: ModelDims,
    runners: Vec<StageRunner>,
}

impl core::fmt::Debug for TractEngine {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("TractEngine").field("dims", &self.dims).finish_non_exhaustive()
    }
}

impl TractEngine {
    /// Load, optimise and plan every stage of `bundle`.
    pub fn load(bundle: &Bundle) -> Result<Self, BundleError> {
        let runners = Stage::ALL
            .iter()
            .map(|&stage| StageRunner::load(bundle, stage))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            dims: bundle.dims().clone(),
            runners,
        })
    }

    /// Open the bundle in `dir` and load it.
    pub fn open(dir: impl AsRef<std::path::Path>) -> Result<Self, BundleError> {
        Self::load(&Bundle::open(dir)?)
    }

    fn runner(&mut self, stage: Stage) -> &mut StageRunner {
        // Stage::ALL order is the load order, so the index is the stage's position.
        &mut self.runners[stage as usize]
    }
}

impl Engine for TractEngine {
    fn dims(&self) -> &ModelDims {
        &self.dims
    }

    fn encode_image(
        &mut self,
        camera: usize,
        image_rgb: &[u8],
        value_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let r = self.runner(Stage::ImageEncoder);
        r.write_input(0, image_rgb)?;
        let index = i64::try_from(camera).map_err(|_| r.err(EngineErrorKind::ShapeMismatch))?;
        r.write_input(1, &[index])?;
        r.run(&mut [value_out])
    }

    fn bev_query(
        &mut self,
        can_bus: &[f32; 18],
        query_out: &mut [f32],
        gkt_weights_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let r = self.runner(Stage::BevQuery);
        r.write_input(0, can_bus)?;
        r.run(&mut [query_out, gkt_weights_out])
    }

    fn bev_encode(
        &mut self,
        query: &[f32],
        gathered: &[f32],
        camera_bev_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let r = self.runner(Stage::BevEncoder);
        r.write_input(0, query)?;
        r.write_input(1, gathered)?;
        r.run(&mut [camera_bev_out])
    }

    fn encode_satellite(
        &mut self,
        crop_rgb: &[u8],
        satellite_bev_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let r = self.runner(Stage::SatelliteEncoder);
        r.write_input(0, crop_rgb)?;
        r.run(&mut [satellite_bev_out])
    }

    fn decode_map(
        &mut self,
        camera_bev: &[f32],
        satellite_bev: &[f32],
        class_logits_out: &mut [f32],
        points_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let r = self.runner(Stage::MapDecoder);
        r.write_input(0, camera_bev)?;
        r.write_input(1, satellite_bev)?;
        r.run(&mut [class_logits_out, points_out])
    }
}
