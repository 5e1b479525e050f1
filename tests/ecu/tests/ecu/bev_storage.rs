//! The BEV feature maps stored as f16 (`SatMap::with_bev_storage`, the storage of
//! `layouts/nano-f16-bev.toml`) over the compiled f32 `test` bundle, against the reference on
//! both golden frames. What f16 storage changes is one rounding of each BEV value: the stored
//! BEVs are the f32 runtime's rounded to nearest half bit for bit (exact, on every target), and
//! within the reference's 1e-4 plus that rounding (half an f16 ulp, |v| 2^-11); the decoder, fed
//! the rounded BEVs, moves the logits and points by at most the bounds below (measured on x86
//! and on qemu's Cortex-A76, then doubled); the decoded map keeps its elements and classes.

use half::f16;
use satmap_ecu_tests::golden::{GoldenFrame, calibration, compiled_engine, max_abs_diff};
use satmap_ecu_tests::parity::STAGE_TOL;
use satmap_runtime::engine_tract::{TractEngine, kernel_family};
use satmap_runtime::frame::FrameLimits;
use satmap_runtime::satellite::FixedCrop;
use satmap_runtime::{FeatureStorage, FeaturesRef, MapFrame, SatMap};

/// Class logits with f16 BEVs against the reference, max abs: measured 1.605e-3 on x86
/// (`intel-avx512f`) and 1.614e-3 on qemu's Cortex-A76 (`aarch64-neon`), doubled.
const LOGITS_TOL: f32 = 3.3e-3;
/// Normalised points with f16 BEVs against the reference, max abs: measured 3.539e-4 (x86) and
/// 3.543e-4 (A76), doubled (7.1e-4 of the BEV range: 2 cm across 30 m).
const POINTS_TOL: f32 = 7.1e-4;

type Runtime<'a> = SatMap<TractEngine, FixedCrop<'a>>;

fn stepped(f: &GoldenFrame, bev: FeatureStorage) -> (Runtime<'_>, MapFrame) {
    let mut map = SatMap::with_bev_storage(
        compiled_engine(),
        &calibration(),
        FixedCrop(&f.satellite),
        FrameLimits::DEFAULT,
        bev,
    )
    .unwrap();
    let (w, h) = (map.dims().image_w as u32, map.dims().image_h as u32);
    let out = map.step(&f.frame(1, w, h)).unwrap().clone();
    (map, out)
}

fn half_bits(bev: FeaturesRef<'_>) -> Vec<u16> {
    match bev {
        FeaturesRef::F16(s) => s.iter().map(|v| v.to_bits()).collect(),
        FeaturesRef::F32(_) => panic!("asked for f16 storage"),
    }
}

/// Largest excess of |got - want| over `STAGE_TOL + |want| 2^-11` (<= 0: within).
fn excess_over_rounding(got: &[f32], want: &[f32]) -> f32 {
    got.iter()
        .zip(want)
        .map(|(g, w)| (g - w).abs() - (STAGE_TOL + w.abs() * 2f32.powi(-11)))
        .fold(f32::NEG_INFINITY, f32::max)
}

#[test]
fn f16_bevs_are_the_f32_bevs_rounded_and_the_maps_stay_within_bounds() {
    println!("kernel family {}", kernel_family());
    for index in 0..2 {
        let f = GoldenFrame::load(index);
        let g = &f.golden;
        let (half, half_map) = stepped(&f, FeatureStorage::F16);
        let b = half.buffers();
        assert_eq!(b.bev_storage(), FeatureStorage::F16);
        for (name, stored) in [
            ("camera_bev", b.camera_bev()),
            ("satellite_bev", b.satellite_bev()),
        ] {
            let wide: Vec<f32> = stored.iter().collect();
            let e = excess_over_rounding(&wide, &g.f32s(name));
            println!("frame {index} {name}: excess over 1e-4 + half an f16 ulp {e:.2e}");
            assert!(e <= 0.0, "frame {index} {name}: {e:e} beyond the tolerance");
        }
        let logits = max_abs_diff(b.logits(), &g.f32s("class_logits"));
        let points = max_abs_diff(b.points(), &g.f32s("points"));
        println!("frame {index}: logits {logits:.3e}, points {points:.3e} from the reference");
        assert!(logits <= LOGITS_TOL, "frame {index} logits {logits:e}");
        assert!(points <= POINTS_TOL, "frame {index} points {points:e}");
        // The same engine in f32 storage (the `test` model's BEVs fit f32 in either layout)
        // gives the f32 bits, and f16 storage holds exactly their rounding.
        let (wide, wide_map) = stepped(&f, FeatureStorage::F32);
        let w = wide.buffers();
        for (name, h, full) in [
            ("camera_bev", b.camera_bev(), w.camera_bev()),
            ("satellite_bev", b.satellite_bev(), w.satellite_bev()),
        ] {
            let rounded: Vec<u16> = full.iter().map(|v| f16::from_f32(v).to_bits()).collect();
            assert!(
                half_bits(h) == rounded,
                "frame {index} {name}: not the rounding"
            );
        }
        assert_eq!(half_map.elements.len(), wide_map.elements.len());
        for (a, c) in half_map.elements.iter().zip(&wide_map.elements) {
            assert_eq!((a.class, a.instance), (c.class, c.instance));
        }
    }
}
