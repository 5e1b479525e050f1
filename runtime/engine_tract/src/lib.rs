//! `satmap-engine-tract` (std): the graph engine over tract: loading compiled bundles, the
//! kernel-family rule, threads, and the engine's graph passes, custom ops and their matching
//! helpers. May import: `satmap-core`, `satmap-bundle`, `satmap-kernels`, tract.
//!
//! The engine runs a bundle's stages over the runtime's fixed buffers (std only).
//!
//! Each stage is loaded once from the bytes the bundle verified (never re-read by path): the NNEF
//! graph of a compiled bundle through tract-nnef and tract-core alone (the ECU build, feature
//! `tract`), or, with the `onnx` feature, the ONNX file of a folder bundle through tract's ONNX
//! front end, given its static input facts. Its inputs and outputs are bound by name, it is
//! optimised, turned into a plan, and given one reused state for the life of the engine
//! (optimisation dominates load time, so the plan is never rebuilt). Inputs are held in reference-counted tensors that are
//! overwritten in place every run, so feeding a stage copies the runtime buffer into tract's
//! memory once and allocates nothing on our side; tract's own intermediate tensors are the
//! graph engine's allocations.
//!
//! Threads: one by default. [`TractEngine::set_threads`] gives the engine a private pool of N
//! threads (never rayon's global pool, whose size the process does not control) and every run
//! executes inside it: tract's matmuls split over output tiles and its row kernels over rows,
//! each reduction stays serial on one thread, so the outputs are bit-identical for any N
//! (`tests/integration/threads.rs` asserts it over a replay).
//!
//! Here: [`TractEngine`] (loading every stage, threads, the [`Engine`] calls). Beside it:
//! `runner` (one stage's plan, state and confined runs), [`kernel_family`](mod@kernel_family) (the one rule naming
//! tract's kernels on this CPU), and three folders whose names say what they hold:
//! [`graph`] (the checked parse of a stage, and the matching helpers every pass uses), [`ops`]
//! (the native ops, each with the pass that puts it into a plan), [`passes`] (the driver,
//! [`passes::rewrite`], and the passes that only reshape tract's own graph); [`gemm`] and
//! [`pool`] are the product driver and the thread split the ops run on.

#![deny(missing_docs)]

use std::num::NonZeroUsize;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;

use tract_linalg::multithread::{Executor, multithread_tract_scope};

pub mod gemm;
pub mod graph;
pub mod kernel_family;
pub mod ops;
pub mod passes;
pub mod pool;
mod runner;
#[cfg(test)]
mod test_support;
pub mod vector_state;

use tract_nnef::framework::Nnef;
use tract_nnef::prelude::*;

use satmap_bundle::{Bundle, BundleError, GraphFormat, Precision};
use satmap_core::engine::{BackendFault, Engine, EngineError, EngineErrorKind, Stage};
use satmap_core::features::{FeaturesMut, FeaturesRef};
use satmap_core::model_dims::ModelDims;

// The load steps `satmap-translate` runs too, on the host, before it writes a stage.
pub use graph::load::{HalfArithmetic, parse_stage_graph};
pub use graph::load::{check_graph_io, engine_error, nnef_model, onnx_model};
pub(crate) use graph::load::{confined, datum};
pub use kernel_family::{KernelFamily, kernel_family};
pub use ops::range_probe::RangeLog;
pub use passes::rewrite::Rewrites;
use runner::{StageRunner, on_engine_threads, panic_message};
pub use satmap_kernels::qgemm::histogram::RangeMethod;

/// All five stages of a bundle, loaded into tract, implementing [`Engine`].
pub struct TractEngine {
    dims: ModelDims,
    runners: Vec<StageRunner>,
    executor: Executor,
    threads: NonZeroUsize,
}

/// What an int8 bundle with calibrated activation ranges (manifest `[int8]`) computes in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Int8Arithmetic {
    /// Its linear layers in int8 with i32 sums (W8A8) on this CPU's integer tier.
    #[default]
    Integer,
    /// Its weights widened to f32, every product in f32 (W8A32): the form before calibration.
    Widened,
}

