//! The committed f16 and int8 compiled bundles (`models/bundles/test-f16.satmap`,
//! `test-int8.satmap`, kept current by `tests/integration/compiled_bundle.rs`) step within their
//! measured bounds of the committed f32 bundle, stage by stage over both golden frames, and in
//! a fraction of its file size.
//!
//! The int8 bundle and the f16 bundle widened at load are weight storage, f32 arithmetic: the
//! deviation is the weights' rounding alone, so their bounds hold on every kernel family. The
//! f16 bundle in f16 arithmetic (on request; tract's NEON fp16 kernels on a core with FEAT_FP16,
//! e.g. the emulated Cortex-A76; its portable f16 kernels where the core has none, as on x86) rounds every
//! activation and partial sum to f16 as well: its bounds are measured on both kernel families.

use std::path::PathBuf;

use satmap_ecu_tests::golden::{
    compiled_engine_as, compiled_f16_engine, compiled_path, max_abs_diff, w8a8_path,
};
use satmap_ecu_tests::parity::stage_buffers;
use satmap_runtime::Stage;
use satmap_runtime::bundle::{Bundle, Precision};
use satmap_runtime::engine_tract::{HalfArithmetic, TractEngine};

/// Largest deviation of the f16 bundle from the f32 one per stage buffer, over both golden
/// frames of the trained `test` weights: measured (2026-12-01) and doubled.
const F16_BOUNDS: [(&str, f32); 8] = [
    ("value", 3.2e-3),         // measured 1.56e-3
    ("bev_query", 0.11),       // 5.14e-2
    ("gkt_weights", 0.022),    // 1.10e-2
    ("gathered", 6.5e-3),      // 3.22e-3
    ("camera_bev", 0.16),      // 7.80e-2
    ("satellite_bev", 8.3e-3), // 4.13e-3
    ("class_logits", 0.19),    // 9.50e-2
    ("points", 0.048),         // 2.39e-2 (normalised to the BEV range)
];

/// The f16 bundle in f16 arithmetic (`bev_query` and `map_decoder` widened: index arithmetic), measured
/// (2026-12-06) on tract's portable f16 kernels (x86, AMD EPYC) and on its NEON fp16 kernels
/// (aarch64, qemu Cortex-A76), the larger of the two doubled.
const F16_NATIVE_BOUNDS: [(&str, f32); 8] = [
    ("value", 0.015),         // measured 7.07e-3 (aarch64; x86 5.37e-3)
    ("bev_query", 0.11),      // 5.14e-2 (widened)
    ("gkt_weights", 0.022),   // 1.10e-2 (widened)
    ("gathered", 8.6e-3),     // 4.29e-3 (aarch64; x86 3.95e-3)
    ("camera_bev", 0.16),     // 7.76e-2 (both)
    ("satellite_bev", 0.086), // 4.28e-2 (x86; aarch64 3.50e-2)
    ("class_logits", 0.22),   // 1.06e-1 (aarch64; x86 9.14e-2)
    ("points", 0.05),         // 2.48e-2 (x86; aarch64 2.26e-2; normalised to the BEV range)
];

/// The same for the int8 bundle (int8 weights, one scale per output channel, f32 arithmetic;
/// the reference points and other tables of under 16 values per channel kept f32): measured
/// (2026-12-07, x86 and aarch64 alike) and doubled.
const INT8_BOUNDS: [(&str, f32); 8] = [
    ("value", 0.045),        // measured 2.22e-2
    ("bev_query", 0.143),    // 7.12e-2
    ("gkt_weights", 0.023),  // 1.14e-2
    ("gathered", 0.039),     // 1.91e-2
    ("camera_bev", 0.194),   // 9.67e-2
    ("satellite_bev", 0.21), // 1.05e-1
    ("class_logits", 1.01),  // 5.02e-1
    ("points", 0.147),       // 7.33e-2 (normalised to the BEV range)
];

/// `precision`'s bundle: its manifest says so, its file is at most `max_size_share` of the f32
/// one, and every stage buffer stays within `bounds` of the f32 bundle's (and moves: the
/// rounding is real).
fn steps_within_bounds_of_f32(
    precision: Precision,
    engine: impl Fn() -> TractEngine,
    bounds: &[(&str, f32)],
    max_size_share: f64,
) {
    steps_within_bounds_of_f32_at(
        compiled_path(precision),
        precision,
        engine,
        bounds,
        max_size_share,
    );
}

/// [`steps_within_bounds_of_f32`] for the bundle at `path`.
fn steps_within_bounds_of_f32_at(
    path: PathBuf,
    precision: Precision,
    engine: impl Fn() -> TractEngine,
    bounds: &[(&str, f32)],
    max_size_share: f64,
) {
    let low = Bundle::open(&path).unwrap();
    assert_eq!(low.manifest().precision, precision);
    let full = Bundle::open(compiled_path(Precision::F32)).unwrap();
    assert_eq!(full.manifest().precision, Precision::F32);
    let size = |p: &PathBuf| std::fs::metadata(p).unwrap().len();
    let (small, big) = (size(&path), size(&compiled_path(Precision::F32)));
    println!("{precision} bundle {small} bytes, f32 {big} bytes");
    assert!(
        (small as f64) < big as f64 * max_size_share,
        "{small} vs {big}"
    );
    let from_f32 = stage_buffers(|| compiled_engine_as(Precision::F32));
    let from_low = stage_buffers(engine);
    let mut moved = false;
    for ((name, got, _), (_, f32s, _)) in from_low.iter().zip(&from_f32) {
        let d = max_abs_diff(got, f32s);
        moved |= d > 0.0;
        let stage = name.split(' ').nth(2).unwrap();
        let bound = bounds
            .iter()
            .find(|(n, _)| *n == stage)
            .map(|(_, b)| *b)
            .unwrap();
        println!("{precision} {name}: max abs diff from f32 {d:e} (bound {bound:e})");
        assert!(d <= bound, "{precision} {name}: {d:e} > {bound:e}");
    }
    assert!(
        moved,
        "the {precision} bundle computes exactly what f32 does: its weights were not rounded"
    );
}

