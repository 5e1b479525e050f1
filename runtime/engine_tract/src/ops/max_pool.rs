//! The ResNet stems' max pooling as a native op: separable, vectorisable, split over channels
//! on the engine's pool.
//!
//! tract 0.23.9 runs a `MaxPool` one output row and kernel row at a time, its stride-2 taps
//! through a stepped iterator, on one thread: 2.5 ms of `nano`'s image encoder (one camera, 64
//! channels, 96 x 160 -> 48 x 80), about the time of one of its 3x3 convolutions.
//! [`native_max_pools`] rewrites every f32 `MaxPool` of NCHW (batch 1) or CHW over two
//! spatial axes without index output into a [`MaxPool2d`]: per input row the maximum over the
//! kernel columns at every column (contiguous passes), kept at the stride's columns, then per
//! output row the maximum of the kernel rows' results.
//!
//! Bit for bit: the kernel (`satmap_kernels::pooling`, whose doc states the rule) folds each
//! window in tract's order with tract's strictly-greater rule, so the separable order gives
//! tract's bits. This module's tests check them against tract's plan, signed zeros
//! and NaNs included, and on every stage of the committed default bundle.
//!
//! Not rewritten: NCHW 2 x 2 windows without dilation. tract 0.23.9 has a path of its own for
//! them (`try_nchw_2x2_f32`: `_mm256_max_ps` over stride-1 interiors, `f32::max` elsewhere),
//! which keeps the later of equal taps and lets a NaN through where the rule above does not (a
//! stride-1 pool of signed zeros and NaNs differed); they stay tract's. No committed model has
//! one (the stems pool 3 x 3).

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::cnn::MaxPool;
use tract_nnef::tract_core::ops::nn::DataFormat;

use satmap_kernels::pooling::{PoolWindow, max_pool_plane};

use crate::gemm;
use crate::graph::matching::replace_with_op;
use crate::ops::unfold::{Unfold, with_batch};
use crate::pool;

/// A 2-D max pooling of `[1, C, H, W]` or `[C, H, W]` f32 (see the module doc).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct MaxPool2d {
    /// The windows: input channels and map, kernel, strides, dilations, padding before, output
    /// map (the geometry a convolution's patches have).
    pub window: Unfold,
    /// Whether input and output carry a batch axis of 1 (NCHW; CHW otherwise).
    pub batch_axis: bool,
}

impl MaxPool2d {
    /// One channel plane's windows, as the kernel takes them.
    fn plane_window(&self) -> PoolWindow {
        let [_, h, w] = self.window.input;
        PoolWindow {
            input: [h, w],
            kernel: self.window.kernel,
            strides: self.window.strides,
            dilations: self.window.dilations,
            pad_before: self.window.pad_before,
            output: self.window.output,
        }
    }
}

impl Op for MaxPool2d {
    fn name(&self) -> StaticName {
        "MaxPool2d".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        Ok(vec![format!(
            "{:?} kernel {:?} strides {:?} -> {:?} [native]",
            self.window.input, self.window.kernel, self.window.strides, self.window.output
        )])
    }
    op_as_typed_op!();
}

