//! The calibration TOML harness: `from_toml_str`, then the projection matrices and the LUT the
//! runtime builds from a calibration the loader accepts.

use proptest::prelude::*;
use satmap_runtime::calibration::from_toml_str;
use satmap_runtime::gkt::Lut;
use satmap_runtime::model_dims::ModelDims;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};
use crate::seeds::{CALIBRATION_TOML, test_dims};

fn calibration_case(input: &Input, dims: &ModelDims) -> CaseResult {
    let Ok(calibration) = from_toml_str(&input.text()) else {
        return Ok(Refused);
    };
    prop_assert!(calibration.is_valid());
    // A calibration the loader accepts is one the runtime builds its table from (`recalibrate`).
    prop_assert!(
        calibration
            .lidar2img(dims.image_scale)
            .iter()
            .all(|m| m.is_finite())
    );
    let lut = Lut::new(dims, &calibration);
    prop_assert!(
        lut.is_ok(),
        "loaded calibration refused by the LUT: {:?}",
        lut.err()
    );
    Ok(Accepted)
}

#[test]
fn calibration_never_panics() {
    let dims = test_dims();
    let seeds = vec![CALIBRATION_TOML.as_bytes().to_vec()];
    let body = |input: &Input| calibration_case(input, &dims);
    assert_seeds_accepted(&seeds, body);
    fuzz("calibration", inputs(seeds, true), body);
}
