//! The committed C-API scenario (`examples/c/scenario.bin`: the two golden frames replayed as
//! four steps with dropout, a degraded step and staged steps) and its Rust run, whose digests
//! per kernel family are `examples/c/expected-<family>.txt`: the files the C example
//! (`examples/c/replay.c`) compares against, on the host and cross-built for aarch64.

use std::path::PathBuf;

use satmap_runtime::engine_tract::kernel_family;
use satmap_runtime::satellite::{Coverage, CropSpec, SatelliteSource};
use satmap_runtime::{EgoPose, Frame, MapFrame, SatMap};

use crate::golden::{GoldenFrame, calibration, compiled_engine, root};

/// One frame of the scenario.
#[derive(Clone, Copy)]
pub struct Step {
    /// Frame sequence number.
    pub sequence: u64,
    /// Which golden frame (0 or 1).
    pub set: usize,
    /// Bit c: camera c delivered an image.
    pub present: u8,
    /// Whether the satellite crop is handed in.
    pub satellite: bool,
    /// Whether the C example runs it as a staged step.
    pub staged: bool,
}

/// The scenario's steps.
pub const STEPS: [Step; 4] = [
    Step {
        sequence: 1,
        set: 0,
        present: 0b11_1111,
        satellite: true,
        staged: false,
    },
    Step {
        sequence: 2,
        set: 1,
        present: 0b11_1111,
        satellite: true,
        staged: true,
    },
    Step {
        sequence: 3,
        set: 0,
        present: 0b11_0111,
        satellite: true,
        staged: false,
    },
    Step {
        sequence: 4,
        set: 1,
        present: 0b00_0001,
        satellite: false,
        staged: true,
    },
];

/// The frame time of `sequence`, microseconds.
#[must_use]
pub fn timestamp_us(sequence: u64) -> u64 {
    1_000_000 + sequence * 500_000
}

/// `examples/c/scenario.bin`.
#[must_use]
pub fn scenario_path() -> PathBuf {
    root().join("examples/c/scenario.bin")
}

/// The digests of the committed scenario's maps for this CPU's kernel family
/// ([`kernel_family`](fn@satmap_runtime::engine_tract::kernel_family)): `SATMAP_BLESS=1` writes this family's file.
#[must_use]
pub fn expected_path() -> PathBuf {
    root().join(format!("examples/c/expected-{}.txt", kernel_family()))
}

/// Whether `SATMAP_BLESS` asks to rewrite the committed files.
#[must_use]
pub fn bless() -> bool {
    std::env::var_os("SATMAP_BLESS").is_some()
}

/// The scenario file, from the two golden frames (format in `examples/c/replay.c`).
#[must_use]
pub fn scenario_bytes(sets: &[GoldenFrame; 2]) -> Vec<u8> {
    let dims = satmap_runtime::ModelDims::test_config();
    let mut b = b"SMSCEN01".to_vec();
    for v in [
        STEPS.len(),
        sets.len(),
        dims.image_w,
        dims.image_h,
        dims.sat_w,
        dims.sat_h,
    ] {
        b.extend_from_slice(&(v as u32).to_le_bytes());
    }
    for g in sets {
        b.extend_from_slice(&g.images);
        b.extend_from_slice(&g.satellite);
    }
    for s in STEPS {
        let g = &sets[s.set];
        b.extend_from_slice(&s.sequence.to_le_bytes());
        b.extend_from_slice(&timestamp_us(s.sequence).to_le_bytes());
        for v in [g.pose.position_m.x, g.pose.position_m.y, g.pose.yaw_rad] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let m = g.motion;
        for v in [m.acceleration_mps2, m.rotation_rate_radps, m.velocity_mps] {
            for x in v.to_array() {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
        b.extend_from_slice(&(s.set as u32).to_le_bytes());
        b.extend_from_slice(&[s.present, u8::from(s.satellite), u8::from(s.staged), 0]);
    }
    b
}

/// The crop the caller hands in with each frame (as the C API's source does).
pub struct SwitchCrop(pub Option<Vec<u8>>);

impl SatelliteSource for SwitchCrop {
    fn crop(&mut self, _pose: &EgoPose, _spec: &CropSpec, out: &mut [u8]) -> Coverage {
        match &self.0 {
            Some(c) if c.len() == out.len() => {
                out.copy_from_slice(c);
                Coverage::Full
            }
            _ => {
                out.fill(0);
                Coverage::None
            }
        }
    }
}

/// The step input of `s` from golden frame `g`.
#[must_use]
pub fn frame<'a>(g: &'a GoldenFrame, s: Step) -> Frame<'a> {
    let dims = satmap_runtime::ModelDims::test_config();
    g.frame_at(
        s.sequence,
        timestamp_us(s.sequence),
        dims.image_w as u32,
        dims.image_h as u32,
        s.present,
    )
}

/// The Rust run of the scenario: one-call steps on heap buffers, over the compiled bundle the C
/// API loads (the folder computes the same within tolerance, bit-identically only on some CPUs:
/// `compiled_bundle.rs`).
///
/// # Panics
/// When a step fails.
#[must_use]
pub fn rust_run(sets: &[GoldenFrame; 2]) -> Vec<MapFrame> {
    let mut map = SatMap::new(compiled_engine(), &calibration(), SwitchCrop(None)).unwrap();
    STEPS
        .iter()
        .map(|&s| {
            let g = &sets[s.set];
            map.satellite_mut().0 = s.satellite.then(|| g.satellite.clone());
            map.step(&frame(g, s)).unwrap().clone()
        })
        .collect()
}

/// Both golden frames.
#[must_use]
pub fn sets() -> [GoldenFrame; 2] {
    [GoldenFrame::load(0), GoldenFrame::load(1)]
}
