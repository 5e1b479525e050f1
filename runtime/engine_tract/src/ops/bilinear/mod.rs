//! The whole bilinear deformable sampler as one native kernel: corners, weights, bounds, flat
//! indices and the weighted corner sum, from the sampling coordinates.
//!
//! `satmap_ref.sampling.bilinear_gather_sum` exports as ~30 element-wise nodes over
//! `[N, heads, 4 x points]` (four-way concats of the corners, clamps, comparisons, a tile of the
//! attention weights, casts) that end in the corner sum [`crate::ops::weighted_sum`] already runs
//! natively. tract runs each of them as a separate pass over a fresh tensor: 30 of `test`'s 40
//! ms `bev_query` after the row softmax. At load, [`fuse_bilinear_samplers`] (`pattern.rs`)
//! recognises that subgraph above every gathered [`crate::ops::weighted_sum::WeightedAxisSum`] and
//! replaces it with [`BilinearCornerSum`] (here), which reads `x`, `y` (pixel coordinates,
//! `loc * size - 0.5`) and the attention weights once per point and keeps every corner in
//! registers.
//!
//! The kernel performs, per query, head and corner-major sample `k = corner * points + point`,
//! (the loop is `satmap_kernels::sampling::bilinear_corner_sums`) the same f32 operations in the
//! same order as the graph it replaces, so its outputs are bit
//! for bit those of the unfused graph (a test asserts it on the committed bundle):
//! `x0 = floor(x)`, `x1 = x0 + 1`, `fx = x - x0`, `gx = 1 - fx` (and the same in y); corner
//! weights `gx * gy, fx * gy, gx * fy, fx * fy`; `w = (corner_weight * attn) * inside` with
//! `inside` 1.0 when `0 <= xs <= W - 1` and `0 <= ys <= H - 1`, else 0.0; the row
//! `((clamp(ys) * W + clamp(xs)) + head * H * W) as i64`; then the corner sum's
//! `acc = acc + row[d] * w`, `k` ascending. Queries are independent, so on the engine's pool
//! of N threads they are split between threads by fixed blocks: the same bits on any N (the
//! engine's thread test asserts the digests on 1 and 2).

use tract_nnef::internal::*;

use rayon::prelude::*;
use satmap_kernels::sampling::{SamplePoints, SampledMap, bilinear_corner_sums};
use tract_linalg::multithread::{Executor, current_tract_executor};

mod pattern;
pub use pattern::fuse_bilinear_samplers;

/// Queries one task of [`BilinearCornerSum`] samples: `bev_query`'s 3,200 make 50 tasks, a
/// decoder layer's fewer; enough to keep two to a few threads busy, few enough that a task's
/// setup (one points buffer) does not count.
const QUERIES_PER_TASK: usize = 64;

/// `out[n, h, 0, :] = sum over k of data[row(n, h, k), :] * w(n, h, k)`, all of the module doc's
/// sampling math done in place; inputs `(data [heads * H * W, dh], x, y, attn [N, heads, P])`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BilinearCornerSum {
    /// Height of the sampled map, in rows.
    pub h: usize,
    /// Width of the sampled map, in columns.
    pub w: usize,
}

impl Op for BilinearCornerSum {
    fn name(&self) -> StaticName {
        "BilinearCornerSum".into()
    }
    op_as_typed_op!();
}

