//! The layout as a linker-map-like table (`satmap-sim memory-map`).

use std::fmt::Write as _;

use crate::{MemoryLayout, Owner};

impl MemoryLayout {
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
