//! The satellite path alone over a whole route: a vehicle driven along the pack's route
//! polyline at a fixed speed and rate, one crop (with its tile verification, decode and
//! prefetch) per step, each step timed. This is how a 100 km route is replayed in minutes: the
//! network is left out, the part whose work depends on the route (tiles, decode, route search)
//! runs exactly as in [`super::replay`], inside the same kind of fixed buffers (the decoded
//! tiles in a `tile_pixels` region sized by `memory_layout.toml`).

use std::time::Instant;

use glam::{DVec2, DVec3};
use satmap_runtime::capacity::layout;
use satmap_runtime::route_pack::{PackSource, RoutePack, TileCodec};
use satmap_runtime::satellite::{Coverage, CropSpec};
use serde::Serialize;

use super::HarnessError;
use super::stats::{Percentiles, Series};

/// Settings of a route replay.
#[derive(Clone, Debug)]
pub struct RouteReplayConfig {
    /// The crop the model takes (`sat_h`, `sat_w`, `sat_gsd_m`, from the bundle).
    pub crop: CropSpec,
    /// Vehicle speed along the route, m/s.
    pub speed_mps: f64,
    /// Step rate, Hz.
    pub rate_hz: f64,
    /// Most steps (the route's end stops the replay earlier).
    pub max_steps: usize,
}

/// What a route replay measured.
#[derive(Clone, Debug, Serialize)]
pub struct RouteReplayReport {
    /// Steps run.
    pub steps: usize,
    /// Route length driven, metres.
    pub driven_m: f64,
    /// The pack's tile codec.
    pub codec: String,
    /// Pack size, bytes.
    pub pack_bytes: usize,
    /// Crop latency of every step (verify + decode + sample + prefetch), microseconds.
    pub crop: Percentiles,
    /// Crop latency of the steps that decoded at least one tile.
    pub crop_with_decode: Percentiles,
    /// Crop latency of the steps that decoded none.
    pub crop_without_decode: Percentiles,
    /// The slowest step: its number (from 0), latency and tiles decoded.
    pub worst_step: (usize, u64, u8),
    /// Tiles decoded over the replay.
    pub decoded_tiles: u64,
    /// Most tiles decoded in one step.
    pub max_decoded_per_step: u8,
    /// Most route segments the cursor examined in one step.
    pub max_route_segments_per_step: u32,
    /// Steps whose crop was not fully covered.
    pub not_full_steps: usize,
    /// The `satellite_crop` budget of `memory_layout.toml`, microseconds.
    pub budget_us: u64,
    /// Whether the slowest step stayed within it.
    pub within_budget: bool,
    /// XXH3-64 over every crop's bytes in order: equal for two packs whose crops are equal
    /// (a raw and a lossless pack of the same imagery), and across runs.
    pub crop_digest: u64,
}

impl RouteReplayReport {
    /// The report as a few lines of text.
    #[must_use]
    pub fn to_text(&self) -> String {
        let row = |name: &str, p: &Percentiles| {
            format!(
                "  {name:<24} {:>7} steps  p50 {:>7} us  p99 {:>7} us  max {:>7} us\n",
                p.count, p.p50_us, p.p99_us, p.max_us
            )
        };
        let mut s = format!(
            "route replay: {} steps over {:.2} km, pack {:.1} MB ({})\n",
            self.steps,
            self.driven_m / 1000.0,
            self.pack_bytes as f64 / 1e6,
            self.codec
        );
        s += &row("satellite crop", &self.crop);
        s += &row("  steps with a decode", &self.crop_with_decode);
        s += &row("  steps without", &self.crop_without_decode);
        s += &format!(
            "  worst step {} : {} us with {} tiles decoded; budget {} us: {}\n",
            self.worst_step.0,
            self.worst_step.1,
            self.worst_step.2,
            self.budget_us,
            if self.within_budget { "ok" } else { "EXCEEDED" }
        );
        s += &format!(
            "  tiles decoded {} (at most {} a step), route segments examined at most {} a step, steps not fully covered {}, crop digest {:016x}\n",
            self.decoded_tiles,
            self.max_decoded_per_step,
            self.max_route_segments_per_step,
            self.not_full_steps,
            self.crop_digest
        );
        s
    }
}

/// The decoded-tile region for `pack`, reserved once: `tile_pixels` of `memory_layout.toml` for
/// a compressed pack, nothing for a raw one (its tiles are read in place).
pub(super) fn tile_buffer(pack: &RoutePack<'_>) -> Vec<u8> {
    let bytes = if pack.codec().needs_decode() {
        layout::TILE_PIXELS_BYTES
    } else {
        0
    };
    vec![0u8; bytes]
}

/// Slowest replay speed, m/s (walking pace / 10): below it a route of any length needs more
/// steps than a replay may run.
pub const MIN_SPEED_MPS: f64 = 0.1;

