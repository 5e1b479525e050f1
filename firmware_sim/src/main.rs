//! `satmap-sim`: the host-side harness and tools, one subcommand each.
//!
//! Each subcommand's arguments and entry point live in `satmap_sim::cli::<name>`; this file only
//! dispatches, so that adding a tool touches one enum line here.

use clap::{Parser, Subcommand};
use satmap_runtime::capacity::layout::{ARENA_BYTES, STEP_SCRATCH_BYTES};
use satmap_sim::arena::{ArenaAllocator, ArenaStorage};

/// The process allocator: the system's until `drive` hands it the arena, then the counting TLSF
/// heap over [`ARENA`]. Library users and unit tests keep the system allocator.
#[global_allocator]
static ALLOC: ArenaAllocator = ArenaAllocator::new();
/// The fixed arena, `[arena] bytes` of memory_layout.toml (in .bss: untouched pages cost nothing).
static ARENA: ArenaStorage<ARENA_BYTES> = ArenaStorage::new();
/// The per-step scratch region, `[arena] step_scratch_bytes` (also in .bss).
static STEP_SCRATCH: ArenaStorage<STEP_SCRATCH_BYTES> = ArenaStorage::new();

/// SatMap host harness and tools.
#[derive(Parser)]
#[command(name = "satmap-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build a route pack from slippy-map tiles or a georeferenced image and a GeoJSON route.
    BuildPack(satmap_sim::cli::build_pack::Args),
    /// Generate a seeded synthetic drive as a scenario folder (tiles, route, frames, GT).
    SynthDrive(satmap_sim::cli::synth_drive::Args),
    /// Training data for `models/`: synthetic drives split by world seed (train / val / test).
    ExportDataset(satmap_sim::cli::export_dataset::Args),
    /// Chamfer-AP of a MapTR-layout predictions file against a ground-truth file.
    Evaluate(satmap_sim::cli::evaluate::Args),
    /// Pictures of a scenario: satellite crop with GT and predictions, contact sheet, GeoJSON.
    Render(satmap_sim::cli::render::Args),
    /// Replay a drive through the runtime inside the fixed arena and report against the budgets.
    Drive(satmap_sim::cli::drive::Args),
    /// Print memory_layout.toml as a linker map (regions, totals, headroom).
    MemoryMap(satmap_sim::cli::memory_map::Args),
    /// Run every stage of bundles in tract and compare with their onnxruntime reference outputs.
    CheckBundle(satmap_sim::cli::check_bundle::Args),
    /// Compile a folder bundle (ONNX stages) into the one-file NNEF bundle the ECU engine loads.
    Compile(satmap_sim::cli::compile::Args),
    /// Time every stage and the step of a bundle on its reference inputs (JSON; `make bench-peers`).
    BenchStages(satmap_sim::cli::bench_stages::Args),
    /// Make an Ed25519 key pair for signing bundles (`<name>.key` secret, `<name>.pub` public).
    Keygen(satmap_sim::cli::keygen::Args),
    /// Sign bundles with a `keygen` secret key (writes `<bundle>.sig`, or `manifest.sig` inside
    /// a folder).
    SignBundle(satmap_sim::cli::sign_bundle::Args),
    /// Print the family of graph kernels this CPU runs (the suffix of per-family digest files).
    KernelFamily,
}

fn main() -> std::process::ExitCode {
    satmap_sim::arena::system_malloc::keep_freed_memory();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::BuildPack(args) => satmap_sim::cli::build_pack::run(&args),
        Command::SynthDrive(args) => satmap_sim::cli::synth_drive::run(&args),
        Command::ExportDataset(args) => satmap_sim::cli::export_dataset::run(&args),
        Command::Evaluate(args) => satmap_sim::cli::evaluate::run(&args),
        Command::Render(args) => satmap_sim::cli::render::run(&args),
        Command::Drive(args) => {
            satmap_sim::cli::drive::run(&args, &ALLOC, &|arena_bytes, scratch_bytes| {
                ALLOC.init(&ARENA, arena_bytes)
                    && ALLOC.init_step_scratch(&STEP_SCRATCH, scratch_bytes)
            })
        }
        Command::MemoryMap(args) => satmap_sim::cli::memory_map::run(&args),
        Command::CheckBundle(args) => satmap_sim::cli::check_bundle::run(&args),
        Command::Compile(args) => satmap_sim::cli::compile::run(&args),
        Command::BenchStages(args) => satmap_sim::cli::bench_stages::run(&args),
        Command::Keygen(args) => satmap_sim::cli::keygen::run(&args),
        Command::SignBundle(args) => satmap_sim::cli::sign_bundle::run(&args),
        Command::KernelFamily => {
            println!("{}", satmap_runtime::engine_tract::kernel_family());
            Ok(())
        }
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(satmap_sim::cli::drive::exit_code(&e))
        }
    }
}
