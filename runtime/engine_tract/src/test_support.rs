//! What the native-kernel tests of `engine_tract` share: the committed files they read, the
//! committed bundle's stages as tract models, deterministic inputs, a single-convolution
//! model, and bitwise views.

use tract_nnef::internal::*;

use crate::passes::rewrite::{Pass, Quantisation, Rewrites, optimise_before};
use crate::{HalfArithmetic, nnef_model};
use satmap_bundle::Bundle;
use satmap_core::engine::Stage;

/// The repository root (the runtime crate's parent).
pub(crate) fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The committed kernel goldens (`python -m satmap_ref.sampling`).
pub(crate) fn kernel_golden() -> Vec<u8> {
    std::fs::read(root().join("models/golden/kernels/weighted_axis_sum.safetensors"))
        .expect("kernel golden (python -m satmap_ref.sampling)")
}

/// Golden tensor `name` (f32 or i64, little-endian) as a tract tensor.
pub(crate) fn golden_tensor(st: &safetensors::SafeTensors<'_>, name: &str) -> Tensor {
    let t = st.tensor(name).expect("golden tensor");
    let dt = match t.dtype() {
        safetensors::Dtype::F32 => f32::datum_type(),
        safetensors::Dtype::I64 => i64::datum_type(),
        other => panic!("{name}: {other:?}"),
    };
    // `from_raw_dt` copies the little-endian bytes of a plain dtype.
    unsafe { Tensor::from_raw_dt(dt, t.shape(), t.data()) }.expect("tensor")
}

/// The bits of an f32 tensor's values.
pub(crate) fn bits(t: &Tensor) -> Vec<u32> {
    t.try_as_plain_ram()
        .expect("plain")
        .as_slice::<f32>()
        .expect("f32")
        .iter()
        .map(|v| v.to_bits())
        .collect()
}

/// `stage` of the committed default bundle, decluttered, before any of the engine's rewrites.
pub(crate) fn committed_stage(stage: Stage) -> TypedModel {
    let bundle = Bundle::open(root().join("models/bundles/test.satmap")).expect("bundle");
    let bytes = bundle.read_stage(stage).expect("stage bytes");
    let entry = bundle.manifest().stage(stage).expect("entry");
    let nnef = tract_nnef::nnef();
    nnef_model(
        stage,
        &nnef,
        &bytes,
        entry,
        bundle.manifest().precision,
        HalfArithmetic::Widened,
    )
    .expect("model")
    .0
    .into_decluttered()
    .expect("declutter")
}

/// [`committed_stage`] through the engine's rewrites that run before `stop`: the graph `stop`
/// sees at load.
pub(crate) fn committed_stage_before(stage: Stage, stop: Pass) -> TypedModel {
    optimise_before(committed_stage(stage), Some(stop), &Quantisation::None)
        .expect("rewrites")
        .0
}

