//! Convolutions in integer arithmetic (W8A8), and the probes a calibration run reads their
//! input maps' ranges with.
//!
//! [`QuantConv`]: the input map quantised once per run with the scale its calibrated range
//! gives (symmetric int8, per tensor), the weights per output channel at load (an int8
//! bundle's kernels come back as the int8 values it stores), and the channel-first integer
//! product ([`qgemm::channel_product`]) over blocks of output pixels: each block's patches
//! ([`Unfold`], the f32 convolution's own gathering, here over bytes) packed into the
//! product's lines, summed in i32 on the integer tier this CPU has, finished in the same store
//! per channel (`sum * (activation scale * channel scale) + bias`, then the epilogue's shortcut
//! and floor), the output channel-first as the graph has it. Blocks are split over the
//! engine's threads; every integer tier gives the same bits.
//!
//! Which convolutions: every one the native f32 passes could take ([`conv_layer_at`]: one
//! group, NCHW or CHW over two spatial axes, batch 1, constant weights and bias), whatever its
//! channel count, keyed by its `Conv` node's name in the decluttered graph; on every target
//! (the f32 [`crate::ops::conv_unfold::UnfoldConv`] is AVX-512-only, the integer tiers are not).

use std::collections::BTreeMap;

use std::sync::Mutex;

use satmap_kernels::qgemm::{self, IntTier, Line, QProductError, QRows, RowFinish, quantize};
use tract_nnef::internal::*;

use crate::graph::matching::replace_with_op;
use crate::ops::conv_layer::{ConvLayer, conv_layer_at};
use crate::ops::finish::Epilogue;
use crate::ops::range_probe::{RangeLog, probe_inputs};
use crate::ops::unfold::{Unfold, with_batch};
use crate::pool;

mod quad_map;
use quad_map::{quad_order, quad_unfold};

/// Most panels of 16 output pixels a block (one task).
const BLOCK_PANELS: usize = 16;

/// Most output pixels of a block.
const BLOCK_PIXELS: usize = BLOCK_PANELS * qgemm::QNR;

/// Bytes of a block's packed patches the block size aims under: each tile of weight rows
/// streams the whole block past it, from L2 (16 panels at `k = 576`, 2 at `k = 4608`).
const BLOCK_BYTES: usize = 192 << 10;

/// A 2-D convolution in int8 with i32 sums, its output channel-first.
#[derive(Clone, Debug)]
pub struct QuantConv {
    /// The patches.
    pub unfold: Unfold,
    /// Whether input and output carry a batch axis of 1 (NCHW; CHW otherwise).
    pub batch_axis: bool,
    /// The shortcut and ReLU after the bias ([`crate::passes::epilogue`]).
    pub epilogue: Epilogue,
    /// The patches of the quantised map, whose values are four channels' bytes (the quad map, [`quad_map`]).
    quads: Unfold,
    /// `1 / activation scale`.
    inv_scale: f32,
    /// The activation's scale times each channel's weight scale.
    row_scale: Arc<Vec<f32>>,
    weights: Arc<QRows>,
    bias: Arc<Vec<f32>>,
    tier: IntTier,
}

impl PartialEq for QuantConv {
    fn eq(&self, other: &Self) -> bool {
        self.unfold == other.unfold
            && self.batch_axis == other.batch_axis
            && self.epilogue == other.epilogue
            && self.inv_scale.to_bits() == other.inv_scale.to_bits()
            && self.tier == other.tier
            && Arc::ptr_eq(&self.weights, &other.weights)
            && Arc::ptr_eq(&self.row_scale, &other.row_scale)
            && Arc::ptr_eq(&self.bias, &other.bias)
    }
}
impl Eq for QuantConv {}

