//! `satmap-sim compile`: turn a folder bundle (the export's ONNX stages) into the one-file
//! compiled bundle the ECU engine loads (NNEF stages; format in `ARCHITECTURE.md`, "Compiled
//! bundle"), checked against a memory layout before it is written.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use satmap_runtime::bundle::{Bundle, Precision};
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::translate::compile;

use crate::cli::memory_map::{built_in_layout_line, read_layout};

/// Arguments of `compile`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The folder bundle to compile (manifest.toml, manifest.sha256, ONNX stages).
    #[arg(long)]
    pub bundle: PathBuf,
    /// The compiled bundle to write (by convention `<name>.satmap`).
    #[arg(long)]
    pub out: PathBuf,
    /// Precision: f32 (as exported), f16 (weights stored as f16) or int8 (weights stored as
    /// int8, one scale per output channel); both widened to f32 at load on this CPU.
    #[arg(long, default_value = "f32")]
    pub precision: Precision,
    /// Memory layout the model must fit (default: the one this binary was built with).
    #[arg(long)]
    pub layout: Option<PathBuf>,
}

/// Compile, write, then load the written file back through the engine once and print the load
/// time next to the folder's.
///
/// # Errors
/// The source bundle refused, a stage that does not translate, the layout too small, or the
/// output not writable.
pub fn run(args: &Args) -> Result<()> {
    let layout = read_layout(args.layout.as_deref())?;
    let source = Bundle::open(&args.bundle)?;
    let compiled = compile(&source, args.precision, |name| {
        layout.region(name).map(|r| r.bytes)
    })?;
    std::fs::write(&args.out, &compiled.bytes)
        .with_context(|| format!("writing {}", args.out.display()))?;
    match &args.layout {
        Some(p) => println!("layout {}", p.display()),
        None => println!("{}", built_in_layout_line()),
    }
    println!(
        "precision {}\n{:<18} {:>12} {:>12} {:>16} {:>14}",
        args.precision, "stage", "onnx bytes", "nnef bytes", "f32 weight bytes", "translate ms"
    );
    for s in &compiled.stages {
        println!(
            "{:<18} {:>12} {:>12} {:>16} {:>14.1}",
            s.stage.name(),
            s.onnx_bytes,
            s.nnef_bytes,
            s.f32_weight_bytes,
            s.translate_ms
        );
    }
    let written = Bundle::open(&args.out)?;
    println!(
        "wrote {} ({} bytes), digest {}",
        args.out.display(),
        compiled.bytes.len(),
        written.digest()
    );
    let t = Instant::now();
    TractEngine::load(&written)?;
    let compiled_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    TractEngine::load(&source)?;
    let onnx_ms = t.elapsed().as_secs_f64() * 1e3;
    println!(
        "load + optimise: {compiled_ms:.0} ms from the compiled bundle, {onnx_ms:.0} ms from ONNX"
    );
    Ok(())
}
