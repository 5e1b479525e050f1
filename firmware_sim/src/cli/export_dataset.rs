//! `satmap-sim export-dataset`: training data for the PyTorch model in `models/`
//! (`python -m satmap_ref.train`), made of synthetic drives split by world seed into train, val
//! and a held-out test split, so no world is seen in two splits.
//!
//! Layout (`satmap-dataset/1`, read by `satmap_ref.train.dataset`):
//! - `index.json`: format, model config, the seeds of each split, and every knob used;
//! - per drive `drive_<seed:05>.safetensors`: `images` u8 `[N, 6, h, w, 3]` (model camera
//!   order), `satellite` u8 `[N, sat_h, sat_w, 3]` (the runtime's crop layout, taken from the
//!   drive's imperfect imagery), `can_bus` f32 `[N, 18]` (the runtime's CAN-bus vector),
//!   `pose` f64 `[N, 3]` (route-frame x, y in metres and yaw in radians), `motion` f64 `[N, 9]`
//!   (ego-frame acceleration m/s^2, rotation rate rad/s, velocity m/s: the CAN-bus inputs);
//! - per drive `drive_<seed:05>.json`: lighting, imagery errors, and per frame its token,
//!   whether it is occluded, and the ground truth (ego frame, metres, cut to the patch).
//!
//! The satellite crop comes from the same satellite raster the tiles and route packs are made
//! of, at the true pose: the registration error and staleness live in the imagery, as they
//! would on a car. A drive whose `.json` exists is skipped, so an interrupted export resumes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, Result};
use safetensors::tensor::{Dtype, TensorView};
use satmap_runtime::can_bus::can_bus;
use satmap_runtime::satellite::SatelliteSource;
use serde::Serialize;

use crate::cli::drive::BadArgument;
use crate::cli::render::satmap_crop_spec;
use crate::synth::drive::{DriveConfig, SyntheticDrive};
use crate::synth::imagery::ImageryConfig;

/// Format tag of `index.json`.
pub const DATASET_FORMAT: &str = "satmap-dataset/1";

/// A half-open range of seeds, written `a..b`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SeedRange {
    /// First seed.
    pub start: u64,
    /// One past the last seed.
    pub end: u64,
}

impl std::str::FromStr for SeedRange {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (a, b) = s
            .split_once("..")
            .ok_or_else(|| format!("{s:?} is not a seed range `a..b`"))?;
        let parse = |t: &str| {
            t.trim()
                .parse::<u64>()
                .map_err(|e| format!("{t:?} in {s:?}: {e}"))
        };
        let (start, end) = (parse(a)?, parse(b)?);
        if start >= end || end - start > 100_000 {
            return Err(format!("{s:?}: need a < b and at most 100000 seeds"));
        }
        Ok(Self { start, end })
    }
}

/// The training split's world seeds (`export-dataset`'s default `--train-seeds`): the only
/// worlds a calibration may look at.
pub const TRAIN_SEEDS: SeedRange = SeedRange {
    start: 1000,
    end: 1160,
};

impl SeedRange {
    /// The seeds, in order.
    pub fn seeds(self) -> impl Iterator<Item = u64> {
        self.start..self.end
    }

    /// Whether every seed of `self` is in `other`.
    #[must_use]
    pub fn within(self, other: Self) -> bool {
        other.start <= self.start && self.end <= other.end
    }

    fn overlaps(self, other: Self) -> bool {
        self.start < other.end && other.start < self.end
    }
}

/// Arguments of `export-dataset`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder.
    #[arg(long, short)]
    pub out: PathBuf,
    /// World seeds of the training split.
    #[arg(long, default_value = "1000..1160")]
    pub train_seeds: SeedRange,
    /// World seeds of the validation split (model selection).
    #[arg(long, default_value = "2000..2016")]
    pub val_seeds: SeedRange,
    /// World seeds of the held-out test split (never used for any choice).
    #[arg(long, default_value = "3000..3024")]
    pub test_seeds: SeedRange,
    /// Frames per drive.
    #[arg(long, default_value_t = 24)]
    pub frames: usize,
    /// Frame rate of the drive, Hz (2 Hz = nuScenes keyframes: 4 m apart at 8 m/s).
    #[arg(long, default_value_t = 2.0)]
    pub drive_hz: f64,
    /// Mean speed, m/s.
    #[arg(long, default_value_t = 8.0)]
    pub speed_mps: f64,
    /// Satellite imagery exactly registered and never stale (for experiments only).
    #[arg(long)]
    pub perfect_imagery: bool,
    /// Worker threads (one drive each at a time).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Serialize)]
struct Index<'a> {
    format: &'static str,
    config: &'static str,
    /// Seeds per split, in name order (a HashMap wrote them in a new order every run).
    splits: BTreeMap<&'static str, Vec<u64>>,
    knobs: Knobs<'a>,
}

