//! One route frame for a whole route: the distortion of the builder + vehicle chain, measured in
//! metres on the ground, and bounded for every route point within `MAX_ROUTE_RADIUS_M` of the
//! frame origin.
//!
//! For a true ground point G (height 0) at distance d from the pack origin, a compass heading
//! and an ego offset e on the crop's boundary (x_e right, y_e forward, the crop's 30 m x 60 m):
//! - truth T: the point at offset e from G in G's own local tangent frame along the heading,
//!   taken at height 0;
//! - runtime: the real `RoutePack::pose_from_wgs84` of a pack at that origin gives the pose, the
//!   crop's formula gives the plane point q, the builder's `ground_point(frame, q)` gives the
//!   ground point whose imagery the pack pixel at q shows (height reset to 0).
//!
//! Errors are ECEF distances: position (e = 0, what shifts the crop), shape (the offset vector
//! from the centre, i.e. scale and rotation), and total. `cargo test --test
//! integration route_frame_distortion -- --nocapture` prints the maxima per distance band.

use glam::{DVec2, DVec3};
use satmap_runtime::geo::{EnuFrame, Geodetic, geodetic_to_ecef};
use satmap_runtime::pose::EgoPose;
use satmap_runtime::route_pack::RoutePack;
use satmap_sim::route_pack_builder::{EARTH_RADIUS_M, MAX_ROUTE_RADIUS_M, ground_point};
use xxhash_rust::xxh3::xxh3_64;

/// Largest total error (crop centre and boundary) within [`ASSERT_RADIUS_M`], metres:
/// measured 9.09 cm (origin on the equator, G 107.5 km due north or south), bound with ~30 %
/// margin. Any metre-sized error on the ground fails it, and so does the old pose that used
/// the fix's height (13.5 m at 800 m up), see `the_bound_catches_a_wrong_chain`.
const TOTAL_BOUND_M: f64 = 0.12;
/// Largest position error (crop centre) within [`ASSERT_RADIUS_M`], metres: measured 8.60 cm.
const POSITION_BOUND_M: f64 = 0.12;
/// Largest shape error (boundary point relative to the centre: scale and rotation) within
/// [`ASSERT_RADIUS_M`], metres: measured 0.52 cm.
const SHAPE_BOUND_M: f64 = 0.01;
/// Where the bounds must hold: the farthest route point plus 2.5 km for a vehicle (and its
/// crop) off the route within a 5 km corridor.
const ASSERT_RADIUS_M: f64 = MAX_ROUTE_RADIUS_M + 2_500.0;

/// Pack origins: latitude, longitude (degrees). The equator is the worst case (meridional
/// radius farthest from the drop's sphere); 52 N sits on the antimeridian.
const ORIGINS: [(f64, f64); 5] = [
    (0.0, 10.0),
    (35.0, 139.7),
    (52.0, -179.6),
    (65.0, 25.0),
    (-35.0, 149.0),
];
/// Origin heights above the ellipsoid, metres.
const ORIGIN_HEIGHTS_M: [f64; 2] = [0.0, 500.0];
/// Heights of the fix above the ellipsoid, metres (the vehicle's own height).
const FIX_HEIGHTS_M: [f64; 2] = [0.0, 800.0];
/// Compass headings of the vehicle, degrees.
const HEADINGS_DEG: [f64; 7] = [0.0, 37.0, 90.0, 135.0, 200.0, 270.0, 315.0];
/// Bearings of G from the origin: every 22.5 degrees.
const BEARINGS: usize = 16;
/// Distances of G from the origin: every 2.5 km up to 150 km.
const DISTANCE_STEP_M: f64 = 2_500.0;
const DISTANCES: usize = 61;

/// Ego offsets (x_e right, y_e forward, metres) on the crop's boundary: corners, edge
/// midpoints and quarter points of the long edges.
const OFFSETS_M: [(f64, f64); 12] = [
    (-15.0, -30.0),
    (15.0, -30.0),
    (-15.0, 30.0),
    (15.0, 30.0),
    (0.0, -30.0),
    (0.0, 30.0),
    (-15.0, 0.0),
    (15.0, 0.0),
    (-15.0, -15.0),
    (15.0, -15.0),
    (-15.0, 15.0),
    (15.0, 15.0),
];

