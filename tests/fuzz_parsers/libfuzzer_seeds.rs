//! The committed seed corpora of the `cargo fuzz` targets (`fuzz/seeds/<target>/`), made here
//! by the same writers and fixtures the proptest harnesses use, and checked against what they
//! make now: a format change that leaves the seeds stale fails this test.
//! `SATMAP_BLESS=1 cargo test --test fuzz_parsers libfuzzer_seeds` rewrites them.
//!
//! Every seed is deterministic on every machine: no float the graph engine computes goes into
//! one (the map frame is built by hand).

use std::path::{Path, PathBuf};

use satmap_runtime::bundle::Bundle;
use satmap_runtime::engine::Stage;
use satmap_runtime::glam::Vec2;
use satmap_runtime::map_frame::{digest, wire};
use satmap_runtime::{CameraState, Health, MapClass, MapElement, MapFrame, SatellitePrior};
use satmap_sim::route_pack_builder::{build_pack, parse_route_geojson};

use crate::compiled_bundle::{reseal, seed_manifest};
use crate::seeds::{BoxImagery, MANIFEST_TOML, pack_options, seed_route_geojson};
use crate::signed_bundle::signed_seed;

fn committed_bundle() -> Bundle {
    Bundle::open(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/bundles/test.satmap"
    ))
    .unwrap()
}

/// `graph.nnef` of a stage tar.
fn graph_text(stage_tar: &[u8]) -> Vec<u8> {
    use std::io::Read as _;
    let mut archive = tar::Archive::new(stage_tar);
    for entry in archive.entries().unwrap() {
        let mut entry = entry.unwrap();
        if entry.path().unwrap().to_str() == Some("graph.nnef") {
            let mut text = Vec::new();
            entry.read_to_end(&mut text).unwrap();
            return text;
        }
    }
    panic!("no graph.nnef")
}

fn map_frame_seed(elements: u16, satellite: SatellitePrior) -> Vec<u8> {
    let mut frame = MapFrame {
        sequence: 17,
        timestamp_us: 8_500_000,
        e2e_counter: 3,
        health: Health {
            satellite,
            degraded: false,
            deadline_overrun: false,
            cameras: [CameraState::Used; 6],
        },
        ..MapFrame::default()
    };
    for k in 0..elements {
        let _ = frame.elements.push(MapElement {
            class: MapClass::from_label(usize::from(k % 3)).unwrap(),
            score: 0.95 - f32::from(k) * 0.01,
            instance: k,
            points_m: core::array::from_fn(|i| Vec2::new(i as f32 * 0.75, f32::from(k) - 10.0)),
        });
    }
    frame.digest = digest(&frame.elements);
    let mut out = vec![0u8; wire::MAX_WIRE_BYTES];
    let n = wire::serialise(&frame, wire::DEFAULT_DATA_ID, &mut out).unwrap();
    out.truncate(n);
    out
}

/// `bytes` behind the re-seal mode byte of `map_frame` and `route_pack`.
fn moded(bytes: Vec<u8>) -> Vec<u8> {
    let mut out = vec![1];
    out.extend(bytes);
    out
}

/// Every target's seeds: `(target, file name, bytes)`.
fn seeds() -> Vec<(&'static str, &'static str, Vec<u8>)> {
    let bundle = committed_bundle();
    let encoder = bundle.read_stage(Stage::BevEncoder).unwrap().into_owned();
    let query_text = graph_text(&bundle.read_stage(Stage::BevQuery).unwrap());
    let signed = signed_seed();
    let mut signed_input = format!("{}\n", signed.signature).into_bytes();
    signed_input.extend_from_slice(&signed.archive);
    let route = parse_route_geojson(&seed_route_geojson(), Path::new("route.geojson")).unwrap();
    let pack = build_pack(&mut BoxImagery::around(route[0]), &route, &pack_options())
        .unwrap()
        .bytes;
    vec![
        (
            "compiled_bundle",
            "stand_in_stages.satmap",
            reseal(seed_manifest().as_bytes()),
        ),
        ("signed_bundle", "signed_stand_in.bin", signed_input),
        ("nnef_stage", "test_bev_encoder.nnef.tar", encoder.clone()),
        ("nnef_text", "test_bev_encoder.nnef", graph_text(&encoder)),
        ("nnef_text", "test_bev_query.nnef", query_text),
        // map_frame and route_pack inputs start with a mode byte: 1 re-seals after the edits.
        (
            "map_frame",
            "three_elements.bin",
            moded(map_frame_seed(3, SatellitePrior::Present)),
        ),
        (
            "map_frame",
            "fifty_partial.bin",
            moded(map_frame_seed(
                50,
                SatellitePrior::Partial {
                    covered_permille: 512,
                },
            )),
        ),
        ("route_pack", "box_imagery.pack", moded(pack)),
        (
            "manifest",
            "test_folder.toml",
            MANIFEST_TOML.as_bytes().to_vec(),
        ),
        (
            "manifest",
            "test_compiled.toml",
            bundle.manifest_bytes().to_vec(),
        ),
        (
            "mcap_recording",
            "two_steps.mcap",
            crate::mcap_recording::seed_recording(None),
        ),
        (
            "mcap_recording",
            "two_steps_zstd.mcap",
            crate::mcap_recording::seed_recording(Some(mcap::Compression::Zstd)),
        ),
    ]
}

fn seeds_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds")
}

#[test]
fn libfuzzer_seeds_are_current() {
    let bless = std::env::var_os("SATMAP_BLESS").is_some();
    for (target, name, bytes) in seeds() {
        let path = seeds_dir().join(target).join(name);
        if bless {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, &bytes).unwrap();
        } else {
            let committed = std::fs::read(&path)
                .unwrap_or_else(|e| panic!("{}: {e} (SATMAP_BLESS=1 writes it)", path.display()));
            assert!(
                committed == bytes,
                "{} is stale: SATMAP_BLESS=1 cargo test --test fuzz_parsers libfuzzer_seeds",
                path.display()
            );
        }
    }
}
