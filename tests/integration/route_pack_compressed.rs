//! Compressed route packs (format version 2) end to end: packs built by the host builder from
//! the same procedural imagery raw, as JPEG and as zlib, read by the runtime's crop.
//!
//! - JPEG crops match the raw pack's within a stated PSNR; zlib crops are bit-identical.
//! - Every single-bit flip of one compressed tile is caught by its checksum before any decode.
//! - Payloads that pass the checksum but are not the tile's image (forged with the writer) are
//!   reported as undecodable tiles, never a panic, and the source stays usable.
//! - The route replay over a compressed pack decodes within its per-step bound and covers
//!   every step; raw and lossless replays give the same crop digest.

use std::sync::OnceLock;

use glam::DVec2;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::pose::EgoPose;
use satmap_runtime::route_pack::{
    MAX_CROP_TILES, PREFETCH_TILES_PER_STEP, PackHeader, PackSource, PackTile, RoutePack,
    TileCodec, TileKey, TileState, encode_pack,
};
use satmap_runtime::satellite::{Coverage, CropSpec};
use satmap_sim::harness::{RouteReplayConfig, replay_route};
use satmap_sim::route_pack_builder::{
    BuildOptions, PAPER_CROP, SyntheticRoute, TileCompression, build_pack, compress_tile, psnr_db,
};

/// Lowest PSNR of any crop of the JPEG (quality 85) pack against the raw pack's, dB. Measured
/// 41.8 dB minimum, 42.4 dB mean over the 20 crops below; the bound leaves 3.8 dB.
const MIN_CROP_PSNR_DB: f64 = 38.0;
const JPEG_QUALITY: u8 = 85;
const ROUTE_KM: f64 = 0.6;

struct Packs {
    route: SyntheticRoute,
    raw: Vec<u8>,
    jpeg: Vec<u8>,
    deflate: Vec<u8>,
}

fn packs() -> &'static Packs {
    static PACKS: OnceLock<Packs> = OnceLock::new();
    PACKS.get_or_init(|| {
        let route = SyntheticRoute::new(7, ROUTE_KM, Geodetic::new(48.137, 11.575, 0.0)).unwrap();
        let build = |compression| {
            let opts = BuildOptions {
                origin: Some(route.anchor()),
                compression,
                ..BuildOptions::default()
            };
            build_pack(&mut route.imagery(), &route.route_wgs84(), &opts)
                .unwrap()
                .bytes
        };
        Packs {
            raw: build(TileCompression::Raw),
            jpeg: build(TileCompression::Jpeg {
                quality: JPEG_QUALITY,
            }),
            deflate: build(TileCompression::Deflate),
            route,
        }
    })
}

/// Poses every 15 m along the route, facing along it, with a sideways offset and a yaw that
/// varies so crops cross tile seams at many angles.
fn poses(route: &SyntheticRoute) -> Vec<EgoPose> {
    let pts = route.route_m();
    pts.windows(2)
        .enumerate()
        .filter(|(i, _)| i % 3 == 0)
        .map(|(i, w)| {
            let d = w[1] - w[0];
            let side = DVec2::new(-d.y, d.x).normalize_or_zero() * (i % 5) as f64;
            EgoPose::new(w[0] + side, d.y.atan2(d.x) + 0.05 * (i % 7) as f64)
        })
        .collect()
}

fn tile_buffer() -> Vec<u8> {
    vec![0u8; satmap_runtime::capacity::layout::TILE_PIXELS_BYTES]
}

fn crop(source: &mut PackSource<'_>, pose: &EgoPose, spec: &CropSpec) -> (Vec<u8>, Coverage) {
    let mut out = vec![0u8; spec.height_px * spec.width_px * 3];
    let report = source.crop_with_report(pose, spec, &mut out);
    (out, report.coverage)
}

