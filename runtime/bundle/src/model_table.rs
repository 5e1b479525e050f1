//! The `[model]` table of `manifest.toml` exactly as the manifest spells it (class and camera
//! names, `gkt_kernel` as a pair), converted into [`ModelDims`]. The numbers are range-checked
//! after parsing (`ModelDims::validate`, called by `Bundle::open`), so a TOML error and a value
//! out of range are told apart.

use satmap_core::calibration::CAMERA_NAMES;
use satmap_core::capacity::NUM_HEADS;
use satmap_core::model_dims::{CLASS_NAMES, ModelDims};

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

/// `[model]` as [`ModelDims`]: the table, then its conversion (serde's `deserialize_with` on
/// the manifest's `model` field; the core's `ModelDims` knows nothing of serde or bundles).
pub(super) fn deserialize_dims<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> Result<ModelDims, D::Error> {
    let table = <ModelTable as serde::Deserialize>::deserialize(deserializer)?;
    ModelDims::try_from(table).map_err(serde::de::Error::custom)
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
        if t.cameras.iter().map(String::as_str).ne(CAMERA_NAMES) {
            return Err(format!(
                "cameras {:?} differ from {CAMERA_NAMES:?}",
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

#[cfg(test)]
mod tests {
    use super::*;
    use satmap_core::model_dims::DimsError;

    /// A `[model]` table's text as the manifest's `model` field reads it.
    fn parse(text: &str) -> Result<ModelDims, toml::de::Error> {
        #[derive(serde::Deserialize)]
        struct Holder {
            #[serde(deserialize_with = "deserialize_dims")]
            model: ModelDims,
        }
        toml::from_str::<Holder>(&format!("[model]\n{text}")).map(|h| h.model)
    }

    #[test]
    fn deserialises_the_manifest_model_table() {
        let text = r#"
config = "test"
embed_dims = 32
bev_h = 80
bev_w = 40
pc_range_m = [-15.0, -30.0, -2.0, 15.0, 30.0, 2.0]
classes = ["divider", "ped_crossing", "boundary"]
num_vec = 50
num_pts = 20
top_k = 50
cameras = ["CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_FRONT_LEFT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT"]
image_scale = 0.2
image_h = 180
image_w = 320
pad_h = 192
pad_w = 320
feat_h = 6
feat_w = 10
gkt_heights_m = [-1.5, -0.5, 0.5, 1.5]
gkt_kernel = [3, 5]
sat_h = 200
sat_w = 100
sat_gsd_m = 0.3
"#;
        let dims = parse(text).unwrap();
        assert_eq!(dims, ModelDims::test_config());
        let bad = text.replace("\"boundary\"", "\"kerb\"");
        assert!(parse(&bad).is_err());
        // Parsing does not range-check; `validate` (run by `Bundle::open`) does.
        let bad = text.replace("top_k = 50", "top_k = 60");
        let parsed = parse(&bad).unwrap();
        assert_eq!(
            parsed.validate(),
            Err(DimsError::TopKTooLarge { top_k: 60, max: 50 })
        );
    }
}
