//! Which runtime buffer lives in which region of `memory_layout.toml`, and whether a model's
//! dimensions fit them: the one check between the generated capacities (a leaf,
//! [`crate::capacity`]) and the types that size buffers from them.

use crate::capacity::{MAX_CAMERAS, layout};
use crate::error::InitError;
use crate::model_dims::ModelDims;

// The tile cache region of the layout must describe the route-pack cache that exists.
const _: () = assert!(layout::TILE_CACHE_SHAPE[0] == crate::route_pack::TILE_CACHE_TILES);
// The decoded-tile region holds whole RGB tiles (`route_pack::codec`).
const _: () = assert!(
    layout::TILE_PIXELS_SHAPE[3] == crate::route_pack::format::CHANNELS
        && layout::TILE_PIXELS_SHAPE[1] == layout::TILE_PIXELS_SHAPE[2]
);

/// Check that every runtime-owned region `dims` needs fits its capacity in `memory_layout.toml`.
///
/// # Errors
/// [`InitError::RegionTooSmall`] naming the first region that overflows, with the
/// bytes the model needs and the region's capacity.
pub fn check_regions(dims: &ModelDims) -> Result<(), InitError> {
    let f32s = |n: usize| n.saturating_mul(4);
    let regions: [(&'static str, usize, usize); 11] = [
        (
            "camera_images",
            MAX_CAMERAS.saturating_mul(dims.image_bytes()),
            layout::CAMERA_IMAGES_BYTES,
        ),
        (
            "value_features",
            f32s(MAX_CAMERAS.saturating_mul(dims.value_len())),
            layout::VALUE_FEATURES_BYTES,
        ),
        (
            "gkt_lut",
            crate::gkt::Lut::capacity_bytes(dims),
            layout::GKT_LUT_BYTES,
        ),
        ("bev_query", f32s(dims.bev_len()), layout::BEV_QUERY_BYTES),
        (
            "gkt_weights",
            f32s(dims.weights_len()),
            layout::GKT_WEIGHTS_BYTES,
        ),
        ("gathered", f32s(dims.bev_len()), layout::GATHERED_BYTES),
        ("camera_bev", f32s(dims.bev_len()), layout::CAMERA_BEV_BYTES),
        (
            "satellite_crop",
            dims.crop_bytes(),
            layout::SATELLITE_CROP_BYTES,
        ),
        (
            "satellite_bev",
            f32s(dims.bev_len()),
            layout::SATELLITE_BEV_BYTES,
        ),
        (
            "class_logits",
            f32s(dims.logits_len()),
            layout::CLASS_LOGITS_BYTES,
        ),
        ("points", f32s(dims.points_len()), layout::POINTS_BYTES),
    ];
    for (region, needed_bytes, capacity_bytes) in regions {
        if needed_bytes > capacity_bytes {
            return Err(InitError::RegionTooSmall {
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
            Err(InitError::RegionTooSmall {
                region: "camera_images",
                needed_bytes: 6 * 640 * 360 * 3,
                capacity_bytes: layout::CAMERA_IMAGES_BYTES,
            })
        );
        let mut dims = ModelDims::test_config();
        dims.embed_dims = 512;
        assert!(matches!(
            check_regions(&dims),
            Err(InitError::RegionTooSmall {
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
