//! The intermediate buffers of one step, reserved once at init and overwritten by every attempted
//! step: the read-only view integrators and tests inspect through [`SatMap::buffers`].
//!
//! After a failed step they hold the partial step (whatever stages ran before the failure); the
//! published map is elsewhere and is not affected.
//!
//! [`SatMap::buffers`]: super::SatMap::buffers

use crate::buffers::MemoryError;
use crate::buffers::Slab;
use crate::calibration::NUM_CAMERAS;
use crate::capacity::CAN_BUS_LEN;
use crate::features::{FeatureSlab, FeatureStorage, FeaturesRef};
use crate::model_dims::ModelDims;

/// The pipeline's intermediate tensors of the last attempted step, row-major, sized from the
/// model dimensions at init.
#[derive(Debug)]
pub struct StepBuffers {
    pub(super) can_bus: [f32; CAN_BUS_LEN],
    /// `[6, F, D]`.
    pub(super) value: Slab<f32>,
    /// `[Q, D]`.
    pub(super) query: Slab<f32>,
    /// `[Q, 4, kp]`.
    pub(super) weights: Slab<f32>,
    /// `[Q, D]`.
    pub(super) gathered: Slab<f32>,
    /// `[bev_h, bev_w, D]`.
    pub(super) camera_bev: FeatureSlab,
    /// `[sat_h, sat_w, 3]`.
    pub(super) crop: Slab<u8>,
    /// `[bev_h, bev_w, D]`.
    pub(super) satellite_bev: FeatureSlab,
    /// `[num_vec, 3]`.
    pub(super) logits: Slab<f32>,
    /// `[num_vec, num_pts, 2]`.
    pub(super) points: Slab<f32>,
}

impl StepBuffers {
    /// Reserve every buffer for `dims`, zeroed, the BEVs in `bev` storage.
    pub(super) fn new(dims: &ModelDims, bev: FeatureStorage) -> Result<Self, MemoryError> {
        Ok(Self {
            can_bus: [0.0; CAN_BUS_LEN],
            value: Slab::zeroed(NUM_CAMERAS * dims.value_len())?,
            query: Slab::zeroed(dims.bev_len())?,
            weights: Slab::zeroed(dims.weights_len())?,
            gathered: Slab::zeroed(dims.bev_len())?,
            camera_bev: FeatureSlab::zeroed(dims.bev_len(), bev)?,
            crop: Slab::zeroed(dims.crop_bytes())?,
            satellite_bev: FeatureSlab::zeroed(dims.bev_len(), bev)?,
            logits: Slab::zeroed(dims.logits_len())?,
            points: Slab::zeroed(dims.points_len())?,
        })
    }

    /// The same buffers in caller-placed regions (cut to the model's lengths and zeroed).
    pub(super) fn placed(p: crate::placement::StepRegions) -> Self {
        Self {
            can_bus: [0.0; CAN_BUS_LEN],
            value: Slab::placed(p.value_features),
            query: Slab::placed(p.bev_query),
            weights: Slab::placed(p.gkt_weights),
            gathered: Slab::placed(p.gathered),
            camera_bev: FeatureSlab::placed(p.camera_bev),
            crop: Slab::placed(p.satellite_crop),
            satellite_bev: FeatureSlab::placed(p.satellite_bev),
            logits: Slab::placed(p.class_logits),
            points: Slab::placed(p.points),
        }
    }

    /// CAN-bus vector of the last attempted step.
    #[must_use]
    pub const fn can_bus(&self) -> &[f32; CAN_BUS_LEN] {
        &self.can_bus
    }

    /// Value features `[6, F, D]` of the last attempted step.
    #[must_use]
    pub fn value(&self) -> &[f32] {
        &self.value
    }

    /// BEV queries `[Q, D]` of the last attempted step.
    #[must_use]
    pub fn query(&self) -> &[f32] {
        &self.query
    }

    /// GKT weights `[Q, 4, kp]` of the last attempted step.
    #[must_use]
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Gather-sum output `[Q, D]` of the last attempted step.
    #[must_use]
    pub fn gathered(&self) -> &[f32] {
        &self.gathered
    }

    /// Camera BEV `[bev_h, bev_w, D]` of the last attempted step, in the runtime's storage.
    #[must_use]
    pub fn camera_bev(&self) -> FeaturesRef<'_> {
        self.camera_bev.as_ref()
    }

    /// Satellite crop `[sat_h, sat_w, 3]` of the last attempted step.
    #[must_use]
    pub fn crop(&self) -> &[u8] {
        &self.crop
    }

    /// Satellite BEV `[bev_h, bev_w, D]` of the last attempted step (zeros when degraded), in
    /// the runtime's storage.
    #[must_use]
    pub fn satellite_bev(&self) -> FeaturesRef<'_> {
        self.satellite_bev.as_ref()
    }

    /// Storage of the two BEV feature maps.
    #[must_use]
    pub fn bev_storage(&self) -> FeatureStorage {
        self.camera_bev.as_ref().storage()
    }

    /// Class logits `[num_vec, 3]` of the last attempted step.
    #[must_use]
    pub fn logits(&self) -> &[f32] {
        &self.logits
    }

    /// Normalised points `[num_vec, num_pts, 2]` of the last attempted step.
    #[must_use]
    pub fn points(&self) -> &[f32] {
        &self.points
    }
}
