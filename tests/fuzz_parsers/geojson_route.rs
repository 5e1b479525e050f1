//! The GeoJSON route harness: `parse_route_geojson` on the seed route and two hand-written
//! layouts (a bare `LineString` and a `Feature`), then a pack build and a load of the built
//! pack.

use std::cell::RefCell;
use std::path::Path;

use proptest::prelude::*;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::route_pack::RoutePack;
use satmap_sim::route_pack_builder::{build_pack, parse_route_geojson};
use satmap_sim::synth::ScenarioPlacement;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Parsed, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};
use crate::seeds::{BoxImagery, pack_options, seed_route_geojson};

fn geojson_case(input: &Input, imagery: &mut BoxImagery) -> CaseResult {
    let Ok(route) = parse_route_geojson(&input.text(), Path::new("route.geojson")) else {
        return Ok(Refused);
    };
    prop_assert!(route.len() >= 2);
    prop_assert!(route.iter().all(Geodetic::is_valid));
    // `build-pack` next; a pack the builder writes is one the runtime loads.
    let Ok(built) = build_pack(imagery, &route, &pack_options()) else {
        return Ok(Parsed);
    };
    let pack = RoutePack::parse(&built.bytes);
    prop_assert!(pack.is_ok(), "built pack refused: {:?}", pack.err());
    prop_assert_eq!(pack.unwrap().tile_count(), built.tiles);
    Ok(Accepted)
}

#[test]
fn geojson_route_never_panics() {
    let anchor = ScenarioPlacement::default().anchor;
    let (lat, lon) = (anchor.lat_deg, anchor.lon_deg);
    let seeds = vec![
        seed_route_geojson().into_bytes(),
        format!(
            r#"{{"type":"LineString","coordinates":[[{lon},{lat}],[{},{},3.5]]}}"#,
            lon + 1e-4,
            lat + 1e-4
        )
        .into_bytes(),
        format!(
            r#"{{"type":"Feature","properties":{{"name":"r"}},"geometry":{{"type":"LineString","coordinates":[[{lon},{lat}],[{},{lat}],[{},{}]]}}}}"#,
            lon + 2e-4,
            lon + 2e-4,
            lat - 1e-4
        )
        .into_bytes(),
    ];
    let imagery = RefCell::new(BoxImagery::around(anchor));
    let body = |input: &Input| geojson_case(input, &mut imagery.borrow_mut());
    assert_seeds_accepted(&seeds, body);
    fuzz("geojson_route", inputs(seeds, true), body);
}