/// Drive along `pack_bytes`'s route and time every crop.
///
/// # Errors
/// A pack that does not load, has no route, or cannot serve `cfg.crop`; settings out of range.
pub fn replay_route(
    pack_bytes: &[u8],
    cfg: &RouteReplayConfig,
) -> Result<RouteReplayReport, HarnessError> {
    // A floor, not just > 0: 1e-308 m/s made the step count overflow (issue 38).
    if !(MIN_SPEED_MPS..100.0).contains(&cfg.speed_mps) {
        return Err(HarnessError::Settings(format!(
            "speed must be in [{MIN_SPEED_MPS}, 100) m/s (got {:?})",
            cfg.speed_mps
        )));
    }
    if !(0.01..=1000.0).contains(&cfg.rate_hz) || !(1..=10_000_000).contains(&cfg.max_steps) {
        return Err(HarnessError::Settings(format!(
            "rate must be in [0.01, 1000] Hz and steps in 1..=10000000 (got {:?}, {})",
            cfg.rate_hz, cfg.max_steps
        )));
    }
    let pack = RoutePack::parse(pack_bytes).map_err(|e| HarnessError::Pack(e.to_string()))?;
    let route: Vec<DVec2> = (0..pack.route_point_count())
        .filter_map(|i| pack.route_point(i))
        .collect();
    let lengths: Vec<f64> = route.windows(2).map(|w| w[0].distance(w[1])).collect();
    let total_m: f64 = lengths.iter().sum();
    if route.len() < 2 || total_m <= 0.0 {
        return Err(HarnessError::Pack("the pack has no route to drive".into()));
    }
    let mut tile_pixels = tile_buffer(&pack);
    let mut source = PackSource::with_tile_buffer(pack, &mut tile_pixels);
    source
        .check_crop_spec(&cfg.crop)
        .map_err(|f| HarnessError::Pack(format!("its tiles cannot serve the crop ({f:?})")))?;
    let step_m = cfg.speed_mps / cfg.rate_hz;
    // `as` saturates; the add must too.
    let steps = ((total_m / step_m).floor() as usize)
        .saturating_add(1)
        .min(cfg.max_steps);
    let mut crop = vec![0u8; cfg.crop.height_px * cfg.crop.width_px * 3];
    let (mut all, mut with, mut without) = (
        Series::with_capacity(steps),
        Series::with_capacity(steps),
        Series::with_capacity(steps),
    );
    let mut worst = (0, 0, 0);
    let mut digest = xxhash_rust::xxh3::Xxh3::new();
    let (mut decoded, mut max_decoded, mut max_segments, mut not_full) = (0u64, 0u8, 0u32, 0);
    let (mut seg, mut seg_start_m) = (0usize, 0.0f64);
    for k in 0..steps {
        let s_m = k as f64 * step_m;
        while seg + 1 < lengths.len() && seg_start_m + lengths[seg] < s_m {
            seg_start_m += lengths[seg];
            seg += 1;
        }
        let (a, b) = (route[seg], route[seg + 1]);
        let t = ((s_m - seg_start_m) / lengths[seg].max(1e-9)).clamp(0.0, 1.0);
        let p = a.lerp(b, t);
        let d = b - a;
        // Through WGS84, as a GNSS fix would arrive: the vehicle's path, not a shortcut.
        let fix = source
            .pack()
            .frame()
            .enu_to_geodetic(DVec3::new(p.x, p.y, 0.0));
        let heading_deg = d.x.atan2(d.y).to_degrees();
        let pose = source.pack().pose_from_wgs84(&fix, heading_deg);
        let started = Instant::now();
        let report = source.crop_with_report(&pose, &cfg.crop, &mut crop);
        let us = started.elapsed().as_micros() as u64;
        digest.update(&crop);
        all.record(us);
        if report.decoded_tiles > 0 {
            with.record(us);
        } else {
            without.record(us);
        }
        if us > worst.1 {
            worst = (k, us, report.decoded_tiles);
        }
        decoded += u64::from(report.decoded_tiles);
        max_decoded = max_decoded.max(report.decoded_tiles);
        max_segments = max_segments.max(report.route_segments_examined);
        if report.coverage != Coverage::Full {
            not_full += 1;
        }
    }
    let budget_us = layout::LATENCY_BUDGETS_US
        .iter()
        .find(|(name, _)| *name == "satellite_crop")
        .map_or(u64::MAX, |(_, us)| *us);
    let codec = match source.pack().codec() {
        TileCodec::Raw => "raw",
        TileCodec::Jpeg => "jpeg",
        TileCodec::Deflate => "deflate",
    };
    Ok(RouteReplayReport {
        steps,
        driven_m: (steps.saturating_sub(1)) as f64 * step_m,
        codec: codec.into(),
        pack_bytes: pack_bytes.len(),
        crop: all.percentiles(),
        crop_with_decode: with.percentiles(),
        crop_without_decode: without.percentiles(),
        worst_step: worst,
        decoded_tiles: decoded,
        max_decoded_per_step: max_decoded,
        max_route_segments_per_step: max_segments,
        not_full_steps: not_full,
        budget_us,
        within_budget: worst.1 <= budget_us,
        crop_digest: digest.digest(),
    })
}
