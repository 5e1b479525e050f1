//! The BEV feature maps in f16 storage over the engine double: the stored values are the f32
//! run's rounded once (bit for bit), a step still allocates nothing, a BEV beyond half's range is
//! refused, and a storage that does not fit the layout's regions is refused by region.

use alloc::vec::Vec;

use half::f16;

use super::*;
use crate::buffers::MemoryError;
use crate::capacity::layout;
use crate::engine::Engine;
use crate::features::{FeaturesMut, FeaturesRef};
use crate::placement::{REGIONS, RuntimeRegions};
use crate::satellite::FixedCrop;
use crate::test_support::{FakeEngine, Images, count_allocations, crop, nuscenes_like};

fn runtime(
    crop: &[u8],
    bev: FeatureStorage,
) -> Result<SatMap<FakeEngine, FixedCrop<'_>>, InitError> {
    SatMap::with_bev_storage(
        FakeEngine::new(ModelDims::test_config()),
        &nuscenes_like(),
        FixedCrop(crop),
        FrameLimits::DEFAULT,
        bev,
    )
}

fn bits(bev: FeaturesRef<'_>) -> Vec<u16> {
    bev.iter().map(|v| f16::from_f32(v).to_bits()).collect()
}

fn rounded(wide: &[f32]) -> Vec<u16> {
    bits(FeaturesRef::F32(wide))
}

#[test]
fn f16_storage_holds_the_f32_outputs_rounded_once_and_steps_without_allocating() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 8);
    let mut half = runtime(&c, FeatureStorage::F16).unwrap();
    assert_eq!(half.buffers().bev_storage(), FeatureStorage::F16);
    let frames: Vec<_> = (1..=3).map(|s| images.frame(s)).collect();
    let (maps, allocations) = count_allocations(|| {
        frames
            .iter()
            .map(|f| half.step(f).map(|m| m.digest))
            .collect::<heapless::Vec<_, 3>>()
    });
    // The one heapless vector of results lives on the stack: the steps allocated nothing.
    assert_eq!(allocations, 0);
    assert!(maps.iter().all(Result::is_ok));
    // The f32 outputs of the same stage inputs (storage-independent buffers of the last step),
    // from the same deterministic engine.
    let b = half.buffers();
    let mut engine = FakeEngine::new(dims.clone());
    let mut camera = alloc::vec![0f32; dims.bev_len()];
    let mut satellite = alloc::vec![0f32; dims.bev_len()];
    engine
        .bev_encode(b.query(), b.gathered(), FeaturesMut::F32(&mut camera))
        .unwrap();
    engine
        .encode_satellite(b.crop(), FeaturesMut::F32(&mut satellite))
        .unwrap();
    assert_eq!(bits(b.camera_bev()), rounded(&camera));
    assert_eq!(bits(b.satellite_bev()), rounded(&satellite));
    // The rounding is visible (the double's BEV is not made of halves already) and within half
    // an f16 ulp: |w| 2^-11 for normal halves, 2^-25 below them (subnormal spacing 2^-24).
    assert!(b.camera_bev().iter().zip(&camera).any(|(h, &w)| h != w));
    let worst = b
        .camera_bev()
        .iter()
        .zip(&camera)
        .map(|(h, &w)| (h - w).abs() - (w.abs() * 2f32.powi(-11)).max(2f32.powi(-25)))
        .fold(f32::NEG_INFINITY, f32::max);
    assert!(worst <= 0.0, "rounding beyond half an ulp by {worst}");
    // A runtime in f32 storage publishes from the unrounded BEVs: the same buffers, the f32
    // bits. (The test model's BEVs, D = 32, fit in f32 even where the layout gives nano's f16.)
    let mut wide = runtime(&c, FeatureStorage::F32).unwrap();
    for f in &frames {
        wide.step(f).unwrap();
    }
    assert_eq!(
        wide.buffers().camera_bev().iter().collect::<Vec<_>>(),
        camera
    );
}

#[test]
fn a_bev_beyond_half_range_is_a_non_finite_output_in_f16_and_passes_in_f32() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 8);
    let mut half = runtime(&c, FeatureStorage::F16).unwrap();
    half.engine_mut().bev_gain = 1e6;
    assert_eq!(
        half.step(&images.frame(1)).map(|m| m.digest),
        Err(StepError::NonFiniteOutput {
            slice: StepSlice::BevEncoder
        })
    );
    // The runtime stays usable: the next frame in range steps.
    half.engine_mut().bev_gain = 1.0;
    assert!(half.step(&images.frame(2)).is_ok());
    let mut wide = runtime(&c, FeatureStorage::F32).unwrap();
    wide.engine_mut().bev_gain = 1e6;
    assert!(wide.step(&images.frame(1)).is_ok());
}

