//! `satmap-layout` (host): parses and checks `memory_layout.toml`; `runtime/core/build.rs` turns it
//! into the core's constants. May import: no SatMap crate.
//!
//! `memory_layout.toml`: the runtime's memory map, like a linker script's `memory.x`.
//!
//! The file names every buffer the runtime holds (shape, dtype, bytes), the arena the graph
//! engine allocates from, and the budgets (peak bytes, per-stage and per-step latency). This
//! crate parses and checks it (for `runtime/core/build.rs`, which turns it into constants, and for the
//! host tools, which print it like a linker map). Messages prefixed `ERROR(layout):` mean the
//! file is wrong; they come with the fix.
#![deny(missing_docs)]

use std::collections::BTreeMap;

mod codegen;
mod error;
mod render;

pub use error::LayoutError;

use serde::Deserialize;

/// Element type of a region.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DType {
    /// 1 byte.
    U8,
    /// 2 bytes.
    U16,
    /// 2 bytes (IEEE half).
    F16,
    /// 4 bytes.
    U32,
    /// 4 bytes.
    F32,
    /// 8 bytes.
    U64,
    /// A packed record: `elem_bytes` gives the size.
    Record,
}

impl DType {
    /// Bytes per element (`None` for records).
    #[must_use]
    pub const fn size_bytes(self) -> Option<usize> {
        match self {
            DType::U8 => Some(1),
            DType::U16 | DType::F16 => Some(2),
            DType::U32 | DType::F32 => Some(4),
            DType::U64 => Some(8),
            DType::Record => None,
        }
    }

    /// The name in the file: `u8`, `f16`, `record`, ...
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            DType::U8 => "u8",
            DType::U16 => "u16",
            DType::F16 => "f16",
            DType::U32 => "u32",
            DType::F32 => "f32",
            DType::U64 => "u64",
            DType::Record => "record",
        }
    }
}

/// The regions whose storage the layout may choose (`f32`, or `f16` to halve them: the BEV
/// feature maps, `satmap_core::features`); both must have the same dtype. Every other float
/// region is f32.
pub const FEATURE_STORAGE_REGIONS: [&str; 2] = ["camera_bev", "satellite_bev"];

/// Who owns a region's memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Owner {
    /// Allocated once by the runtime at init.
    #[default]
    Runtime,
    /// Provided by the caller every step (borrowed).
    Caller,
    /// Read in place from flash (route packs).
    Flash,
}

/// One named buffer.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// What the buffer holds.
    pub doc: String,
    /// Shape (capacity).
    pub shape: Vec<usize>,
    /// Element type.
    pub dtype: DType,
    /// Size of one element for `dtype = "record"`.
    #[serde(default)]
    pub elem_bytes: Option<usize>,
    /// Total bytes: must equal the product of the shape times the element size.
    pub bytes: usize,
    /// Who owns it.
    #[serde(default)]
    pub owner: Owner,
}

/// The graph engine's arena and the harness's whole-process arena.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Arena {
    /// Size of the fixed arena the host harness runs the whole runtime in, bytes.
    pub bytes: usize,
    /// Of which reserved for the graph engine (weights, plans), bytes.
    pub graph_engine_bytes: usize,
    /// The per-step scratch region, apart from the arena: every allocation made during a step
    /// (the graph engine's activations, a compressed pack's tile decoder) is served here and
    /// returned before the step ends, so the arena itself sees no allocation in a step. Sized
    /// from the largest step the layout's model makes; checked at load by a rehearsal step.
    pub step_scratch_bytes: usize,
}

/// Budgets the harness checks.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Budgets {
    /// The machine and configuration the latency budgets are stated for.
    pub reference: String,
    /// Largest arena peak allowed, bytes.
    pub peak_bytes: usize,
    /// Step period of the replay clock, microseconds (the deadline of one step).
    pub step_period_us: u64,
    /// Per-stage latency budgets, microseconds, by stage name (`image_encoder` is per camera;
    /// `gkt_gather` is the native kernel; `step` is the whole step).
    pub latency_us: BTreeMap<String, u64>,
}

/// The whole memory map.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MemoryLayout {
    /// The model configuration the capacities are sized for.
    pub sized_for: String,
    /// Buffers, by name.
    pub region: BTreeMap<String, Region>,
    /// Arena sizes.
    pub arena: Arena,
    /// Budgets.
    pub budgets: Budgets,
}

