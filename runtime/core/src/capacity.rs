//! Link-time capacities of the runtime: the fixed upper bounds every buffer and fixed-capacity
//! container is sized from.
//!
//! These are the numbers that `memory_layout.toml` will generate later; keep every such bound
//! here, in one place, so a build script can replace this file's values without touching code.

/// Map elements a [`crate::map_frame::MapFrame`] can hold (the decode top-k bound).
pub const MAX_TOP_K: usize = 50;

/// Points per polyline, fixed by the model's point queries.
pub const NUM_POINTS: usize = 20;

/// Map classes the head predicts (divider, ped_crossing, boundary).
pub const NUM_CLASSES: usize = 3;

/// GKT heads: one per reference height.
pub const NUM_HEADS: usize = 4;

/// Largest GKT kernel (rows x cols) the weights buffer and the look-up table accept.
pub const MAX_KERNEL_POINTS: usize = 25;

/// Length of the CAN-bus vector fed to the BEV query stage.
pub const CAN_BUS_LEN: usize = 18;

/// Largest BEV query count: query ids in the look-up table are stored as `u16`.
pub const MAX_QUERIES: usize = u16::MAX as usize + 1;

/// Largest feature-map size (`feat_h * feat_w`): feature indices are stored as `u16`.
pub const MAX_FEATURES: usize = u16::MAX as usize + 1;

/// Capacities and budgets generated from `memory_layout.toml` by `runtime/core/build.rs`: one
/// `<REGION>_BYTES` and `<REGION>_SHAPE` per region, the arena sizes and the latency budgets.
#[allow(missing_docs)]
pub mod layout {
    include!(concat!(env!("OUT_DIR"), "/memory_layout.rs"));
}
