//! Model dimensions: the `[model]` table of a bundle manifest, checked once at init, and the
//! buffer sizes derived from it.
//!
//! Frames: `pc_range_m` is `[xmin, ymin, zmin, xmax, ymax, zmax]` in the ego frame (x right,
//! y forward, z up). The BEV grid has `bev_h` rows along y (row 0 at the rear) and `bev_w` columns
//! along x (column 0 at the left).

use crate::calibration::NUM_CAMERAS;
use crate::capacity::{
    MAX_FEATURES, MAX_KERNEL_POINTS, MAX_QUERIES, MAX_TOP_K, NUM_CLASSES, NUM_HEADS, NUM_POINTS,
};
use crate::pose::Axis;
use crate::satellite::CropSpec;

mod error;
pub use error::{DimsError, ImageSide};

/// Coarsest satellite ground sampling distance a model may ask for, metres per pixel (the route
/// pack's own limit): coarser crops would step the sampler by more pack pixels than it indexes.
pub const MAX_SAT_GSD_M: f64 = 100.0;

/// Class names in head order, as the manifest spells them.
pub const CLASS_NAMES: [&str; NUM_CLASSES] = ["divider", "ped_crossing", "boundary"];

/// Shapes and geometry of one exported model configuration (`test`, `nano`, `paper`).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelDims {
    /// Channels of every feature and BEV tensor (`D`).
    pub embed_dims: usize,
    /// BEV rows (along ego y).
    pub bev_h: usize,
    /// BEV columns (along ego x).
    pub bev_w: usize,
    /// Perception range `[xmin, ymin, zmin, xmax, ymax, zmax]`, ego metres.
    pub pc_range_m: [f32; 6],
    /// Instance queries of the map decoder.
    pub num_vec: usize,
    /// Points per instance.
    pub num_pts: usize,
    /// Elements kept by decode.
    pub top_k: usize,
    /// Resized (unpadded) camera image height, pixels.
    pub image_h: usize,
    /// Resized (unpadded) camera image width, pixels.
    pub image_w: usize,
    /// Padded image height the encoder sees, pixels.
    pub pad_h: usize,
    /// Padded image width the encoder sees, pixels.
    pub pad_w: usize,
    /// Resize factor from the raw calibration size to `image_w x image_h`.
    pub image_scale: f64,
    /// Feature-map rows of one camera.
    pub feat_h: usize,
    /// Feature-map columns of one camera.
    pub feat_w: usize,
    /// GKT reference heights (one per head), ego z metres.
    pub gkt_heights_m: [f32; NUM_HEADS],
    /// GKT kernel rows.
    pub kernel_h: usize,
    /// GKT kernel columns.
    pub kernel_w: usize,
    /// Satellite crop rows (along ego y).
    pub sat_h: usize,
    /// Satellite crop columns (along ego x).
    pub sat_w: usize,
    /// Satellite crop ground sampling distance, metres per pixel.
    pub sat_gsd_m: f64,
}

impl ModelDims {
    /// BEV queries, `bev_h * bev_w` (`Q`).
    #[must_use]
    pub const fn num_queries(&self) -> usize {
        self.bev_h * self.bev_w
    }

    /// Feature cells of one camera, `feat_h * feat_w` (`F`).
    #[must_use]
    pub const fn num_features(&self) -> usize {
        self.feat_h * self.feat_w
    }

    /// f32 values of one camera's value features, `F * D`.
    #[must_use]
    pub const fn value_len(&self) -> usize {
        self.num_features() * self.embed_dims
    }

    /// Channels per GKT head, `D / 4`.
    #[must_use]
    pub const fn head_dims(&self) -> usize {
        self.embed_dims / NUM_HEADS
    }

    /// GKT kernel points, `kernel_h * kernel_w`.
    #[must_use]
    pub const fn kernel_points(&self) -> usize {
        self.kernel_h * self.kernel_w
    }

    /// f32 values of the GKT weights, `Q * 4 * kernel_points`.
    #[must_use]
    pub const fn weights_len(&self) -> usize {
        self.num_queries() * NUM_HEADS * self.kernel_points()
    }

    /// f32 values of one `[Q, D]` / `[bev_h, bev_w, D]` tensor.
    #[must_use]
    pub const fn bev_len(&self) -> usize {
        self.num_queries() * self.embed_dims
    }

