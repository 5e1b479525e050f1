//! What each slice of a step computes ([`SatMap::run_slice`]): the engine stage or native kernel
//! it runs, on which buffers, and the check of what it wrote. The one-call step and the staged
//! step both run their slices through here, so they give the same bits.

use super::staged::Pending;
use super::{MAX_NORMALISED_POINT, SatMap, StepError, StepSlice};
use crate::can_bus::can_bus;
use crate::engine::Engine;
use crate::features::FeaturesRef;
use crate::frame::Frame;
use crate::gkt::gather_sum;
use crate::map_frame::SatellitePrior;
use crate::satellite::{Coverage, SatelliteSource};

impl<E: Engine, S: SatelliteSource> SatMap<E, S> {
    /// Run `slice` of the staged step `p` on `frame`, writing its buffers.
    pub(super) fn run_slice(
        &mut self,
        slice: StepSlice,
        frame: &Frame<'_>,
        p: &mut Pending,
    ) -> Result<(), StepError> {
        let b = &mut self.buffers;
        match slice {
            StepSlice::BevQuery => {
                b.can_bus = can_bus(&frame.pose, &frame.motion);
                self.engine
                    .bev_query(&b.can_bus, &mut b.query, &mut b.weights)?;
                finite(slice, &[&b.query, &b.weights])?;
            }
            StepSlice::ImageEncoder { camera } => {
                let camera = usize::from(camera);
                let value_len = self.dims.value_len();
                // step_begin checked this image; only a different frame can lack it here.
                let (Some(image), Some(value)) = (
                    frame.images.get(camera).copied().flatten(),
                    b.value.chunks_exact_mut(value_len).nth(camera),
                ) else {
                    return Err(StepError::FrameMismatch {
                        expected_sequence: p.sequence,
                        got_sequence: frame.sequence,
                    });
                };
                self.engine.encode_image(camera, image.rgb, value)?;
                finite(slice, &[value])?;
            }
            StepSlice::GktGather => {
                // The table lives in caller memory: a stray write there changed every later map
                // silently (issue 38 found 30 of 200 single-bit flips doing so).
                self.lut.verify()?;
                gather_sum(
                    &self.lut,
                    &b.value,
                    &b.weights,
                    &mut b.gathered,
                    p.cameras.mask,
                )?;
                finite(slice, &[&b.gathered])?;
            }
            StepSlice::BevEncoder => {
                self.engine
                    .bev_encode(&b.query, &b.gathered, b.camera_bev.as_mut())?;
                finite_features(slice, b.camera_bev.as_ref())?;
            }
            StepSlice::Satellite => {
                let spec = self.dims.crop_spec();
                let coverage = self.satellite.crop(&p.pose, &spec, &mut b.crop);
                let (prior, degraded) = match coverage {
                    Coverage::Full => (SatellitePrior::Present, false),
                    Coverage::Partial { covered_permille } => {
                        (SatellitePrior::Partial { covered_permille }, false)
                    }
                    Coverage::None => (SatellitePrior::Missing, true),
                    Coverage::Corrupt => (SatellitePrior::Corrupt, true),
                };
                if degraded {
                    b.satellite_bev.as_mut().fill_zero();
                } else {
                    self.engine
                        .encode_satellite(&b.crop, b.satellite_bev.as_mut())?;
                    finite_features(slice, b.satellite_bev.as_ref())?;
                }
                (p.prior, p.degraded) = (prior, degraded);
            }
            StepSlice::MapDecoder => {
                self.engine.decode_map(
                    b.camera_bev.as_ref(),
                    b.satellite_bev.as_ref(),
                    &mut b.logits,
                    &mut b.points,
                )?;
                finite(slice, &[&b.logits])?;
                // Points are normalised to the BEV range (sigmoid outputs in [0, 1]); a finite
                // but huge value would still decode to an infinite coordinate in metres, so
                // they are bounded, not only finite (NaN fails the bound too).
                if !b.points.iter().all(|v| v.abs() <= MAX_NORMALISED_POINT) {
                    return Err(StepError::NonFiniteOutput { slice });
                }
            }
        }
        Ok(())
    }
}

/// Every value of `outputs` finite, or the slice's [`StepError::NonFiniteOutput`]: one counted
/// pass over what the slice wrote (a bad input such as a finite 1e38 velocity otherwise turns
/// the BEV non-finite and still decodes to a map marked healthy).
fn finite(slice: StepSlice, outputs: &[&[f32]]) -> Result<(), StepError> {
    if outputs.iter().all(|o| o.iter().all(|v| v.is_finite())) {
        Ok(())
    } else {
        Err(StepError::NonFiniteOutput { slice })
    }
}

/// [`finite`] for a BEV feature map: in f16 storage an f32 output beyond half's range was stored
/// as infinity, so this also refuses a BEV the storage could not hold.
fn finite_features(slice: StepSlice, features: FeaturesRef<'_>) -> Result<(), StepError> {
    if features.all_finite() {
        Ok(())
    } else {
        Err(StepError::NonFiniteOutput { slice })
    }
}
