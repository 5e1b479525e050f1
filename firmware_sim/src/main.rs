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
enum Command {
    /// Build a route pack from slippy-map tiles or a georeferenced image and a GeoJSON route.
    BuildPack(satmap_sim::cli::build_pack::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::BuildPack(args) => satmap_sim::cli::build_pack::run(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
