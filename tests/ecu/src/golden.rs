//! Golden-vector access: the committed `test` bundles, the calibration and the frames written by
//! `models/` (`python -m satmap_ref.golden`). Paths are the repository's, compiled in: a test
//! binary cross-built for another target runs in the same tree (targets/in-chroot.sh mounts it
//! at the same path).

use std::path::PathBuf;

use safetensors::SafeTensors;
use satmap_runtime::bundle::{Bundle, Precision};
use satmap_runtime::calibration::{Calibration, from_toml_file};
use satmap_runtime::engine_tract::{HalfArithmetic, TractEngine};
use satmap_runtime::glam::{DVec2, Vec3};
use satmap_runtime::{CameraImage, EgoMotion, EgoPose, Frame};

/// Repository root.
#[must_use]
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The committed `test` folder bundle (ONNX stages and their onnxruntime reference outputs).
#[must_use]
pub fn bundle_dir() -> PathBuf {
    root().join("models/bundles/test")
}

/// The committed compiled `test` bundle of `precision`, as an ECU (and the C API) loads it:
/// `test.satmap` (f32), `test-f16.satmap`, `test-int8.satmap`.
#[must_use]
pub fn compiled_path(precision: Precision) -> PathBuf {
    root().join(match precision {
        Precision::F32 => "models/bundles/test.satmap",
        Precision::F16 => "models/bundles/test-f16.satmap",
        Precision::Int8 => "models/bundles/test-int8.satmap",
    })
}

/// The committed int8 `test` bundle with calibrated activation ranges (W8A8):
/// `test-w8a8.satmap`, `test-int8.satmap`'s stages with an `[int8]` table.
#[must_use]
pub fn w8a8_path() -> PathBuf {
    root().join("models/bundles/test-w8a8.satmap")
}

/// The rig the goldens were made with.
///
/// # Panics
/// When the committed calibration does not load.
#[must_use]
pub fn calibration() -> Calibration {
    from_toml_file(&root().join("models/calibration/nuscenes_like.toml")).unwrap()
}

/// The tract engine over the committed compiled f32 `test` bundle.
///
/// # Panics
/// When the committed bundle does not load.
#[must_use]
pub fn compiled_engine() -> TractEngine {
    compiled_engine_as(Precision::F32)
}

/// The tract engine over the committed compiled `test` bundle of `precision`.
///
/// # Panics
/// When the committed bundle does not load.
#[must_use]
pub fn compiled_engine_as(precision: Precision) -> TractEngine {
    let path = compiled_path(precision);
    TractEngine::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The tract engine over the committed compiled f16 `test` bundle in the arithmetic `half`.
///
/// # Panics
/// When the committed bundle does not load.
#[must_use]
pub fn compiled_f16_engine(half: HalfArithmetic) -> TractEngine {
    let path = compiled_path(Precision::F16);
    Bundle::open(&path)
        .and_then(|b| TractEngine::load_with(&b, half))
        .unwrap_or_else(|e| panic!("{} ({half:?}): {e}", path.display()))
}

/// One golden safetensors file, owned.
pub struct Golden {
    bytes: Vec<u8>,
}

impl Golden {
    /// `models/golden/test/<name>`.
    ///
    /// # Panics
    /// When the file cannot be read.
    #[must_use]
    pub fn load(name: &str) -> Self {
        Self::from_path(&root().join("models/golden/test").join(name))
    }

    /// Any safetensors file, e.g. a folder bundle's `reference.safetensors`.
    ///
    /// # Panics
    /// When the file cannot be read.
    #[must_use]
    pub fn from_path(path: &std::path::Path) -> Self {
        Self {
            bytes: std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        }
    }

    fn st(&self) -> SafeTensors<'_> {
        SafeTensors::deserialize(&self.bytes).unwrap()
    }

    /// Tensor `name`, asserted of type `dtype`, read as little-endian values of `W` bytes.
    fn values<T, const W: usize>(
        &self,
        name: &str,
        dtype: safetensors::Dtype,
        from_le: fn([u8; W]) -> T,
    ) -> Vec<T> {
        let st = self.st();
        let t = st
            .tensor(name)
            .unwrap_or_else(|e| panic!("golden tensor {name}: {e}"));
        assert_eq!(t.dtype(), dtype, "{name}");
        t.data()
            .chunks_exact(W)
            .map(|b| from_le(b.try_into().unwrap()))
            .collect()
    }

    /// Raw little-endian bytes of a tensor.
    ///
    /// # Panics
    /// When the tensor is missing.
    #[must_use]
    pub fn bytes(&self, name: &str) -> Vec<u8> {
        self.st().tensor(name).unwrap().data().to_vec()
    }

    /// An F32 tensor.
    ///
    /// # Panics
    /// When the tensor is missing or of another type.
    #[must_use]
    pub fn f32s(&self, name: &str) -> Vec<f32> {
        self.values(name, safetensors::Dtype::F32, f32::from_le_bytes)
    }

    /// An F64 tensor.
    ///
    /// # Panics
    /// When the tensor is missing or of another type.
    #[must_use]
    pub fn f64s(&self, name: &str) -> Vec<f64> {
        self.values(name, safetensors::Dtype::F64, f64::from_le_bytes)
    }

    /// An I64 tensor.
    ///
    /// # Panics
    /// When the tensor is missing or of another type.
    #[must_use]
    pub fn i64s(&self, name: &str) -> Vec<i64> {
        self.values(name, safetensors::Dtype::I64, i64::from_le_bytes)
    }

    /// An I32 tensor.
    ///
    /// # Panics
    /// When the tensor is missing or of another type.
    #[must_use]
    pub fn i32s(&self, name: &str) -> Vec<i32> {
        self.values(name, safetensors::Dtype::I32, i32::from_le_bytes)
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
    ///
    /// # Panics
    /// When the golden file is missing or malformed.
    #[must_use]
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

    /// The step input for this golden frame, every camera present.
    #[must_use]
    pub fn frame(&self, sequence: u64, width_px: u32, height_px: u32) -> Frame<'_> {
        self.frame_with(sequence, width_px, height_px, 0b11_1111)
    }

    /// The step input for this golden frame with the cameras of `present` (bit c: camera c),
    /// at 1 s + `sequence` x 100 ms.
    #[must_use]
    pub fn frame_with(
        &self,
        sequence: u64,
        width_px: u32,
        height_px: u32,
        present: u8,
    ) -> Frame<'_> {
        let timestamp_us = 1_000_000 + sequence * 100_000;
        self.frame_at(sequence, timestamp_us, width_px, height_px, present)
    }

    /// The step input for this golden frame at `timestamp_us` (every image captured then) with
    /// the cameras of `present` (bit c: camera c).
    #[must_use]
    pub fn frame_at(
        &self,
        sequence: u64,
        timestamp_us: u64,
        width_px: u32,
        height_px: u32,
        present: u8,
    ) -> Frame<'_> {
        let per = (width_px * height_px * 3) as usize;
        Frame {
            sequence,
            timestamp_us,
            pose: self.pose,
            motion: self.motion,
            images: core::array::from_fn(|c| {
                (present >> c & 1 == 1).then(|| CameraImage {
                    width_px,
                    height_px,
                    rgb: &self.images[c * per..(c + 1) * per],
                    capture_us: timestamp_us,
                    valid: true,
                })
            }),
        }
    }
}

/// Largest absolute difference (NaN counts as infinite).
///
/// # Panics
/// When the lengths differ.
#[must_use]
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
