//! The layout as Rust constants: what `runtime/core/build.rs` writes to `OUT_DIR`.

use std::fmt::Write as _;

use crate::MemoryLayout;

impl MemoryLayout {
    /// Rust source with one `pub const <NAME>_BYTES: usize`, `<NAME>_DTYPE` and `<NAME>_SHAPE`
    /// per region, the arena sizes and the budgets: what `runtime/core/build.rs` writes to
    /// `OUT_DIR`.
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
            let _ = writeln!(s, "/// `{name}`: element type, as in the layout file.");
            let _ = writeln!(s, "pub const {upper}_DTYPE: &str = {:?};", r.dtype.name());
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
}