/// Distance bands of the table, metres: `(lo, hi]`, the first one including 0.
const BANDS_M: [(f64, f64); 4] = [
    (0.0, 10_000.0),
    (10_000.0, 50_000.0),
    (50_000.0, 100_000.0),
    (100_000.0, 150_000.0),
];

/// A one-tile pack at `origin`, so that the real `RoutePack::pose_from_wgs84` runs. Written
/// byte by byte as format version 1 (`FORMAT.md`), which every runtime reads: the test depends
/// on the frame, not on the writer's API.
fn pack_at(origin: Geodetic) -> Vec<u8> {
    const TILE_PX: u16 = 8;
    let payload = vec![0u8; usize::from(TILE_PX).pow(2) * 3];
    let mut index = Vec::new();
    index.extend_from_slice(&0i32.to_le_bytes());
    index.extend_from_slice(&0i32.to_le_bytes());
    index.extend_from_slice(&xxh3_64(&payload).to_le_bytes());
    let mut out = Vec::new();
    out.extend_from_slice(b"SMRPACK\0");
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&80u16.to_le_bytes());
    out.extend_from_slice(&TILE_PX.to_le_bytes());
    out.extend_from_slice(&[3, 0]);
    for v in [origin.lat_deg, origin.lon_deg, origin.height_m, 1.0, 0.0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&xxh3_64(&index).to_le_bytes());
    let header_xxh3 = xxh3_64(&out);
    out.extend_from_slice(&header_xxh3.to_le_bytes());
    out.extend_from_slice(&index);
    out.extend_from_slice(&payload);
    out
}

/// The ground point (height 0) at great-circle distance `d_m` and initial bearing
/// `bearing_deg` from `origin` on a sphere of the mean radius: a placement independent of the
/// chain under test (d is nominal; the table bands by plane distance).
fn destination(origin: &Geodetic, d_m: f64, bearing_deg: f64) -> Geodetic {
    let (lat1, lon1) = (origin.lat_deg.to_radians(), origin.lon_deg.to_radians());
    let delta = d_m / EARTH_RADIUS_M;
    let b = bearing_deg.to_radians();
    let lat2 = (lat1.sin() * delta.cos() + lat1.cos() * delta.sin() * b.cos()).asin();
    let lon2 =
        lon1 + (b.sin() * delta.sin() * lat1.cos()).atan2(delta.cos() - lat1.sin() * lat2.sin());
    Geodetic::new(lat2.to_degrees(), lon2.to_degrees(), 0.0)
}

/// ECEF of `p` taken at height 0.
fn on_ground(p: &Geodetic) -> DVec3 {
    geodetic_to_ecef(&Geodetic::new(p.lat_deg, p.lon_deg, 0.0))
}

/// Truth: ECEF of the point at ego offset `e` (x right, y forward) from `g` in `g`'s own local
/// tangent frame, the vehicle heading `heading_deg` (clockwise from north), at height 0.
fn truth(g: &Geodetic, heading_deg: f64, e: DVec2) -> DVec3 {
    let (s, c) = heading_deg.to_radians().sin_cos();
    let forward = DVec2::new(s, c);
    let right = DVec2::new(c, -s);
    let enu = right * e.x + forward * e.y;
    on_ground(&EnuFrame::new(*g).enu_to_geodetic(enu.extend(0.0)))
}

/// The plane point the crop samples for ego offset `e` (`crop.rs`: `position + x_e (sin yaw,
/// -cos yaw) + y_e (cos yaw, sin yaw)`).
fn crop_point(pose: &EgoPose, e: DVec2) -> DVec2 {
    let (s, c) = pose.yaw_rad.sin_cos();
    pose.position_m + DVec2::new(s, -c) * e.x + DVec2::new(c, s) * e.y
}

/// The chain under test: fix -> pose, and plane point -> ground point.
struct Chain<'a> {
    pose: &'a dyn Fn(&RoutePack<'_>, &Geodetic, f64) -> EgoPose,
    ground: &'a dyn Fn(&EnuFrame, DVec2) -> Geodetic,
}

fn real_pose(pack: &RoutePack<'_>, fix: &Geodetic, heading_deg: f64) -> EgoPose {
    pack.pose_from_wgs84(fix, heading_deg)
}

fn real_ground(frame: &EnuFrame, p: DVec2) -> Geodetic {
    ground_point(frame, p)
}

const REAL: Chain<'static> = Chain {
    pose: &real_pose,
    ground: &real_ground,
};

