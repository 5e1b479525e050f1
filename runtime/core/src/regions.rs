//! Which runtime buffer lives in which region of the memory layout (`memory_layout.toml`, or the
//! `SATMAP_LAYOUT` file the build was generated from), and whether a model's dimensions fit
//! them: the one check between the generated capacities (a leaf, [`crate::capacity`]) and the
//! types that size buffers from them.

use crate::buffers::MemoryError;
use crate::calibration::NUM_CAMERAS;
use crate::capacity::layout;
use crate::features::FeatureStorage;
use crate::model_dims::ModelDims;

// The tile cache region of the layout must describe the route-pack cache that exists.
const _: () = assert!(layout::TILE_CACHE_SHAPE[0] == crate::route_pack::TILE_CACHE_TILES);
// The decoded-tile region holds whole RGB tiles (`route_pack::codec`).
const _: () = assert!(
    layout::TILE_PIXELS_SHAPE[3] == crate::route_pack::format::CHANNELS
        && layout::TILE_PIXELS_SHAPE[1] == layout::TILE_PIXELS_SHAPE[2]
);

/// Runtime-owned regions whose size depends on the model's dimensions, in check order.
pub const MODEL_REGIONS: [&str; 11] = [
    "camera_images",
    "value_features",
    "gkt_lut",
    "bev_query",
    "gkt_weights",
    "gathered",
    "camera_bev",
    "satellite_crop",
    "satellite_bev",
    "class_logits",
    "points",
];

/// Bytes `dims` needs in each of [`MODEL_REGIONS`], as (region name, bytes), in that order,
/// with the BEV feature maps in `bev` storage.
#[must_use]
pub fn region_needs(dims: &ModelDims, bev: FeatureStorage) -> [(&'static str, usize); 11] {
    let f32s = |n: usize| n.saturating_mul(4);
    let bevs = |n: usize| n.saturating_mul(bev.elem_bytes());
    let needs = [
        NUM_CAMERAS.saturating_mul(dims.image_bytes()),
        f32s(NUM_CAMERAS.saturating_mul(dims.value_len())),
        crate::gkt::Lut::capacity_bytes(dims),
        f32s(dims.bev_len()),
        f32s(dims.weights_len()),
        f32s(dims.bev_len()),
        bevs(dims.bev_len()),
        dims.crop_bytes(),
        bevs(dims.bev_len()),
        f32s(dims.logits_len()),
        f32s(dims.points_len()),
    ];
    core::array::from_fn(|i| (MODEL_REGIONS[i], needs[i]))
}

/// Capacity of a model-dependent region in the layout this build was generated from, bytes
/// (`None` for a region that does not scale with the model).
#[must_use]
pub fn built_in_capacity(region: &str) -> Option<usize> {
    Some(match region {
        "camera_images" => layout::CAMERA_IMAGES_BYTES,
        "value_features" => layout::VALUE_FEATURES_BYTES,
        "gkt_lut" => layout::GKT_LUT_BYTES,
        "bev_query" => layout::BEV_QUERY_BYTES,
        "gkt_weights" => layout::GKT_WEIGHTS_BYTES,
        "gathered" => layout::GATHERED_BYTES,
        "camera_bev" => layout::CAMERA_BEV_BYTES,
        "satellite_crop" => layout::SATELLITE_CROP_BYTES,
        "satellite_bev" => layout::SATELLITE_BEV_BYTES,
        "class_logits" => layout::CLASS_LOGITS_BYTES,
        "points" => layout::POINTS_BYTES,
        _ => return None,
    })
}

/// Check that every runtime-owned region `dims` needs fits its capacity in the memory layout
/// this build was generated from (`memory_layout.toml`, or the build's `SATMAP_LAYOUT` file),
/// the BEVs in that layout's storage ([`FeatureStorage::LAYOUT`]).
///
/// # Errors
/// [`MemoryError::RegionTooSmall`] naming the first region that overflows, with the
/// bytes the model needs and the region's capacity.
pub fn check_regions(dims: &ModelDims) -> Result<(), MemoryError> {
    check_regions_with(dims, FeatureStorage::LAYOUT, built_in_capacity)
}

/// [`check_regions`] against other capacities, e.g. a layout file read at run time:
/// `capacity(region)` gives a region's bytes, `None` (a region the layout lacks) counts as 0;
/// `bev` is the storage of the BEV feature maps (that file's `camera_bev` dtype).
///
/// # Errors
/// [`MemoryError::RegionTooSmall`] naming the first region that overflows.
pub fn check_regions_with(
    dims: &ModelDims,
    bev: FeatureStorage,
    capacity: impl Fn(&str) -> Option<usize>,
) -> Result<(), MemoryError> {
    for (region, needed_bytes) in region_needs(dims, bev) {
        let capacity_bytes = capacity(region).unwrap_or(0);
        if needed_bytes > capacity_bytes {
            return Err(MemoryError::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map_frame::MapFrame;

    #[test]
    fn test_config_fits_every_region() {
        assert_eq!(check_regions(&ModelDims::test_config()), Ok(()));
    }

    #[test]
    fn larger_model_names_the_region_that_overflows() {
        // The paper config's images (scale 0.4: 640 x 360) do not fit the nano-sized layout.
        let mut dims = ModelDims::test_config();
        dims.image_w = 640;
        dims.image_h = 360;
        assert_eq!(
            check_regions(&dims),
            Err(MemoryError::RegionTooSmall {
                region: "camera_images",
                needed_bytes: 6 * 640 * 360 * 3,
                capacity_bytes: layout::CAMERA_IMAGES_BYTES,
            })
        );
        let mut dims = ModelDims::test_config();
        dims.embed_dims = 512;
        assert!(matches!(
            check_regions(&dims),
            Err(MemoryError::RegionTooSmall {
                region: "value_features",
                needed_bytes: 737_280,
                ..
            })
        ));
    }

    #[test]
    fn map_frame_region_is_the_published_frame() {
        assert_eq!(size_of::<MapFrame>(), layout::MAP_FRAME_BYTES);
    }
}
