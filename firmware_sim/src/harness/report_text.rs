//! The drive report as the human-readable table `satmap-sim drive` prints.

use std::fmt::Write as _;

use super::report::{Report, WARMUP_STEPS};

impl Report {
    /// The human-readable table.
    #[must_use]
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let mib = |b: usize| b as f64 / (1024.0 * 1024.0);
        let ms = |us: u64| us as f64 / 1000.0;
        let _ = writeln!(
            s,
            "satmap-sim drive: {} frames of {}",
            self.frames, self.scenario
        );
        let _ = writeln!(s, "bundle {} (config `{}`)", self.bundle, self.config);
        let _ = writeln!(
            s,
            "memory layout {} (sized for `{}`)",
            self.layout, self.layout_sized_for
        );
        let _ = writeln!(
            s,
            "virtual clock {:.3} Hz (step period {:.1} ms); budgets for: {}",
            self.rate_hz,
            ms(self.step_period_us),
            self.budget_reference
        );
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "{:<18} {:>7} {:>10} {:>10} {:>10} {:>10} {:>6}",
            "stage", "samples", "p50 ms", "p99 ms", "max ms", "budget ms", "over"
        );
        for st in &self.stages {
            let _ = writeln!(
                s,
                "{:<18} {:>7} {:>10.2} {:>10.2} {:>10.2} {:>10.1} {:>6}",
                st.name,
                st.latency.count,
                ms(st.latency.p50_us),
                ms(st.latency.p99_us),
                ms(st.latency.max_us),
                ms(st.budget_us),
                st.over_budget
            );
        }
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "deadline misses    {} of {} steps (stage budget misses {})",
            self.deadline_misses,
            self.steps.len(),
            self.stage_budget_misses
        );
        let a = &self.arena;
        let _ = writeln!(
            s,
            "arena peak         {} bytes ({:.1} MiB) of budget {} ({:.1} MiB), arena {} ({:.1} MiB)",
            a.peak_bytes,
            mib(a.peak_bytes),
            a.peak_budget_bytes,
            mib(a.peak_budget_bytes),
            a.capacity_bytes,
            mib(a.capacity_bytes)
        );
        let _ = writeln!(
            s,
            "  graph engine     {} bytes ({:.1} MiB) after loading the bundle",
            a.graph_engine_bytes,
            mib(a.graph_engine_bytes)
        );
        let _ = writeln!(
            s,
            "  runtime regions  {} bytes ({:.1} MiB) reserved by SatMap::new (layout capacity {})",
            a.runtime_regions_bytes,
            mib(a.runtime_regions_bytes),
            a.layout_runtime_bytes
        );
        let al = &self.allocations;
        let _ = writeln!(
            s,
            "allocations/step   after {WARMUP_STEPS} warm-up steps ({} steps): outside the graph \
             engine max {}, inside max {}, tile decoder scratch max {}; arena peak growth {} \
             bytes",
            al.steps,
            al.outside_engine_max_per_step,
            al.engine_max_per_step,
            al.decoder_max_per_step,
            al.peak_growth_bytes
        );
        let d = &self.degraded;
        let _ = write!(
            s,
            "degraded steps     {} of {} ({:.1}%; stated limit {:.1}%)",
            d.steps,
            self.steps.len(),
            100.0 * d.share,
            100.0 * d.max_share
        );
        if d.by_reason.is_empty() {
            let _ = writeln!(s);
        } else {
            let _ = writeln!(s, ": {}", d.reasons_text());
        }
        let _ = writeln!(s, "run digest         {}", self.run_digest);
        if let Some(q) = &self.map_quality {
            let classes: Vec<String> = q
                .class_ap
                .iter()
                .map(|(n, ap)| format!("{n} {ap:.3}"))
                .collect();
            let _ = writeln!(
                s,
                "map mAP            {:.4} ({})",
                q.mean_ap,
                classes.join(", ")
            );
            let _ = writeln!(s, "                   {}", q.note);
        }
        if self.exceeded.is_empty() {
            let _ = writeln!(s, "verdict            all budgets met");
        } else {
            let _ = writeln!(s, "verdict            BUDGET EXCEEDED");
            for e in &self.exceeded {
                let _ = writeln!(s, "  - {e}");
            }
        }
        if let Some(why) = self.degraded_verdict() {
            let _ = writeln!(s, "verdict            DEGRADED RUN");
            let _ = writeln!(s, "  - {why}");
        }
        s
    }
}
