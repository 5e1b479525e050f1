//! One module per `satmap-sim` subcommand: its clap arguments and its `run` entry point.

pub mod build_pack;
pub mod evaluate;
pub mod render;
pub mod synth_drive;