/// The choices of a load ([`TractEngine::load_options`]).
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// An f16 bundle's arithmetic.
    pub half: HalfArithmetic,
    /// An int8 bundle's arithmetic.
    pub int8: Int8Arithmetic,
    /// A calibration run: every layer the int8 passes take gets a probe recording its input's
    /// range into this log (and runs in f32).
    pub observe: Option<RangeLog>,
}

/// Most threads [`TractEngine::set_threads`] starts (more than any ECU or host core count
/// this runtime targets).
pub const MAX_ENGINE_THREADS: usize = 64;

/// The engine's thread pool could not be started (the OS refused a thread).
#[derive(Debug, thiserror::Error)]
#[error("cannot start a pool of {threads} engine threads: {reason}")]
pub struct ThreadPoolError {
    /// Threads asked for.
    pub threads: usize,
    /// The operating system's reason.
    pub reason: String,
}

impl core::fmt::Debug for TractEngine {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("TractEngine")
            .field("dims", &self.dims)
            .finish_non_exhaustive()
    }
}

impl TractEngine {
    /// Load, optimise and plan every stage of `bundle`; an f16 bundle widened to f32
    /// arithmetic. Decided by count: on the `test` bundle under qemu's Cortex-A76, tract's f16
    /// path retired 1.5-2x the instructions of the f32 one on the encoders (docs/perf.md, "On
    /// ARM"), so f16 arithmetic is a choice ([`TractEngine::load_with`]), not the default.
    pub fn load(bundle: &Bundle) -> Result<Self, BundleError> {
        Self::load_options(bundle, &LoadOptions::default())
    }

    /// [`TractEngine::load`] with an f16 bundle's arithmetic chosen by the caller (an f32 or
    /// int8 bundle ignores it). [`HalfArithmetic::Native`] on a core without f16 arithmetic
    /// runs tract's portable f16 kernels: correct, and slow.
    pub fn load_with(bundle: &Bundle, half: HalfArithmetic) -> Result<Self, BundleError> {
        Self::load_options(
            bundle,
            &LoadOptions {
                half,
                ..LoadOptions::default()
            },
        )
    }

    /// [`TractEngine::load`] with every choice of [`LoadOptions`].
    pub fn load_options(bundle: &Bundle, options: &LoadOptions) -> Result<Self, BundleError> {
        // tract-core's operators only: a graph that needs another registry is refused at load.
        let nnef = tract_nnef::nnef();
        // tract panics on some graphs it cannot run (an axis past the rank, a stride of 0):
        // a clean error naming the stage instead. Stack overflow and hangs are not panics; the
        // structural check before tract (`graph_check`) keeps those graphs away.
        let runners = Stage::ALL
            .iter()
            .map(|&stage| confined(stage, || StageRunner::load(bundle, &nnef, stage, options)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            dims: bundle.dims().clone(),
            runners,
            executor: Executor::SingleThread,
            threads: NonZeroUsize::MIN,
        })
    }

    /// The arithmetic `stage` of an f16 bundle runs in (a stage with index arithmetic runs
    /// [`HalfArithmetic::Widened`] whatever was asked); `None` for an f32 or int8 bundle.
    #[must_use]
    pub fn half_arithmetic(&self, stage: Stage) -> Option<HalfArithmetic> {
        self.runners.get(stage as usize)?.half
    }

