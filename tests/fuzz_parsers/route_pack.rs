//! The route pack harness: `PackSource::from_bytes` on edits of a pack built from the seed
//! route (slot 1 resealed after the edits so the field rules behind the checksums are reached),
//! then the index, route and crop invariants of a pack that loads.

use std::path::Path;

use glam::DVec2;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use satmap_runtime::pose::EgoPose;
use satmap_runtime::route_pack::format::HEADER_LEN;
use satmap_runtime::route_pack::{PackSource, RoutePack};
use satmap_runtime::satellite::SatelliteSource;
use satmap_sim::route_pack_builder::{build_pack, parse_route_geojson};
use xxhash_rust::xxh3::xxh3_64;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};
use crate::seeds::{BoxImagery, CROP, pack_options, seed_route_geojson};

/// Recompute both checksums (offsets from `runtime/core/src/route_pack/FORMAT.md`) so an edit of the
/// header, route or index reaches the field rules behind them.
fn reseal(bytes: &mut [u8]) {
    if bytes.len() < HEADER_LEN {
        return;
    }
    let count = |off: usize| u32::from_le_bytes(bytes[off..off + 4].try_into().unwrap()) as usize;
    let meta_end = HEADER_LEN
        .saturating_add(count(56).saturating_mul(16))
        .saturating_add(count(60).saturating_mul(16));
    if meta_end <= bytes.len() {
        let index = xxh3_64(&bytes[HEADER_LEN..meta_end]);
        bytes[64..72].copy_from_slice(&index.to_le_bytes());
    }
    let header = xxh3_64(&bytes[..72]);
    bytes[72..80].copy_from_slice(&header.to_le_bytes());
}

/// Every tile the index lists is in bounds and found by its key; nothing past the end is.
fn check_pack(pack: &RoutePack<'_>) -> Result<(), TestCaseError> {
    let n = pack.tile_count();
    let tile_bytes = pack.header().tile_bytes();
    for i in 0..n {
        let key = pack.tile_key(i);
        prop_assert!(key.is_some(), "tile {i} of {n} has no key");
        prop_assert_eq!(pack.find_tile(key.unwrap()), Some(i));
        let len = pack.tile_payload_unverified(i).map(<[u8]>::len);
        if pack.codec().needs_decode() {
            prop_assert!(len.is_some_and(|n| (1..=pack.header().max_payload_len()).contains(&n)));
        } else {
            prop_assert_eq!(len, Some(tile_bytes));
        }
        let _ = pack.verified_tile(i);
    }
    prop_assert!(pack.tile_key(n).is_none() && pack.tile_payload_unverified(n).is_none());
    let r = pack.route_point_count();
    for i in 0..r {
        prop_assert!(pack.route_point(i).is_some_and(|p| p.is_finite()));
    }
    prop_assert!(pack.route_point(r).is_none());
    Ok(())
}

fn route_pack_case(input: &Input) -> CaseResult {
    let mut bytes = input.bytes.clone();
    // Slot 1: the same seed with the checksums recomputed after the edits.
    if input.slot == 1 {
        reseal(&mut bytes);
    }
    let Ok(mut source) = PackSource::from_bytes(&bytes) else {
        return Ok(Refused);
    };
    check_pack(source.pack())?;
    let route: Vec<DVec2> = (0..source.pack().route_point_count())
        .filter_map(|i| source.pack().route_point(i))
        .collect();
    let mut out = [0u8; 20 * 12 * 3];
    let poses = [DVec2::ZERO, DVec2::new(5.0, -3.0)]
        .into_iter()
        .chain(route.first().copied())
        .chain(route.last().copied());
    for (k, p) in poses.enumerate() {
        let _ = source.distance_to_route_m(p);
        source.crop(&EgoPose::new(p, k as f64 * 1.3), &CROP, &mut out);
        let report = source.last_report();
        prop_assert!(report.covered_px <= report.total_px);
    }
    Ok(Accepted)
}

#[test]
fn route_pack_never_panics() {
    let route = parse_route_geojson(&seed_route_geojson(), Path::new("route.geojson")).unwrap();
    let mut imagery = BoxImagery::around(route[0]);
    let pack = build_pack(&mut imagery, &route, &pack_options())
        .unwrap()
        .bytes;
    // Slot 1 is the same pack, resealed after the edits (see `route_pack_case`).
    let seeds = vec![pack.clone(), pack];
    assert_seeds_accepted(&seeds, route_pack_case);
    fuzz("route_pack", inputs(seeds, false), route_pack_case);
}