#[derive(Serialize)]
struct Knobs<'a> {
    frames_per_drive: usize,
    drive_hz: f64,
    speed_mps: f64,
    image_width_px: usize,
    image_height_px: usize,
    satellite_gsd_m: f64,
    imagery: &'a ImageryConfig,
    occlusion_near_m: f64,
}

#[derive(Serialize)]
struct DriveRecord {
    seed: u64,
    lighting: crate::synth::LightingPreset,
    stale: bool,
    registration: RegistrationRecord,
    missing_crossings: usize,
    missing_lane_lines: usize,
    frames: Vec<FrameRecord>,
}

#[derive(Serialize)]
struct RegistrationRecord {
    offset_m: [f64; 2],
    yaw_rad: f64,
}

#[derive(Serialize)]
struct FrameRecord {
    token: String,
    occluded_share: f64,
    vectors: Vec<VectorRecord>,
}

#[derive(Serialize)]
struct VectorRecord {
    cls_name: &'static str,
    pts: Vec<[f64; 2]>,
}

/// Sample token of frame `index` of drive `seed` (unique across the dataset).
#[must_use]
pub fn frame_token(seed: u64, index: usize) -> String {
    format!("s{seed:05}_f{index:06}")
}

/// An export resumed into a folder that already holds one must use its format, config and
/// knobs: drives on disk are skipped, so other knobs would leave an `index.json` describing
/// data it does not hold (issue 38: it exited 0 so). The seed splits may grow.
///
/// # Errors
/// [`BadArgument`] naming the first field that differs; the old index unreadable.
fn check_resume(path: &Path, fresh: &serde_json::Value) -> Result<()> {
    if !path.exists() {
        return Ok(());
    }
    let text = satmap_runtime::host_files::read_text_capped(
        path,
        satmap_runtime::host_files::MAX_CONFIG_BYTES,
    )
    .with_context(|| path.display().to_string())?;
    let old: serde_json::Value =
        serde_json::from_str(&text).with_context(|| path.display().to_string())?;
    for key in ["format", "config", "knobs"] {
        if old.get(key) != fresh.get(key) {
            return Err(BadArgument(format!(
                "{}: this folder holds a dataset made with other {key} ({} there, {} now); \
                 resume only with the same settings, or choose another --out",
                path.display(),
                old.get(key).unwrap_or(&serde_json::Value::Null),
                fresh.get(key).unwrap_or(&serde_json::Value::Null)
            ))
            .into());
        }
    }
    Ok(())
}

/// Write the dataset.
///
/// # Errors
/// Overlapping splits, bad drive settings, or a file that cannot be written.
pub fn run(args: &Args) -> Result<()> {
    let splits = [
        ("train", args.train_seeds),
        ("val", args.val_seeds),
        ("test", args.test_seeds),
    ];
    for (i, (a, ra)) in splits.iter().enumerate() {
        for (b, rb) in &splits[i + 1..] {
            if ra.overlaps(*rb) {
                return Err(BadArgument(format!(
                    "the {a} and {b} seed ranges overlap: a world may be in one split only"
                ))
                .into());
            }
        }
    }
    if args.frames == 0 || args.frames > 10_000 {
        return Err(BadArgument(format!(
            "--frames must be in 1..=10000 (got {})",
            args.frames
        ))
        .into());
    }
    if args.threads == 0 || args.threads > 64 {
        return Err(BadArgument(format!(
            "--threads must be in 1..=64 (got {})",
            args.threads
        ))
        .into());
    }
    let imagery = if args.perfect_imagery {
        ImageryConfig::perfect()
    } else {
        ImageryConfig::default()
    };
    let config = DriveConfig {
        num_frames: args.frames,
        frame_rate_hz: args.drive_hz,
        mean_speed_mps: args.speed_mps,
        imagery,
        ..DriveConfig::default()
    };
    // Before anything is written: an index.json with knobs no drive can be made with would
    // then refuse every corrected resume.
    config.check()?;
    std::fs::create_dir_all(&args.out).with_context(|| args.out.display().to_string())?;
    let spec = satmap_crop_spec();
    let index = Index {
        format: DATASET_FORMAT,
        config: "test",
        splits: splits
            .iter()
            .map(|(name, r)| (*name, r.seeds().collect()))
            .collect(),
        knobs: Knobs {
            frames_per_drive: args.frames,
            drive_hz: args.drive_hz,
            speed_mps: args.speed_mps,
            image_width_px: config.image_width_px,
            image_height_px: config.image_height_px,
            satellite_gsd_m: spec.gsd_m,
            imagery: &config.imagery,
            occlusion_near_m: crate::synth::drive::OCCLUSION_NEAR_M,
        },
    };
    let path = args.out.join("index.json");
    check_resume(&path, &serde_json::to_value(&index)?)?;
    std::fs::write(&path, serde_json::to_string_pretty(&index)?)
        .with_context(|| path.display().to_string())?;

    let seeds: Vec<u64> = splits.iter().flat_map(|(_, r)| r.seeds()).collect();
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(seeds.len() as u64)
    };
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} drives {elapsed} (eta {eta})")
    {
        bar.set_style(style);
    }
    let next = AtomicUsize::new(0);
    let first_error: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..args.threads {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&seed) = seeds.get(i) else { break };
                    if let Err(e) = export_drive(seed, &config, &args.out) {
                        if let Ok(mut slot) = first_error.lock() {
                            slot.get_or_insert(e);
                        }
                        break;
                    }
                    bar.inc(1);
                }
            });
        }
    });
    bar.finish_and_clear();
    if let Some(e) = first_error.into_inner().ok().flatten() {
        return Err(e);
    }
    println!(
        "wrote {} drives x {} frames to {}",
        seeds.len(),
        args.frames,
        args.out.display()
    );
    Ok(())
}

