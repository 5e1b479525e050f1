//! `satmap-ecu-tests` (std, ECU build): what the ECU build proves on every target. May import:
//! `satmap-runtime` (with `tract`).
//!
//! Shared by the ECU tests (`tests/ecu/tests/`) and the workspace's integration tests
//! (`tests/integration/`): the golden vectors written by `models/` (`python -m satmap_ref.golden`)
//! the parity checks of a step against them, with their tolerances, and the C-API scenario. Depends on the ECU build
//! of the runtime only, so that it cross-builds for every target the runtime claims.

pub mod golden;
pub mod parity;
pub mod scenario;
pub mod stages;
