//! [`StageRunner`]: one loaded stage (its plan's reused state, its input tensors, what the
//! load-time rewrites put in it), how a run is confined (panics caught, tract's message kept)
//! and put on the engine's threads, and the backend codes of its errors.

use super::*;
use crate::passes::rewrite::Quantisation;

/// One loaded stage: its plan's reused state and its input tensors.
pub(super) struct StageRunner {
    pub(super) stage: Stage,
    pub(super) state: TypedSimpleState,
    pub(super) inputs: Vec<Arc<Tensor>>,
    pub(super) output_lens: Vec<usize>,
    /// What the load-time rewrites put into this stage's plan.
    pub(super) rewrites: Rewrites,
    /// tract's message of the last failed run (the core error carries only a code).
    pub(super) last_error: Option<String>,
    /// The arithmetic of an f16 stage (`None`: an f32 or int8 graph).
    pub(super) half: Option<HalfArithmetic>,
}

impl StageRunner {
    pub(super) fn load(
        bundle: &Bundle,
        nnef: &Nnef,
        stage: Stage,
        options: &LoadOptions,
    ) -> Result<Self, BundleError> {
        let half = options.half;
        let entry = bundle.manifest().stage(stage)?;
        let bytes = bundle.read_stage(stage)?;
        let engine_err = engine_error(stage);
        let (model, half) = match bundle.format() {
            GraphFormat::Nnef => nnef_model(
                stage,
                nnef,
                &bytes,
                entry,
                bundle.manifest().precision,
                half,
            )?,
            GraphFormat::Onnx => (onnx_model(stage, &bytes, entry)?, None),
        };
        drop(bytes);
        let quantisation = quantisation(bundle, stage, options).map_err(engine_err)?;
        let (model, rewrites) = model
            .into_decluttered()
            .and_then(|m| crate::passes::rewrite::optimise(m, &quantisation))
            .map_err(engine_err)?;
        let plan = model.into_runnable().map_err(engine_err)?;
        check_graph_io(
            stage,
            plan.model(),
            entry.inputs.as_slice(),
            entry.outputs.as_slice(),
        )?;
        let state = plan.spawn().map_err(engine_err)?;
        let inputs = entry
            .inputs
            .iter()
            .map(|spec| Tensor::zero_dt(datum(spec.dtype), &spec.shape).map(Arc::new))
            .collect::<TractResult<Vec<_>>>()
            .map_err(engine_err)?;
        let output_lens = entry
            .outputs
            .iter()
            .map(|s| s.shape.iter().product())
            .collect();
        Ok(Self {
            stage,
            state,
            inputs,
            output_lens,
            rewrites,
            last_error: None,
            half,
        })
    }

    pub(super) fn err(&self, kind: EngineErrorKind) -> EngineError {
        EngineError {
            stage: self.stage,
            kind,
        }
    }

    /// Copy `src` into input `ix` (as `T`).
    pub(super) fn write_input<T: Datum + Copy>(
        &mut self,
        ix: usize,
        src: &[T],
    ) -> Result<(), EngineError> {
        self.with_input(ix, |dst: &mut [T]| {
            if dst.len() == src.len() {
                dst.copy_from_slice(src);
                Ok(())
            } else {
                Err(EngineErrorKind::ShapeMismatch {
                    expected: dst.len(),
                    got: src.len(),
                })
            }
        })
    }

    /// Copy the feature map `src` into input `ix`, widened to f32 (the graphs take f32).
    pub(super) fn write_features(
        &mut self,
        ix: usize,
        src: FeaturesRef<'_>,
    ) -> Result<(), EngineError> {
        self.with_input(ix, |dst: &mut [f32]| {
            src.load(dst).map_err(|m| EngineErrorKind::ShapeMismatch {
                // `load`'s map is the given slice here, the tensor the expected length.
                expected: m.got,
                got: m.expected,
            })
        })
    }

    /// `write` on input `ix` as a slice of `T`. The state drops its references to the inputs
    /// at the end of every run, so the tensor is uniquely owned here.
    fn with_input<T: Datum>(
        &mut self,
        ix: usize,
        write: impl FnOnce(&mut [T]) -> Result<(), EngineErrorKind>,
    ) -> Result<(), EngineError> {
        let stage = self.stage;
        let err = |kind| EngineError { stage, kind };
        let tensor = self
            .inputs
            .get_mut(ix)
            .ok_or(err(EngineErrorKind::Backend(BackendFault::NoSuchInput)))?;
        let tensor =
            Arc::get_mut(tensor).ok_or(err(EngineErrorKind::Backend(BackendFault::InputShared)))?;
        let mut view = tensor
            .try_as_plain_ram_mut()
            .map_err(|_| err(EngineErrorKind::Backend(BackendFault::InputDtype)))?;
        let dst = view
            .as_slice_mut::<T>()
            .map_err(|_| err(EngineErrorKind::Backend(BackendFault::InputDtype)))?;
        write(dst).map_err(err)
    }

