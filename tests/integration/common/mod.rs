//! Golden-vector access shared by the integration tests: the committed `test` bundle, the
//! calibration and the frames written by `models/` (`python -m satmap_ref.golden`).

use std::path::PathBuf;

use glam::{DVec2, Vec3};
use safetensors::SafeTensors;
use satmap_runtime::calibration::{Calibration, from_toml_file};
use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::{CameraImage, EgoMotion, EgoPose, Frame};

/// Repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The committed `test` bundle.
pub fn bundle_dir() -> PathBuf {
    root().join("models/bundles/test")
}

/// The rig the goldens were made with.
pub fn calibration() -> Calibration {
    from_toml_file(&root().join("models/calibration/nuscenes_like.toml")).unwrap()
}

/// Load the tract engine over the committed `test` bundle.
pub fn engine() -> TractEngine {
    TractEngine::open(bundle_dir()).unwrap()
}

/// The tract engine over the committed compiled `test` bundle, as an ECU (and the C API) loads it.
pub fn compiled_engine() -> TractEngine {
    TractEngine::open(root().join("models/bundles/test.satmap")).unwrap()
}

/// One golden safetensors file, owned.
pub struct Golden {
    bytes: Vec<u8>,
}

impl Golden {
    /// `models/golden/test/<name>`.
    pub fn load(name: &str) -> Self {
        let path = root().join("models/golden/test").join(name);
        Self {
            bytes: std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        }
    }

    fn st(&self) -> SafeTensors<'_> {
        SafeTensors::deserialize(&self.bytes).unwrap()
    }

    /// Raw little-endian bytes of a tensor.
    pub fn bytes(&self, name: &str) -> Vec<u8> {
        self.st().tensor(name).unwrap().data().to_vec()
    }

    /// A tensor as f32 (the reader `check-bundle` uses, so both check dtypes alike).
    pub fn f32s(&self, name: &str) -> Vec<f32> {
        satmap_sim::cli::check_bundle::f32s(&self.st(), name).unwrap()
    }

    /// A tensor as f64.
    pub fn f64s(&self, name: &str) -> Vec<f64> {
        let st = self.st();
        let t = st.tensor(name).unwrap();
        assert_eq!(t.dtype(), safetensors::Dtype::F64, "{name}");
        t.data()
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect()
    }

    /// A tensor as i64.
    pub fn i64s(&self, name: &str) -> Vec<i64> {
        let st = self.st();
        let t = st.tensor(name).unwrap();
        assert_eq!(t.dtype(), safetensors::Dtype::I64, "{name}");
        t.data()
            .chunks_exact(8)
            .map(|b| i64::from_le_bytes(b.try_into().unwrap()))
            .collect()
    }

    /// A tensor as i32.
    pub fn i32s(&self, name: &str) -> Vec<i32> {
        let st = self.st();
        let t = st.tensor(name).unwrap();
        assert_eq!(t.dtype(), safetensors::Dtype::I32, "{name}");
        t.data()
            .chunks_exact(4)
            .map(|b| i32::from_le_bytes(b.try_into().unwrap()))
            .collect()
    }
}

/// A golden frame with its decoded inputs.
pub struct GoldenFrame {
    /// The file.
    pub golden: Golden,
    /// `[6, H, W, 3]` images.
    pub images: Vec<u8>,
    /// Satellite crop.
    pub satellite: Vec<u8>,
    /// Pose (yaw from the golden; the position does not reach the network).
    pub pose: EgoPose,
    /// Ego motion.
    pub motion: EgoMotion,
}

impl GoldenFrame {
    /// Frame `index` (0 or 1).
    pub fn load(index: usize) -> Self {
        let golden = Golden::load(&format!("frame_{index:03}.safetensors"));
        let v3 = |name: &str| {
            let v = golden.f64s(name);
            Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
        };
        let pose = EgoPose::new(DVec2::new(0.0, 0.0), golden.f64s("ego_yaw_rad")[0]);
        let motion = EgoMotion {
            acceleration_mps2: v3("acceleration_mps2"),
            rotation_rate_radps: v3("rotation_rate_radps"),
            velocity_mps: v3("velocity_mps"),
        };
        Self {
            images: golden.bytes("images"),
            satellite: golden.bytes("satellite"),
            golden,
            pose,
            motion,
        }
    }

    /// The step input for this golden frame.
    pub fn frame(&self, sequence: u64, width_px: u32, height_px: u32) -> Frame<'_> {
        let per = (width_px * height_px * 3) as usize;
        Frame {
            sequence,
            timestamp_us: 1_000_000 + sequence * 100_000,
            pose: self.pose,
            motion: self.motion,
            images: core::array::from_fn(|c| {
                Some(CameraImage {
                    width_px,
                    height_px,
                    rgb: &self.images[c * per..(c + 1) * per],
                    capture_us: 1_000_000 + sequence * 100_000,
                    valid: true,
                })
            }),
        }
    }
}

/// Largest absolute difference (NaN counts as infinite).
pub fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "length");
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d = (x - y).abs();
            if d.is_nan() { f32::INFINITY } else { d }
        })
        .fold(0.0, f32::max)
}
