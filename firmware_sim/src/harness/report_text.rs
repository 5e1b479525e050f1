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
            "  runtime regions  {} bytes ({:.1} MiB) reserved by SatMap::new, BEV maps {} \
             (layout capacity {})",
            a.runtime_regions_bytes,
            mib(a.runtime_regions_bytes),
            a.bev_storage,
            a.layout_runtime_bytes
        );
        let sc = &a.step_scratch;
        if sc.capacity_bytes > 0 {
            let _ = writeln!(
                s,
                "  step scratch     {} bytes ({:.1} MiB) at most in a step, {} ({:.1} MiB) at the \
                 load-time rehearsal ({} allocations), region {} ({:.1} MiB)",
                sc.step_peak_max_bytes,
                mib(sc.step_peak_max_bytes),
                sc.rehearsal_peak_bytes,
                mib(sc.rehearsal_peak_bytes),
                sc.rehearsal_allocations,
                sc.capacity_bytes,
                mib(sc.capacity_bytes)
            );
            if sc.engine_threads > 1 {
                let _ = writeln!(
                    s,
                    "                   ({} engine threads: lasting per-worker buffers grown in a \
                     step stay in the scratch, {} bytes at most; judged with one thread only)",
                    sc.engine_threads, self.allocations.step_scratch_left_max_bytes
                );
            }
        }
        let al = &self.allocations;
        let _ = writeln!(
            s,
            "allocations/step   in the arena max {} (every step), step scratch left after a step \
             max {} bytes; after {WARMUP_STEPS} warm-up steps ({} steps): outside the graph \
             engine max {}, inside max {}, tile decoder scratch max {}; arena peak growth {} \
             bytes",
            al.arena_max_per_step,
            al.step_scratch_left_max_bytes,
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
