//! Minimal reproduction of the tract 0.23.9 limitations behind our convolution stages, and what
//! the engine runs instead (docs/perf.md): the f32 3x3 convolutions of `nano`, each run as a
//! tract `Conv` (tract's own choice of path: lazy im2col for all of these), as a `Conv` planned
//! with eager im2col (tract's knobs scoped to the plan), as tract's matrix product alone on the
//! same GEMM (the im2col operand given, `[m, k] x [k, n]`, m = output channels, k = 9 x input
//! channels, n = output pixels), as the same GEMM through matrixmultiply (ndarray's pure-Rust
//! kernel, AVX2 + FMA, no AVX-512), and, on an AVX-512 CPU, through the engine's own product:
//! the whole convolution as the engine plans it (`native_unfold_conv`:
//! `engine_tract::ops::conv_unfold`, patches gathered into the packed blocks) and the product alone
//! on operands packed beforehand (`native_gemm_packed`: `engine_tract::gemm`). FLOPs per call
//! are `2 m k n` (criterion's "elements"); the group names carry the shape. The `gemm` crate's
//! columns of docs/perf.md were measured with this file at commit 7174941.
//!
//! Run: `cargo bench --workspace --exclude satmap-nostd-check --bench tract_conv --profile test`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use satmap_engine_tract::gemm;
use satmap_engine_tract::ops::conv_unfold::unfold_convs;
use tract_nnef::prelude::tract_ndarray::{Array2, linalg::general_mat_mul};
use tract_nnef::prelude::*;
use tract_nnef::tract_core::ops::cnn::{Conv, KernelFormat, PaddingSpec, PoolSpec};
use tract_nnef::tract_core::ops::einsum::EinSum;
use tract_nnef::tract_core::ops::nn::DataFormat;
use tract_nnef::tract_core::tract_data::knobs::KnobScope;

/// `(input channels, output channels, height_px, width_px)` of a 3x3, stride-1, same-padded
/// conv of `nano`: ResNet-18's layer1..layer4 on a 180 x 320 camera image, two of the satellite
/// FPN's and the map decoder's input projection.
const SHAPES: [(usize, usize, usize, usize); 7] = [
    (64, 64, 45, 80),
    (128, 128, 23, 40),
    (256, 256, 12, 20),
    (512, 512, 6, 10),
    (256, 256, 50, 25),
    (256, 256, 25, 13),
    (512, 256, 80, 40),
];

/// Deterministic values in [-0.5, 0.5): the timing does not depend on them.
fn values(n: usize, seed: usize) -> Vec<f32> {
    (0..n)
        .map(|i| ((i * 7919 + seed * 104_729) % 1000) as f32 / 1000.0 - 0.5)
        .collect()
}

fn conv_plan(ci: usize, co: usize, h: usize, w: usize) -> TractResult<Arc<TypedSimplePlan>> {
    conv_model(ci, co, h, w)?.into_optimized()?.into_runnable()
}

/// The same convolution through the engine's native product
/// (`engine_tract::ops::conv_unfold::unfold_convs`), as the engine plans it on the AVX-512 tier.
fn native_plan(ci: usize, co: usize, h: usize, w: usize) -> TractResult<Arc<TypedSimplePlan>> {
    let (model, rewritten) = unfold_convs(conv_model(ci, co, h, w)?)?;
    if rewritten != 1 {
        return Err(TractError::msg("the pass left the convolution alone"));
    }
    model.into_optimized()?.into_runnable()
}

fn conv_model(ci: usize, co: usize, h: usize, w: usize) -> TractResult<TypedModel> {
    let mut model = TypedModel::default();
    let x = model.add_source("x", f32::fact([1, ci, h, w]))?;
    let weights = Tensor::from_shape(&[co, ci, 3, 3], &values(co * ci * 9, 1))?;
    let kernel = model.add_const("k", weights)?;
    let bias = model.add_const("b", Tensor::from_shape(&[co], &values(co, 2))?)?;
    let pool_spec = PoolSpec {
        data_format: DataFormat::NCHW,
        kernel_shape: tvec!(3, 3),
        padding: PaddingSpec::SameUpper,
        dilations: None,
        strides: None,
        input_channels: ci,
        output_channels: co,
    };
    let conv = Conv {
        pool_spec,
        kernel_fmt: KernelFormat::OIHW,
        group: 1,
        q_params: None,
    };
    let y = model.wire_node("conv", conv, &[x, kernel, bias])?;
    model.select_output_outlets(&y)?;
    Ok(model)
}