/// What the load-time rewrites put into each stage of the committed default bundle on this
/// host: the one table the engine's test and each rewrite's own test check against.
///
/// The binary ops tract's optimiser leaves on its generic path depend on the kernel tier: the
/// AVX-512 kernels fuse fewer of them (both vendors, measured on `intel-avx512f` and with
/// `TRACT_X86_KIND=amd`) than the AVX2 + FMA ones (`amd-fma`, measured under `qemu-x86_64
/// -cpu EPYC-Rome` on 2026-12-05, after the LayerNorm pass took most of them). A tier without
/// counts here (`generic`) fails the tests until they are measured and added.
pub(crate) fn committed_rewrites(stage: Stage) -> Rewrites {
    let avx512 = crate::kernel_family().ends_with("-avx512f");
    // Per stage in `Stage::ALL` order: image, bev_query, bev_encoder, satellite, decoder.
    let broadcast = if avx512 {
        [4, 4, 0, 10, 2]
    } else {
        [2, 3, 0, 9, 2]
    };
    // Linear layers run natively on the AVX-512 tier: the image encoder's 1x1 projection,
    // bev_query's value/offset/weight/output projections, bev_encoder's, the Swin blocks' and
    // the decoder's (per stage, `Stage::ALL` order).
    // The attention output projections over heads and head width too, once `contraction` has
    // merged those two axes (bev_query's one, the Swin's multi-head blocks', the decoder's).
    let linears = if avx512 { [1, 7, 3, 21, 24] } else { [0; 5] };
    // 1x1 convolutions of channel-first maps: the tiny ResNet's downsampling projections and
    // the image neck's lateral; six in the satellite encoder (its FPN's channel-first maps).
    let pointwise = if avx512 { [4, 0, 0, 6, 0] } else { [0; 5] };
    // Products of two activations: the Swin windows' attention where a window has 8 tokens or
    // more, the decoder's live self-attention scores (its 8-wide weighted values stay tract's).
    let batched = if avx512 { [0, 0, 0, 4, 1] } else { [0; 5] };
    // Convolutions of 8 channels or more: the tiny ResNet's (its stem too), the Swin's patch
    // embedding and the satellite FPN's, the decoder's input projection.
    let convs = if avx512 { [10, 0, 0, 4, 1] } else { [0; 5] };
    // Native products that took the ReLU, the residual Add or both after them (AVX-512 only):
    // the ResNet stem and both convolutions of each of its four blocks; the feed-forward and
    // attention output layers' residuals and ReLUs of bev_query, bev_encoder and the decoder;
    // the satellite encoder's ReLU'd convolutions and its Swin blocks' residuals.
    let epilogues = if avx512 { [9, 3, 3, 11, 13] } else { [0; 5] };
    // LayerNorms, on every tier: bev_query's two, bev_encoder's two, the Swin's (two a block,
    // the patch mergings' and the four feature outputs'), the decoder's (three a layer and
    // its heads').
    let layer_norms = [0, 2, 2, 18, 8];
    let none = Rewrites {
        layer_norms: layer_norms[stage as usize],
        broadcast_binaries: broadcast[stage as usize],
        native_linears: linears[stage as usize],
        pointwise_convs: pointwise[stage as usize],
        native_batched: batched[stage as usize],
        unfolded_convs: convs[stage as usize],
        epilogues: epilogues[stage as usize],
        ..Rewrites::default()
    };
    match stage {
        // The ResNet stem's max pooling, on every tier.
        Stage::ImageEncoder => Rewrites {
            max_pools: 1,
            ..none
        },
        Stage::BevEncoder => none,
        // One deformable self-attention sampler; softmaxes of its sampling and GKT weights.
        Stage::BevQuery => Rewrites {
            weighted_sums: 1,
            bilinear_samplers: 1,
            row_softmaxes: 2,
            ..none
        },
        // One window attention and one tanh GELU per Swin block (`test`'s depths are 1, 2, 1,
        // 1), on every tier.
        Stage::SatelliteEncoder => Rewrites {
            row_softmaxes: 5,
            tanh_gelus: 5,
            ..none
        },
        // Per decoder layer (`test` has 2) one cross-attention sampler and two softmaxes; the
        // layer-0 self-attention reads its learned queries only, so it is computed at load.
        Stage::MapDecoder => Rewrites {
            weighted_sums: 2,
            bilinear_samplers: 2,
            row_softmaxes: 4,
            folded_outlets: 4,
            ..none
        },
    }
}

