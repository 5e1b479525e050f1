//! `memory_layout.toml`: the runtime's memory map, like a linker script's `memory.x`.
//!
//! The file names every buffer the runtime holds (shape, dtype, bytes), the arena the graph
//! engine allocates from, and the budgets (peak bytes, per-stage and per-step latency). This
//! crate parses and checks it (for `runtime/core/build.rs`, which turns it into constants, and for the
//! host tools, which print it like a linker map). Messages prefixed `ERROR(layout):` mean the
//! file is wrong; they come with the fix.
#![deny(missing_docs)]

use std::collections::BTreeMap;
use std::fmt::Write as _;

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
}

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

/// What is wrong with a layout file.
#[derive(Debug, thiserror::Error)]
pub enum LayoutError {
    /// Not TOML, or fields missing or unknown.
    #[error("ERROR(layout): memory_layout.toml does not parse: {0}")]
    Parse(String),
    /// A region's `bytes` does not match its shape and dtype.
    #[error(
        "ERROR(layout): region `{region}` declares {declared} bytes but shape {shape:?} x {elem} \
         bytes per element is {computed}. Fix `bytes` (or the shape)."
    )]
    Bytes {
        /// Region name.
        region: String,
        /// Declared bytes.
        declared: usize,
        /// Shape.
        shape: Vec<usize>,
        /// Element size.
        elem: usize,
        /// Computed bytes.
        computed: usize,
    },
    /// A record region has no `elem_bytes` (or a non-record has one).
    #[error(
        "ERROR(layout): region `{0}`: `elem_bytes` is required for dtype \"record\" and only for it"
    )]
    ElemBytes(String),
    /// A region the runtime needs is missing.
    #[error("ERROR(layout): region `{0}` is missing; the runtime needs it")]
    MissingRegion(&'static str),
    /// A budget the harness needs is missing.
    #[error("ERROR(layout): [budgets.latency_us] has no `{0}`")]
    MissingBudget(&'static str),
    /// The step period is zero (the replay clock would not advance).
    #[error(
        "ERROR(layout): [budgets] step_period_us is 0; give the deadline of one step in microseconds"
    )]
    ZeroStepPeriod,
    /// The per-step scratch region is empty (every step allocates inside the graph engine).
    #[error(
        "ERROR(layout): [arena] step_scratch_bytes is 0; give the per-step scratch region's size \
         (the largest step's graph engine activations)"
    )]
    ZeroStepScratch,
    /// The peak budget is larger than the arena, so it could never be checked.
    #[error(
        "ERROR(layout): [budgets] peak_bytes = {peak} exceeds [arena] bytes = {arena}; the arena \
         caps the peak. Lower peak_bytes or raise the arena."
    )]
    PeakAboveArena {
        /// Peak budget.
        peak: usize,
        /// Arena size.
        arena: usize,
    },
    /// The runtime-owned regions plus the graph engine do not fit the arena.
    #[error(
        "ERROR(layout): runtime regions ({regions} bytes) + graph engine ({graph} bytes) = {total} \
         bytes exceed [arena] bytes = {arena}. Raise [arena] bytes or shrink a region."
    )]
    ArenaTooSmall {
        /// Sum of runtime-owned regions.
        regions: usize,
        /// Graph engine reservation.
        graph: usize,
        /// Their sum.
        total: usize,
        /// Arena size.
        arena: usize,
    },
}

