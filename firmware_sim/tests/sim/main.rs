//! satmap-sim's integration tests, one module a concern, in one test binary (one link instead of
//! one a file). `harness_arena` stays a binary of its own: it declares the arena allocator as the
//! process's global allocator.

mod bundle_signing_cli;
mod cli_exit_codes;
mod cli_refusals;
mod common;
mod drive_mcap;
mod eval_chamfer_ap;
mod eval_geos_buffer;
mod eval_maptr_protocol;
mod export_dataset;
mod harness_clock;
mod harness_digest;
mod harness_exhaustion;
mod render_pictures;
mod route_pack_builder;
mod route_replay_cli;
mod synth_drive;
mod trained_model_map;
