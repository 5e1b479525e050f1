//! One memory layout per product variant: `memory_layout.toml` (the default build, sized for
//! `nano`) and every `layouts/<config>.toml` (built with `SATMAP_LAYOUT=layouts/<config>.toml`).
//! Runs under the default build without a bundle: each variant file passes satmap-layout's
//! checks, keeps the default's region names, leaves the regions the runtime checks at compile
//! time untouched, and its capacities accept its config's dimensions with the same check
//! `SatMap::new` runs (`regions::check_regions_with`). `make test-paper` builds the `paper`
//! layout and drives the paper bundle through it.

use std::path::{Path, PathBuf};

use satmap_layout::MemoryLayout;
use satmap_runtime::capacity::layout;
use satmap_runtime::model_dims::ModelDims;
use satmap_runtime::regions::{MODEL_REGIONS, check_regions, check_regions_with, region_needs};
use satmap_runtime::{FeatureStorage, MemoryError};

/// Regions whose size does not depend on the model: the runtime asserts them against its own
/// types at compile time (`regions.rs`, `route_pack`), so every variant must keep them.
const FIXED_REGIONS: [&str; 5] = [
    "can_bus",
    "map_frame",
    "tile_cache",
    "tile_pixels",
    "route_pack",
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn parse(path: &Path) -> MemoryLayout {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    MemoryLayout::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The storage `map` gives the BEV feature maps.
fn bev_storage(map: &MemoryLayout) -> FeatureStorage {
    let dtype = map.region("camera_bev").unwrap().dtype;
    FeatureStorage::from_name(dtype.name()).unwrap()
}

fn fits(dims: &ModelDims, map: &MemoryLayout) -> Result<(), MemoryError> {
    check_regions_with(dims, bev_storage(map), |name| {
        map.region(name).map(|r| r.bytes)
    })
}

/// Every `layouts/*.toml`, by file stem.
fn variants() -> Vec<(String, MemoryLayout)> {
    let mut out: Vec<_> = std::fs::read_dir(root().join("layouts"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| {
            let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
            (stem, parse(&p))
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn every_variant_layout_parses_and_keeps_the_default_regions() {
    let default = parse(&root().join("memory_layout.toml"));
    let variants = variants();
    assert!(
        variants.iter().any(|(name, _)| name == "paper"),
        "layouts/paper.toml is missing"
    );
    for (name, map) in &variants {
        // `<config>.toml`, or `<config>-<option>.toml` for a variant of a config's layout.
        assert!(
            *name == map.sized_for || name.starts_with(&format!("{}-", map.sized_for)),
            "layouts/{name}.toml: sized_for {}",
            map.sized_for
        );
        assert!(
            map.region.keys().eq(default.region.keys()),
            "layouts/{name}.toml: region names differ from memory_layout.toml"
        );
        for region in FIXED_REGIONS {
            assert_eq!(
                map.region(region),
                default.region(region),
                "layouts/{name}.toml: region `{region}` must equal memory_layout.toml's"
            );
        }
        assert!(
            map.budgets.peak_bytes <= map.arena.bytes,
            "layouts/{name}.toml: peak budget above the arena"
        );
    }
}

#[test]
fn paper_layout_is_sized_for_the_paper_dims() {
    let paper = parse(&root().join("layouts/paper.toml"));
    let dims = ModelDims::paper_config();
    assert_eq!(dims.validate(), Ok(()));
    assert_eq!(fits(&dims, &paper), Ok(()));
    // Sized for the paper, not merely large enough: each model region is exactly what it needs.
    for (region, needed) in region_needs(&dims, FeatureStorage::F32) {
        assert_eq!(
            paper.region(region).unwrap().bytes,
            needed,
            "layouts/paper.toml: region `{region}`"
        );
    }
    // The small `test` model fits the paper layout too; `nano` (100 instance queries) does not.
    assert_eq!(fits(&ModelDims::test_config(), &paper), Ok(()));
    let mut nano = ModelDims::paper_config();
    nano.num_vec = 100;
    assert!(matches!(
        fits(&nano, &paper),
        Err(MemoryError::RegionTooSmall {
            region: "class_logits",
            needed_bytes: 1200,
            capacity_bytes: 600
        })
    ));
}

#[test]
fn the_f16_bev_layout_is_the_default_with_both_bevs_halved() {
    let default = parse(&root().join("memory_layout.toml"));
    let half = parse(&root().join("layouts/nano-f16-bev.toml"));
    assert_eq!(bev_storage(&default), FeatureStorage::F32);
    assert_eq!(bev_storage(&half), FeatureStorage::F16);
    for (name, region) in &half.region {
        let wide = default.region(name).unwrap();
        if name.ends_with("_bev") {
            assert_eq!(region.shape, wide.shape, "{name}");
            assert_eq!(region.bytes * 2, wide.bytes, "{name}");
        } else {
            assert_eq!(region, wide, "{name}");
        }
    }
    assert_eq!(
        default.runtime_bytes() - half.runtime_bytes(),
        2 * 80 * 40 * 256 * 2
    );
    // Sized for nano: nano's dims fit in f16 storage; in f32 the BEVs overflow, by region.
    let mut nano = ModelDims::test_config();
    nano.embed_dims = 256;
    nano.num_vec = 100;
    assert_eq!(fits(&nano, &half), Ok(()));
    assert_eq!(
        check_regions_with(&nano, FeatureStorage::F32, |name| half
            .region(name)
            .map(|r| r.bytes)),
        Err(MemoryError::RegionTooSmall {
            region: "camera_bev",
            needed_bytes: 80 * 40 * 256 * 4,
            capacity_bytes: 80 * 40 * 256 * 2,
        })
    );
}

#[test]
fn default_layout_refuses_the_paper_dims_by_region() {
    let default = parse(&root().join("memory_layout.toml"));
    assert_eq!(
        fits(&ModelDims::paper_config(), &default),
        Err(MemoryError::RegionTooSmall {
            region: "camera_images",
            needed_bytes: 6 * 450 * 800 * 3,
            capacity_bytes: 6 * 180 * 320 * 3,
        })
    );
}

#[test]
fn built_in_constants_are_the_built_in_layout_file() {
    // What build.rs generated is what `layout::SOURCE_TOML` says, whichever file was chosen.
    let built_in = MemoryLayout::parse(layout::SOURCE_TOML).unwrap();
    assert_eq!(built_in.sized_for, layout::SIZED_FOR);
    assert_eq!(built_in.arena.bytes, layout::ARENA_BYTES);
    assert_eq!(built_in.budgets.peak_bytes, layout::PEAK_BUDGET_BYTES);
    let on_disk = std::fs::read_to_string(root().join(layout::SOURCE_PATH)).unwrap();
    assert_eq!(on_disk, layout::SOURCE_TOML, "{}", layout::SOURCE_PATH);
    for dims in [ModelDims::test_config(), ModelDims::paper_config()] {
        assert_eq!(check_regions(&dims), fits(&dims, &built_in));
    }
    assert_eq!(bev_storage(&built_in), FeatureStorage::LAYOUT);
    for (i, (region, _)) in region_needs(&ModelDims::test_config(), FeatureStorage::LAYOUT)
        .iter()
        .enumerate()
    {
        assert_eq!(*region, MODEL_REGIONS[i]);
        assert!(built_in.region(region).is_some(), "{region}");
    }
}
