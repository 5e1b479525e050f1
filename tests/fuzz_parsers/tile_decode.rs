//! The compressed-tile harness: a version 2 pack whose one tile is the fuzzed payload, written
//! by the runtime's own writer so its checksum matches and the payload reaches the decoder
//! (slot 0 as JPEG, slot 1 as zlib), then cropped. A payload that decodes covers the crop; one
//! that does not is an undecodable tile and only fill is written; nothing panics, and the
//! source keeps working.

use glam::DVec2;
use proptest::prelude::*;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::pose::EgoPose;
use satmap_runtime::route_pack::{
    PackHeader, PackSource, PackTile, RoutePack, TileCodec, TileKey, TileState, encode_pack,
};
use satmap_runtime::satellite::{Coverage, CropSpec};
use satmap_sim::route_pack_builder::{TileCompression, compress_tile};

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Parsed, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};

const SIDE_PX: u16 = 32;
const SPEC: CropSpec = CropSpec {
    height_px: 12,
    width_px: 12,
    gsd_m: 0.5,
    x_min_m: -3.0,
    y_min_m: -3.0,
};

fn codec_of(slot: usize) -> TileCodec {
    if slot == 0 {
        TileCodec::Jpeg
    } else {
        TileCodec::Deflate
    }
}

fn tile_decode_case(input: &Input) -> CaseResult {
    let header = PackHeader {
        tile_size_px: SIDE_PX,
        origin: Geodetic::new(48.0, 11.0, 0.0),
        gsd_m: 0.5,
        corridor_width_m: 10.0,
        tile_count: 0,
        route_point_count: 0,
        codec: codec_of(input.slot),
    };
    let tile = PackTile {
        key: TileKey::new(0, 0),
        payload: &input.bytes,
    };
    // Empty or over-long payloads are refused by the writer, as the reader would refuse them.
    let Ok(bytes) = encode_pack(&header, &[], &[tile]) else {
        return Ok(Refused);
    };
    let pack = RoutePack::parse(&bytes);
    prop_assert!(pack.is_ok(), "the writer's pack does not load: {pack:?}");
    let mut pixels = vec![0u8; 4 * usize::from(SIDE_PX).pow(2) * 3];
    let mut source = PackSource::with_tile_buffer(pack.unwrap(), &mut pixels);
    let mut out = [0u8; 12 * 12 * 3];
    let pose = EgoPose::new(DVec2::new(8.0, 8.0), 0.4);
    for _ in 0..2 {
        let report = source.crop_with_report(&pose, &SPEC, &mut out);
        match source.cache().peek(0) {
            Some(TileState::Verified) => prop_assert_eq!(report.coverage, Coverage::Full),
            Some(TileState::Undecodable) => {
                prop_assert_eq!(report.coverage, Coverage::Corrupt);
                prop_assert!(out.iter().all(|&v| v == 0));
            }
            other => prop_assert!(false, "tile state {other:?}"),
        }
    }
    Ok(if source.cache().peek(0) == Some(TileState::Verified) {
        Accepted
    } else {
        Parsed
    })
}

#[test]
fn tile_decode_never_panics() {
    let rgb: Vec<u8> = (0..usize::from(SIDE_PX).pow(2) * 3)
        .map(|i| ((i * 37) % 251) as u8)
        .collect();
    let seeds: Vec<Vec<u8>> = [
        TileCompression::Jpeg { quality: 75 },
        TileCompression::Deflate,
    ]
    .into_iter()
    .map(|c| compress_tile(c, &rgb, SIDE_PX).unwrap().payload)
    .collect();
    assert_seeds_accepted(&seeds, tile_decode_case);
    fuzz("tile_decode", inputs(seeds, false), tile_decode_case);
}