#[test]
fn version_2_is_written_for_compressed_tiles_and_version_1_for_raw() {
    let p = packs();
    let version = |b: &[u8]| u16::from_le_bytes([b[8], b[9]]);
    assert_eq!(version(&p.raw), 1);
    assert_eq!(version(&p.jpeg), 2);
    assert_eq!(version(&p.deflate), 2);
    assert_eq!(RoutePack::parse(&p.jpeg).unwrap().codec(), TileCodec::Jpeg);
    assert_eq!(
        RoutePack::parse(&p.deflate).unwrap().codec(),
        TileCodec::Deflate
    );
    let tiles = RoutePack::parse(&p.raw).unwrap().tile_count();
    assert_eq!(RoutePack::parse(&p.jpeg).unwrap().tile_count(), tiles);
    // The procedural imagery is textured like aerial imagery: JPEG wins several times over.
    assert!(
        p.jpeg.len() * 4 < p.raw.len(),
        "{} vs {}",
        p.jpeg.len(),
        p.raw.len()
    );
    assert!(p.deflate.len() < p.raw.len());
}

#[test]
fn jpeg_crops_match_raw_within_the_stated_psnr_and_zlib_crops_are_identical() {
    let p = packs();
    let (mut raw_buf, mut jpeg_buf, mut zlib_buf) = (tile_buffer(), tile_buffer(), tile_buffer());
    let mut raw = PackSource::with_tile_buffer(RoutePack::parse(&p.raw).unwrap(), &mut raw_buf);
    let mut jpeg = PackSource::with_tile_buffer(RoutePack::parse(&p.jpeg).unwrap(), &mut jpeg_buf);
    let mut zlib =
        PackSource::with_tile_buffer(RoutePack::parse(&p.deflate).unwrap(), &mut zlib_buf);
    for source in [&raw, &jpeg, &zlib] {
        source.check_crop_spec(&PAPER_CROP).unwrap();
    }
    let (mut worst, mut sum, mut n) = (f64::INFINITY, 0.0, 0);
    for pose in poses(&p.route) {
        let (a, cov_a) = crop(&mut raw, &pose, &PAPER_CROP);
        let (b, cov_b) = crop(&mut jpeg, &pose, &PAPER_CROP);
        let (c, cov_c) = crop(&mut zlib, &pose, &PAPER_CROP);
        assert_eq!(cov_a, Coverage::Full, "{pose:?}");
        assert_eq!((cov_b, cov_c), (cov_a, cov_a));
        assert!(a == c, "lossless crop differs at {pose:?}");
        let se: u64 = a
            .iter()
            .zip(&b)
            .map(|(&x, &y)| u64::from(x.abs_diff(y)).pow(2))
            .sum();
        let psnr = psnr_db(se, a.len() as u64);
        worst = worst.min(psnr);
        sum += psnr;
        n += 1;
    }
    println!(
        "JPEG q{JPEG_QUALITY} crops vs raw over {n} poses: PSNR min {worst:.1} dB, mean {:.1} dB",
        sum / f64::from(n)
    );
    assert!(n >= 10);
    assert!(worst >= MIN_CROP_PSNR_DB, "worst crop PSNR {worst:.2} dB");
    // Every compressed tile the crops used was decoded, none failed.
    assert!(jpeg.cache().decoded_total() > 0);
    assert_eq!(raw.cache().decoded_total(), 0);
}