impl EvalOp for MaxPool2d {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let x = args_1!(inputs);
        let [c, h, w] = self.window.input;
        let [oh, ow] = self.window.output;
        let want = with_batch(self.batch_axis, self.window.input);
        ensure!(
            x.shape() == &*want,
            "MaxPool2d input {:?}, expected {want:?}",
            x.shape()
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let mut out = gemm::output_tensor(&with_batch(self.batch_axis, [c, oh, ow]))?;
        let mut po = out.try_as_plain_ram_mut()?;
        let ys = po.as_slice_mut::<f32>()?;
        if ys.is_empty() {
            return Ok(tvec!(out.into_tvalue()));
        }
        // Channels a task: eight tasks in all, split over the pool when worth its dispatch.
        let parallel = pool::worth_threads(c * h * w * self.window.kernel[0]);
        let per_task = c.div_ceil(8).max(1);
        let (window, plane_out) = (self.plane_window(), oh * ow);
        let done = pool::on_threads(parallel, ys, per_task * plane_out, |t, outs| {
            gemm::pack::with_scratch(window.scratch_len(), |scratch| {
                outs.chunks_exact_mut(plane_out).enumerate().all(|(i, o)| {
                    let ch = t * per_task + i;
                    max_pool_plane(&window, &xs[ch * h * w..][..h * w], o, scratch)
                })
            })
        });
        ensure!(done, "max pooling task failed");
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for MaxPool2d {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 1 && inputs[0].datum_type == f32::datum_type());
        let [c, _, _] = self.window.input;
        let [oh, ow] = self.window.output;
        Ok(tvec!(f32::fact(&*with_batch(self.batch_axis, [c, oh, ow]))))
    }

    as_op!();
}

/// Rewrite every f32 `MaxPool` of a decluttered `model` over two spatial axes, NCHW with batch
/// 1 or CHW, without index output, into a [`MaxPool2d`]; returns the model and the number
/// rewritten.
///
/// # Errors
/// tract refusing a patch (an inconsistent model).
pub fn native_max_pools(mut model: TypedModel) -> TractResult<(TypedModel, usize)> {
    let names: Vec<String> = model.nodes().iter().map(|n| n.name.clone()).collect();
    let mut done = 0;
    for name in names {
        let id = model.node_id_by_name(&name)?;
        let node = model.node(id);
        let Some(pool) = node.op_as::<MaxPool>() else {
            continue;
        };
        let spec = &pool.pool_spec;
        if pool.with_index_outputs.is_some()
            || !matches!(spec.data_format, DataFormat::NCHW | DataFormat::CHW)
        {
            continue;
        }
        let fact = model.outlet_fact(node.inputs[0])?;
        if fact.datum_type != f32::datum_type() {
            continue;
        }
        let Some(xs) = fact.shape.as_concrete() else {
            continue;
        };
        let batch_axis = spec.data_format == DataFormat::NCHW;
        let (c, h, w) = match *xs {
            [1, c, h, w] if batch_axis => (c, h, w),
            [c, h, w] if !batch_axis => (c, h, w),
            _ => continue,
        };
        let Some(window) = Unfold::of_pool(spec, [c, h, w]) else {
            continue;
        };
        if batch_axis && window.kernel == [2, 2] && window.dilations == [1, 1] {
            continue;
        }
        let op = MaxPool2d { window, batch_axis };
        let x = node.inputs[0];
        replace_with_op(&mut model, &[x], id, format!("{name}.max_pool"), op)?;
        done += 1;
    }
    Ok((model, done))
}

#[cfg(test)]
mod tests {
    //! The op against tract's plan of the same `MaxPool`, bit for bit: ResNet's stem pooling,
    //! odd maps, wide strides, dilation, windows wholly in the padding, signed zeros and NaNs;
    //! and every stage of the committed default bundle.
    use super::*;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{assert_pass_keeps_stage_bits, bits, on_two_threads, run_optimized};
    use tract_nnef::tract_core::ops::cnn::{PaddingSpec, PoolSpec};

    /// `(channels, [h, w], kernel, stride, pad, dilation, batch axis)`.
    type Shape = (usize, [usize; 2], usize, usize, usize, usize, bool);

