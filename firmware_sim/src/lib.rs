//! `satmap-sim` (host): the harness (replay, arena, report), synthetic worlds, the evaluator,
//! pictures, route-pack builder and the CLI. May import: `satmap-runtime` (with `onnx`),
//! `satmap-recording`, `satmap-layout`.
//!
//! Host-side simulation harness and tools for the SatMap ECU runtime.
//!
//! `cli` holds one module per `satmap-sim` subcommand (arguments + entry point); the other
//! modules are the libraries those commands and the integration tests use.
#![deny(missing_docs)]

pub mod arena;
pub mod cli;
pub mod eval;
pub mod harness;
pub mod render;
pub mod route_pack_builder;
pub mod synth;
