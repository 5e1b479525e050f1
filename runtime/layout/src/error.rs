//! Why a layout file is refused ([`LayoutError`]), one variant per rule with the values.

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
    /// A BEV region's dtype is neither f32 nor f16.
    #[error(
        "ERROR(layout): region `{region}` has dtype \"{dtype}\"; the BEV feature maps are stored \
         as \"f32\" or \"f16\""
    )]
    FeatureDtype {
        /// Region name.
        region: &'static str,
        /// Its dtype.
        dtype: &'static str,
    },
    /// The two BEV regions have different dtypes.
    #[error(
        "ERROR(layout): camera_bev is \"{camera_bev}\" but satellite_bev is \"{satellite_bev}\"; \
         the decoder reads both in one storage. Give both the same dtype."
    )]
    FeatureDtypesDiffer {
        /// camera_bev's dtype.
        camera_bev: &'static str,
        /// satellite_bev's dtype.
        satellite_bev: &'static str,
    },
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
            Self::FeatureDtype { .. } => "FeatureDtype",
            Self::FeatureDtypesDiffer { .. } => "FeatureDtypesDiffer",
            Self::MissingRegion(_) => "MissingRegion",
            Self::MissingBudget(_) => "MissingBudget",
            Self::ZeroStepPeriod => "ZeroStepPeriod",
            Self::ZeroStepScratch => "ZeroStepScratch",
            Self::PeakAboveArena { .. } => "PeakAboveArena",
            Self::ArenaTooSmall { .. } => "ArenaTooSmall",
        }
    }
}