    fn pool_model((c, [h, w], k, s, p, d, batch): Shape) -> (TypedModel, TVec<TValue>) {
        let shape: Vec<usize> = if batch {
            vec![1, c, h, w]
        } else {
            vec![c, h, w]
        };
        let mut model = TypedModel::default();
        let x = model.add_source("x", f32::fact(&shape)).unwrap();
        let pool = MaxPool {
            pool_spec: PoolSpec {
                data_format: if batch {
                    DataFormat::NCHW
                } else {
                    DataFormat::CHW
                },
                kernel_shape: tvec!(k, k),
                padding: PaddingSpec::Explicit(tvec!(p, p), tvec!(p, p)),
                dilations: Some(tvec!(d, d)),
                strides: Some(tvec!(s, s)),
                input_channels: c,
                output_channels: c,
            },
            with_index_outputs: None,
        };
        let y = model.wire_node("pool", pool, &[x]).unwrap();
        model.select_output_outlets(&y).unwrap();
        // Coarse values so that windows tie, with signed zeros and NaNs among them.
        let values: Vec<f32> = (0..c * h * w)
            .map(|i| match (i * 7919) % 13 {
                0 => 0.0,
                1 => -0.0,
                2 if i % 5 == 0 => f32::NAN,
                v => (v as f32 - 6.0) * 0.5,
            })
            .collect();
        let input = Tensor::from_shape(&shape, &values).unwrap();
        (model.into_decluttered().unwrap(), tvec![input.into()])
    }

    #[test]
    fn pools_compute_tracts_bits() {
        let cases: [Shape; 8] = [
            // nano's stem pooling; an odd map; a stride wider than the kernel; dilation; a
            // padding wider than the map's edge windows; no batch axis (also 2 x 2 windows at
            // strides 1 and 2: tract's row-span path, which keeps the rule). Issue 40: a test
            // per assumption on tract's internals; here that every path of tract's we replace
            // keeps the first of equal taps and lets no NaN win.
            (64, [96, 160], 3, 2, 1, 1, true),
            (5, [13, 17], 3, 2, 1, 1, true),
            (3, [11, 10], 3, 4, 0, 1, true),
            (4, [15, 14], 3, 1, 2, 2, true),
            (2, [3, 4], 3, 1, 2, 1, true),
            (6, [9, 7], 3, 2, 1, 1, false),
            (4, [12, 20], 2, 1, 0, 1, false),
            (4, [12, 20], 2, 2, 0, 1, false),
        ];
        for case in cases {
            let (model, inputs) = pool_model(case);
            let (native, n) = native_max_pools(model.clone()).unwrap();
            assert_eq!(n, 1, "{case:?}");
            assert!(native.nodes().iter().any(|n| n.op_is::<MaxPool2d>()));
            let want = run_optimized(model, &inputs);
            let got = run_optimized(native, &inputs);
            assert_eq!(got[0].shape(), want[0].shape(), "{case:?}");
            assert_eq!(bits(&got[0]), bits(&want[0]), "{case:?}");
        }
    }

    #[test]
    fn nchw_two_by_two_pools_stay_tracts() {
        // tract 0.23.9's own 2 x 2 path picks other taps on ties and NaNs (module doc): the
        // stride-1 case below differed bit for bit when it was rewritten.
        for stride in [1, 2, 3] {
            let (model, _) = pool_model((4, [12, 20], 2, stride, 0, 1, true));
            assert_eq!(native_max_pools(model).unwrap().1, 0, "stride {stride}");
        }
    }

    #[test]
    fn pools_on_two_threads_compute_the_same_bits() {
        let (model, inputs) = pool_model((64, [96, 160], 3, 2, 1, 1, true));
        let want = run_optimized(model.clone(), &inputs);
        let native = native_max_pools(model).unwrap().0;
        let got = on_two_threads(|| run_optimized(native, &inputs));
        assert_eq!(bits(&got[0]), bits(&want[0]));
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let op = MaxPool2d {
            window: Unfold {
                input: [2, 4, 4],
                kernel: [3, 3],
                strides: [2, 2],
                dilations: [1, 1],
                pad_before: [1, 1],
                output: [2, 2],
            },
            batch_axis: true,
        };
        let x = Tensor::zero::<f32>(&[1, 3, 4, 4]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
    }

    #[test]
    fn rewritten_stages_compute_what_they_computed_bit_for_bit() {
        assert_pass_keeps_stage_bits(Pass::MaxPools, native_max_pools);
    }
}