impl QuantConv {
    /// The convolution over `unfold`'s patches with OIHW weights `w` (row-major f32, one row
    /// an output channel) and one bias a channel, its input of largest magnitude `abs_max`,
    /// on `tier`, no epilogue.
    ///
    /// # Errors
    /// Weights that are not `bias.len()` rows of the patches' depth, or deeper than the exact
    /// limit.
    pub fn new(
        unfold: Unfold,
        batch_axis: bool,
        w: &[f32],
        bias: Vec<f32>,
        abs_max: f32,
        tier: IntTier,
    ) -> TractResult<Self> {
        let m = bias.len();
        let k = unfold.depth();
        ensure!(
            k > 0 && w.len() == m * k,
            "QuantConv: {} weights for {m} channels of depth {k}",
            w.len()
        );
        let quads = quad_unfold(&unfold);
        let w = quad_order(&unfold, w, m);
        let (weights, w_scales) = QRows::quantise(&w, m, quads.depth() * 4)?;
        let a_scale = quantize::scale_for(abs_max);
        Ok(Self {
            unfold,
            batch_axis,
            quads,
            epilogue: Epilogue::default(),
            inv_scale: 1.0 / a_scale,
            row_scale: Arc::new(w_scales.iter().map(|&s| a_scale * s).collect()),
            weights: Arc::new(weights),
            bias: Arc::new(bias),
            tier,
        })
    }

    /// This convolution with `epilogue` after its bias.
    #[must_use]
    pub fn with_epilogue(&self, epilogue: Epilogue) -> Self {
        Self {
            epilogue,
            ..self.clone()
        }
    }

    fn input_shape(&self) -> TVec<usize> {
        with_batch(self.batch_axis, self.unfold.input)
    }

    fn output_shape(&self) -> TVec<usize> {
        let [oh, ow] = self.unfold.output;
        with_batch(self.batch_axis, [self.bias.len(), oh, ow])
    }

    /// Output pixels `p0..p0 + cols` of every channel into the scratch's `local` (`m` rows
    /// of `cols`): each group of the block's patches (four channels at one tap, for each
    /// pixel) gathered from the quantised map `xq` as one patch row of its four-byte values,
    /// and laid into the panels' lines; then the product.
    fn block(
        &self,
        xq: &[u32],
        (p0, cols): (usize, usize),
        residual: Option<&[f32]>,
        scratch: &mut BlockScratch,
    ) -> Result<(), QProductError> {
        let groups = self.quads.depth();
        let panels = cols.div_ceil(qgemm::QNR);
        let width = panels * qgemm::QNR;
        let m = self.bias.len();
        let n = self.unfold.output[0] * self.unfold.output[1];
        scratch.size(panels * groups, m * cols);
        let BlockScratch { lines, row, local } = scratch;
        let lines = &mut lines[..panels * groups];
        let row = &mut row[..width];
        for g in 0..groups {
            self.quads.patch_row(xq, g, p0, row);
            for (p, words) in row.chunks_exact(qgemm::QNR).enumerate() {
                let line = &mut lines[p * groups + g].0;
                for (dst, w) in line.chunks_exact_mut(4).zip(words) {
                    for (d, b) in dst.iter_mut().zip(w.to_le_bytes()) {
                        *d = b as i8;
                    }
                }
            }
        }
        let finish = RowFinish {
            scale: &self.row_scale,
            bias: Some(&self.bias),
            residual: residual.map(|r| (&r[p0..], n)),
            floor: self.epilogue.floor,
        };
        let local = &mut local[..m * cols];
        qgemm::channel_product(self.tier, &self.weights, lines, cols, finish, local, cols)
    }
}

/// A task's buffers, kept per thread between runs (they only grow, so a step allocates here
/// only the first time a thread meets its deepest convolution).
#[derive(Default)]
struct BlockScratch {
    /// The block's packed patches.
    lines: Vec<Line>,
    /// One patch row of the block's pixels.
    row: Vec<u32>,
    /// The block's output, a row a channel.
    local: Vec<f32>,
}

impl BlockScratch {
    fn size(&mut self, lines: usize, local: usize) {
        if self.lines.len() < lines {
            self.lines.resize(lines, Line([0; qgemm::pack::LINE]));
        }
        if self.row.len() < BLOCK_PIXELS {
            self.row.resize(BLOCK_PIXELS, 0);
        }
        if self.local.len() < local {
            self.local.resize(local, 0.0);
        }
    }
}

std::thread_local! {
    /// The quantised input map of the convolution this thread is running (the quad map, [`quad_map`]).
    static MAP: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
    /// This thread's block buffers.
    static BLOCK: std::cell::RefCell<BlockScratch> = std::cell::RefCell::new(BlockScratch::default());
}

impl Op for QuantConv {
    fn info(&self) -> TractResult<Vec<String>> {
        let [oh, ow] = self.unfold.output;
        Ok(vec![format!(
            "Mult: m:{} k:{} n:{} int8 on {}",
            self.bias.len(),
            self.unfold.depth(),
            oh * ow,
            self.tier
        )])
    }

