//! The backend contract the step drives: five graph stages with fixed-size inputs and outputs
//! (see `ARCHITECTURE.md`, "Stages"). The tract engine implements it behind the `tract` feature;
//! unit tests use a deterministic pure-Rust double.
//!
//! Every buffer is owned by the step and sized from [`ModelDims`] at init; an engine writes
//! every element of each `_out` slice and must not keep references to them. The two BEV feature
//! maps come in the storage the runtime chose ([`crate::features`]): an engine computes in f32
//! and stores into them, or widens them, through [`FeaturesMut`] and [`FeaturesRef`].

use core::fmt;

use crate::capacity::CAN_BUS_LEN;
use crate::features::{FeaturesMut, FeaturesRef};
use crate::model_dims::ModelDims;

/// The graph stages, in step order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// `image_encoder`: one camera image to its value features `[F, D]`.
    ImageEncoder,
    /// `bev_query`: CAN-bus vector to BEV queries `[Q, D]` and GKT weights `[Q, 4, kp]`.
    BevQuery,
    /// `bev_encoder`: queries and gathered features to the camera BEV `[bev_h, bev_w, D]`.
    BevEncoder,
    /// `satellite_encoder`: satellite crop to the satellite BEV `[bev_h, bev_w, D]`.
    SatelliteEncoder,
    /// `map_decoder`: both BEVs to class logits `[num_vec, 3]` and points `[num_vec, 20, 2]`.
    MapDecoder,
}

impl Stage {
    /// All stages in step order.
    pub const ALL: [Self; 5] = [
        Self::ImageEncoder,
        Self::BevQuery,
        Self::BevEncoder,
        Self::SatelliteEncoder,
        Self::MapDecoder,
    ];

    /// The stage name used in bundle manifests.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ImageEncoder => "image_encoder",
            Self::BevQuery => "bev_query",
            Self::BevEncoder => "bev_encoder",
            Self::SatelliteEncoder => "satellite_encoder",
            Self::MapDecoder => "map_decoder",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What went wrong in a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum EngineErrorKind {
    /// A buffer does not have the length the stage's static shape needs.
    ShapeMismatch {
        /// Elements the stage needs.
        expected: usize,
        /// Elements given.
        got: usize,
    },
    /// Camera index outside the rig.
    CameraIndex {
        /// Index given.
        camera: usize,
    },
    /// The graph backend failed.
    Backend(BackendFault),
}

/// How a graph backend failed a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum BackendFault {
    /// An input tensor was still shared when the next run wanted to write it.
    InputShared,
    /// The backend returned an error while running the stage (the backend keeps its message).
    RunFailed,
    /// The stage has fewer inputs than the runtime writes.
    NoSuchInput,
    /// An input tensor's element type differs from the runtime buffer's.
    InputDtype,
    /// The stage produced another number of outputs than the manifest declares.
    OutputCount,
    /// An output is not f32.
    OutputDtype,
    /// The backend panicked while running the stage (caught; the stage's state was renewed and
    /// the engine stays usable; the backend keeps the message).
    RunPanicked,
}

impl fmt::Display for BackendFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InputShared => "an input tensor is still shared",
            Self::RunFailed => "the backend failed to run the stage",
            Self::NoSuchInput => "the stage has fewer inputs than the runtime writes",
            Self::InputDtype => "an input's element type differs from the runtime buffer's",
            Self::OutputCount => "the stage produced another number of outputs than declared",
            Self::OutputDtype => "an output is not f32",
            Self::RunPanicked => "the backend panicked running the stage (caught)",
        })
    }
}

/// A stage failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EngineError {
    /// Which stage.
    pub stage: Stage,
    /// What went wrong.
    pub kind: EngineErrorKind,
}

impl fmt::Display for EngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            EngineErrorKind::ShapeMismatch { expected, got } => {
                write!(
                    f,
                    "stage {}: buffer of {got} elements, expected {expected}",
                    self.stage
                )
            }
            EngineErrorKind::CameraIndex { camera } => {
                write!(
                    f,
                    "stage {}: camera index {camera} outside the rig",
                    self.stage
                )
            }
            EngineErrorKind::Backend(fault) => write!(f, "stage {}: {fault}", self.stage),
        }
    }
}

impl core::error::Error for EngineError {}

/// The graph backend. Implementations must be deterministic: the same inputs give the same
/// output bits on every call.
pub trait Engine {
    /// Shapes of the loaded model.
    fn dims(&self) -> &ModelDims;

    /// Encode camera `camera`'s image (`[image_h, image_w, 3]` u8) into `value_out` (`[F, D]`).
    ///
    /// # Errors
    /// An [`EngineError`] with `stage = ImageEncoder`.
    fn encode_image(
        &mut self,
        camera: usize,
        image_rgb: &[u8],
        value_out: &mut [f32],
    ) -> Result<(), EngineError>;

    /// BEV queries `[Q, D]` and softmaxed GKT weights `[Q, 4, kp]` from the CAN-bus vector.
    ///
    /// # Errors
    /// An [`EngineError`] with `stage = BevQuery`.
    fn bev_query(
        &mut self,
        can_bus: &[f32; CAN_BUS_LEN],
        query_out: &mut [f32],
        gkt_weights_out: &mut [f32],
    ) -> Result<(), EngineError>;

    /// Camera BEV `[bev_h, bev_w, D]` from the queries and the gathered features (`[Q, D]` each),
    /// stored in `camera_bev_out`'s storage.
    ///
    /// # Errors
    /// An [`EngineError`] with `stage = BevEncoder`.
    fn bev_encode(
        &mut self,
        query: &[f32],
        gathered: &[f32],
        camera_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError>;

    /// Satellite BEV `[bev_h, bev_w, D]` from the crop (`[sat_h, sat_w, 3]` u8), stored in
    /// `satellite_bev_out`'s storage.
    ///
    /// # Errors
    /// An [`EngineError`] with `stage = SatelliteEncoder`.
    fn encode_satellite(
        &mut self,
        crop_rgb: &[u8],
        satellite_bev_out: FeaturesMut<'_>,
    ) -> Result<(), EngineError>;

    /// Class logits `[num_vec, 3]` and normalised points `[num_vec, num_pts, 2]` from both BEVs.
    ///
    /// # Errors
    /// An [`EngineError`] with `stage = MapDecoder`.
    fn decode_map(
        &mut self,
        camera_bev: FeaturesRef<'_>,
        satellite_bev: FeaturesRef<'_>,
        class_logits_out: &mut [f32],
        points_out: &mut [f32],
    ) -> Result<(), EngineError>;
}