fn matmul_plan(m: usize, k: usize, n: usize) -> TractResult<Arc<TypedSimplePlan>> {
    let mut model = TypedModel::default();
    let a = model.add_const("a", Tensor::from_shape(&[m, k], &values(m * k, 1))?)?;
    let b = model.add_source("b", f32::fact([k, n]))?;
    let mm = EinSum::new("mk,kn->mn".parse()?, f32::datum_type());
    let y = model.wire_node("mm", mm, &[a, b])?;
    model.select_output_outlets(&y)?;
    model.into_optimized()?.into_runnable()
}

fn bench(crit: &mut Criterion) {
    // tract's knobs that send every convolution tract would run through lazy im2col to eager
    // im2col and one matrix product instead (docs/perf.md).
    let eager = KnobScope::new([
        ("TRACT_LAZY_IM2COL_MIN_KERNEL", "1000000000"),
        ("TRACT_LAZY_IM2COL_MAX_EAGER_BYTES", "1000000000000"),
    ])
    .expect("knobs");
    for (ci, co, h, w) in SHAPES {
        let (m, k, n) = (co, 9 * ci, h * w);
        let mut g = crit.benchmark_group(format!("conv3x3_{ci}to{co}_{h}x{w}_m{m}_k{k}_n{n}"));
        g.sample_size(20);
        g.throughput(Throughput::Elements((2 * m * k * n) as u64));

        let x: TValue = Tensor::from_shape(&[1, ci, h, w], &values(ci * h * w, 3))
            .expect("input")
            .into();
        let conv = conv_plan(ci, co, h, w).expect("conv plan");
        g.bench_function("tract_conv", |b| {
            b.iter(|| conv.run(tvec![black_box(x.clone())]).expect("runs"))
        });
        let conv_eager = eager.enter(|| conv_plan(ci, co, h, w)).expect("conv plan");
        g.bench_function("tract_conv_eager_im2col", |b| {
            b.iter(|| conv_eager.run(tvec![black_box(x.clone())]).expect("runs"))
        });

        if gemm::tier().is_some() {
            let native = native_plan(ci, co, h, w).expect("native plan");
            g.bench_function("native_unfold_conv", |b| {
                b.iter(|| native.run(tvec![black_box(x.clone())]).expect("runs"))
            });
        }

        let mm = matmul_plan(m, k, n).expect("matmul plan");
        let im2col: TValue = Tensor::from_shape(&[k, n], &values(k * n, 3))
            .expect("operand")
            .into();
        g.bench_function("tract_matmul", |b| {
            b.iter(|| mm.run(tvec![black_box(im2col.clone())]).expect("runs"))
        });

        if gemm::tier().is_some() {
            // The native product alone, both operands packed beforehand.
            let pa = gemm::PackedA::from_row_major(&values(m * k, 1), m, k);
            let pb = gemm::PackedB::from_row_major(&values(k * n, 3), k, n);
            let mut c = vec![0.0f32; m * n];
            g.bench_function("native_gemm_packed", |b| {
                b.iter(|| {
                    let ops = gemm::Operands {
                        a: pa.as_slice(),
                        b: gemm::BSource::Packed(pb.as_slice()),
                        m,
                        n,
                        k,
                        ldc: n,
                    };
                    assert!(gemm::product(&ops, black_box(&mut c), gemm::Bias::None));
                })
            });
        }

        let a = Array2::from_shape_vec((m, k), values(m * k, 1)).expect("a");
        let bm = Array2::from_shape_vec((k, n), values(k * n, 3)).expect("b");
        let mut out = Array2::<f32>::zeros((m, n));
        g.bench_function("matrixmultiply_sgemm", |b| {
            b.iter(|| general_mat_mul(1.0, black_box(&a), black_box(&bm), 0.0, &mut out))
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