    /// Bytes of one camera image, `image_h * image_w * 3`.
    #[must_use]
    pub const fn image_bytes(&self) -> usize {
        self.image_h * self.image_w * 3
    }

    /// Bytes of the satellite crop, `sat_h * sat_w * 3`.
    #[must_use]
    pub const fn crop_bytes(&self) -> usize {
        self.sat_h * self.sat_w * 3
    }

    /// f32 values of the class logits, `num_vec * 3`.
    #[must_use]
    pub const fn logits_len(&self) -> usize {
        self.num_vec * NUM_CLASSES
    }

    /// f32 values of the normalised points, `num_vec * num_pts * 2`.
    #[must_use]
    pub const fn points_len(&self) -> usize {
        self.num_vec * self.num_pts * 2
    }

    /// Geometry of the satellite crop: the BEV range sampled at `sat_gsd_m`, ego-centred.
    #[must_use]
    pub fn crop_spec(&self) -> CropSpec {
        CropSpec {
            height_px: self.sat_h,
            width_px: self.sat_w,
            gsd_m: self.sat_gsd_m,
            x_min_m: f64::from(self.pc_range_m[0]),
            y_min_m: f64::from(self.pc_range_m[1]),
        }
    }

    /// Check every bound this runtime relies on; called by `SatMap::new`.
    ///
    /// # Errors
    /// The first violated bound, as a [`DimsError`].
    pub fn validate(&self) -> Result<(), DimsError> {
        let sizes = [
            ("embed_dims", self.embed_dims),
            ("bev_h", self.bev_h),
            ("bev_w", self.bev_w),
            ("num_vec", self.num_vec),
            ("num_pts", self.num_pts),
            ("top_k", self.top_k),
            ("image_h", self.image_h),
            ("image_w", self.image_w),
            ("pad_h", self.pad_h),
            ("pad_w", self.pad_w),
            ("feat_h", self.feat_h),
            ("feat_w", self.feat_w),
            ("kernel_h", self.kernel_h),
            ("kernel_w", self.kernel_w),
            ("sat_h", self.sat_h),
            ("sat_w", self.sat_w),
        ];
        if let Some((field, _)) = sizes.iter().find(|(_, v)| *v == 0) {
            return Err(DimsError::Zero { field });
        }
        if self.pc_range_m.iter().any(|v| !v.is_finite()) {
            return Err(DimsError::NonFinite {
                field: "pc_range_m",
            });
        }
        if self.gkt_heights_m.iter().any(|v| !v.is_finite()) {
            return Err(DimsError::NonFinite {
                field: "gkt_heights_m",
            });
        }
        if !self.image_scale.is_finite() {
            return Err(DimsError::NonFinite {
                field: "image_scale",
            });
        }
        if !self.sat_gsd_m.is_finite() {
            return Err(DimsError::NonFinite { field: "sat_gsd_m" });
        }
        if self.image_scale <= 0.0 {
            return Err(DimsError::NotPositive {
                field: "image_scale",
            });
        }
        if self.sat_gsd_m <= 0.0 {
            return Err(DimsError::NotPositive { field: "sat_gsd_m" });
        }
        if self.sat_gsd_m > MAX_SAT_GSD_M {
            return Err(DimsError::AboveMax {
                field: "sat_gsd_m",
                max: MAX_SAT_GSD_M as u32,
            });
        }
        for (a, axis) in Axis::ALL.into_iter().enumerate() {
            if self.pc_range_m[a] >= self.pc_range_m[a + 3] {
                return Err(DimsError::EmptyRange { axis });
            }
        }
        let (z_min_m, z_max_m) = (self.pc_range_m[2], self.pc_range_m[5]);
        if let Some(head) = self
            .gkt_heights_m
            .iter()
            .position(|h| !(z_min_m..=z_max_m).contains(h))
        {
            return Err(DimsError::HeightOutsideRange { head });
        }
        // The satellite crop is the BEV range sampled at `sat_gsd_m`, its pixel counts rounded
        // (as the exporter does): a crop covering another extent would place satellite features
        // beside the camera features of other cells. Half a pixel, plus a millimetre for the
        // f32 range, is the rounding.
        let extents = [
            (false, self.sat_w, self.pc_range_m[3] - self.pc_range_m[0]),
            (true, self.sat_h, self.pc_range_m[4] - self.pc_range_m[1]),
        ];
        for (along_y, px, range_m) in extents {
            let covered_m = px as f64 * self.sat_gsd_m;
            if (covered_m - f64::from(range_m)).abs() > 0.5 * self.sat_gsd_m + 1e-3 {
                return Err(DimsError::SatelliteExtent { along_y });
            }
        }
        if !self.embed_dims.is_multiple_of(NUM_HEADS) {
            return Err(DimsError::EmbedDimsNotDivisibleByHeads {
                embed_dims: self.embed_dims,
                heads: NUM_HEADS,
            });
        }
        let queries = self.bev_h.saturating_mul(self.bev_w);
        if queries > MAX_QUERIES {
            return Err(DimsError::TooManyQueries {
                queries,
                max: MAX_QUERIES,
            });
        }
        let features = self.feat_h.saturating_mul(self.feat_w);
        if features > MAX_FEATURES {
            return Err(DimsError::TooManyFeatures {
                features,
                max: MAX_FEATURES,
            });
        }
        let points = self.kernel_h.saturating_mul(self.kernel_w);
        if points > MAX_KERNEL_POINTS {
            return Err(DimsError::KernelTooLarge {
                points,
                max: MAX_KERNEL_POINTS,
            });
        }
        if self.num_pts != NUM_POINTS {
            return Err(DimsError::PointsMismatch {
                num_pts: self.num_pts,
                expected: NUM_POINTS,
            });
        }
        let max_k = MAX_TOP_K.min(self.num_vec.saturating_mul(NUM_CLASSES));
        if self.top_k > max_k {
            return Err(DimsError::TopKTooLarge {
                top_k: self.top_k,
                max: max_k,
            });
        }
        if self.pad_h < self.image_h {
            return Err(DimsError::PaddingSmallerThanImage {
                side: ImageSide::Height,
            });
        }
        if self.pad_w < self.image_w {
            return Err(DimsError::PaddingSmallerThanImage {
                side: ImageSide::Width,
            });
        }
        // Sizes that pass every bound above may still overflow a derived buffer length in bytes
        // (`embed_dims = 2^62`): refuse them here so no accessor below can overflow.
        let f32_bytes = |n: Option<usize>| n.and_then(|v| v.checked_mul(4));
        let lens = [
            f32_bytes(
                features
                    .checked_mul(self.embed_dims)
                    .and_then(|v| v.checked_mul(NUM_CAMERAS)),
            ),
            f32_bytes(queries.checked_mul(self.embed_dims)),
            self.image_h
                .checked_mul(self.image_w)
                .and_then(|v| v.checked_mul(3 * NUM_CAMERAS)),
            self.pad_h
                .checked_mul(self.pad_w)
                .and_then(|v| v.checked_mul(3)),
            self.sat_h
                .checked_mul(self.sat_w)
                .and_then(|v| v.checked_mul(3)),
            f32_bytes(self.num_vec.checked_mul(NUM_POINTS * 2)),
        ];
        if lens.iter().any(Option::is_none) {
            return Err(DimsError::SizeOverflow);
        }
        Ok(())
    }