/// Worst errors (metres) over a set of cases, with the case of the worst total.
#[derive(Clone, Debug, Default)]
struct Worst {
    position_m: f64,
    shape_m: f64,
    total_m: f64,
    cases: usize,
    worst_case: String,
}

impl Worst {
    fn add(&mut self, position_m: f64, shape_m: f64, total_m: f64, case: impl FnOnce() -> String) {
        self.cases += 1;
        self.position_m = self.position_m.max(position_m);
        self.shape_m = self.shape_m.max(shape_m);
        if total_m > self.total_m {
            self.total_m = total_m;
            self.worst_case = case();
        }
    }
}

/// Run `chain` over every case; the worst errors in each of `bands` (plane distance of G from
/// the origin, `(lo, hi]`, the first including its `lo`).
fn measure(chain: &Chain<'_>, bands: &[(f64, f64)]) -> Vec<Worst> {
    let mut worst = vec![Worst::default(); bands.len()];
    for (lat, lon) in ORIGINS {
        for h0 in ORIGIN_HEIGHTS_M {
            let origin = Geodetic::new(lat, lon, h0);
            let bytes = pack_at(origin);
            let pack = RoutePack::parse(&bytes).unwrap();
            let frame = pack.frame();
            for k in 0..DISTANCES {
                let d_m = k as f64 * DISTANCE_STEP_M;
                for b in 0..BEARINGS {
                    let bearing = b as f64 * 360.0 / BEARINGS as f64;
                    let g = destination(&origin, d_m, bearing);
                    let radius_m = frame.geodetic_to_enu(&g).truncate().length();
                    let in_band = |(i, &(lo, hi)): (usize, &(f64, f64))| {
                        (radius_m > lo || (i == 0 && radius_m >= lo)) && radius_m <= hi
                    };
                    let Some(band) = bands.iter().enumerate().position(in_band) else {
                        continue;
                    };
                    let g_ecef = on_ground(&g);
                    for fix_h in FIX_HEIGHTS_M {
                        let fix = Geodetic::new(g.lat_deg, g.lon_deg, fix_h);
                        for heading in HEADINGS_DEG {
                            let pose = (chain.pose)(&pack, &fix, heading);
                            let centre = on_ground(&(chain.ground)(frame, pose.position_m));
                            let position_m = centre.distance(g_ecef);
                            let case = |e: DVec2| {
                                move || {
                                    format!(
                                        "origin ({lat}, {lon}, {h0} m), d {:.1} km, bearing \
                                         {bearing}, fix height {fix_h} m, heading {heading}, \
                                         offset ({}, {})",
                                        d_m / 1000.0,
                                        e.x,
                                        e.y
                                    )
                                }
                            };
                            worst[band].add(position_m, 0.0, position_m, case(DVec2::ZERO));
                            for (x_e, y_e) in OFFSETS_M {
                                let e = DVec2::new(x_e, y_e);
                                let r = on_ground(&(chain.ground)(frame, crop_point(&pose, e)));
                                let t = truth(&g, heading, e);
                                let shape_m = ((r - centre) - (t - g_ecef)).length();
                                worst[band].add(position_m, shape_m, r.distance(t), case(e));
                            }
                        }
                    }
                }
            }
        }
    }
    worst
}

fn print_table(title: &str, bands: &[(f64, f64)], worst: &[Worst]) {
    println!("{title}");
    println!("| band (km) | cases | position max (cm) | shape max (cm) | total max (cm) |");
    println!("|---|---|---|---|---|");
    for (&(lo, hi), w) in bands.iter().zip(worst) {
        println!(
            "| {:.1}-{:.1} | {} | {:.2} | {:.3} | {:.2} |",
            lo / 1000.0,
            hi / 1000.0,
            w.cases,
            w.position_m * 100.0,
            w.shape_m * 100.0,
            w.total_m * 100.0
        );
    }
    for (&(lo, hi), w) in bands.iter().zip(worst) {
        println!(
            "worst total in {:.1}-{:.1} km: {}",
            lo / 1000.0,
            hi / 1000.0,
            w.worst_case
        );
    }
}

/// The worst errors within the supported radius.
fn worst_within_bound(chain: &Chain<'_>) -> Worst {
    measure(chain, &[(0.0, ASSERT_RADIUS_M)]).remove(0)
}

