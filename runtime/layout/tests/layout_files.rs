//! The repository's `memory_layout.toml` parses, and each bad fixture in `tests/layouts/` fails
//! with the `LayoutError` its name announces.

use std::path::PathBuf;

use satmap_layout::{LayoutError, MemoryLayout};

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(repo_root().join(rel)).unwrap()
}

#[test]
fn repository_layout_parses_and_fits() {
    let layout = MemoryLayout::parse(&read("memory_layout.toml")).unwrap();
    assert_eq!(layout.sized_for, "nano");
    // Spot-check capacities against the nano dimensions (D = 256, Q = 3200, F = 60).
    assert_eq!(layout.region("bev_query").unwrap().bytes, 3200 * 256 * 4);
    assert_eq!(
        layout.region("value_features").unwrap().bytes,
        6 * 60 * 256 * 4
    );
    assert_eq!(
        layout.region("gkt_lut").unwrap().bytes,
        6 * 3200 * 2 * (1 + 4 * 15) + 3200
    );
    assert!(layout.runtime_bytes() + layout.arena.graph_engine_bytes <= layout.arena.bytes);
    let consts = layout.to_rust_consts();
    assert!(consts.contains("pub const BEV_QUERY_BYTES: usize = 3276800;"));
    assert!(consts.contains("pub const GKT_LUT_ELEM_BYTES: usize = 733;"));
    assert!(consts.contains("pub const CAMERA_BEV_DTYPE: &str = \"f32\";"));
    let half = MemoryLayout::parse(&read("layouts/nano-f16-bev.toml")).unwrap();
    let half_consts = half.to_rust_consts();
    assert!(half_consts.contains("pub const CAMERA_BEV_DTYPE: &str = \"f16\";"));
    assert!(half_consts.contains("pub const SATELLITE_BEV_BYTES: usize = 1638400;"));
    assert!(consts.contains("pub const STEP_BUDGET_US: u64 ="));
    let map = layout.render_map();
    for name in satmap_layout::REQUIRED_REGIONS {
        assert!(map.contains(name), "map lacks {name}");
    }
    assert!(map.contains("headroom"));
}

/// A fixture name and the check its error must pass.
type Case = (&'static str, fn(&LayoutError) -> bool);

#[test]
fn each_bad_fixture_fails_with_its_error() {
    let cases: [Case; 12] = [
        ("bad_bytes", |e| {
            matches!(e, LayoutError::Bytes { region, declared: 368_000, computed: 368_640, .. }
                if region == "value_features")
        }),
        ("bad_missing_region", |e| {
            matches!(e, LayoutError::MissingRegion("gathered"))
        }),
        ("bad_missing_budget", |e| {
            matches!(e, LayoutError::MissingBudget("gkt_gather"))
        }),
        ("bad_arena_too_small", |e| {
            matches!(
                e,
                LayoutError::ArenaTooSmall {
                    graph: 805_306_368,
                    arena: 805_306_368,
                    ..
                }
            )
        }),
        (
            "bad_parse",
            |e| matches!(e, LayoutError::Parse(m) if m.contains("f31")),
        ),
        (
            "bad_unknown_field",
            |e| matches!(e, LayoutError::Parse(m) if m.contains("size_for")),
        ),
        (
            "bad_record_without_elem_bytes",
            |e| matches!(e, LayoutError::ElemBytes(r) if r == "tile_cache"),
        ),
        ("bad_feature_dtype", |e| {
            matches!(
                e,
                LayoutError::FeatureDtype {
                    region: "satellite_bev",
                    dtype: "u32"
                }
            )
        }),
        ("bad_feature_dtypes_differ", |e| {
            matches!(
                e,
                LayoutError::FeatureDtypesDiffer {
                    camera_bev: "f16",
                    satellite_bev: "f32"
                }
            )
        }),
        ("bad_zero_step_period", |e| {
            matches!(e, LayoutError::ZeroStepPeriod)
        }),
        ("bad_zero_step_scratch", |e| {
            matches!(e, LayoutError::ZeroStepScratch)
        }),
        ("bad_peak_above_arena", |e| {
            matches!(
                e,
                LayoutError::PeakAboveArena {
                    peak: 905_306_368,
                    arena: 805_306_368
                }
            )
        }),
    ];
    let dir = repo_root().join("tests/layouts");
    let on_disk = std::fs::read_dir(&dir).unwrap().count();
    assert_eq!(
        on_disk,
        cases.len(),
        "every fixture in tests/layouts/ needs a case here"
    );
    for (name, expected) in cases {
        let text = read(&format!("tests/layouts/{name}.toml"));
        let err = MemoryLayout::parse(&text).unwrap_err();
        assert!(expected(&err), "{name}: got {err:?}");
        assert!(
            err.to_string().starts_with("ERROR(layout):"),
            "{name}: {err}"
        );
    }
}

#[test]
fn region_sizes_that_sum_past_usize_are_an_arena_error_not_an_overflow() {
    // Four runtime regions of 2^62 bytes each (f32 x 2^60, consistent with their shapes):
    // their sum is 2^64, one past usize::MAX on a 64-bit host.
    let mut text = read("memory_layout.toml");
    for shape in [
        "shape = [18]\ndtype = \"f32\"\nbytes = 72",
        "shape = [6, 60, 256]\ndtype = \"f32\"\nbytes = 368640",
        "shape = [3200, 4, 15]\ndtype = \"f32\"\nbytes = 768000",
        "shape = [100, 20, 2]\ndtype = \"f32\"\nbytes = 16000",
    ] {
        assert!(text.contains(shape), "fixture drifted: {shape}");
        text = text.replace(
            shape,
            "shape = [1152921504606846976]\ndtype = \"f32\"\nbytes = 4611686018427387904",
        );
    }
    let err = MemoryLayout::parse(&text).unwrap_err();
    assert!(
        matches!(err, LayoutError::ArenaTooSmall { regions, .. } if regions == usize::MAX),
        "{err}"
    );
}