    /// The `test` configuration of `ARCHITECTURE.md` (D = 32, 320x180 images, 6x10 features).
    #[must_use]
    pub const fn test_config() -> Self {
        Self {
            embed_dims: 32,
            bev_h: 80,
            bev_w: 40,
            pc_range_m: [-15.0, -30.0, -2.0, 15.0, 30.0, 2.0],
            num_vec: 50,
            num_pts: NUM_POINTS,
            top_k: 50,
            image_h: 180,
            image_w: 320,
            pad_h: 192,
            pad_w: 320,
            image_scale: 0.2,
            feat_h: 6,
            feat_w: 10,
            gkt_heights_m: [-1.5, -0.5, 0.5, 1.5],
            kernel_h: 3,
            kernel_w: 5,
            sat_h: 200,
            sat_w: 100,
            sat_gsd_m: 0.3,
        }
    }

    /// The paper's shapes (D = 256, 800x450 images padded to 800x480, 15x25 features, satellite
    /// crop 400x200 at 0.15 m/px), as `satmap_ref.config` exports them.
    #[must_use]
    pub const fn paper_config() -> Self {
        Self {
            embed_dims: 256,
            image_h: 450,
            image_w: 800,
            pad_h: 480,
            pad_w: 800,
            image_scale: 0.5,
            feat_h: 15,
            feat_w: 25,
            sat_h: 400,
            sat_w: 200,
            sat_gsd_m: 0.15,
            ..Self::test_config()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn test_and_paper_configs_validate() {
        assert_eq!(ModelDims::test_config().validate(), Ok(()));
        assert_eq!(ModelDims::paper_config().validate(), Ok(()));
        let d = ModelDims::paper_config();
        assert_eq!(d.num_queries(), 3200);
        assert_eq!(d.num_features(), 375);
        assert_eq!(d.head_dims(), 64);
        assert_eq!(d.weights_len(), 3200 * 60);
    }

    #[test]
    fn validate_reports_each_bound() {
        let mut d = ModelDims::test_config();
        d.top_k = 51;
        assert_eq!(
            d.validate(),
            Err(DimsError::TopKTooLarge { top_k: 51, max: 50 })
        );
        let mut d = ModelDims::test_config();
        d.embed_dims = 30;
        assert!(matches!(
            d.validate(),
            Err(DimsError::EmbedDimsNotDivisibleByHeads { .. })
        ));
        let mut d = ModelDims::test_config();
        d.feat_w = 0;
        assert_eq!(d.validate(), Err(DimsError::Zero { field: "feat_w" }));
        let mut d = ModelDims::test_config();
        d.pc_range_m[4] = -40.0;
        assert_eq!(d.validate(), Err(DimsError::EmptyRange { axis: Axis::Y }));
        let mut d = ModelDims::test_config();
        d.num_pts = 10;
        assert!(matches!(
            d.validate(),
            Err(DimsError::PointsMismatch { .. })
        ));
    }

    #[test]
    fn validate_refuses_numbers_that_place_the_map_elsewhere() {
        // Heights must lie in [zmin, zmax] = [-2, 2].
        let mut d = ModelDims::test_config();
        d.gkt_heights_m[3] = 2.5;
        assert_eq!(d.validate(), Err(DimsError::HeightOutsideRange { head: 3 }));
        // The bit flip the adversarial test found: pc_range x min -15 -> -14 leaves the 100 px
        // x 0.3 m crop 1 m wider than the range.
        let mut d = ModelDims::test_config();
        d.pc_range_m[0] = -14.0;
        assert_eq!(
            d.validate(),
            Err(DimsError::SatelliteExtent { along_y: false })
        );
        // 100 px x 0.31 m = 31 m against 30 m: more than half a pixel off.
        let mut d = ModelDims::test_config();
        d.sat_gsd_m = 0.31;
        assert_eq!(
            d.validate(),
            Err(DimsError::SatelliteExtent { along_y: false })
        );
        // paper_r50: 100 m at 0.15 m rounds to 667 px (100.05 m), which is the exporter's crop.
        let mut d = ModelDims::test_config();
        d.pc_range_m = [-25.0, -50.0, -2.0, 25.0, 50.0, 2.0];
        (d.sat_h, d.sat_w, d.sat_gsd_m) = (667, 333, 0.15);
        assert_eq!(d.validate(), Ok(()));
        let mut d = ModelDims::test_config();
        d.sat_h = 201;
        assert_eq!(
            d.validate(),
            Err(DimsError::SatelliteExtent { along_y: true })
        );
    }

    #[test]
    fn validate_refuses_sizes_that_overflow_instead_of_panicking() {
        let mut d = ModelDims::test_config();
        d.embed_dims = 1 << 62;
        assert_eq!(d.validate(), Err(DimsError::SizeOverflow));
        let mut d = ModelDims::test_config();
        d.pad_w = usize::MAX;
        assert_eq!(d.validate(), Err(DimsError::SizeOverflow));
    }

    #[test]
    fn crop_spec_matches_range() {
        let s = ModelDims::test_config().crop_spec();
        assert_eq!((s.height_px, s.width_px), (200, 100));
        assert_eq!((s.x_min_m, s.y_min_m, s.gsd_m), (-15.0, -30.0, 0.3));
    }
}