#[test]
fn one_route_frame_stays_within_its_bound_up_to_the_max_route_radius() {
    let worst = measure(&REAL, &BANDS_M);
    print_table(
        "route frame distortion, builder + vehicle chain, on the ground:",
        &BANDS_M,
        &worst,
    );
    let within = worst_within_bound(&REAL);
    println!(
        "within {:.1} km (MAX_ROUTE_RADIUS_M + 2.5 km): position {:.2} cm, shape {:.3} cm, \
         total {:.2} cm ({} cases); bounds {} / {} / {} cm",
        ASSERT_RADIUS_M / 1000.0,
        within.position_m * 100.0,
        within.shape_m * 100.0,
        within.total_m * 100.0,
        within.cases,
        POSITION_BOUND_M * 100.0,
        SHAPE_BOUND_M * 100.0,
        TOTAL_BOUND_M * 100.0
    );
    assert!(within.cases > 100_000, "{} cases", within.cases);
    assert!(
        within.position_m <= POSITION_BOUND_M,
        "position {} m",
        within.position_m
    );
    assert!(
        within.shape_m <= SHAPE_BOUND_M,
        "shape {} m",
        within.shape_m
    );
    assert!(
        within.total_m <= TOTAL_BOUND_M,
        "total {} m at {}",
        within.total_m,
        within.worst_case
    );
    // Next to the origin the chain is exact up to float rounding and the mm-scale local scale.
    assert!(worst[0].total_m < 0.002, "{:?}", worst[0]);
}

/// The bound would catch the mistakes it is there for: each mutant chain exceeds it within the
/// supported radius.
#[test]
fn the_bound_catches_a_wrong_chain() {
    // The old pose: the fix taken at its own height (800 m here), 12 m off at 100 km.
    let fix_height_used = |pack: &RoutePack<'_>, fix: &Geodetic, heading_deg: f64| {
        let frame = pack.frame();
        let here = frame.geodetic_to_enu(fix);
        let (s, c) = heading_deg.to_radians().sin_cos();
        let ahead = EnuFrame::new(*fix).enu_to_geodetic(DVec3::new(10.0 * s, 10.0 * c, 0.0));
        let d = frame.geodetic_to_enu(&ahead) - here;
        EgoPose::new(here.truncate(), d.y.atan2(d.x))
    };
    // The builder reading the imagery under the tangent plane itself (no drop to the ellipsoid).
    let no_drop = |frame: &EnuFrame, p: DVec2| frame.enu_to_geodetic(p.extend(0.0));
    // The heading taken as a yaw at the origin (meridian convergence left out): a rotation of
    // the crop, up to a degree at 100 km.
    let no_convergence = |pack: &RoutePack<'_>, fix: &Geodetic, heading_deg: f64| {
        let pose = pack.pose_from_wgs84(fix, heading_deg);
        EgoPose::new(
            pose.position_m,
            EnuFrame::yaw_rad_from_heading_deg(heading_deg),
        )
    };
    // Any metre-sized error on the ground, e.g. a sphere-for-ellipsoid slip: the ground point
    // 1 m east of where it should be.
    let one_metre_east = |frame: &EnuFrame, p: DVec2| {
        let g = ground_point(frame, p);
        EnuFrame::new(g).enu_to_geodetic(DVec3::X)
    };
    let mutants: [(&str, Chain<'_>); 4] = [
        (
            "fix height used",
            Chain {
                pose: &fix_height_used,
                ground: &real_ground,
            },
        ),
        (
            "no drop to the ellipsoid",
            Chain {
                pose: &real_pose,
                ground: &no_drop,
            },
        ),
        (
            "no meridian convergence",
            Chain {
                pose: &no_convergence,
                ground: &real_ground,
            },
        ),
        (
            "ground point 1 m off",
            Chain {
                pose: &real_pose,
                ground: &one_metre_east,
            },
        ),
    ];
    for (name, chain) in mutants {
        let w = worst_within_bound(&chain);
        println!(
            "mutant {name}: position {:.2} cm, shape {:.3} cm, total {:.2} cm",
            w.position_m * 100.0,
            w.shape_m * 100.0,
            w.total_m * 100.0
        );
        assert!(
            w.total_m > 2.0 * TOTAL_BOUND_M,
            "{name}: {} m is not caught by the {TOTAL_BOUND_M} m bound",
            w.total_m
        );
    }
}