    fn name(&self) -> StaticName {
        "QuantConv".into()
    }
    op_as_typed_op!();
}

impl EvalOp for QuantConv {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let out_shape = self.output_shape();
        let residual = self.epilogue.shortcut(&inputs, &out_shape)?;
        let x = &inputs[0];
        ensure!(
            x.shape() == &*self.input_shape(),
            "QuantConv input {:?}, expected {:?}",
            x.shape(),
            self.input_shape()
        );
        let px = x.try_as_plain_ram()?;
        let xs = px.as_slice::<f32>()?;
        let [oh, ow] = self.unfold.output;
        let (m, n) = (self.bias.len(), oh * ow);
        let mut out = crate::gemm::output_tensor(&out_shape)?;
        let mut po = out.try_as_plain_ram_mut()?;
        let c = po.as_slice_mut::<f32>()?;
        ensure!(c.len() == m * n, "QuantConv output of {} values", c.len());
        let shared = pool::DisjointParts(c.as_mut_ptr());
        let panel_bytes = self.quads.depth() * qgemm::pack::LINE;
        let block_pixels = (BLOCK_BYTES / panel_bytes.max(1)).clamp(1, BLOCK_PANELS) * qgemm::QNR;
        let blocks = n.div_ceil(block_pixels);
        // The map taken out of its thread-local for the run and put back after, so that no
        // borrow is held while the pool runs tasks (a waiting worker may run other jobs).
        let mut map = MAP.take();
        let [c4, h, w] = self.quads.input;
        let len = c4 * h * w;
        if map.len() < len {
            map.resize(len, 0);
        }
        if !quantize::quads(xs, self.unfold.input, self.inv_scale, &mut map[..len]) {
            MAP.set(map);
            bail!(
                "QuantConv input of {} values for {:?}",
                xs.len(),
                self.unfold.input
            );
        }
        let xq = &map[..len];
        // The first error of a task (a tier this CPU lacks, a mis-sized operand: bugs, never
        // input), returned as it is.
        let failed: Mutex<Option<QProductError>> = Mutex::new(None);
        let task = |b: usize| -> bool {
            let p0 = b * block_pixels;
            let cols = block_pixels.min(n - p0);
            BLOCK.with(|scratch| {
                let mut scratch = scratch.borrow_mut();
                if let Err(e) = self.block(xq, (p0, cols), residual, &mut scratch) {
                    let mut first = failed
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    first.get_or_insert(e);
                    return false;
                }
                for (o, row) in scratch.local.chunks_exact(cols).take(m).enumerate() {
                    // SAFETY: the output holds `m * n` values (checked above) and stays
                    // mutably borrowed until every task has returned; channel `o`'s pixels
                    // `p0..p0 + cols` lie inside it, and no other task writes them (tasks
                    // own disjoint blocks of pixels) or reads the output.
                    unsafe {
                        std::ptr::copy_nonoverlapping(row.as_ptr(), shared.at(o * n + p0), cols);
                    }
                }
                true
            })
        };
        let done = if pool::worth_threads(m * self.unfold.depth() * n) && !pool::in_task() {
            pool::on_pool(blocks, task)
        } else {
            (0..blocks).all(task)
        };
        MAP.set(map);
        if let Some(e) = failed
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
        {
            return Err(e.into());
        }
        ensure!(done, "integer convolution: a task failed");
        Ok(tvec!(out.into_tvalue()))
    }
}

impl TypedOp for QuantConv {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        self.epilogue.output_facts(inputs, &self.output_shape())
    }

    fn cost(&self, _inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let [oh, ow] = self.unfold.output;
        let macs = self.bias.len() * self.unfold.depth() * oh * ow;
        Ok(tvec!((Cost::FMA(i8::datum_type()), macs.to_dim())))
    }

    as_op!();
}

/// Replace every convolution [`conv_layer_at`] takes that has a range in `ranges` by a
/// [`QuantConv`] on `tier`; returns the model and the number replaced.
///
/// # Errors
/// tract refusing a patch, or weights that do not quantise.
pub fn quantise_convs(
    mut model: TypedModel,
    ranges: &BTreeMap<String, f32>,
    tier: IntTier,
) -> TractResult<(TypedModel, usize)> {
    let mut done = 0;
    for id in model.eval_order()? {
        let name = model.node(id).name.clone();
        let Some(&abs_max) = ranges.get(&name) else {
            continue;
        };
        let Some(ConvLayer {
            unfold,
            batch_axis,
            x,
            kernel,
            bias,
        }) = conv_layer_at(&model, id)?
        else {
            continue;
        };
        let w = kernel.try_as_plain_ram()?;
        let op = QuantConv::new(
            unfold,
            batch_axis,
            w.as_slice::<f32>()?,
            bias,
            abs_max,
            tier,
        )?;
        replace_with_op(&mut model, &[x], id, format!("{name}.int8"), op)?;
        done += 1;
    }
    Ok((model, done))
}