    /// Run every later stage on `threads` threads: 1 is the calling thread alone; more start a
    /// private pool of `threads` workers named `satmap-engine-<i>` (the calling thread waits
    /// while they run). The outputs do not depend on the count. On error the engine keeps its
    /// previous setting and stays usable.
    ///
    /// # Errors
    /// [`ThreadPoolError`] when the operating system refuses a thread.
    pub fn set_threads(&mut self, threads: NonZeroUsize) -> Result<(), ThreadPoolError> {
        // A million threads aborted the process inside rayon (issue 38): refused, named.
        if threads.get() > MAX_ENGINE_THREADS {
            return Err(ThreadPoolError {
                threads: threads.get(),
                reason: format!("at most {MAX_ENGINE_THREADS} engine threads"),
            });
        }
        self.executor = if threads.get() == 1 {
            Executor::SingleThread
        } else {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads.get())
                .thread_name(|i| format!("satmap-engine-{i}"))
                .build()
                .map_err(|e| ThreadPoolError {
                    threads: threads.get(),
                    reason: e.to_string(),
                })?;
            Executor::MultiThread(Arc::new(pool))
        };
        self.threads = threads;
        Ok(())
    }

    /// Run `stage` once more on the inputs of its last run, timing every node of its plan:
    /// wall milliseconds summed per operator kind (tract's op name; a matrix product also by
    /// its shape and kernel, `OptMatMul m:64 k:576 n:3840 avx512_mmm_f32_16x12`, where tract
    /// reports them), largest first. A measurement tool (`satmap-sim bench-stages --ops`), not a
    /// step path: it allocates.
    ///
    /// # Errors
    /// The run failing, as [`Engine`]'s stage calls report it.
    pub fn profile_ops(&mut self, stage: Stage) -> Result<Vec<(String, f64)>, EngineError> {
        let (r, executor) = self.runner(stage);
        let inputs: TVec<TValue> = r
            .inputs
            .iter()
            .map(|t| TValue::from_const(Arc::clone(t)))
            .collect();
        let mut totals: Vec<(String, f64)> = Vec::new();
        let state = &mut r.state;
        let run = on_engine_threads(executor, || {
            state.run_plan_with_eval(inputs, |ctx, op_state, node, node_inputs| {
                let t = std::time::Instant::now();
                let out = vector_state::eval_node(ctx, op_state, node, node_inputs);
                let ms = t.elapsed().as_secs_f64() * 1e3;
                let name = op_key(node.op());
                match totals.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, total)) => *total += ms,
                    None => totals.push((name, ms)),
                }
                out
            })
        });
        if let Err(e) = run {
            r.last_error = Some(format!("{e:#}"));
            return Err(r.err(EngineErrorKind::Backend(BackendFault::RunFailed)));
        }
        totals.sort_by(|a, b| b.1.total_cmp(&a.1));
        Ok(totals)
    }

    /// What the load-time rewrites put into `stage`'s plan: how many of its ops run as the
    /// engine's native kernels ([`rewrite`](crate::passes::rewrite)); all zero for a stage that did not load.
    #[must_use]
    pub fn rewrites(&self, stage: Stage) -> Rewrites {
        self.runners
            .get(stage as usize)
            .map_or_else(Rewrites::default, |r| r.rewrites)
    }

    /// Threads the stages run on (see [`TractEngine::set_threads`]).
    #[must_use]
    pub fn threads(&self) -> NonZeroUsize {
        self.threads
    }

    /// Open the bundle at `path` (a compiled bundle file or a folder) and load it.
    pub fn open(path: impl AsRef<std::path::Path>) -> Result<Self, BundleError> {
        Self::load(&Bundle::open(path)?)
    }

    /// tract's message for the last failed run of `stage`, if any.
    #[must_use]
    pub fn last_error(&self, stage: Stage) -> Option<&str> {
        self.runners.get(stage as usize)?.last_error.as_deref()
    }

    /// The stage's runner and the executor it runs in.
    fn runner(&mut self, stage: Stage) -> (&mut StageRunner, &Executor) {
        // Stage::ALL order is the load order, so the index is the stage's position.
        (&mut self.runners[stage as usize], &self.executor)
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
        let (r, executor) = self.runner(Stage::ImageEncoder);
        r.write_input(0, image_rgb)?;
        let index =
            i64::try_from(camera).map_err(|_| r.err(EngineErrorKind::CameraIndex { camera }))?;
        r.write_input(1, &[index])?;
        r.run(executor, &mut [value_out.into()])
    }

    fn bev_query(
        &mut self,
        can_bus: &[f32; 18],
        query_out: &mut [f32],
        gkt_weights_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let (r, executor) = self.runner(Stage::BevQuery);
        r.write_input(0, can_bus)?;
        r.run(executor, &mut [query_out.into(), gkt_weights_out.into()])
    }

    fn bev_encode(
        &mut self,
        query: &[f32],
        gathered: &[f32],
        camera_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError> {
        let (r, executor) = self.runner(Stage::BevEncoder);
        r.write_input(0, query)?;
        r.write_input(1, gathered)?;
        r.run(executor, &mut [camera_bev_out])
    }

    fn encode_satellite(
        &mut self,
        crop_rgb: &[u8],
        satellite_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError> {
        let (r, executor) = self.runner(Stage::SatelliteEncoder);
        r.write_input(0, crop_rgb)?;
        r.run(executor, &mut [satellite_bev_out])
    }

    fn decode_map(
        &mut self,
        camera_bev: FeaturesRef<'_>,
        satellite_bev: FeaturesRef<'_>,
        class_logits_out: &mut [f32],
        points_out: &mut [f32],
    ) -> Result<(), EngineError> {
        let (r, executor) = self.runner(Stage::MapDecoder);
        r.write_features(0, camera_bev)?;
        r.write_features(1, satellite_bev)?;
        r.run(executor, &mut [class_logits_out.into(), points_out.into()])
    }
}

/// The key [`TractEngine::profile_ops`] sums a node's time under: tract's op name, and for a
/// matrix product its `m`, `k`, `n` and kernel from tract's own description of the op
/// (`Mult: m:64 k:576 n:3840 with [avx512_mmm_f32_16x12]`), so that one shape's cost shows;
/// the native products describe themselves the same way, with `native` for the kernel.
fn op_key(op: &dyn Op) -> String {
    let name = op.name();
    let products = [
        "OptMatMul",
        "PackedLinear",
        "UnfoldConv",
        "BatchedProduct",
        "PointwiseConv",
    ];
    if !products.contains(&&*name) {
        return name.into_owned();
    }
    let info = op.info().unwrap_or_default();
    match info.iter().find_map(|l| l.strip_prefix("Mult: ")) {
        Some(mult) => format!("{name} {}", mult.replace(" with [", " ").replace(']', "")),
        None => name.into_owned(),
    }
}

#[cfg(test)]
mod op_key_tests {
    //! The profile's key: a matrix product by its shape and kernel, anything else by name.
    use super::*;
    use tract_nnef::tract_core::ops::einsum::EinSum;

    #[test]
    fn a_matmul_is_keyed_by_its_shape_and_kernel_other_ops_by_name() {
        let mut model = TypedModel::default();
        let a = model.add_source("a", f32::fact([64, 32])).unwrap();
        let b = model
            .add_const("b", Tensor::zero::<f32>(&[32, 48]).unwrap())
            .unwrap();
        let op = EinSum {
            axes: "mk,kn->mn".parse().unwrap(),
            operating_dt: f32::datum_type(),
            q_params: None,
        };
        let c = model.wire_node("mm", op, &[a, b]).unwrap();
        model.select_output_outlets(&c).unwrap();
        let model = model.into_optimized().unwrap();
        let keys: Vec<String> = model.nodes().iter().map(|n| op_key(n.op())).collect();
        let mm = keys
            .iter()
            .find(|k| k.starts_with("OptMatMul "))
            .expect("an OptMatMul");
        assert!(mm.starts_with("OptMatMul m:64 k:32 n:48 "), "{mm}");
        assert!(!mm.contains('[') && !mm.contains("with"), "{mm}");
        assert!(keys.iter().any(|k| k == "Source"), "{keys:?}");
    }
}
