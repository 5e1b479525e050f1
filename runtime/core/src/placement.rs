//! Caller-placed memory: the runtime-owned regions of `memory_layout.toml` that scale with the
//! model, handed over by the integrator (placed by their linker script, sized from the layout)
//! instead of reserved on the heap. [`RuntimeRegions`] is what `SatMap::in_regions` and the C
//! API's `satmap_create` take; [`REGIONS`] lists them, in that order, with their sizes.
//!
//! Contract: every region is at least its `memory_layout.toml` size and starts on a
//! [`REGION_ALIGN`]-byte boundary; the runtime keeps the `'static` borrow for its whole life and
//! zeroes what it uses at init. A region that is too small or misaligned is refused by name
//! ([`MemoryError::RegionTooSmall`], [`MemoryError::RegionMisaligned`]).

use crate::buffers::MemoryError;
use crate::calibration::NUM_CAMERAS;
use crate::capacity::layout;
use crate::features::{FeatureStorage, PlacedFeatures};
use crate::gkt::Lut;
use crate::model_dims::ModelDims;

/// Alignment every placed region must have, bytes (f32 buffers need 4; 16 lets a target's
/// vector loads stay aligned).
pub const REGION_ALIGN: usize = 16;

/// A placed region's identity: its `memory_layout.toml` name and size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RegionSpec {
    /// Name, as in `memory_layout.toml`.
    pub name: &'static str,
    /// Bytes the caller must provide (the layout's `bytes`).
    pub bytes: usize,
}

/// The placed regions, in [`RuntimeRegions`] field order (the C API's region ids).
pub const REGIONS: [RegionSpec; 10] = [
    spec("value_features", layout::VALUE_FEATURES_BYTES),
    spec("gkt_lut", layout::GKT_LUT_BYTES),
    spec("bev_query", layout::BEV_QUERY_BYTES),
    spec("gkt_weights", layout::GKT_WEIGHTS_BYTES),
    spec("gathered", layout::GATHERED_BYTES),
    spec("camera_bev", layout::CAMERA_BEV_BYTES),
    spec("satellite_crop", layout::SATELLITE_CROP_BYTES),
    spec("satellite_bev", layout::SATELLITE_BEV_BYTES),
    spec("class_logits", layout::CLASS_LOGITS_BYTES),
    spec("points", layout::POINTS_BYTES),
];

const fn spec(name: &'static str, bytes: usize) -> RegionSpec {
    RegionSpec { name, bytes }
}

/// The integrator's memory for the runtime's model-sized buffers, one field per region of
/// [`REGIONS`] (same order).
#[derive(Debug)]
#[allow(missing_docs)] // each field is the region of the same name in memory_layout.toml
pub struct RuntimeRegions {
    pub value_features: &'static mut [u8],
    pub gkt_lut: &'static mut [u8],
    pub bev_query: &'static mut [u8],
    pub gkt_weights: &'static mut [u8],
    pub gathered: &'static mut [u8],
    pub camera_bev: &'static mut [u8],
    pub satellite_crop: &'static mut [u8],
    pub satellite_bev: &'static mut [u8],
    pub class_logits: &'static mut [u8],
    pub points: &'static mut [u8],
}

/// The step's buffers cut from [`RuntimeRegions`], typed and at the model's lengths.
pub(crate) struct StepRegions {
    pub(crate) value_features: &'static mut [f32],
    pub(crate) bev_query: &'static mut [f32],
    pub(crate) gkt_weights: &'static mut [f32],
    pub(crate) gathered: &'static mut [f32],
    pub(crate) camera_bev: PlacedFeatures,
    pub(crate) satellite_crop: &'static mut [u8],
    pub(crate) satellite_bev: PlacedFeatures,
    pub(crate) class_logits: &'static mut [f32],
    pub(crate) points: &'static mut [f32],
}

/// The look-up table's three arrays cut from the `gkt_lut` region.
pub(crate) struct LutRegions {
    pub(crate) queries: &'static mut [u16],
    pub(crate) indices: &'static mut [u16],
    pub(crate) count: &'static mut [u8],
}

