//! The route-pack builder end to end: slippy tiles and a world-file image drawn from a known
//! pattern in the route frame, packed, then cropped by the runtime: a marker lands where the
//! geodesy says, the pattern survives resampling, and bad inputs give the right error.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};
use image::RgbImage;
use satmap_runtime::geo::web_mercator::{lat_lon_to_world_px, world_px_to_lat_lon};
use satmap_runtime::geo::{EnuFrame, Geodetic, TileId, WorldPixel};
use satmap_runtime::pose::EgoPose;
use satmap_runtime::route_pack::{PackSource, RoutePack};
use satmap_runtime::satellite::{Coverage, CropSpec};
use satmap_sim::route_pack_builder::imagery::Gap;
use satmap_sim::route_pack_builder::{
    BuildError, BuildOptions, Imagery, PAPER_CROP, SlippyTiles, WorldCrs, WorldFileImage,
    build_pack, parse_route_geojson,
};

const ORIGIN: Geodetic = Geodetic::new(42.336, -71.057, 0.0);
const ZOOM: u8 = 19;
const MARKER_M: DVec2 = DVec2::new(30.0, 5.0);

/// The ground truth, in the route frame (ENU at `ORIGIN`): a 0.75 m red disc at `MARKER_M`,
/// green and blue sinusoids of 10 m period along x and y.
fn world(p: DVec2) -> [u8; 3] {
    let red = if p.distance(MARKER_M) <= 0.75 { 255 } else { 0 };
    let wave = |v: f64| (128.0 + 100.0 * (TAU * v / 10.0).sin()).round() as u8;
    [red, wave(p.x), wave(p.y)]
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("satmap_route_pack_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn route_geojson(points_m: &[DVec2]) -> String {
    let frame = EnuFrame::new(ORIGIN);
    let coords: Vec<String> = points_m
        .iter()
        .map(|p| {
            let g = frame.enu_to_geodetic(DVec3::new(p.x, p.y, 0.0));
            format!("[{:.10}, {:.10}]", g.lon_deg, g.lat_deg)
        })
        .collect();
    format!(
        r#"{{"type": "Feature", "properties": {{}}, "geometry": {{"type": "LineString", "coordinates": [{}]}}}}"#,
        coords.join(", ")
    )
}

fn route(points_m: &[DVec2]) -> Vec<Geodetic> {
    parse_route_geojson(&route_geojson(points_m), Path::new("test.geojson")).unwrap()
}

/// Write zoom-`zoom` tiles covering route-frame box `lo..hi`, each pixel painted with `world`
/// at its centre.
fn write_tiles(dir: &Path, zoom: u8, lo: DVec2, hi: DVec2) {
    let frame = EnuFrame::new(ORIGIN);
    let corner = |p: DVec2| frame.enu_to_geodetic(DVec3::new(p.x, p.y, 0.0));
    let (sw, ne) = (corner(lo), corner(hi));
    let t0 = TileId::from_lat_lon(ne.lat_deg, sw.lon_deg, zoom).unwrap();
    let t1 = TileId::from_lat_lon(sw.lat_deg, ne.lon_deg, zoom).unwrap();
    for tx in t0.x..=t1.x {
        for ty in t0.y..=t1.y {
            let img = RgbImage::from_fn(256, 256, |c, r| {
                let w = WorldPixel {
                    x_px: f64::from(tx * 256 + c) + 0.5,
                    y_px: f64::from(ty * 256 + r) + 0.5,
                };
                let (lat, lon) = world_px_to_lat_lon(w, zoom);
                let enu = frame.geodetic_to_enu(&Geodetic::new(lat, lon, 0.0));
                image::Rgb(world(enu.truncate()))
            });
            let col = dir.join(zoom.to_string()).join(tx.to_string());
            std::fs::create_dir_all(&col).unwrap();
            img.save(col.join(format!("{ty}.png"))).unwrap();
        }
    }
}

fn opts() -> BuildOptions {
    BuildOptions {
        corridor_width_m: 20.0,
        gsd_m: 0.25,
        tile_size_px: 64,
        ..BuildOptions::default()
    }
}

/// Crop around the marker at an oblique yaw; check the marker centroid and the sinusoids.
fn check_pack(bytes: &[u8]) {
    let mut source = PackSource::from_bytes(bytes).unwrap();
    let spec = CropSpec {
        height_px: 80,
        width_px: 80,
        gsd_m: 0.25,
        x_min_m: -10.0,
        y_min_m: -10.0,
    };
    let pose = EgoPose::new(MARKER_M, 0.4);
    let mut out = vec![0u8; 80 * 80 * 3];
    let report = source.crop_with_report(&pose, &spec, &mut out);
    assert_eq!(report.coverage, Coverage::Full);
    let (mut sum, mut sr, mut sc) = (0.0, 0.0, 0.0);
    let (mut err_g, mut err_b) = (0.0, 0.0);
    for r in 0..80 {
        for c in 0..80 {
            let px = &out[(r * 80 + c) * 3..][..3];
            let v = f64::from(px[0]);
            sum += v;
            sr += v * r as f64;
            sc += v * c as f64;
            let ego = DVec2::new(
                -10.0 + (c as f64 + 0.5) * 0.25,
                -10.0 + (r as f64 + 0.5) * 0.25,
            );
            let truth = world(pose.ego_to_route(ego));
            err_g += (f64::from(px[1]) - f64::from(truth[1])).abs();
            err_b += (f64::from(px[2]) - f64::from(truth[2])).abs();
        }
    }
    // The marker is at the ego origin: crop pixel (39.5, 39.5); 0.15 px is 3.75 cm. The disc is
    // aliased in the source tiles (painted at pixel centres), hence not 0.01 px.
    assert!(sum > 0.0);
    assert!((sr / sum - 39.5).abs() < 0.15, "row centroid {}", sr / sum);
    assert!((sc / sum - 39.5).abs() < 0.15, "col centroid {}", sc / sum);
    assert!(err_g / 6400.0 < 1.5, "green mean error {}", err_g / 6400.0);
    assert!(err_b / 6400.0 < 1.5, "blue mean error {}", err_b / 6400.0);
}

#[test]
fn slippy_tiles_pack_puts_the_marker_where_geodesy_says() {
    let dir = scratch("slippy");
    write_tiles(&dir, ZOOM, DVec2::new(-30.0, -30.0), DVec2::new(90.0, 40.0));
    let path = [DVec2::ZERO, DVec2::new(30.0, 5.0), DVec2::new(60.0, 10.0)];
    let mut tiles = SlippyTiles::open(&dir, None).unwrap();
    assert_eq!((tiles.zoom(), tiles.tile_px()), (ZOOM, 256));
    let built = build_pack(&mut tiles, &route(&path), &opts()).unwrap();
    assert_eq!(built.skipped_tiles, 0);
    assert!(
        (built.route_length_m - (30.4138 + 30.4138)).abs() < 0.01,
        "{}",
        built.route_length_m
    );
    let pack = RoutePack::parse(&built.bytes).unwrap();
    assert_eq!(pack.header().tile_size_px, 64);
    assert!((pack.header().origin.lat_deg - ORIGIN.lat_deg).abs() < 1e-9);
    // Route points survive in the route frame.
    assert!(pack.route_point(1).unwrap().distance(path[1]) < 1e-3);
    // The corridor (10 m either side) is covered along the whole route.
    for k in 0..=60 {
        let p = path[0].lerp(path[2], f64::from(k) / 60.0);
        for off in [-9.0, 0.0, 9.0] {
            let q = p + DVec2::new(0.0, off);
            let key = satmap_runtime::route_pack::TileKey::new(
                (q.x / 16.0).floor() as i32,
                (q.y / 16.0).floor() as i32,
            );
            assert!(pack.find_tile(key).is_some(), "{q}");
        }
    }
    check_pack(&built.bytes);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn world_file_image_pack_matches_the_slippy_one() {
    let dir = scratch("world");
    let frame = EnuFrame::new(ORIGIN);
    // A north-up image in EPSG:3857 at zoom-19 resolution over the route area.
    let nw = frame.enu_to_geodetic(DVec3::new(-30.0, 40.0, 0.0));
    let w0 = lat_lon_to_world_px(nw.lat_deg, nw.lon_deg, ZOOM);
    let merc_m_per_px =
        2.0 * std::f64::consts::PI * 6_378_137.0 / (256.0 * f64::from(1u32 << ZOOM));
    let (width, height) = (560u32, 340u32);
    let img = RgbImage::from_fn(width, height, |c, r| {
        let w = WorldPixel {
            x_px: w0.x_px + f64::from(c) + 0.5,
            y_px: w0.y_px + f64::from(r) + 0.5,
        };
        let (lat, lon) = world_px_to_lat_lon(w, ZOOM);
        image::Rgb(world(
            frame
                .geodetic_to_enu(&Geodetic::new(lat, lon, 0.0))
                .truncate(),
        ))
    });
    img.save(dir.join("ortho.png")).unwrap();
    let half_world_m = std::f64::consts::PI * 6_378_137.0;
    let c_m = (w0.x_px + 0.5) * merc_m_per_px - half_world_m;
    let f_m = half_world_m - (w0.y_px + 0.5) * merc_m_per_px;
    std::fs::write(
        dir.join("ortho.pgw"),
        format!("{merc_m_per_px}\n0\n0\n{}\n{c_m}\n{f_m}\n", -merc_m_per_px),
    )
    .unwrap();
    let mut image =
        WorldFileImage::open(&dir.join("ortho.png"), None, WorldCrs::WebMercator).unwrap();
    let path = [DVec2::ZERO, DVec2::new(30.0, 5.0), DVec2::new(60.0, 10.0)];
    let built = build_pack(&mut image, &route(&path), &opts()).unwrap();
    check_pack(&built.bytes);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_tiles_route_outside_and_unreadable_images_are_clear_errors() {
    // Zoom 21 (14 m tiles here) so the corridor spans tiles that hold no route vertex.
    const Z: u8 = 21;
    let dir = scratch("errors");
    write_tiles(&dir, Z, DVec2::new(-15.0, -15.0), DVec2::new(75.0, 25.0));
    let frame = EnuFrame::new(ORIGIN);
    let tile_at = |p: DVec2| {
        let g = frame.enu_to_geodetic(DVec3::new(p.x, p.y, 0.0));
        TileId::from_lat_lon(g.lat_deg, g.lon_deg, Z).unwrap()
    };
    let ends = [DVec2::ZERO, DVec2::new(60.0, 10.0)];
    let path = route(&ends);
    // A route running 500 m east leaves the tiles at its second point.
    let mut tiles = SlippyTiles::open(&dir, Some(Z)).unwrap();
    let err = build_pack(
        &mut tiles,
        &route(&[DVec2::ZERO, DVec2::new(500.0, 0.0)]),
        &opts(),
    )
    .unwrap_err();
    assert!(
        matches!(err, BuildError::RouteOutsideImagery { index: 1, .. }),
        "{err}"
    );
    // Delete a tile mid-corridor (no vertex in it): a missing-tile error naming it.
    let hole = tile_at(DVec2::new(30.0, 5.0));
    assert!(ends.iter().all(|p| tile_at(*p) != hole));
    std::fs::remove_file(dir.join(format!("{Z}/{}/{}.png", hole.x, hole.y))).unwrap();
    let mut tiles = SlippyTiles::open(&dir, Some(Z)).unwrap();
    let err = build_pack(&mut tiles, &path, &opts()).unwrap_err();
    assert!(
        matches!(&err, BuildError::MissingTile { zoom, x, y, .. } if (*zoom, *x, *y) == (Z, hole.x, hole.y)),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains(&format!("{Z}/{}/{}", hole.x, hole.y)),
        "{err}"
    );
    // With allow_missing the pack tiles over the hole are left out and the rest is packed.
    let lenient = BuildOptions {
        allow_missing: true,
        ..opts()
    };
    let mut tiles = SlippyTiles::open(&dir, Some(Z)).unwrap();
    let built = build_pack(&mut tiles, &path, &lenient).unwrap();
    assert!(
        built.skipped_tiles > 0 && built.tiles > built.skipped_tiles,
        "{built:?}"
    );
    RoutePack::parse(&built.bytes).unwrap();
    // A corrupt PNG is an unreadable-image error naming the file.
    let first = tile_at(DVec2::new(1.0, 0.0));
    let bad = dir.join(format!("{Z}/{}/{}.png", first.x, first.y));
    std::fs::write(&bad, b"not a png").unwrap();
    let mut tiles = SlippyTiles::open(&dir, Some(Z)).unwrap_or_else(|e| panic!("{e}"));
    let err = build_pack(&mut tiles, &path, &opts()).unwrap_err();
    assert!(
        matches!(&err, BuildError::UnreadableImage { path, .. } if *path == bad),
        "{err}"
    );
    // A zoom level that is not there.
    assert!(matches!(
        SlippyTiles::open(&dir, Some(12)),
        Err(BuildError::TileFolder { .. })
    ));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_explicit_origin_keeps_the_callers_frame() {
    // Route starting 20 m east of ORIGIN, pack frame pinned to ORIGIN: route-frame positions are
    // those of `world`, so the marker check holds unchanged.
    let dir = scratch("origin");
    write_tiles(&dir, ZOOM, DVec2::new(-30.0, -30.0), DVec2::new(90.0, 40.0));
    let path = [
        DVec2::new(20.0, 0.0),
        DVec2::new(30.0, 5.0),
        DVec2::new(60.0, 10.0),
    ];
    let mut tiles = SlippyTiles::open(&dir, None).unwrap();
    let pinned = BuildOptions {
        origin: Some(ORIGIN),
        ..opts()
    };
    let built = build_pack(&mut tiles, &route(&path), &pinned).unwrap();
    let pack = RoutePack::parse(&built.bytes).unwrap();
    assert!(pack.route_point(0).unwrap().distance(path[0]) < 1e-3);
    check_pack(&built.bytes);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn geojson_routes_in_their_usual_wrappings() {
    let p = Path::new("r.geojson");
    let line = r#"{"type": "LineString", "coordinates": [[-71.05, 42.33], [-71.04, 42.34, 12.0]]}"#;
    let feature = format!(r#"{{"type": "Feature", "properties": null, "geometry": {line}}}"#);
    let collection = format!(
        r#"{{"type": "FeatureCollection", "features": [{{"type": "Feature", "properties": null, "geometry": {{"type": "Point", "coordinates": [0, 0]}}}}, {feature}]}}"#
    );
    for text in [line.to_string(), feature, collection] {
        let r = parse_route_geojson(&text, p).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!((r[1].lat_deg, r[1].lon_deg), (42.34, -71.04));
    }
    let one_point = r#"{"type": "LineString", "coordinates": [[-71.05, 42.33]]}"#;
    assert!(matches!(
        parse_route_geojson(one_point, p),
        Err(BuildError::RouteShape { .. })
    ));
    let polygon = r#"{"type": "Point", "coordinates": [1, 2]}"#;
    assert!(matches!(
        parse_route_geojson(polygon, p),
        Err(BuildError::RouteShape { .. })
    ));
    let swapped = r#"{"type": "LineString", "coordinates": [[42.33, -171.05], [42.34, -171.04]]}"#;
    assert!(matches!(
        parse_route_geojson(swapped, p),
        Err(BuildError::RouteShape { .. })
    ));
    assert!(matches!(
        parse_route_geojson("{", p),
        Err(BuildError::RouteGeoJson { .. })
    ));
}

#[test]
fn build_pack_command_writes_a_loadable_pack() {
    let dir = scratch("cli");
    write_tiles(&dir, ZOOM, DVec2::new(-30.0, -30.0), DVec2::new(90.0, 40.0));
    let route_path = dir.join("route.geojson");
    std::fs::write(
        &route_path,
        route_geojson(&[DVec2::ZERO, DVec2::new(30.0, 5.0), DVec2::new(60.0, 10.0)]),
    )
    .unwrap();
    let args = satmap_sim::cli::build_pack::Args {
        route: Some(route_path),
        synthetic_km: None,
        seed: 1,
        tiles: Some(dir.clone()),
        zoom: None,
        image: None,
        world_file: None,
        world_crs: WorldCrs::WebMercator,
        out: dir.join("route.pack"),
        corridor_m: 20.0,
        gsd_m: 0.25,
        tile_px: 64,
        crop_h_px: 80,
        crop_w_px: 80,
        crop_gsd_m: 0.25,
        allow_missing: false,
        quiet: true,
        origin: None,
        codec: satmap_sim::cli::build_pack::CodecArg::Raw,
        jpeg_quality: 85,
    };
    satmap_sim::cli::build_pack::run(&args).unwrap();
    let bytes = std::fs::read(dir.join("route.pack")).unwrap();
    check_pack(&bytes);
    let bad = satmap_sim::cli::build_pack::Args {
        tile_px: 100,
        ..args
    };
    // A missing route names the file once, then the OS's reason.
    let missing = satmap_sim::cli::build_pack::Args {
        route: Some(dir.join("gone.geojson")),
        tile_px: 64,
        ..bad.clone()
    };
    let err = satmap_sim::cli::build_pack::run(&missing).unwrap_err();
    let text = format!("{err:#}");
    assert_eq!(text.matches("gone.geojson").count(), 1, "{text}");
    assert!(text.starts_with("cannot read "), "{text}");
    let err = satmap_sim::cli::build_pack::run(&bad).unwrap_err();
    assert_eq!(
        format!("{err:#}"),
        "--tile-px 100 is outside the powers of two 8..=1024 px"
    );
    // Numbers are checked before any file is read: a NaN gsd with a route that does not exist.
    let nan = satmap_sim::cli::build_pack::Args {
        gsd_m: f64::NAN,
        route: Some(dir.join("no_such_route.geojson")),
        ..bad
    };
    let err = satmap_sim::cli::build_pack::run(&nan).unwrap_err();
    assert_eq!(
        format!("{err:#}"),
        "--gsd-m NaN is outside (0.001, 100] m/px"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Imagery that must not be touched: the checks below all come before any imagery work.
struct Untouchable;

impl Imagery for Untouchable {
    fn project(&self, _lat_deg: f64, _lon_deg: f64) -> DVec2 {
        panic!("imagery projected before the up-front checks refused the build")
    }
    fn sample(&mut self, _p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        panic!("imagery sampled before the up-front checks refused the build")
    }
    fn gap_error(&self, _gap: &Gap, _lat_deg: f64, _lon_deg: f64) -> BuildError {
        BuildError::Empty
    }
}

fn refused(route_m: &[DVec2], opts: &BuildOptions) -> BuildError {
    build_pack(&mut Untouchable, &route(route_m), opts).unwrap_err()
}

/// A 4 x 4 px crop: small enough that 8 px tiles pass the crop check, so the size checks are
/// what refuses.
const TINY_CROP: CropSpec = CropSpec {
    height_px: 4,
    width_px: 4,
    gsd_m: 0.15,
    x_min_m: -0.3,
    y_min_m: -0.3,
};

#[test]
fn numeric_options_out_of_range_name_the_flag() {
    let line = [DVec2::ZERO, DVec2::new(50.0, 0.0)];
    let base = BuildOptions::default();
    let cases: [(BuildOptions, &str); 12] = [
        (
            BuildOptions {
                gsd_m: f64::NAN,
                ..base.clone()
            },
            "--gsd-m",
        ),
        (
            BuildOptions {
                gsd_m: -0.15,
                ..base.clone()
            },
            "--gsd-m",
        ),
        (
            BuildOptions {
                gsd_m: f64::INFINITY,
                ..base.clone()
            },
            "--gsd-m",
        ),
        (
            BuildOptions {
                gsd_m: 0.001,
                ..base.clone()
            },
            "--gsd-m",
        ),
        (
            BuildOptions {
                corridor_width_m: f64::NAN,
                ..base.clone()
            },
            "--corridor-m",
        ),
        (
            BuildOptions {
                corridor_width_m: -1.0,
                ..base.clone()
            },
            "--corridor-m",
        ),
        (
            BuildOptions {
                corridor_width_m: 10_000.5,
                ..base.clone()
            },
            "--corridor-m",
        ),
        (
            BuildOptions {
                tile_size_px: 100,
                ..base.clone()
            },
            "--tile-px",
        ),
        (
            BuildOptions {
                tile_size_px: 2048,
                ..base.clone()
            },
            "--tile-px",
        ),
        (
            BuildOptions {
                crop: CropSpec {
                    height_px: 0,
                    ..PAPER_CROP
                },
                ..base.clone()
            },
            "--crop-h-px",
        ),
        (
            BuildOptions {
                crop: CropSpec {
                    width_px: 5000,
                    ..PAPER_CROP
                },
                ..base.clone()
            },
            "--crop-w-px",
        ),
        (
            BuildOptions {
                crop: CropSpec {
                    gsd_m: f64::NAN,
                    ..PAPER_CROP
                },
                ..base.clone()
            },
            "--crop-gsd-m",
        ),
    ];
    for (opts, flag) in cases {
        let err = refused(&line, &opts);
        assert!(
            matches!(&err, BuildError::OptionRange { option, .. } if *option == flag),
            "{flag}: {err}"
        );
        assert!(err.to_string().starts_with(flag), "{err}");
    }
}

#[test]
fn tiles_of_8_to_64_px_are_too_small_for_the_paper_crop() {
    // The 400 x 200 crop at 0.15 m/px on a 0.15 m/px pack spans 8 x 8 = 64 tiles of 64 px at
    // 45 deg (and 8 x 5 = 40 at 0 deg): every crop would fail. 128 px tiles: 25 at worst.
    let line = [DVec2::ZERO, DVec2::new(50.0, 0.0)];
    for tile_size_px in [8u16, 16, 32, 64] {
        let opts = BuildOptions {
            tile_size_px,
            ..BuildOptions::default()
        };
        let err = refused(&line, &opts);
        match err {
            BuildError::TilesTooSmallForCrop {
                tiles,
                max_tiles: 36,
                min_tile_px: Some(128),
                ..
            } => {
                assert!(tiles > 36, "{tile_size_px} px: {tiles}");
                if tile_size_px == 64 {
                    assert_eq!(tiles, 64);
                }
            }
            other => panic!("{tile_size_px} px: {other}"),
        }
    }
    let ok = BuildOptions {
        tile_size_px: 128,
        ..BuildOptions::default()
    };
    ok.validate().unwrap();
    let err = refused(
        &line,
        &BuildOptions {
            tile_size_px: 64,
            ..ok
        },
    );
    assert!(
        err.to_string().contains("use --tile-px 128 or larger"),
        "{err}"
    );
}

#[test]
fn a_sub_millimetre_gsd_is_refused_before_any_tile_is_listed() {
    // 0.0011 m/px: the 60 m x 30 m crop is over 54 000 px long, more than 36 tiles even of
    // 1024 px, so no tile size fits.
    let opts = BuildOptions {
        gsd_m: 0.0011,
        ..BuildOptions::default()
    };
    let err = refused(&[DVec2::ZERO, DVec2::new(1000.0, 0.0)], &opts);
    assert!(
        matches!(err, BuildError::TilesTooSmallForCrop { min_tile_px: None, tiles, .. } if tiles > 36),
        "{err}"
    );
    assert!(err.to_string().contains("use a coarser --gsd-m"), "{err}");
}

#[test]
fn a_10_km_corridor_at_8_px_tiles_is_refused_by_count() {
    // 1.2 m tiles, 5 km either side of a 101 m route east: rows floor(-5000 / 1.2) = -4167 to
    // floor(5000 / 1.2) = 4166 (8334), columns -4167 to floor(5101 / 1.2) = 4250 (8418):
    // 70 155 612 tiles against the format's 1 000 000.
    let opts = BuildOptions {
        corridor_width_m: 10_000.0,
        tile_size_px: 8,
        crop: TINY_CROP,
        ..BuildOptions::default()
    };
    let err = refused(&[DVec2::ZERO, DVec2::new(101.0, 0.0)], &opts);
    assert!(
        matches!(
            err,
            BuildError::PackTooLarge {
                what: "tiles",
                needed: 70_155_612,
                limit: 1_000_000,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn a_pack_larger_than_the_route_pack_region_is_refused_by_size() {
    // 256 px tiles of 38.4 m, 40 m either side of a 15001 m route east: rows -2..=1 (4),
    // columns -2..=floor(15041 / 38.4) = 391 (394): 1576 tiles. 80 + 2 * 16 + 1576 * 16 +
    // 1576 * 196 608 = 309 879 536 bytes against the 256 MiB region.
    let opts = BuildOptions {
        corridor_width_m: 80.0,
        ..BuildOptions::default()
    };
    let err = refused(&[DVec2::ZERO, DVec2::new(15001.0, 0.0)], &opts);
    assert!(
        matches!(
            err,
            BuildError::PackTooLarge {
                what: "bytes",
                needed: 309_879_536,
                limit: 268_435_456,
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains("route_pack region of memory_layout.toml"),
        "{err}"
    );
}

#[test]
fn too_many_route_points_or_corridor_runs_are_refused() {
    let frame = EnuFrame::new(ORIGIN);
    let points = |n: usize, spacing_m: f64| -> Vec<Geodetic> {
        (0..n)
            .map(|i| frame.enu_to_geodetic(DVec3::new(i as f64 * spacing_m, 0.0, 0.0)))
            .collect()
    };
    let opts = BuildOptions::default();
    let err = build_pack(&mut Untouchable, &points(1_000_001, 0.001), &opts).unwrap_err();
    assert!(
        matches!(
            err,
            BuildError::PackTooLarge {
                what: "route points",
                needed: 1_000_001,
                limit: 1_000_000,
                ..
            }
        ),
        "{err}"
    );
    // A million points 1 mm apart, 1.2 m tiles, 61 m corridor: every segment spans rows
    // floor(-30.5 / 1.2) = -26 to floor(30.5 / 1.2) = 25, 52 runs each: 51 999 948 runs.
    let dense = BuildOptions {
        corridor_width_m: 61.0,
        tile_size_px: 8,
        crop: TINY_CROP,
        ..BuildOptions::default()
    };
    let err = build_pack(&mut Untouchable, &points(1_000_000, 0.001), &dense).unwrap_err();
    assert!(
        matches!(
            err,
            BuildError::PackTooLarge {
                what: "corridor runs (route segments x tile rows)",
                needed: 51_999_948,
                limit: 4_000_000,
                ..
            }
        ),
        "{err}"
    );
}
