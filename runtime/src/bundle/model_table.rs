//! The `[model]` table of `manifest.toml` exactly as the manifest spells it (class and camera
//! names, `gkt_kernel` as a pair), converted into [`ModelDims`]. The numbers are range-checked
//! after parsing (`ModelDims::validate`, called by `Bundle::open`), so a TOML error and a value
//! out of range are told apart.

use crate::capacity::NUM_HEADS;
use crate::model_dims::{CLASS_NAMES, MANIFEST_CAMERAS, ModelDims};

/// Raw `[model]` table (see `ARCHITECTURE.md`, "Bundle"); only serde builds it.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelTable {
    #[allow(
        dead_code,
        reason = "the config name is informative; shapes carry the meaning"
    )]
    config: Option<String>,
    embed_dims: usize,
    bev_h: usize,
    bev_w: usize,
    pc_range_m: [f32; 6],
    classes: Vec<String>,
    num_vec: usize,
    num_pts: usize,
    top_k: usize,
    cameras: Vec<String>,
    image_scale: f64,
    image_h: usize,
    image_w: usize,
    pad_h: usize,
    pad_w: usize,
    feat_h: usize,
    feat_w: usize,
    gkt_heights_m: [f32; NUM_HEADS],
    gkt_kernel: [usize; 2],
    sat_h: usize,
    sat_w: usize,
    sat_gsd_m: f64,
}

impl TryFrom<ModelTable> for ModelDims {
    type Error = String;

    fn try_from(t: ModelTable) -> Result<Self, Self::Error> {
        if t.classes.iter().map(String::as_str).ne(CLASS_NAMES) {
            return Err(format!(
                "classes {:?} differ from {CLASS_NAMES:?}",
                t.classes
            ));
        }
        if t.cameras.iter().map(String::as_str).ne(MANIFEST_CAMERAS) {
            return Err(format!(
                "cameras {:?} differ from {MANIFEST_CAMERAS:?}",
                t.cameras
            ));
        }
        Ok(ModelDims {
            embed_dims: t.embed_dims,
            bev_h: t.bev_h,
            bev_w: t.bev_w,
            pc_range_m: t.pc_range_m,
            num_vec: t.num_vec,
            num_pts: t.num_pts,
            top_k: t.top_k,
            image_h: t.image_h,
            image_w: t.image_w,
            pad_h: t.pad_h,
            pad_w: t.pad_w,
            image_scale: t.image_scale,
            feat_h: t.feat_h,
            feat_w: t.feat_w,
            gkt_heights_m: t.gkt_heights_m,
            kernel_h: t.gkt_kernel[0],
            kernel_w: t.gkt_kernel[1],
            sat_h: t.sat_h,
            sat_w: t.sat_w,
            sat_gsd_m: t.sat_gsd_m,
        })
    }
}