/// Regions the runtime cannot run without.
pub const REQUIRED_REGIONS: [&str; 14] = [
    "camera_images",
    "value_features",
    "gkt_lut",
    "bev_query",
    "gkt_weights",
    "gathered",
    "camera_bev",
    "satellite_crop",
    "satellite_bev",
    "class_logits",
    "points",
    "map_frame",
    "tile_cache",
    "tile_pixels",
];

/// Latency budgets the harness checks.
pub const REQUIRED_BUDGETS: [&str; 8] = [
    "image_encoder",
    "bev_query",
    "gkt_gather",
    "bev_encoder",
    "satellite_crop",
    "satellite_encoder",
    "map_decoder",
    "step",
];

impl MemoryLayout {
    /// Parse and check a layout.
    pub fn parse(text: &str) -> Result<Self, LayoutError> {
        let layout: MemoryLayout =
            toml::from_str(text).map_err(|e| LayoutError::Parse(e.to_string()))?;
        layout.check()?;
        Ok(layout)
    }

    /// Check sizes, required regions and budgets, and that everything fits the arena.
    pub fn check(&self) -> Result<(), LayoutError> {
        for name in REQUIRED_REGIONS {
            if !self.region.contains_key(name) {
                return Err(LayoutError::MissingRegion(name));
            }
        }
        for name in REQUIRED_BUDGETS {
            if !self.budgets.latency_us.contains_key(name) {
                return Err(LayoutError::MissingBudget(name));
            }
        }
        self.check_feature_storage()?;
        for (name, r) in &self.region {
            let elem = match (r.dtype.size_bytes(), r.elem_bytes) {
                (Some(s), None) => s,
                (None, Some(s)) if s > 0 => s,
                _ => return Err(LayoutError::ElemBytes(name.clone())),
            };
            let computed = r
                .shape
                .iter()
                .try_fold(elem, |acc, &d| acc.checked_mul(d))
                .unwrap_or(usize::MAX);
            if computed != r.bytes {
                return Err(LayoutError::Bytes {
                    region: name.clone(),
                    declared: r.bytes,
                    shape: r.shape.clone(),
                    elem,
                    computed,
                });
            }
        }
        if self.budgets.step_period_us == 0 {
            return Err(LayoutError::ZeroStepPeriod);
        }
        if self.arena.step_scratch_bytes == 0 {
            return Err(LayoutError::ZeroStepScratch);
        }
        if self.budgets.peak_bytes > self.arena.bytes {
            return Err(LayoutError::PeakAboveArena {
                peak: self.budgets.peak_bytes,
                arena: self.arena.bytes,
            });
        }
        let regions = self.runtime_bytes();
        let total = regions.saturating_add(self.arena.graph_engine_bytes);
        if total > self.arena.bytes {
            return Err(LayoutError::ArenaTooSmall {
                regions,
                graph: self.arena.graph_engine_bytes,
                total,
                arena: self.arena.bytes,
            });
        }
        Ok(())
    }

    /// The BEV regions are `f32` or `f16`, both the same.
    fn check_feature_storage(&self) -> Result<(), LayoutError> {
        let [camera, satellite] = FEATURE_STORAGE_REGIONS.map(|n| self.region.get(n));
        for (name, r) in FEATURE_STORAGE_REGIONS.iter().zip([camera, satellite]) {
            if let Some(r) = r
                && !matches!(r.dtype, DType::F32 | DType::F16)
            {
                return Err(LayoutError::FeatureDtype {
                    region: name,
                    dtype: r.dtype.name(),
                });
            }
        }
        match (camera, satellite) {
            (Some(c), Some(s)) if c.dtype != s.dtype => Err(LayoutError::FeatureDtypesDiffer {
                camera_bev: c.dtype.name(),
                satellite_bev: s.dtype.name(),
            }),
            _ => Ok(()),
        }
    }

    /// A region by name.
    #[must_use]
    pub fn region(&self, name: &str) -> Option<&Region> {
        self.region.get(name)
    }

    /// Bytes of all runtime-owned regions.
    #[must_use]
    pub fn runtime_bytes(&self) -> usize {
        self.region
            .values()
            .filter(|r| r.owner == Owner::Runtime)
            // Saturating: sizes from the file may sum past usize, and the arena check then
            // reports the layout instead of the parser overflowing (build.rs runs it too).
            .fold(0usize, |acc, r| acc.saturating_add(r.bytes))
    }
}