#[test]
fn every_single_bit_flip_of_a_compressed_tile_is_caught_before_decoding() {
    let p = packs();
    let pack = RoutePack::parse(&p.jpeg).unwrap();
    let pose = poses(&p.route)[0];
    // The tile under the vehicle.
    let side_m = pack.tile_side_m();
    let key = TileKey::new(
        (pose.position_m.x / side_m).floor() as i32,
        (pose.position_m.y / side_m).floor() as i32,
    );
    let tile = pack.find_tile(key).unwrap();
    let payload = pack.tile_payload_unverified(tile).unwrap();
    let start = payload.as_ptr() as usize - p.jpeg.as_ptr() as usize;
    let bits = payload.len() * 8;
    assert!(bits > 10_000, "a real JPEG tile: {bits} bits");
    let mut bytes = p.jpeg.clone();
    let mut checked_by_crop = 0;
    for bit in 0..bits {
        let at = start + bit / 8;
        bytes[at] ^= 1 << (bit % 8);
        // Payloads are outside the load-time checksums: the pack still loads, and the tile's
        // own checksum refuses it.
        let flipped = RoutePack::parse(&bytes).unwrap();
        assert!(
            flipped.verified_tile(tile).is_none(),
            "bit {bit} undetected"
        );
        if bit % 509 == 0 {
            // Through the crop: the tile is corrupt, never handed to the decoder.
            let mut buf = tile_buffer();
            let mut source = PackSource::with_tile_buffer(flipped, &mut buf);
            let (_, coverage) = crop(&mut source, &pose, &PAPER_CROP);
            assert_eq!(coverage, Coverage::Corrupt, "bit {bit}");
            assert_eq!(source.cache().peek(tile), Some(TileState::Corrupt));
            assert_eq!(source.last_report().first_corrupt, Some(key));
            checked_by_crop += 1;
        }
        bytes[at] ^= 1 << (bit % 8);
    }
    println!("{bits} single-bit flips of tile {key:?}, {checked_by_crop} also through the crop");
    assert!(checked_by_crop > 20);
    assert_eq!(bytes, p.jpeg);
}

/// A one-tile pack of `codec` whose payload is `payload`, checksummed by the writer (so it
/// passes verification and reaches the decoder).
fn forged(codec: TileCodec, payload: &[u8]) -> Vec<u8> {
    let header = PackHeader {
        tile_size_px: 64,
        origin: Geodetic::new(48.0, 11.0, 0.0),
        gsd_m: 0.5,
        corridor_width_m: 10.0,
        tile_count: 0,
        route_point_count: 0,
        codec,
    };
    encode_pack(
        &header,
        &[],
        &[PackTile {
            key: TileKey::new(0, 0),
            payload,
        }],
    )
    .unwrap()
}

#[test]
fn payloads_that_pass_the_checksum_but_are_not_the_tile_are_undecodable_not_a_panic() {
    let rgb: Vec<u8> = (0..64 * 64 * 3).map(|i| (i % 253) as u8).collect();
    let jpeg = compress_tile(TileCompression::Jpeg { quality: 80 }, &rgb, 64)
        .unwrap()
        .payload;
    let zlib = compress_tile(TileCompression::Deflate, &rgb, 64)
        .unwrap()
        .payload;
    let small_rgb = &rgb[..32 * 32 * 3];
    let jpeg_32 = compress_tile(TileCompression::Jpeg { quality: 80 }, small_rgb, 32)
        .unwrap()
        .payload;
    let zlib_32 = compress_tile(TileCompression::Deflate, small_rgb, 32)
        .unwrap()
        .payload;
    let noise: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let cases: Vec<(&str, TileCodec, Vec<u8>)> = vec![
        ("noise as JPEG", TileCodec::Jpeg, noise.clone()),
        ("noise as zlib", TileCodec::Deflate, noise),
        (
            "truncated JPEG",
            TileCodec::Jpeg,
            jpeg[..jpeg.len() / 2].to_vec(),
        ),
        ("JPEG header only", TileCodec::Jpeg, jpeg[..200].to_vec()),
        ("JPEG of 32 px in a 64 px pack", TileCodec::Jpeg, jpeg_32),
        ("zlib of 32 px in a 64 px pack", TileCodec::Deflate, zlib_32),
        (
            "truncated zlib",
            TileCodec::Deflate,
            zlib[..zlib.len() - 9].to_vec(),
        ),
        ("zlib labelled JPEG", TileCodec::Jpeg, zlib.clone()),
        ("JPEG labelled zlib", TileCodec::Deflate, jpeg.clone()),
        ("one byte", TileCodec::Jpeg, vec![0xFF]),
    ];
    let spec = CropSpec {
        height_px: 20,
        width_px: 20,
        gsd_m: 0.5,
        x_min_m: -5.0,
        y_min_m: -5.0,
    };
    let centre = EgoPose::new(DVec2::new(16.0, 16.0), 0.3);
    for (name, codec, payload) in cases {
        let bytes = forged(codec, &payload);
        let mut buf = tile_buffer();
        let mut source = PackSource::with_tile_buffer(RoutePack::parse(&bytes).unwrap(), &mut buf);
        assert!(source.pack().verified_tile(0).is_some(), "{name}");
        let (out, coverage) = crop(&mut source, &centre, &spec);
        assert_eq!(coverage, Coverage::Corrupt, "{name}");
        assert_eq!(
            source.cache().peek(0),
            Some(TileState::Undecodable),
            "{name}"
        );
        assert!(out.iter().all(|&v| v == 0), "{name}: only fill is written");
        // Still usable: the next crop reports the same, without decoding again.
        let (_, again) = crop(&mut source, &centre, &spec);
        assert_eq!(again, Coverage::Corrupt);
        assert_eq!(source.last_report().decoded_tiles, 0, "{name}");
    }
    // The genuine payloads decode and cover the crop.
    for (codec, payload) in [(TileCodec::Jpeg, jpeg), (TileCodec::Deflate, zlib)] {
        let bytes = forged(codec, &payload);
        let mut buf = tile_buffer();
        let mut source = PackSource::with_tile_buffer(RoutePack::parse(&bytes).unwrap(), &mut buf);
        assert_eq!(crop(&mut source, &centre, &spec).1, Coverage::Full);
    }
}

