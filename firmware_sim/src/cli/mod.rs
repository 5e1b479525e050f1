//! One module per `satmap-sim` subcommand: its clap arguments and its `run` entry point.

pub mod bench_stages;
pub mod build_pack;
pub mod check_bundle;
pub mod compile;
pub mod drive;
pub mod evaluate;
pub mod export_dataset;
pub mod keygen;
pub mod memory_map;
pub mod render;
pub mod sign_bundle;
pub mod synth_drive;