#[test]
fn storage_is_checked_against_the_layout_regions() {
    let c = crop(&ModelDims::test_config());
    // The layout's own storage always fits the test model; f16 fits any layout f32 fits.
    assert!(runtime(&c, FeatureStorage::LAYOUT).is_ok());
    assert!(runtime(&c, FeatureStorage::F16).is_ok());
    // A layout whose BEV regions hold exactly the f16 maps (every other region roomy): f16
    // fits, f32 is refused naming the first BEV region with both sizes.
    let dims = ModelDims::test_config();
    let half_bytes = dims.bev_len() * 2;
    let capacity = |region: &str| {
        Some(if region.ends_with("_bev") {
            half_bytes
        } else {
            usize::MAX
        })
    };
    assert_eq!(
        crate::regions::check_regions_with(&dims, FeatureStorage::F16, capacity),
        Ok(())
    );
    assert_eq!(
        crate::regions::check_regions_with(&dims, FeatureStorage::F32, capacity),
        Err(MemoryError::RegionTooSmall {
            region: "camera_bev",
            needed_bytes: 2 * half_bytes,
            capacity_bytes: half_bytes,
        })
    );
    // The built-in layout's BEV regions are at least the f16 maps of the layout's config.
    assert!(layout::CAMERA_BEV_BYTES >= half_bytes && layout::SATELLITE_BEV_BYTES >= half_bytes);
}

/// `len` zeroed bytes at a `REGION_ALIGN` boundary, leaked (standing in for a linker script's
/// static section).
fn region(len: usize) -> &'static mut [u8] {
    use crate::placement::REGION_ALIGN;
    let v: &'static mut [u8] = Vec::leak(alloc::vec![0u8; len + REGION_ALIGN]);
    let skip = v.as_ptr().align_offset(REGION_ALIGN);
    &mut v[skip..skip + len]
}

/// Every region at its layout size, `camera_bev` `short_bytes` shorter.
fn layout_regions(short_bytes: usize) -> RuntimeRegions {
    let r = |name: &str| {
        let bytes = REGIONS
            .iter()
            .find(|s| s.name == name)
            .map_or(0, |s| s.bytes);
        region(if name == "camera_bev" {
            bytes - short_bytes
        } else {
            bytes
        })
    };
    RuntimeRegions {
        value_features: r("value_features"),
        gkt_lut: r("gkt_lut"),
        bev_query: r("bev_query"),
        gkt_weights: r("gkt_weights"),
        gathered: r("gathered"),
        camera_bev: r("camera_bev"),
        satellite_crop: r("satellite_crop"),
        satellite_bev: r("satellite_bev"),
        class_logits: r("class_logits"),
        points: r("points"),
    }
}

#[test]
fn placed_regions_hold_the_bevs_in_the_layout_storage_and_step_like_the_heap() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 8);
    let mut placed = SatMap::in_regions(
        FakeEngine::new(dims.clone()),
        &nuscenes_like(),
        FixedCrop(&c),
        FrameLimits::DEFAULT,
        layout_regions(0),
    )
    .unwrap();
    assert_eq!(placed.buffers().bev_storage(), FeatureStorage::LAYOUT);
    let mut heap = runtime(&c, FeatureStorage::LAYOUT).unwrap();
    for s in 1..=3 {
        let f = images.frame(s);
        assert_eq!(placed.step(&f).unwrap(), heap.step(&f).unwrap());
    }
    assert_eq!(
        bits(placed.buffers().camera_bev()),
        bits(heap.buffers().camera_bev())
    );
    // A BEV region one element short of the layout's storage is refused by name.
    let refused = SatMap::in_regions(
        FakeEngine::new(dims),
        &nuscenes_like(),
        FixedCrop(&c),
        FrameLimits::DEFAULT,
        layout_regions(FeatureStorage::LAYOUT.elem_bytes()),
    );
    assert!(matches!(
        refused.err(),
        Some(InitError::Memory(MemoryError::RegionTooSmall {
            region: "camera_bev",
            ..
        }))
    ));
}