/// Put a [`crate::ops::range_probe::RangeProbe`] into `log` before every convolution
/// [`conv_layer_at`] takes in `stage`; returns the model and the number of probes.
///
/// # Errors
/// tract refusing a patch.
pub fn probe_convs(
    model: TypedModel,
    log: &RangeLog,
    stage: &str,
) -> TractResult<(TypedModel, usize)> {
    probe_inputs(model, log, stage, |model, id| {
        Ok(conv_layer_at(model, id)?.map(|conv| conv.x))
    })
}

#[cfg(test)]
mod tests {
    //! The int8 convolution against the f32 convolution it replaces (within the quantisation's
    //! bound, stated below), bit for bit across every integer tier this CPU has and across 1 and 2
    //! threads; the fused shortcut and floor against the unfused steps; the probes.
    use super::*;
    use crate::test_support::{ConvShape, bits, conv_model, on_two_threads, run_optimized};
    use satmap_kernels::qgemm::histogram::RangeMethod;

    fn values(t: &TValue) -> Vec<f32> {
        t.try_as_plain_ram()
            .unwrap()
            .as_slice::<f32>()
            .unwrap()
            .to_vec()
    }

    fn shapes() -> Vec<ConvShape> {
        vec![
            // `test`'s 8-channel stem (7x7, stride 2, padding 3), a 3x3 of the satellite FPN
            // without the batch axis, a strided one with ragged blocks, 4 channels (half a
            // tile), a dilated one, and a deep one (k = 576) over more than one block.
            ConvShape::new(3, 8, [48, 64], 7, 2, 3),
            ConvShape {
                batch: false,
                ..ConvShape::new(32, 32, [25, 13], 3, 1, 1)
            },
            ConvShape::new(16, 24, [23, 41], 3, 2, 1),
            ConvShape::new(8, 4, [9, 7], 3, 1, 1),
            ConvShape {
                dilation: 2,
                ..ConvShape::new(5, 16, [13, 17], 3, 1, 2)
            },
            ConvShape::new(64, 32, [20, 40], 3, 1, 1),
        ]
    }

    #[test]
    fn int8_convolutions_stay_within_the_quantisation_bound_and_agree_on_every_tier() {
        for s in shapes() {
            let (model, inputs) = conv_model(&s);
            let want = values(&run_optimized(model.clone(), &inputs)[0]);
            let abs_max = quantize::abs_max(&values(&inputs[0]));
            let ranges = BTreeMap::from([("conv".to_owned(), abs_max)]);
            let mut first: Option<Vec<u32>> = None;
            for tier in IntTier::ALL.into_iter().filter(|t| t.runs_here()) {
                let (q, done) = quantise_convs(model.clone(), &ranges, tier).unwrap();
                assert_eq!(done, 1, "{} -> {}", s.ci, s.co);
                assert!(q.nodes().iter().any(|n| n.op_is::<QuantConv>()));
                let got = run_optimized(q.clone(), &inputs);
                // Bound: each of k products off by at most half a step of each operand
                // (|x|, |w| <= 0.5 here, the weight scale at most 0.5 / 127):
                // k * (0.5 * s_w / 2 + 0.5 * s_x / 2 + s_x * s_w / 4).
                let k = s.ci * s.k * s.k;
                let (s_x, s_w) = (abs_max / 127.0, 0.5 / 127.0);
                let bound = k as f32 * (0.25 * s_w + 0.25 * s_x + s_x * s_w / 4.0);
                let worst = values(&got[0])
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                assert!(
                    worst <= bound,
                    "{} -> {} on {tier}: {worst} > {bound}",
                    s.ci,
                    s.co
                );
                assert!(
                    worst > 0.0,
                    "int8 that equals f32 bit for bit was not quantised"
                );
                let b = bits(&got[0]);
                let two = on_two_threads(|| run_optimized(q, &inputs));
                assert_eq!(bits(&two[0]), b, "{tier}: two threads differ from one");
                match &first {
                    None => first = Some(b),
                    Some(f) => assert_eq!(&b, f, "{tier} differs from the first tier"),
                }
            }
        }
    }