/// Write one drive's two files (the `.json` last, so its presence means the drive is whole).
fn export_drive(seed: u64, config: &DriveConfig, out: &Path) -> Result<()> {
    let json_path = out.join(format!("drive_{seed:05}.json"));
    if json_path.exists() {
        return Ok(());
    }
    let drive = SyntheticDrive::new(seed, config.clone())
        .with_context(|| format!("drive of seed {seed}"))?;
    let spec = satmap_crop_spec();
    let n = drive.len();
    let (w, h) = (config.image_width_px, config.image_height_px);
    let crop_len = spec.height_px * spec.width_px * 3;
    let mut images = Vec::with_capacity(n * drive.image_bytes());
    let mut satellite = vec![0u8; n * crop_len];
    let mut can = Vec::with_capacity(n * 18 * 4);
    let mut pose = Vec::with_capacity(n * 3 * 8);
    let mut motion = Vec::with_capacity(n * 9 * 8);
    let mut frames = Vec::with_capacity(n);
    let mut source = drive.satellite_source();
    for (i, frame) in drive.frames().enumerate() {
        images.extend_from_slice(&frame.images);
        source.crop(
            &frame.pose,
            &spec,
            &mut satellite[i * crop_len..(i + 1) * crop_len],
        );
        for v in can_bus(&frame.pose, &frame.motion) {
            can.extend_from_slice(&v.to_le_bytes());
        }
        let p = &frame.pose;
        for v in [p.position_m.x, p.position_m.y, p.yaw_rad] {
            pose.extend_from_slice(&v.to_le_bytes());
        }
        let m = &frame.motion;
        for v in [m.acceleration_mps2, m.rotation_rate_radps, m.velocity_mps]
            .iter()
            .flat_map(|v| v.to_array())
        {
            motion.extend_from_slice(&f64::from(v).to_le_bytes());
        }
        frames.push(FrameRecord {
            token: frame_token(seed, i),
            occluded_share: drive.occluded_share(&frame.pose, &frame.ground_truth),
            vectors: frame
                .ground_truth
                .iter()
                .map(|v| VectorRecord {
                    cls_name: v.class.name(),
                    pts: v.points_m.clone(),
                })
                .collect(),
        });
    }
    let tensors = [
        (
            "images",
            TensorView::new(Dtype::U8, vec![n, 6, h, w, 3], &images)?,
        ),
        (
            "satellite",
            TensorView::new(
                Dtype::U8,
                vec![n, spec.height_px, spec.width_px, 3],
                &satellite,
            )?,
        ),
        ("can_bus", TensorView::new(Dtype::F32, vec![n, 18], &can)?),
        ("pose", TensorView::new(Dtype::F64, vec![n, 3], &pose)?),
        ("motion", TensorView::new(Dtype::F64, vec![n, 9], &motion)?),
    ];
    let st_path = out.join(format!("drive_{seed:05}.safetensors"));
    safetensors::serialize_to_file(tensors, None, &st_path)
        .with_context(|| st_path.display().to_string())?;
    let e = drive.imagery_errors();
    let record = DriveRecord {
        seed,
        lighting: drive.lighting_preset(),
        stale: e.stale,
        registration: RegistrationRecord {
            offset_m: e.registration.offset_m.to_array(),
            yaw_rad: e.registration.yaw_rad,
        },
        missing_crossings: e.missing_crossings,
        missing_lane_lines: e.missing_lane_lines,
        frames,
    };
    std::fs::write(&json_path, serde_json::to_string(&record)?)
        .with_context(|| json_path.display().to_string())?;
    Ok(())
}