impl EvalOp for BilinearCornerSum {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        ensure!(inputs.len() == 4, "BilinearCornerSum takes four inputs");
        let shape = inputs[1].shape();
        ensure!(
            shape.len() == 3,
            "sampling coordinates are [N, heads, points]"
        );
        ensure!(
            inputs[2].shape() == shape && inputs[3].shape() == shape,
            "x, y and the attention weights differ in shape"
        );
        let (n, heads, points) = (shape[0], shape[1], shape[2]);
        let data_plain = inputs[0].try_as_plain_ram()?;
        let data = data_plain.as_slice::<f32>()?;
        ensure!(inputs[0].rank() == 2, "the sampled map is [rows, dh]");
        let (rows, dh) = (inputs[0].shape()[0], inputs[0].shape()[1]);
        ensure!(
            rows == heads * self.h * self.w,
            "the map has {rows} rows, not heads x H x W"
        );
        let xp = inputs[1].try_as_plain_ram()?;
        let yp = inputs[2].try_as_plain_ram()?;
        let ap = inputs[3].try_as_plain_ram()?;
        let (xs, ys, attn) = (
            xp.as_slice::<f32>()?,
            yp.as_slice::<f32>()?,
            ap.as_slice::<f32>()?,
        );
        let map = SampledMap {
            data,
            h: self.h,
            w: self.w,
            dh,
        };
        let samples = SamplePoints {
            x: xs,
            y: ys,
            attention: attn,
            heads,
            points,
        };
        let mut out = vec![0.0f32; n * heads * dh];
        let query_len = heads * dh;
        let task = |(t, chunk): (usize, &mut [f32])| -> TractResult<()> {
            let mut corners = vec![[0.0f32; 9]; points];
            bilinear_corner_sums(&map, &samples, t * QUERIES_PER_TASK, chunk, &mut corners)
                .map_err(|e| format_err!("sample row {} out of range (0..{})", e.row, e.rows))
        };
        if query_len > 0 {
            let chunk_len = QUERIES_PER_TASK * query_len;
            match current_tract_executor() {
                Executor::MultiThread(pool) => pool.install(|| {
                    out.par_chunks_mut(chunk_len)
                        .enumerate()
                        .try_for_each(|(i, chunk)| {
                            crate::vector_state::clear_upper();
                            task((i, chunk))
                        })
                })?,
                // The engine never runs on rayon's global pool (see `TractEngine::set_threads`).
                _ => out.chunks_mut(chunk_len).enumerate().try_for_each(task)?,
            }
        }
        Ok(tvec!(
            Tensor::from_shape(&[n, heads, 1, dh], &out)?.into_tvalue()
        ))
    }
}

impl TypedOp for BilinearCornerSum {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == 4);
        ensure!(inputs.iter().all(|f| f.datum_type == f32::datum_type()));
        ensure!(inputs[0].rank() == 2 && inputs[1].rank() == 3);
        let s = &inputs[1].shape;
        Ok(tvec!(f32::fact([
            s[0].clone(),
            s[1].clone(),
            1.to_dim(),
            inputs[0].shape[1].clone()
        ])))
    }

    fn cost(&self, inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let n: TDim = inputs[1].shape.iter().product::<TDim>() * 4 * inputs[0].shape[1].clone();
        Ok(tvec!((Cost::FMA(f32::datum_type()), n)))
    }

    as_op!();
}

#[cfg(test)]
mod tests {
    //! The kernel against `satmap_ref.sampling.bilinear_corner_sum` (committed vectors), and the
    //! rewrite against the unfused graph of the committed default bundle, both bit for bit.

    use super::*;
    use crate::ops::weighted_sum::WeightedAxisSum;
    use crate::passes::rewrite::Pass;
    use crate::test_support::{
        assert_same_bits, bits, committed_rewrites, committed_stage_before, golden_tensor,
        inputs_of, kernel_golden, run_optimized,
    };
    use satmap_core::engine::Stage;

    #[test]
    fn the_kernel_is_the_python_reference_bit_for_bit() {
        let bytes = kernel_golden();
        let st = safetensors::SafeTensors::deserialize(&bytes).expect("safetensors");
        let inputs: TVec<TValue> = ["sampler_rows", "sampler_x", "sampler_y", "sampler_attn"]
            .iter()
            .map(|n| golden_tensor(&st, n).into_tvalue())
            .collect();
        let op = BilinearCornerSum { h: 5, w: 4 };
        let out = op
            .eval_out_of_plan(inputs.clone())
            .expect("eval")
            .expect("out of plan");
        let want = golden_tensor(&st, "sampler_out");
        assert_eq!(out[0].shape(), want.shape());
        assert_eq!(bits(&out[0]), bits(&want));
        // A map of the wrong size is an error value, not a panic or a wrong read.
        let err = BilinearCornerSum { h: 6, w: 4 }
            .eval_out_of_plan(inputs)
            .unwrap_err();
        assert!(format!("{err:#}").contains("rows"), "{err:#}");
    }

    #[test]
    fn fused_samplers_compute_the_unfused_graph_bit_for_bit() {
        for stage in Stage::ALL {
            let plain = committed_stage_before(stage, Pass::BilinearSamplers);
            let (fused, n) = fuse_bilinear_samplers(plain.clone()).expect("fuse");
            assert_eq!(n, committed_rewrites(stage).bilinear_samplers, "{stage}");
            let left = fused
                .nodes()
                .iter()
                .filter(|n| n.op_is::<WeightedAxisSum>())
                .count();
            assert_eq!(
                left, 0,
                "{stage}: every corner sum is inside a fused sampler"
            );
            let inputs = inputs_of(&plain);
            let (a, b) = (run_optimized(plain, &inputs), run_optimized(fused, &inputs));
            assert_same_bits(stage, &a, &b);
        }
    }
}
