//! Runs one stage of a committed compiled `test` bundle `REPEATS` times on the reference inputs,
//! on one thread, and prints a digest of its outputs: the program `targets/insn_counts.sh` runs
//! under qemu's instruction-counting plugin. Two runs (1 and 1 + n repeats) differ by n stage
//! runs exactly: loading, planning and the first run's lazy set-up cancel out.
//!
//! ```text
//! stage_insns f32|f16|f16-widened|int8 image_encoder|bev_query|bev_encoder|satellite_encoder|map_decoder REPEATS
//! ```
//!
//! `f16` runs the f16 bundle in the arithmetic this core has (f16 on FEAT_FP16), `f16-widened`
//! in f32 arithmetic.

use std::process::ExitCode;

use satmap_ecu_tests::golden::compiled_path;
use satmap_ecu_tests::stages::{ReferenceInputs, StageOutputs};
use satmap_runtime::Stage;
use satmap_runtime::bundle::{Bundle, Precision};
use satmap_runtime::engine_tract::{HalfArithmetic, TractEngine, kernel_family};

fn parse(args: &[String]) -> Result<(Precision, HalfArithmetic, Stage, usize), String> {
    let [_, precision, stage, repeats] = args else {
        return Err("usage: stage_insns f32|f16|f16-widened|int8 STAGE REPEATS".into());
    };
    let (precision, half) = match precision.as_str() {
        "f32" => (Precision::F32, HalfArithmetic::Widened),
        "f16" => (Precision::F16, HalfArithmetic::of_this_core()),
        "f16-widened" => (Precision::F16, HalfArithmetic::Widened),
        "int8" => (Precision::Int8, HalfArithmetic::Widened),
        other => {
            return Err(format!(
                "precision {other:?}: one of f32, f16, f16-widened, int8"
            ));
        }
    };
    let stage = Stage::ALL
        .into_iter()
        .find(|s| s.name() == stage)
        .ok_or_else(|| format!("stage {stage:?}: one of image_encoder, bev_query, bev_encoder, satellite_encoder, map_decoder"))?;
    let repeats = repeats
        .parse()
        .map_err(|e| format!("repeats {repeats:?}: {e}"))?;
    Ok((precision, half, stage, repeats))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let (precision, half, stage, repeats) = match parse(&args) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let path = compiled_path(precision);
    let mut engine = match Bundle::open(&path).and_then(|b| TractEngine::load_with(&b, half)) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("{}: {e}", path.display());
            return ExitCode::FAILURE;
        }
    };
    let inputs = ReferenceInputs::load();
    let mut outputs = StageOutputs::new(&engine);
    for _ in 0..repeats {
        if let Err(e) = outputs.run(&mut engine, stage, &inputs) {
            eprintln!("{stage}: {e}");
            return ExitCode::FAILURE;
        }
    }
    // The outputs' bits folded (FNV-1a), so a count is tied to what the stage computed.
    let digest = outputs
        .of(stage)
        .iter()
        .flat_map(|o| o.iter())
        .fold(0xcbf2_9ce4_8422_2325_u64, |h, x| {
            (h ^ u64::from(x.to_bits())).wrapping_mul(0x100_0000_01b3)
        });
    println!(
        "{} {stage} x{repeats} kernel_family={} f16_arithmetic={} digest={digest:016x}",
        path.display(),
        kernel_family(),
        engine
            .half_arithmetic(stage)
            .map_or("-", HalfArithmetic::name),
    );
    ExitCode::SUCCESS
}
