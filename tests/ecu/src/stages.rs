//! One stage at a time on the folder bundle's `reference.safetensors` inputs (the onnxruntime
//! reference's own): what the thread test compares bit for bit and what the instruction counter
//! (`examples/stage_insns.rs`, `targets/insn_counts.sh`) runs under the emulator.

use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::features::{FeaturesMut, FeaturesRef};
use satmap_runtime::{Engine, EngineError, Stage};

use crate::golden::{Golden, bundle_dir};

/// Every stage's inputs from the committed folder bundle's reference file.
pub struct ReferenceInputs {
    /// `image_encoder.image`, u8 RGB (camera 0).
    pub image: Vec<u8>,
    /// `satellite_encoder.satellite`, u8 RGB.
    pub crop: Vec<u8>,
    /// `bev_query.can_bus`.
    pub can_bus: [f32; 18],
    /// `bev_encoder.bev_query`.
    pub query: Vec<f32>,
    /// `bev_encoder.gathered`.
    pub gathered: Vec<f32>,
    /// `map_decoder.camera_bev`.
    pub camera_bev: Vec<f32>,
    /// `map_decoder.satellite_bev`.
    pub satellite_bev: Vec<f32>,
}

impl ReferenceInputs {
    /// `models/bundles/test/reference.safetensors`.
    ///
    /// # Panics
    /// When the file or a tensor is missing, or the CAN-bus vector is not 18 values.
    #[must_use]
    pub fn load() -> Self {
        let r = Golden::from_path(&bundle_dir().join("reference.safetensors"));
        Self {
            image: r.bytes("image_encoder.image"),
            crop: r.bytes("satellite_encoder.satellite"),
            can_bus: r.f32s("bev_query.can_bus").try_into().unwrap(),
            query: r.f32s("bev_encoder.bev_query"),
            gathered: r.f32s("bev_encoder.gathered"),
            camera_bev: r.f32s("map_decoder.camera_bev"),
            satellite_bev: r.f32s("map_decoder.satellite_bev"),
        }
    }
}

/// Every stage's output buffers, sized from the engine's dims.
pub struct StageOutputs {
    value: Vec<f32>,
    query: Vec<f32>,
    weights: Vec<f32>,
    camera_bev: Vec<f32>,
    satellite_bev: Vec<f32>,
    logits: Vec<f32>,
    points: Vec<f32>,
}

impl StageOutputs {
    /// Zeroed buffers for `engine`'s model.
    #[must_use]
    pub fn new(engine: &TractEngine) -> Self {
        let d = engine.dims();
        Self {
            value: vec![0.0; d.value_len()],
            query: vec![0.0; d.bev_len()],
            weights: vec![0.0; d.weights_len()],
            camera_bev: vec![0.0; d.bev_len()],
            satellite_bev: vec![0.0; d.bev_len()],
            logits: vec![0.0; d.logits_len()],
            points: vec![0.0; d.points_len()],
        }
    }

    /// Run `stage` once on `r`, writing its outputs here.
    ///
    /// # Errors
    /// The engine's, for the stage.
    pub fn run(
        &mut self,
        engine: &mut TractEngine,
        stage: Stage,
        r: &ReferenceInputs,
    ) -> Result<(), EngineError> {
        match stage {
            Stage::ImageEncoder => engine.encode_image(0, &r.image, &mut self.value),
            Stage::BevQuery => engine.bev_query(&r.can_bus, &mut self.query, &mut self.weights),
            Stage::BevEncoder => engine.bev_encode(
                &r.query,
                &r.gathered,
                FeaturesMut::F32(&mut self.camera_bev),
            ),
            Stage::SatelliteEncoder => {
                engine.encode_satellite(&r.crop, FeaturesMut::F32(&mut self.satellite_bev))
            }
            Stage::MapDecoder => engine.decode_map(
                FeaturesRef::F32(&r.camera_bev),
                FeaturesRef::F32(&r.satellite_bev),
                &mut self.logits,
                &mut self.points,
            ),
        }
    }

    /// The outputs of `stage` (two for `bev_query` and `map_decoder`).
    #[must_use]
    pub fn of(&self, stage: Stage) -> Vec<&[f32]> {
        match stage {
            Stage::ImageEncoder => vec![&self.value],
            Stage::BevQuery => vec![&self.query, &self.weights],
            Stage::BevEncoder => vec![&self.camera_bev],
            Stage::SatelliteEncoder => vec![&self.satellite_bev],
            Stage::MapDecoder => vec![&self.logits, &self.points],
        }
    }

    /// Every output as raw bits, in stage order.
    #[must_use]
    pub fn bits(&self) -> Vec<Vec<u32>> {
        Stage::ALL
            .iter()
            .flat_map(|&s| self.of(s))
            .map(|v| v.iter().map(|x| x.to_bits()).collect())
            .collect()
    }
}
