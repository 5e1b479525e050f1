//! The workspace's integration tests across crates, one module a concern, in one test binary:
//! each binary of ~250 MB is linked on its own, so one binary instead of ten saves that link and
//! the monomorphised tract code each would compile again, and its tests share the cores.
//! `fuzz_parsers` stays a binary of its own (`make fuzz` runs it alone at campaign size).

mod bundle_check;
mod bundle_integrity;
mod bundle_signature;
mod c_api;
mod caller_memory;
mod common;
mod compiled_bundle;
mod docs_links;
mod forged_graphs;
mod golden_step;
mod int8_arithmetic;
mod layout_variants;
mod route_frame_distortion;
mod route_pack_compressed;
mod threads;