/// Deterministic inputs: f32 spread over [-2, 2) (enough to drive samples past the map edges),
/// u8 over the whole byte range (camera pixels), i64 0 (the first camera's index).
pub(crate) fn inputs_of(model: &TypedModel) -> TVec<TValue> {
    model
        .input_outlets()
        .expect("inputs")
        .iter()
        .map(|&o| {
            let fact = model.outlet_fact(o).expect("fact");
            let shape = fact.shape.as_concrete().expect("static").to_vec();
            let n: usize = shape.iter().product();
            let hash = (0..n as u32).map(|i| i.wrapping_mul(2_654_435_761) >> 8);
            let t = if fact.datum_type == i64::datum_type() {
                Tensor::from_shape(&shape, &vec![0i64; n])
            } else if fact.datum_type == u8::datum_type() {
                let v: Vec<u8> = hash.map(|h| (h & 0xff) as u8).collect();
                Tensor::from_shape(&shape, &v)
            } else {
                let v: Vec<f32> = hash
                    .map(|h| h as f32 / (1u32 << 24) as f32 * 4.0 - 2.0)
                    .collect();
                Tensor::from_shape(&shape, &v)
            };
            t.expect("tensor").into_tvalue()
        })
        .collect()
}

/// `model` as it stands (already optimised, or decluttered on purpose) run once on `inputs`.
pub(crate) fn run_plain(model: TypedModel, inputs: &TVec<TValue>) -> TVec<TValue> {
    model
        .into_runnable()
        .and_then(|p| p.run(inputs.clone()))
        .expect("run")
}

/// A pass that runs before tract's optimiser (`rewrite` at `pass`) computes every committed
/// stage as the graph it was given, bit for bit, both optimised as the engine plans them.
pub(crate) fn assert_pass_keeps_stage_bits(
    pass: Pass,
    rewrite: fn(TypedModel) -> TractResult<(TypedModel, usize)>,
) {
    for stage in Stage::ALL {
        let plain = committed_stage_before(stage, pass);
        let inputs = inputs_of(&plain);
        let (rewritten, _) = rewrite(plain.clone()).expect("rewrite");
        let (a, b) = (
            run_optimized(plain, &inputs),
            run_optimized(rewritten, &inputs),
        );
        assert_same_bits(stage, &a, &b);
    }
}

/// Two runs of `stage` computed the same outputs, bit for bit.
pub(crate) fn assert_same_bits(stage: Stage, a: &[TValue], b: &[TValue]) {
    assert_eq!(a.len(), b.len(), "{stage}: output count");
    for (x, y) in a.iter().zip(b) {
        assert_eq!(bits(x), bits(y), "{stage}");
    }
}

/// `f` on a private pool of two threads, as the engine runs after `set_threads(2)`.
pub(crate) fn on_two_threads<R>(f: impl FnOnce() -> R) -> R {
    let pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool"),
    );
    tract_linalg::multithread::multithread_tract_scope(
        tract_linalg::multithread::Executor::MultiThread(pool),
        f,
    )
}

/// `model` optimised and run once on `inputs`, as the engine plans it.
pub(crate) fn run_optimized(model: TypedModel, inputs: &TVec<TValue>) -> TVec<TValue> {
    model
        .into_optimized()
        .and_then(|m| m.into_runnable())
        .and_then(|p| p.run(inputs.clone()))
        .expect("run")
}

/// One 2-D convolution for the convolution passes' tests: channels in and out, input map,
/// square kernel, stride, padding each side, dilation, and whether the input has a batch axis
/// (NCHW) or not (CHW, as tract declutters some).
pub(crate) struct ConvShape {
    pub ci: usize,
    pub co: usize,
    pub hw: [usize; 2],
    pub k: usize,
    pub stride: usize,
    pub pad: usize,
    pub dilation: usize,
    pub batch: bool,
}

impl ConvShape {
    /// Undilated.
    pub(crate) fn new(
        ci: usize,
        co: usize,
        hw: [usize; 2],
        k: usize,
        stride: usize,
        pad: usize,
    ) -> Self {
        Self {
            ci,
            co,
            hw,
            k,
            stride,
            pad,
            dilation: 1,
            batch: true,
        }
    }
}

/// Deterministic f32 values in [-0.5, 0.5), `seed` picking the sequence.
fn conv_values(n: usize, seed: usize) -> Vec<f32> {
    (0..n)
        .map(|i| ((i * 7919 + seed * 104_729) % 1000) as f32 / 1000.0 - 0.5)
        .collect()
}

