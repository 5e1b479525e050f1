//! `satmap-sim`: the host-side harness and tools, one subcommand each.
//!
//! Each subcommand's arguments and entry point live in `satmap_sim::cli::<name>`; this file only
//! dispatches, so that adding a tool touches one enum line here.

use clap::{Parser, Subcommand};

/// SatMap host harness and tools.
#[derive(Parser)]
#[command(name = "satmap-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match cli.command {}
}