/// The f16 bundle widened to f32 arithmetic, within [`F16_BOUNDS`], in under 60% of the f32 file.
#[test]
fn the_f16_bundle_widened_steps_within_its_bounds_of_f32() {
    let engine = || compiled_f16_engine(HalfArithmetic::Widened);
    assert_eq!(
        engine().half_arithmetic(Stage::ImageEncoder),
        Some(HalfArithmetic::Widened)
    );
    steps_within_bounds_of_f32(Precision::F16, engine, &F16_BOUNDS, 0.6);
}

/// The f16 bundle in f16 arithmetic, within [`F16_NATIVE_BOUNDS`]: the encoders run in f16,
/// `bev_query` and `map_decoder` widened (their index arithmetic: sampling locations).
#[test]
fn the_f16_bundle_in_f16_arithmetic_steps_within_its_bounds_of_f32() {
    let engine = || compiled_f16_engine(HalfArithmetic::Native);
    let loaded = engine();
    for stage in Stage::ALL {
        let want = if matches!(stage, Stage::BevQuery | Stage::MapDecoder) {
            HalfArithmetic::Widened
        } else {
            HalfArithmetic::Native
        };
        assert_eq!(loaded.half_arithmetic(stage), Some(want), "{stage}");
    }
    drop(loaded);
    steps_within_bounds_of_f32(Precision::F16, engine, &F16_NATIVE_BOUNDS, 0.6);
}

/// Opened without a choice, the f16 bundle is widened on every core (f16 arithmetic costs more
/// instructions than f32 through tract on this model: docs/perf.md); the f32 bundle has no f16
/// arithmetic to report.
#[test]
fn the_f16_bundle_is_widened_unless_asked() {
    println!(
        "this core: f16 arithmetic {}",
        if HalfArithmetic::of_this_core() == HalfArithmetic::Native {
            "present"
        } else {
            "absent"
        }
    );
    let f16 = compiled_engine_as(Precision::F16);
    for stage in Stage::ALL {
        assert_eq!(f16.half_arithmetic(stage), Some(HalfArithmetic::Widened));
    }
    assert_eq!(
        compiled_engine_as(Precision::F32).half_arithmetic(Stage::MapDecoder),
        None
    );
}

/// The int8 bundle, within [`INT8_BOUNDS`], in under 45% of the f32 file.
#[test]
fn the_int8_bundle_steps_within_its_bounds_of_f32() {
    steps_within_bounds_of_f32(
        Precision::Int8,
        || compiled_engine_as(Precision::Int8),
        &INT8_BOUNDS,
        0.45,
    );
}

/// The int8 bundle with calibrated ranges, its 15 convolutions and its linear layers (56 on
/// AVX-512, 47 on aarch64) in integer arithmetic on this CPU's integer tier (AVX-512 VNNI,
/// AVX-VNNI or AVX2 on x86; `sdot` on aarch64: every tier gives the same integer sums, the rest
/// is the kernel family's f32): measured (2026-12-07, the convolutions in int8 too, the
/// reference points f32) on the AVX-512 VNNI Xeon and on qemu's Cortex-A76, the larger doubled.
const W8A8_BOUNDS: [(&str, f32); 8] = [
    ("value", 0.103),         // measured 5.11e-2 (both)
    ("bev_query", 0.189),     // 9.44e-2 (x86; aarch64 7.97e-2)
    ("gkt_weights", 0.045),   // 2.24e-2 (x86; aarch64 1.75e-2)
    ("gathered", 0.067),      // 3.33e-2 (x86; aarch64 3.32e-2)
    ("camera_bev", 0.284),    // 1.42e-1 (aarch64; x86 1.34e-1)
    ("satellite_bev", 0.453), // 2.26e-1 (x86; aarch64 2.10e-1)
    ("class_logits", 1.02),   // 5.10e-1 (aarch64; x86 4.25e-1)
    ("points", 0.157),        // 7.82e-2 (x86; aarch64 5.21e-2; normalised to the BEV range)
];

/// The W8A8 bundle, within [`W8A8_BOUNDS`], in under 45% of the f32 file; its convolutions and
/// linear layers are int8 products.
#[test]
fn the_w8a8_bundle_steps_within_its_bounds_of_f32() {
    let engine = || {
        let path = w8a8_path();
        TractEngine::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    };
    let loaded = engine();
    let (linears, convs): (usize, usize) = Stage::ALL.iter().fold((0, 0), |(l, c), &s| {
        let r = loaded.rewrites(s);
        (l + r.int8_linears, c + r.int8_convs)
    });
    drop(loaded);
    // Linear layers: 56 where the native f32 product runs (AVX-512: products over several axes
    // are first reshaped into linear layers), 47 where tract's products run (aarch64). The 15
    // convolutions on every target.
    println!("{linears} int8 linear layers, {convs} int8 convolutions");
    assert!(linears >= 45, "{linears} int8 linear layers");
    assert_eq!(convs, 15, "int8 convolutions");
    steps_within_bounds_of_f32_at(w8a8_path(), Precision::Int8, engine, &W8A8_BOUNDS, 0.45);
}