#[test]
fn a_compressed_pack_without_a_tile_buffer_is_refused_at_load_not_per_step() {
    let p = packs();
    let source = PackSource::new(RoutePack::parse(&p.jpeg).unwrap());
    assert!(matches!(
        source.check_crop_spec(&PAPER_CROP),
        Err(satmap_runtime::route_pack::CropFault::TileBuffer { slots: 0, .. })
    ));
    let mut small = vec![0u8; 3 * 256 * 256 * 3];
    let source = PackSource::with_tile_buffer(RoutePack::parse(&p.jpeg).unwrap(), &mut small);
    assert!(matches!(
        source.check_crop_spec(&PAPER_CROP),
        Err(satmap_runtime::route_pack::CropFault::TileBuffer { slots: 3, .. })
    ));
    // Raw packs need none.
    PackSource::new(RoutePack::parse(&p.raw).unwrap())
        .check_crop_spec(&PAPER_CROP)
        .unwrap();
}

#[test]
fn route_replay_over_a_compressed_pack_decodes_within_its_bound_and_covers_every_step() {
    let p = packs();
    let cfg = RouteReplayConfig {
        crop: PAPER_CROP,
        speed_mps: 15.0,
        rate_hz: 10.0,
        max_steps: 100_000,
    };
    let jpeg = replay_route(&p.jpeg, &cfg).unwrap();
    let raw = replay_route(&p.raw, &cfg).unwrap();
    let zlib = replay_route(&p.deflate, &cfg).unwrap();
    assert!(jpeg.steps >= 35, "{jpeg:?}");
    for r in [&jpeg, &raw, &zlib] {
        assert_eq!(r.not_full_steps, 0, "{r:?}");
    }
    assert!(jpeg.decoded_tiles > 0);
    assert_eq!(raw.decoded_tiles, 0);
    // The tile buffer holds a crop's tiles and the ones ahead: along a route each tile is
    // decoded once (a cache too small for that decodes the same tiles again every few steps).
    let tiles = RoutePack::parse(&p.jpeg).unwrap().tile_count() as u64;
    println!(
        "route replay: {} steps, {} tiles decoded of {tiles} in the pack, at most {} a step",
        jpeg.steps, jpeg.decoded_tiles, jpeg.max_decoded_per_step
    );
    assert!(
        jpeg.decoded_tiles <= tiles,
        "{} decodes",
        jpeg.decoded_tiles
    );
    assert!(usize::from(jpeg.max_decoded_per_step) <= MAX_CROP_TILES + PREFETCH_TILES_PER_STEP);
    // Lossless crops equal raw ones over the whole route; the lossy ones differ, and repeat.
    assert_eq!(zlib.crop_digest, raw.crop_digest);
    assert_ne!(jpeg.crop_digest, raw.crop_digest);
    assert_eq!(
        replay_route(&p.jpeg, &cfg).unwrap().crop_digest,
        jpeg.crop_digest
    );
}
