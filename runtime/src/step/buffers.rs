//! The intermediate buffers of one step, reserved once at init and overwritten by every attempted
//! step: the read-only view integrators and tests inspect through [`SatMap::buffers`].
//!
//! After a failed step they hold the partial step (whatever stages ran before the failure); the
//! published map is elsewhere and is not affected.
//!
//! [`SatMap::buffers`]: super::SatMap::buffers

use alloc::vec::Vec;

use crate::buffers::zeroed;
use crate::calibration::NUM_CAMERAS;
use crate::capacity::CAN_BUS_LEN;
use crate::error::InitError;
use crate::model_dims::ModelDims;

/// The pipeline's intermediate tensors of the last attempted step, row-major, sized from the
/// model dimensions at init.
#[derive(Clone, Debug)]
pub struct StepBuffers {
    pub(super) can_bus: [f32; CAN_BUS_LEN],
    /// `[6, F, D]`.
    pub(super) value: Vec<f32>,
    /// `[Q, D]`.
    pub(super) query: Vec<f32>,
    /// `[Q, 4, kp]`.
    pub(super) weights: Vec<f32>,
    /// `[Q, D]`.
    pub(super) gathered: Vec<f32>,
    /// `[bev_h, bev_w, D]`.
    pub(super) camera_bev: Vec<f32>,
    /// `[sat_h, sat_w, 3]`.
    pub(super) crop: Vec<u8>,
    /// `[bev_h, bev_w, D]`.
    pub(super) satellite_bev: Vec<f32>,
    /// `[num_vec, 3]`.
    pub(super) logits: Vec<f32>,
    /// `[num_vec, num_pts, 2]`.
    pub(super) points: Vec<f32>,
}

impl StepBuffers {
    /// Reserve every buffer for `dims`, zeroed.
    pub(super) fn new(dims: &ModelDims) -> Result<Self, InitError> {
        Ok(Self {
            can_bus: [0.0; CAN_BUS_LEN],
            value: zeroed(NUM_CAMERAS * dims.value_len())?,
            query: zeroed(dims.bev_len())?,
            weights: zeroed(dims.weights_len())?,
            gathered: zeroed(dims.bev_len())?,
            camera_bev: zeroed(dims.bev_len())?,
            crop: zeroed(dims.crop_bytes())?,
            satellite_bev: zeroed(dims.bev_len())?,
            logits: zeroed(dims.logits_len())?,
            points: zeroed(dims.points_len())?,
        })
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

    /// Camera BEV `[bev_h, bev_w, D]` of the last attempted step.
    #[must_use]
    pub fn camera_bev(&self) -> &[f32] {
        &self.camera_bev
    }

    /// Satellite crop `[sat_h, sat_w, 3]` of the last attempted step.
    #[must_use]
    pub fn crop(&self) -> &[u8] {
        &self.crop
    }

    /// Satellite BEV `[bev_h, bev_w, D]` of the last attempted step (zeros when degraded).
    #[must_use]
    pub fn satellite_bev(&self) -> &[f32] {
        &self.satellite_bev
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