    /// Run the stage and store each f32 output into the matching buffer of `outs`, in that
    /// buffer's storage.
    pub(super) fn run(
        &mut self,
        executor: &Executor,
        outs: &mut [FeaturesMut<'_>],
    ) -> Result<(), EngineError> {
        if outs.len() != self.output_lens.len() {
            return Err(self.err(EngineErrorKind::Backend(BackendFault::OutputCount)));
        }
        for (out, &n) in outs.iter().zip(&self.output_lens) {
            if out.len() != n {
                return Err(self.err(EngineErrorKind::ShapeMismatch {
                    expected: n,
                    got: out.len(),
                }));
            }
        }
        let inputs: TVec<TValue> = self
            .inputs
            .iter()
            .map(|t| TValue::from_const(Arc::clone(t)))
            .collect();
        let state = &mut self.state;
        let run = || state.run_plan_with_eval(inputs, vector_state::eval_node);
        // A graph tract panics on (an index past a table that only the step's values reveal)
        // is an error of this stage, not of the process. The state that unwound may hold
        // half a turn (and references to the inputs): a fresh one from the same plan replaces it.
        let results = match catch_unwind(AssertUnwindSafe(|| on_engine_threads(executor, run))) {
            Ok(Ok(results)) => results,
            Ok(Err(e)) => {
                self.last_error = Some(format!("{e:#}"));
                return Err(self.err(EngineErrorKind::Backend(BackendFault::RunFailed)));
            }
            Err(panic) => {
                self.last_error = Some(format!("tract panicked: {}", panic_message(&*panic)));
                let plan = Arc::clone(self.state.plan());
                if let Ok(fresh) = plan.spawn() {
                    self.state = fresh;
                }
                return Err(self.err(EngineErrorKind::Backend(BackendFault::RunPanicked)));
            }
        };
        if results.len() != outs.len() {
            return Err(self.err(EngineErrorKind::Backend(BackendFault::OutputCount)));
        }
        for (value, out) in results.iter().zip(outs.iter_mut()) {
            let src = value
                .try_as_plain_ram()
                .and_then(|v| v.as_slice::<f32>())
                .map_err(|_| self.err(EngineErrorKind::Backend(BackendFault::OutputDtype)))?;
            out.store(src).map_err(|m| {
                self.err(EngineErrorKind::ShapeMismatch {
                    expected: m.expected,
                    got: m.got,
                })
            })?;
        }
        Ok(())
    }
}

/// What `stage`'s load does with its linear layers: probes for a calibration run; int8 for an
/// int8 bundle with calibrated ranges unless the caller asked for widened weights; else f32.
fn quantisation(bundle: &Bundle, stage: Stage, options: &LoadOptions) -> TractResult<Quantisation> {
    if let Some(log) = &options.observe {
        return Ok(Quantisation::Observe {
            log: log.clone(),
            stage: stage.name(),
        });
    }
    let manifest = bundle.manifest();
    match (&manifest.int8, options.int8) {
        (Some(cal), Int8Arithmetic::Integer) if manifest.precision == Precision::Int8 => {
            let tier = satmap_kernels::qgemm::IntTier::chosen()?;
            Ok(Quantisation::Int8 {
                ranges: cal.stage_ranges(stage),
                tier,
            })
        }
        _ => Ok(Quantisation::None),
    }
}

/// The text of a caught panic's payload (`panic!` with a literal or a format).
pub(super) fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("(no message)")
}

/// Run `job` (a whole plan) on the engine's threads, `executor` installed as tract's (and the
/// native ops') executor for it: on a pool, inside it, so the plan's serial ops run on one of
/// its workers and its parallel ops split with the others. Run from the calling thread
/// instead, a pool of N workers plus the caller made N + 1 threads on N cores: between
/// parallel ops the idle workers spun beside the caller's serial ops (`test`'s satellite
/// encoder ran slower on two threads than on one).
pub(super) fn on_engine_threads<R: Send>(executor: &Executor, job: impl FnOnce() -> R + Send) -> R {
    let scoped = || multithread_tract_scope(executor.clone(), job);
    match executor {
        Executor::MultiThread(pool) => pool.install(scoped),
        _ => scoped(),
    }
}