impl RuntimeRegions {
    /// Check every region (size against the layout, alignment) and cut the model's buffers
    /// from them, the BEVs in the layout's storage ([`FeatureStorage::LAYOUT`]). `dims` must
    /// already fit the layout (`regions::check_regions`).
    pub(crate) fn split(self, dims: &ModelDims) -> Result<(StepRegions, LutRegions), MemoryError> {
        let Self {
            value_features,
            gkt_lut,
            bev_query,
            gkt_weights,
            gathered,
            camera_bev,
            satellite_crop,
            satellite_bev,
            class_logits,
            points,
        } = self;
        let [
            s_value,
            s_lut,
            s_query,
            s_weights,
            s_gathered,
            s_camera_bev,
            s_crop,
            s_sat_bev,
            s_logits,
            s_points,
        ] = REGIONS;
        let (q_n, i_n, c_n) = Lut::storage_lens(dims);
        let lut = checked(s_lut, gkt_lut)?;
        let (queries, rest) = lut.split_at_mut(q_n * 2);
        let (indices, rest) = rest.split_at_mut(i_n * 2);
        let lut = LutRegions {
            queries: u16s(s_lut, queries)?,
            indices: u16s(s_lut, indices)?,
            count: &mut rest[..c_n],
        };
        let step = StepRegions {
            value_features: f32s(s_value, value_features, NUM_CAMERAS * dims.value_len())?,
            bev_query: f32s(s_query, bev_query, dims.bev_len())?,
            gkt_weights: f32s(s_weights, gkt_weights, dims.weights_len())?,
            gathered: f32s(s_gathered, gathered, dims.bev_len())?,
            camera_bev: features(s_camera_bev, camera_bev, dims.bev_len())?,
            satellite_crop: &mut checked(s_crop, satellite_crop)?[..dims.crop_bytes()],
            satellite_bev: features(s_sat_bev, satellite_bev, dims.bev_len())?,
            class_logits: f32s(s_logits, class_logits, dims.logits_len())?,
            points: f32s(s_points, points, dims.points_len())?,
        };
        Ok((step, lut))
    }
}

/// `region` after the size and alignment checks.
fn checked(spec: RegionSpec, region: &'static mut [u8]) -> Result<&'static mut [u8], MemoryError> {
    if region.len() < spec.bytes {
        return Err(MemoryError::RegionTooSmall {
            region: spec.name,
            needed_bytes: spec.bytes,
            capacity_bytes: region.len(),
        });
    }
    if region.as_ptr().align_offset(REGION_ALIGN) != 0 {
        return Err(MemoryError::RegionMisaligned {
            region: spec.name,
            align: REGION_ALIGN,
        });
    }
    Ok(region)
}

fn f32s(
    spec: RegionSpec,
    region: &'static mut [u8],
    len: usize,
) -> Result<&'static mut [f32], MemoryError> {
    let region = checked(spec, region)?;
    bytemuck::try_cast_slice_mut(&mut region[..len * 4]).map_err(|_| {
        MemoryError::RegionMisaligned {
            region: spec.name,
            align: REGION_ALIGN,
        }
    })
}

/// A BEV region cut to `len` elements of the layout's storage.
fn features(
    spec: RegionSpec,
    region: &'static mut [u8],
    len: usize,
) -> Result<PlacedFeatures, MemoryError> {
    Ok(match FeatureStorage::LAYOUT {
        FeatureStorage::F32 => PlacedFeatures::F32(f32s(spec, region, len)?),
        FeatureStorage::F16 => {
            let region = checked(spec, region)?;
            let capacity_bytes = region.len();
            // `check_regions` made the layout's region hold `len` halves; this keeps the cut
            // from relying on it.
            let bytes = len.checked_mul(2).and_then(|n| region.get_mut(..n)).ok_or(
                MemoryError::RegionTooSmall {
                    region: spec.name,
                    needed_bytes: len.saturating_mul(2),
                    capacity_bytes,
                },
            )?;
            PlacedFeatures::F16(u16s(spec, bytes)?)
        }
    })
}

fn u16s(spec: RegionSpec, bytes: &'static mut [u8]) -> Result<&'static mut [u16], MemoryError> {
    bytemuck::try_cast_slice_mut(bytes).map_err(|_| MemoryError::RegionMisaligned {
        region: spec.name,
        align: REGION_ALIGN,
    })
}
