//! The Rust GKT look-up table and native gather-sum against the Python reference
//! (`models/golden/test/lut.safetensors`, `frame_*.safetensors`).
//!
//! Tolerances: the LUT and the projection matrices must be equal element for element; the
//! gather-sum must be bit-identical (same operations in the same order as
//! `satmap_ref.gkt.gather_sum`).

use satmap_ecu_tests::golden::{Golden, GoldenFrame, calibration, compiled_path};
use satmap_runtime::bundle::{Bundle, Precision};
use satmap_runtime::gkt::kernel::gather_sum;
use satmap_runtime::gkt::lut::Lut;

fn lut() -> Lut {
    let bundle = Bundle::open(compiled_path(Precision::F32)).unwrap();
    Lut::new(bundle.dims(), &calibration()).unwrap()
}

#[test]
fn lidar2img_equals_python_bit_for_bit() {
    let dense = lut().to_dense();
    let golden = Golden::load("lut.safetensors").f32s("lidar2img");
    assert_eq!(dense.lidar2img.len(), golden.len());
    for (i, (a, b)) in dense.lidar2img.iter().zip(&golden).enumerate() {
        assert_eq!(
            a.to_bits(),
            b.to_bits(),
            "lidar2img element {i}: {a} vs {b}"
        );
    }
}

#[test]
fn lut_equals_python_element_for_element() {
    let dense = lut().to_dense();
    let golden = Golden::load("lut.safetensors");
    assert_eq!(dense.mask, golden.bytes("mask"), "participation mask");
    assert_eq!(dense.count, golden.i32s("count"), "camera counts");
    let index = golden.i32s("index");
    assert_eq!(dense.index.len(), index.len());
    let mismatches = dense
        .index
        .iter()
        .zip(&index)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(mismatches, 0, "{mismatches} LUT indices differ");
    // The rig overlaps: some queries see two cameras, none sees none in the front half.
    assert!(dense.count.iter().any(|&c| c >= 2));
}

#[test]
fn native_gather_sum_is_bit_identical_to_reference() {
    let lut = lut();
    for index in 0..2 {
        let f = GoldenFrame::load(index);
        let value = f.golden.f32s("value");
        let weights = f.golden.f32s("gkt_weights");
        let want = f.golden.f32s("gathered");
        let mut got = vec![f32::NAN; want.len()];
        gather_sum(
            &lut,
            &value,
            &weights,
            &mut got,
            satmap_runtime::CameraMask::ALL,
        )
        .unwrap();
        let differing = got
            .iter()
            .zip(&want)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differing, 0,
            "frame {index}: {differing} gathered values differ"
        );
    }
}

#[test]
fn recalibrate_rebuilds_the_same_table() {
    let mut lut = lut();
    let before = lut.to_dense();
    let mut moved = calibration();
    moved.cameras[0].translation_m.x += 0.5;
    lut.rebuild(&moved).unwrap();
    assert_ne!(
        lut.to_dense().index,
        before.index,
        "a moved camera changes the table"
    );
    lut.rebuild(&calibration()).unwrap();
    assert_eq!(lut.to_dense(), before);
}