/// A decluttered f32 NCHW convolution of shape `s` (OIHW weights, a bias), and its input.
pub(crate) fn conv_model(s: &ConvShape) -> (TypedModel, TVec<TValue>) {
    use tract_nnef::tract_core::ops::cnn::conv::KernelFormat;
    use tract_nnef::tract_core::ops::cnn::{Conv, PaddingSpec, PoolSpec};
    use tract_nnef::tract_core::ops::nn::DataFormat;
    let [h, w] = s.hw;
    let mut model = TypedModel::default();
    let shape: Vec<usize> = if s.batch {
        vec![1, s.ci, h, w]
    } else {
        vec![s.ci, h, w]
    };
    let x = model.add_source("x", f32::fact(&shape)).unwrap();
    let weights = Tensor::from_shape(
        &[s.co, s.ci, s.k, s.k],
        &conv_values(s.co * s.ci * s.k * s.k, 1),
    )
    .unwrap();
    let kernel = model.add_const("k", weights).unwrap();
    let bias = Tensor::from_shape(&[s.co], &conv_values(s.co, 2)).unwrap();
    let bias = model.add_const("b", bias).unwrap();
    let conv = Conv {
        pool_spec: PoolSpec {
            data_format: if s.batch {
                DataFormat::NCHW
            } else {
                DataFormat::CHW
            },
            kernel_shape: tvec!(s.k, s.k),
            padding: PaddingSpec::Explicit(tvec!(s.pad, s.pad), tvec!(s.pad, s.pad)),
            dilations: Some(tvec!(s.dilation, s.dilation)),
            strides: Some(tvec!(s.stride, s.stride)),
            input_channels: s.ci,
            output_channels: s.co,
        },
        kernel_fmt: KernelFormat::OIHW,
        group: 1,
        q_params: None,
    };
    let y = model.wire_node("conv", conv, &[x, kernel, bias]).unwrap();
    model.select_output_outlets(&y).unwrap();
    let input = Tensor::from_shape(&shape, &conv_values(s.ci * h * w, 3)).unwrap();
    (model.into_decluttered().unwrap(), tvec![input.into()])
}

/// `x [lead.., k] . W (+ b)`, W stored `[k, n]` or (transposed) `[n, k]`.
pub(crate) fn linear_model(
    lead: &[usize],
    k: usize,
    n: usize,
    transposed: bool,
    bias: bool,
) -> TypedModel {
    let values = |len: usize, seed: usize| -> Vec<f32> {
        (0..len)
            .map(|i| ((i * 7919 + seed * 104_729) % 1013) as f32 / 500.0 - 1.0)
            .collect()
    };
    let mut model = TypedModel::default();
    let mut shape: Vec<usize> = lead.to_vec();
    shape.push(k);
    let x = model.add_source("x", f32::fact(&shape)).unwrap();
    let (w_shape, w_axes) = if transposed {
        ([n, k], "nk")
    } else {
        ([k, n], "kn")
    };
    let w = Tensor::from_shape(&w_shape, &values(k * n, 1)).unwrap();
    let w = model.add_const("w", w).unwrap();
    let lead_axes: String = "abc".chars().take(lead.len()).collect();
    let expr = format!("{lead_axes}k,{w_axes}->{lead_axes}n");
    let es = tract_nnef::tract_core::ops::einsum::EinSum {
        axes: expr.parse().unwrap(),
        operating_dt: f32::datum_type(),
        q_params: None,
    };
    let mut y = model.wire_node("mm", es, &[x, w]).unwrap()[0];
    if bias {
        let mut b_shape = vec![1; lead.len()];
        b_shape.push(n);
        let b = Tensor::from_shape(&b_shape, &values(n, 2)).unwrap();
        let b = model.add_const("b", b).unwrap();
        y = model
            .wire_node("add", tract_nnef::tract_core::ops::math::add(), &[y, b])
            .unwrap()[0];
    }
    model.select_output_outlets(&[y]).unwrap();
    model.into_decluttered().unwrap()
}