    #[test]
    fn a_convolution_without_a_range_stays_f32() {
        let (model, _) = conv_model(&ConvShape::new(16, 24, [23, 41], 3, 2, 1));
        let (_, done) = quantise_convs(model, &BTreeMap::new(), IntTier::Generic).unwrap();
        assert_eq!(done, 0);
    }

    #[test]
    fn probes_record_each_convolutions_input_range_and_change_no_bit() {
        let (model, inputs) = conv_model(&ConvShape::new(16, 24, [23, 41], 3, 2, 1));
        let want = run_optimized(model.clone(), &inputs);
        let log = RangeLog::default();
        let (probed, done) = probe_convs(model, &log, "stage").unwrap();
        assert_eq!(done, 1);
        let got = run_optimized(probed, &inputs);
        assert_eq!(bits(&got[0]), bits(&want[0]));
        let ranges = log.ranges(RangeMethod::AbsMax);
        assert_eq!(
            ranges.get(&("stage".to_owned(), "conv".to_owned())),
            Some(&quantize::abs_max(&values(&inputs[0])))
        );
        assert_eq!(ranges.len(), 1);
    }

    fn op_of(s: &ConvShape) -> (QuantConv, TVec<TValue>) {
        let (model, inputs) = conv_model(s);
        let conv = conv_layer_at(&model, model.node_id_by_name("conv").unwrap())
            .unwrap()
            .expect("a convolution the passes take");
        let w = conv.kernel.try_as_plain_ram().unwrap();
        let op = QuantConv::new(
            conv.unfold.clone(),
            conv.batch_axis,
            w.as_slice::<f32>().unwrap(),
            conv.bias.clone(),
            0.5,
            IntTier::default_here(),
        )
        .unwrap();
        (op, inputs)
    }

    #[test]
    fn the_fused_shortcut_and_floor_give_the_unfused_bits() {
        // One block, and four blocks with a ragged last one (the shortcut read from each
        // block's first pixel on), on one thread and on two.
        for s in [
            ConvShape::new(16, 24, [23, 41], 3, 2, 1),
            ConvShape::new(64, 32, [20, 40], 3, 1, 1),
        ] {
            let (op, x) = op_of(&s);
            let plain = values(&op.eval_out_of_plan(x.clone()).unwrap().unwrap()[0]);
            let shape = op.output_shape();
            let res: Vec<f32> = (0..plain.len())
                .map(|i| ((i * 7) % 11) as f32 / 5.0 - 1.0)
                .collect();
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
            inputs.push(Tensor::from_shape(&shape, &res).unwrap().into_tvalue());
            let got = fused.eval_out_of_plan(inputs.clone()).unwrap().unwrap();
            assert_eq!(bits(&got[0]), want, "{} -> {}", s.ci, s.co);
            let two = on_two_threads(|| fused.eval_out_of_plan(inputs).unwrap().unwrap());
            assert_eq!(bits(&two[0]), want, "{} -> {} on two threads", s.ci, s.co);
        }
    }

    #[test]
    fn weights_of_another_size_are_refused() {
        let (op, _) = op_of(&ConvShape::new(8, 4, [9, 7], 3, 1, 1));
        let bias = vec![0.0f32; 4];
        for len in [4 * 72 - 1, 4 * 72 + 1, 0] {
            let w = vec![0.1f32; len];
            assert!(
                QuantConv::new(
                    op.unfold.clone(),
                    true,
                    &w,
                    bias.clone(),
                    1.0,
                    IntTier::Generic
                )
                .is_err(),
                "{len} weights"
            );
        }
    }

    #[test]
    fn a_wrong_input_is_an_error_value() {
        let (op, _) = op_of(&ConvShape::new(8, 4, [9, 7], 3, 1, 1));
        let x = Tensor::zero::<f32>(&[1, 8, 9, 8]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(x.into_tvalue())).is_err());
        // The op stays usable.
        let ok = Tensor::zero::<f32>(&[1, 8, 9, 7]).unwrap();
        assert!(op.eval_out_of_plan(tvec!(ok.into_tvalue())).is_ok());
    }
}
