//! Geodesy against published reference values, and cm-level round trips over 20 km.

use glam::DVec3;
use satmap_core::geo::ellipsoid::{WGS84_A_M, WGS84_B_M};
use satmap_core::geo::web_mercator::{
    ground_resolution_m_per_px, lat_lon_to_world_px, world_px_to_lat_lon,
};
use satmap_core::geo::{
    EnuFrame, Geodetic, TileId, WorldPixel, ecef_to_geodetic, geodetic_to_ecef,
};

#[test]
fn ecef_of_axis_points_matches_the_ellipsoid_definition() {
    let p = geodetic_to_ecef(&Geodetic::new(0.0, 0.0, 0.0));
    assert!((p - DVec3::new(WGS84_A_M, 0.0, 0.0)).length() < 1e-6);
    let p = geodetic_to_ecef(&Geodetic::new(0.0, 90.0, 100.0));
    assert!((p - DVec3::new(0.0, WGS84_A_M + 100.0, 0.0)).length() < 1e-6);
    let p = geodetic_to_ecef(&Geodetic::new(90.0, 0.0, 0.0));
    // Published WGS84 semi-minor axis: 6 356 752.3142 m.
    assert!((p.z - 6_356_752.314_2).abs() < 1e-3, "{p}");
    assert!((WGS84_B_M - 6_356_752.314_245).abs() < 1e-6);
}

#[test]
fn enu_matches_the_published_zermatt_matterhorn_example() {
    // MathWorks `geodetic2enu` documentation example (WGS84): Matterhorn from Zermatt is
    // xEast = -7134.8, yNorth = -4556.3, zUp = 2852.4 (printed to 5 significant digits).
    let frame = EnuFrame::new(Geodetic::new(46.017, 7.750, 1673.0));
    let enu = frame.geodetic_to_enu(&Geodetic::new(45.976, 7.658, 4531.0));
    assert!((enu.x - -7134.8).abs() < 0.06, "{enu}");
    assert!((enu.y - -4556.3).abs() < 0.06, "{enu}");
    assert!((enu.z - 2852.4).abs() < 0.06, "{enu}");
}

#[test]
fn web_mercator_matches_the_published_chicago_example() {
    // Google Maps JavaScript API "Map and Tile Coordinates": Chicago (41.85, -87.65) at zoom 3
    // has world coordinate (65.67111, 95.17493), pixel (525, 761), tile (2, 2).
    let world = lat_lon_to_world_px(41.85, -87.65, 0);
    assert!((world.x_px - 65.671_111).abs() < 1e-5, "{world:?}");
    assert!((world.y_px - 95.174_927).abs() < 1e-5, "{world:?}");
    let px = lat_lon_to_world_px(41.85, -87.65, 3);
    assert_eq!((px.x_px.floor(), px.y_px.floor()), (525.0, 761.0));
    assert_eq!(
        TileId::from_lat_lon(41.85, -87.65, 3),
        Some(TileId {
            zoom: 3,
            x: 2,
            y: 2
        })
    );
}

#[test]
fn web_mercator_edges_and_resolution() {
    // OSM wiki: zoom-0 resolution at the equator is 156 543.03 m/px.
    assert!((ground_resolution_m_per_px(0.0, 0) - 156_543.034).abs() < 1e-3);
    // Zoom 20 at 45 deg: ~0.105 m/px (the SatMap spec's "0.1-0.15 m at nuScenes latitudes").
    let r = ground_resolution_m_per_px(45.0, 20);
    assert!((r - 0.105_55).abs() < 1e-4, "{r}");
    let z = 17;
    let nw = TileId {
        zoom: z,
        x: 0,
        y: 0,
    }
    .bounds_lat_lon()
    .0;
    assert!((nw.0 - 85.051_128_78).abs() < 1e-6 && (nw.1 + 180.0).abs() < 1e-9);
    assert_eq!(
        TileId::containing(
            WorldPixel {
                x_px: -0.5,
                y_px: 3.0
            },
            z
        ),
        None
    );
    assert_eq!(TileId::from_lat_lon(0.0, 0.0, 31), None);
}

#[test]
fn web_mercator_round_trips_below_a_micro_pixel() {
    for &(lat, lon) in &[
        (0.0, 0.0),
        (41.85, -87.65),
        (-33.86, 151.21),
        (1.29, 103.85),
        (84.0, 179.9),
    ] {
        let p = lat_lon_to_world_px(lat, lon, 20);
        let (lat2, lon2) = world_px_to_lat_lon(p, 20);
        let back = lat_lon_to_world_px(lat2, lon2, 20);
        assert!((back.x_px - p.x_px).abs() < 1e-6 && (back.y_px - p.y_px).abs() < 1e-6);
        assert!((lat2 - lat).abs() < 1e-10 && (lon2 - lon).abs() < 1e-10);
    }
}

#[test]
fn ecef_geodetic_round_trip_is_sub_millimetre() {
    for lat in [-89.9, -60.0, -12.3, 0.0, 1.5, 42.36, 78.0, 89.99] {
        for lon in [-179.0, -71.06, 0.0, 103.8, 180.0] {
            for h in [-100.0, 0.0, 8848.0, 35_000.0] {
                let g = Geodetic::new(lat, lon, h);
                let back = ecef_to_geodetic(geodetic_to_ecef(&g));
                let err_m = (geodetic_to_ecef(&back) - geodetic_to_ecef(&g)).length();
                assert!(err_m < 1e-3, "{g:?} -> {back:?}: {err_m} m");
                assert!((back.height_m - h).abs() < 1e-3);
            }
        }
    }
}

#[test]
fn enu_round_trips_at_cm_level_over_20_km() {
    for origin in [
        Geodetic::new(42.336, -71.057, 10.0),
        Geodetic::new(1.30, 103.78, 5.0),
        Geodetic::new(-45.0, 170.0, 0.0),
    ] {
        let frame = EnuFrame::new(origin);
        for k in 0..=40 {
            let angle = f64::from(k) * 0.157;
            let d_m = 500.0 * f64::from(k);
            let enu = DVec3::new(d_m * angle.cos(), d_m * angle.sin(), 2.0);
            let g = frame.enu_to_geodetic(enu);
            let back = frame.geodetic_to_enu(&g);
            assert!((back - enu).length() < 0.01, "{origin:?} {enu}: {back}");
        }
        // Ground distances in the frame match geodesic ones to ~1e-4 over 20 km: a point
        // 20 km north along the meridian sits 20 km (+-3 m) up the y axis.
        let north = frame.enu_to_geodetic(DVec3::new(0.0, 20_000.0, 0.0));
        assert!((north.lon_deg - origin.lon_deg).abs() < 1e-9);
        assert!(north.lat_deg > origin.lat_deg);
    }
}

#[test]
fn yaw_from_compass_heading() {
    let east = EnuFrame::yaw_rad_from_heading_deg(90.0);
    assert!(east.abs() < 1e-12);
    let north = EnuFrame::yaw_rad_from_heading_deg(0.0);
    assert!((north - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
}
