//! One module per `satmap-sim` subcommand: its clap arguments and its `run` entry point.

pub mod build_pack;