impl LayoutError {
    /// Name of the variant, for tests and machine-readable reports.
    #[must_use]
    pub const fn kind(&self) -> &'static str {
        match self {
            Self::Parse(_) => "Parse",
            Self::Bytes { .. } => "Bytes",
            Self::ElemBytes(_) => "ElemBytes",
            Self::MissingRegion(_) => "MissingRegion",
            Self::MissingBudget(_) => "MissingBudget",
            Self::ZeroStepPeriod => "ZeroStepPeriod",
            Self::ZeroStepScratch => "ZeroStepScratch",
            Self::PeakAboveArena { .. } => "PeakAboveArena",
            Self::ArenaTooSmall { .. } => "ArenaTooSmall",
        }
    }
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

    /// Rust source with one `pub const <NAME>_BYTES: usize` and `<NAME>_SHAPE` per region, the
    /// arena sizes and the budgets: what `runtime/core/build.rs` writes to `OUT_DIR`.
    #[must_use]
    pub fn to_rust_consts(&self) -> String {
        let mut s = String::from(
            "// Generated from memory_layout.toml by runtime/core/build.rs. Edit the TOML.\n",
        );
        let _ = writeln!(s, "/// Model configuration the capacities are sized for.");
        let _ = writeln!(s, "pub const SIZED_FOR: &str = {:?};", self.sized_for);
        for (name, r) in &self.region {
            let upper = name.to_uppercase();
            let _ = writeln!(
                s,
                "/// `{name}`: {} (capacity, bytes).",
                r.doc.replace('\n', " ")
            );
            let _ = writeln!(s, "pub const {upper}_BYTES: usize = {};", r.bytes);
            if let Some(elem) = r.elem_bytes {
                let _ = writeln!(s, "/// `{name}`: bytes of one record.");
                let _ = writeln!(s, "pub const {upper}_ELEM_BYTES: usize = {elem};");
            }
            let _ = writeln!(s, "/// `{name}`: shape (capacity).");
            let _ = writeln!(
                s,
                "pub const {upper}_SHAPE: [usize; {}] = {:?};",
                r.shape.len(),
                r.shape
            );
        }
        let _ = writeln!(s, "/// Whole host arena, bytes.");
        let _ = writeln!(s, "pub const ARENA_BYTES: usize = {};", self.arena.bytes);
        let _ = writeln!(s, "/// Graph engine share of the arena, bytes.");
        let _ = writeln!(
            s,
            "pub const GRAPH_ENGINE_BYTES: usize = {};",
            self.arena.graph_engine_bytes
        );
        let _ = writeln!(
            s,
            "/// Per-step scratch region (apart from the arena), bytes."
        );
        let _ = writeln!(
            s,
            "pub const STEP_SCRATCH_BYTES: usize = {};",
            self.arena.step_scratch_bytes
        );
        let _ = writeln!(s, "/// Peak arena budget, bytes.");
        let _ = writeln!(
            s,
            "pub const PEAK_BUDGET_BYTES: usize = {};",
            self.budgets.peak_bytes
        );
        let _ = writeln!(s, "/// Step period (deadline), microseconds.");
        let _ = writeln!(
            s,
            "pub const STEP_PERIOD_US: u64 = {};",
            self.budgets.step_period_us
        );
        let _ = writeln!(
            s,
            "/// Machine and configuration the latency budgets are stated for."
        );
        let _ = writeln!(
            s,
            "pub const BUDGET_REFERENCE: &str = {:?};",
            self.budgets.reference
        );
        for (name, us) in &self.budgets.latency_us {
            let _ = writeln!(s, "/// Latency budget of `{name}`, microseconds.");
            let _ = writeln!(
                s,
                "pub const {}_BUDGET_US: u64 = {us};",
                name.to_uppercase()
            );
        }
        let _ = writeln!(s, "/// Every latency budget as (name, microseconds).");
        let _ = writeln!(
            s,
            "pub const LATENCY_BUDGETS_US: [(&str, u64); {}] = [",
            self.budgets.latency_us.len()
        );
        for (name, us) in &self.budgets.latency_us {
            let _ = writeln!(s, "    ({name:?}, {us}),");
        }
        let _ = writeln!(s, "];");
        s
    }

    /// The map as a linker-map-like table: every region with its offset, size and owner, the
    /// totals and the arena headroom.
    #[must_use]
    pub fn render_map(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "memory map (sized for config `{}`)", self.sized_for);
        let _ = writeln!(
            s,
            "{:<16} {:>12} {:>12} {:<8} {:<7} {:<22} doc",
            "region", "offset", "bytes", "owner", "dtype", "shape"
        );
        let mut offset = 0usize;
        for owner in [Owner::Runtime, Owner::Caller, Owner::Flash] {
            for (name, r) in self.region.iter().filter(|(_, r)| r.owner == owner) {
                let off = if owner == Owner::Runtime {
                    let o = format!("0x{offset:08x}");
                    offset = offset
                        .saturating_add(r.bytes.checked_next_multiple_of(64).unwrap_or(usize::MAX));
                    o
                } else {
                    "-".into()
                };
                let _ = writeln!(
                    s,
                    "{:<16} {:>12} {:>12} {:<8} {:<7} {:<22} {}",
                    name,
                    off,
                    r.bytes,
                    format!("{:?}", r.owner).to_lowercase(),
                    format!("{:?}", r.dtype).to_lowercase(),
                    format!("{:?}", r.shape),
                    r.doc
                );
            }
        }
        let regions = self.runtime_bytes();
        let used = regions.saturating_add(self.arena.graph_engine_bytes);
        let _ = writeln!(s, "{:-<100}", "");
        let _ = writeln!(
            s,
            "runtime regions      {regions:>12} bytes ({:.2} MiB)",
            mib(regions)
        );
        let _ = writeln!(
            s,
            "graph engine         {:>12} bytes ({:.2} MiB)",
            self.arena.graph_engine_bytes,
            mib(self.arena.graph_engine_bytes)
        );
        let _ = writeln!(
            s,
            "arena                {:>12} bytes ({:.2} MiB), headroom {} bytes ({:.1} %)",
            self.arena.bytes,
            mib(self.arena.bytes),
            self.arena.bytes - used.min(self.arena.bytes),
            100.0 * (self.arena.bytes - used.min(self.arena.bytes)) as f64
                / self.arena.bytes.max(1) as f64
        );
        let _ = writeln!(
            s,
            "step scratch         {:>12} bytes ({:.2} MiB), apart from the arena: every step's \
             allocations, empty between steps",
            self.arena.step_scratch_bytes,
            mib(self.arena.step_scratch_bytes)
        );
        let _ = writeln!(
            s,
            "peak budget          {:>12} bytes",
            self.budgets.peak_bytes
        );
        s
    }
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}
