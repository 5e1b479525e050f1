//! [`SyntheticRoute`]: a procedural winding road of up to 200 km in a local ENU frame, and
//! [`SyntheticRouteImagery`], satellite-like imagery of the ground around it, both
//! deterministic from a seed. The imagery is procedural (no raster), so a pack of any route
//! length can be built from it with [`build_pack`](super::build_pack).
//!
//! Route: a heading that follows straights and circular arcs (radius 150..1500 m) joined by
//! linear curvature ramps (clothoid-like, 40..100 m), integrated at one vertex every ~10 m.
//! Once the road is farther than [`HOME_FRACTION`] of its length from its start, arcs turn
//! back towards the start, so the road winds instead of running away (100 km routes of seeds
//! 1..3 stay within 21 km of their start, well inside the builder's
//! [`MAX_ROUTE_RADIUS_M`](super::MAX_ROUTE_RADIUS_M)).
//!
//! Imagery: source coordinates are the route frame's metres (ENU at the anchor, as
//! [`RasterImagery`](crate::harness::world_imagery::RasterImagery)). A 7 m asphalt band along
//! the route with solid edge lines and a dashed centre line (3 m dashes every 12 m), gravel
//! shoulders and grass verges, over farmland: domain-warped Voronoi fields (~50..200 m) of
//! eight kinds (crops, soil, pasture, meadow, woodland) with their own base colour, row
//! stripes and texture, field-edge tracks, and blobs of trees. Texture is value noise of four
//! octaves (90, 7, 2.5 and 0.9 m, four channels each, read from one 256 x 256 lattice table at
//! a different rotation and offset per octave) plus a 0.25 m grain hash. Markings and the
//! asphalt's edge are box-filtered over one pack pixel ([`SyntheticRoute::imagery_at`]).
//! Distance to the road uses a hash grid of the route's segments ([`CELL_M`] cells) built
//! once; a sample (about 90 ns) does no allocation and never returns a gap.

use std::f64::consts::{PI, TAU};

use glam::{DVec2, DVec3, Vec2, Vec3A, Vec4};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use satmap_runtime::geo::{EnuFrame, Geodetic};

use super::error::BuildError;
use super::frame::ground_point;
use super::imagery::{Gap, Imagery};

/// Longest route, kilometres.
pub const MAX_ROUTE_KM: f64 = 200.0;
/// Target spacing of route vertices, metres (the exact spacing divides the length evenly).
pub const VERTEX_STEP_M: f64 = 10.0;
/// Smallest curve radius of the road, metres.
pub const MIN_RADIUS_M: f64 = 150.0;
/// Largest curve radius of an arc, metres.
pub const MAX_RADIUS_M: f64 = 1500.0;
/// Width of the asphalt, metres (two 3.5 m lanes).
pub const ROAD_WIDTH_M: f64 = 7.0;
/// Beyond this distance from the start, as a fraction of the length, arcs turn homewards.
pub const HOME_FRACTION: f64 = 0.3;
/// Side of a cell of the road's segment grid, metres.
pub const CELL_M: f64 = 16.0;

/// Distance from the centre line up to which the road (and its verge) is drawn, metres; the
/// segment grid lists every segment within this distance of a cell.
const ROAD_REACH_M: f64 = 9.0;
/// Share of pieces that are straights (while not homing).
const STRAIGHT_SHARE: f64 = 0.35;
/// Side of a cell of the field Voronoi grid, metres (one field per cell on average).
const FIELD_CELL_M: f64 = 110.0;

/// A procedural winding road in the local ENU frame of an anchor.
#[derive(Clone, Debug)]
pub struct SyntheticRoute {
    seed: u64,
    anchor: Geodetic,
    frame: EnuFrame,
    route_m: Vec<DVec2>,
    length_m: f64,
    grid: SegmentGrid,
}

impl SyntheticRoute {
    /// A road of `length_km` from `anchor` (the route frame's origin and the road's first
    /// point), shaped by `seed`.
    ///
    /// # Errors
    /// [`BuildError::Option`] for a length that is not finite or outside (0, 200] km, or an
    /// anchor that is not a valid WGS84 position.
    pub fn new(seed: u64, length_km: f64, anchor: Geodetic) -> Result<Self, BuildError> {
        if !(length_km.is_finite() && length_km > 0.0 && length_km <= MAX_ROUTE_KM) {
            return Err(BuildError::Option(format!(
                "synthetic route length {length_km} km is outside (0, {MAX_ROUTE_KM}] km"
            )));
        }
        if !anchor.is_valid() || anchor.lat_deg.abs() > 89.0 {
            return Err(BuildError::Option(format!(
                "synthetic route anchor {anchor:?} is not a valid position below 89 deg latitude"
            )));
        }
        let length_m = length_km * 1000.0;
        let route_m = generate_route(seed, length_m);
        let length_m = route_m.windows(2).map(|w| w[0].distance(w[1])).sum();
        let grid = SegmentGrid::new(&route_m);
        Ok(Self {
            seed,
            anchor,
            frame: EnuFrame::new(anchor),
            route_m,
            length_m,
            grid,
        })
    }

    /// The route in WGS84 (ellipsoid height 0), one point per vertex of [`Self::route_m`]:
    /// the point on the ellipsoid straight below (along the frame's up) the plane point, so
    /// that WGS84 -> ENU at [`Self::anchor`] (the builder with this origin, the vehicle, and
    /// [`Imagery::project`] here) gives back [`Self::route_m`] to well under a millimetre.
    #[must_use]
    pub fn route_wgs84(&self) -> Vec<Geodetic> {
        self.route_m
            .iter()
            .map(|p| on_ellipsoid(&self.frame, *p))
            .collect()
    }

    /// The route's vertices in the route frame (ENU at [`Self::anchor`], x east, y north),
    /// metres; the first is the origin.
    #[must_use]
    pub fn route_m(&self) -> &[DVec2] {
        &self.route_m
    }

    /// Length of the polyline, metres.
    #[must_use]
    pub const fn length_m(&self) -> f64 {
        self.length_m
    }

    /// The route frame's origin.
    #[must_use]
    pub const fn anchor(&self) -> Geodetic {
        self.anchor
    }

    /// Largest distance of a vertex from the first one, metres.
    #[must_use]
    pub fn max_distance_from_start_m(&self) -> f64 {
        self.route_m.iter().map(|p| p.length()).fold(0.0, f64::max)
    }

    /// The imagery of the ground around the road, its markings filtered for packs at
    /// [`DEFAULT_PIXEL_M`] (0.15 m/px); see [`Self::imagery_at`] for other resolutions.
    #[must_use]
    pub fn imagery(&self) -> SyntheticRouteImagery<'_> {
        SyntheticRouteImagery::new(self, DEFAULT_PIXEL_M)
    }

    /// The imagery for packs at `gsd_m` metres per pixel: the 0.15..0.2 m lane markings are
    /// box-filtered over one pixel, so at a coarser GSD than the filter's they keep their
    /// weight instead of vanishing between pixel centres.
    #[must_use]
    pub fn imagery_at(&self, gsd_m: f64) -> SyntheticRouteImagery<'_> {
        SyntheticRouteImagery::new(self, gsd_m)
    }
}

/// The point at ellipsoid height 0 whose ENU x, y in `frame` are `p` (height set to exactly 0).
///
/// Forcing height 0 on the plane point itself would shift it sideways by about
/// `d^3 / 2R^2` (1.5 m at 50 km); the builder's [`ground_point`] (the plane point dropped onto
/// a sphere) is within metres of the ellipsoid, and one step along the frame's up by its height
/// lands on the ellipsoid to within micrometres without moving the point in x, y.
fn on_ellipsoid(frame: &EnuFrame, p: DVec2) -> Geodetic {
    let g = ground_point(frame, p);
    let z_m = frame.geodetic_to_enu(&g).z - g.height_m;
    let g = frame.enu_to_geodetic(DVec3::new(p.x, p.y, z_m));
    Geodetic::new(g.lat_deg, g.lon_deg, 0.0)
}

/// One piece of the road: the curvature ramps linearly from `k_from` to `k_to` over
/// `ramp_m`, then stays at `k_to` until `len_m`.
struct Piece {
    k_from: f64,
    k_to: f64,
    ramp_m: f64,
    len_m: f64,
    s_m: f64,
}

impl Piece {
    fn curvature(&self, s_m: f64) -> f64 {
        if s_m >= self.ramp_m {
            self.k_to
        } else {
            self.k_from + (self.k_to - self.k_from) * s_m / self.ramp_m
        }
    }
}

/// Angle wrapped to [-pi, pi).
fn wrap_angle(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// The next piece after the road reached `p` with `heading` and curvature `k_now`.
fn next_piece(rng: &mut Pcg64, p: DVec2, heading: f64, k_now: f64, total_m: f64) -> Piece {
    let ramp_m = rng.random_range(40.0..100.0);
    let straight = |rng: &mut Pcg64, lo: f64, hi: f64| Piece {
        k_from: k_now,
        k_to: 0.0,
        ramp_m,
        len_m: ramp_m + rng.random_range(lo..hi),
        s_m: 0.0,
    };
    let radius = MIN_RADIUS_M * (MAX_RADIUS_M / MIN_RADIUS_M).powf(rng.random_range(0.0..1.0));
    let (sign, turn) = if p.length() > HOME_FRACTION * total_m {
        let err = wrap_angle((-p).to_angle() - heading);
        if err.abs() < 0.3 {
            return straight(rng, 200.0, 600.0);
        }
        (err.signum(), err.abs() * rng.random_range(0.7..1.0))
    } else {
        if rng.random_range(0.0..1.0) < STRAIGHT_SHARE {
            return straight(rng, 100.0, 800.0);
        }
        let sign = if rng.random_range(0.0..1.0) < 0.5 {
            -1.0
        } else {
            1.0
        };
        (sign, rng.random_range(0.25..1.7))
    };
    Piece {
        k_from: k_now,
        k_to: sign / radius,
        ramp_m,
        len_m: ramp_m + turn * radius,
        s_m: 0.0,
    }
}

/// The road's vertices: `length_m` in equal steps of about [`VERTEX_STEP_M`], from the origin.
fn generate_route(seed: u64, length_m: f64) -> Vec<DVec2> {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5e7_0ad5_ca1e_b0a7);
    let steps = (length_m / VERTEX_STEP_M).ceil().max(1.0) as usize;
    let ds = length_m / steps as f64;
    let mut p = DVec2::ZERO;
    let mut heading = rng.random_range(-PI..PI);
    let mut k = 0.0;
    let mut piece = next_piece(&mut rng, p, heading, k, length_m);
    let mut points = Vec::with_capacity(steps + 1);
    points.push(p);
    for _ in 0..steps {
        if piece.s_m >= piece.len_m {
            piece = next_piece(&mut rng, p, heading, k, length_m);
        }
        // Constant curvature over the step, taken at its middle: the chord leaves at the mean
        // heading, so consecutive chords turn by at most ds / MIN_RADIUS_M.
        k = piece.curvature(piece.s_m + 0.5 * ds);
        p += ds * DVec2::from_angle(heading + 0.5 * k * ds);
        heading = wrap_angle(heading + k * ds);
        piece.s_m += ds;
        points.push(p);
    }
    points
}

/// One route segment: start, unit direction, length, and arc length at its start.
#[derive(Clone, Copy, Debug)]
struct Segment {
    a: DVec2,
    dir: DVec2,
    len: f64,
    s0: f64,
}

/// One slot of the open-addressing cell table; `start == end` is an empty slot (an occupied
/// cell has at least one segment).
#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    cx: i32,
    cy: i32,
    start: u32,
    end: u32,
}

/// Route segments by [`CELL_M`] cell: every segment within [`ROAD_REACH_M`] of a cell is
/// listed (copied) under it.
#[derive(Clone, Debug)]
struct SegmentGrid {
    segments: Vec<Segment>,
    slots: Vec<Slot>,
    mask: usize,
}

/// Floor of `v` as an `i32`, for |v| < 2^31 (beyond, or for NaN, some `i32`), without a libm
/// call or the saturation checks of `as`: adding 1.5 * 2^52 rounds to an integer in the low
/// mantissa bits (two's complement), then one compare turns the rounding into a floor.
#[inline]
fn floor_i32(v: f64) -> i32 {
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let i = (v + MAGIC).to_bits() as u32 as i32;
    i.wrapping_sub(i32::from(f64::from(i) > v))
}

#[inline]
fn slot_of(cx: i32, cy: i32, mask: usize) -> usize {
    let key = (u64::from(cx as u32) << 32) | u64::from(cy as u32);
    (key.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32) as usize & mask
}

impl SegmentGrid {
    fn new(route_m: &[DVec2]) -> Self {
        let mut entries: Vec<(i32, i32, Segment)> = Vec::new();
        let mut s0 = 0.0;
        for w in route_m.windows(2) {
            let d = w[1] - w[0];
            let len = d.length();
            let seg = Segment {
                a: w[0],
                dir: if len > 0.0 { d / len } else { DVec2::X },
                len,
                s0,
            };
            s0 += len;
            let lo = w[0].min(w[1]) - ROAD_REACH_M;
            let hi = w[0].max(w[1]) + ROAD_REACH_M;
            for cy in floor_i32(lo.y / CELL_M)..=floor_i32(hi.y / CELL_M) {
                for cx in floor_i32(lo.x / CELL_M)..=floor_i32(hi.x / CELL_M) {
                    entries.push((cx, cy, seg));
                }
            }
        }
        entries.sort_unstable_by_key(|&(cx, cy, _)| (cx, cy));
        let cells = entries
            .windows(2)
            .filter(|w| (w[0].0, w[0].1) != (w[1].0, w[1].1))
            .count()
            + 1;
        let capacity = (2 * cells).next_power_of_two().max(16);
        let mask = capacity - 1;
        let mut slots = vec![Slot::default(); capacity];
        let mut start = 0;
        while start < entries.len() {
            let (cx, cy, _) = entries[start];
            let end = entries[start..]
                .iter()
                .position(|&(x, y, _)| (x, y) != (cx, cy))
                .map_or(entries.len(), |n| start + n);
            let mut i = slot_of(cx, cy, mask);
            while slots[i].start != slots[i].end {
                i = (i + 1) & mask;
            }
            slots[i] = Slot {
                cx,
                cy,
                start: start as u32,
                end: end as u32,
            };
            start = end;
        }
        Self {
            segments: entries.into_iter().map(|(_, _, s)| s).collect(),
            slots,
            mask,
        }
    }

    /// The range of [`Self::segments`] listed under cell `(cx, cy)` (empty if none).
    fn cell(&self, cx: i32, cy: i32) -> (u32, u32) {
        let mut i = slot_of(cx, cy, self.mask);
        loop {
            let s = self.slots[i];
            if s.start == s.end {
                return (0, 0);
            }
            if s.cx == cx && s.cy == cy {
                return (s.start, s.end);
            }
            i = (i + 1) & self.mask;
        }
    }
}

/// 32-bit integer hash of a lattice point.
#[inline]
fn hash2(seed: u32, x: i32, y: i32) -> u32 {
    let mut h = seed
        ^ (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841).rotate_left(16);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^ (h >> 16)
}

/// Re-mix of a hash for a further independent value.
#[inline]
fn remix(h: u32) -> u32 {
    let h = (h ^ 0x9e37_79b9).wrapping_mul(0x2c1b_3c6d);
    h ^ (h >> 15)
}

/// A hash as a number in [0, 1).
#[inline]
fn unit(h: u32) -> f64 {
    f64::from(h >> 8) * (1.0 / 16_777_216.0)
}

#[inline]
fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    // A product, not a quotient: with constant edges the reciprocal folds at compile time.
    let t = ((x - e0) * (1.0 / (e1 - e0))).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Share of a pixel of width `pixel_m` (`inv_pixel` its inverse) centred at `x` that the
/// interval of width `width` centred at 0 covers (a box-filtered edge: markings thinner than
/// a pixel keep their area instead of aliasing).
#[inline]
fn box_cover(x: f32, width: f32, pixel_m: f32, inv_pixel: f32) -> f32 {
    let lo = (x - 0.5 * pixel_m).max(-0.5 * width);
    let hi = (x + 0.5 * pixel_m).min(0.5 * width);
    ((hi - lo) * inv_pixel).clamp(0.0, 1.0)
}

/// Side of the value-noise lattice table, lattice points (a power of two; every octave tiles
/// it, at its own rotation, scale and offset, so the repeats do not line up).
const LATTICE_SIDE: usize = 256;
/// The lattice table: four independent values in [0, 1] per lattice point.
type Lattice = [Vec4; LATTICE_SIDE * LATTICE_SIDE];

/// One value-noise octave: route-frame metres to lattice coordinates.
#[derive(Clone, Copy, Debug)]
struct Octave {
    row_x: DVec2,
    row_y: DVec2,
    offset: DVec2,
}

/// The four octaves' maps side by side (lane k: octave k), for lattice coordinates relative
/// to a road-grid cell's corner: `x = base_x + xx * dx + xy * dy` with `(dx, dy)` the point
/// minus the corner (under 16 m, so f32 keeps it exact enough anywhere on a 200 km route).
#[derive(Clone, Copy, Debug)]
struct OctaveLanes {
    xx: Vec4,
    xy: Vec4,
    yx: Vec4,
    yy: Vec4,
}

/// The octaves, periods in metres: 0 (90 m) warp x, warp y, moisture, large tree density;
/// 1 (7 m) small tree density, bare-soil patches, texture, canopy; 2 and 3 (2.5, 0.9 m)
/// texture, canopy.
const OCTAVE_PERIODS_M: [f64; 4] = [90.0, 7.0, 2.5, 0.9];

/// A kind of field: base colour, row-stripe contrast, texture contrast, bare-soil patchiness,
/// extra tree density.
struct FieldKind {
    base: Vec3A,
    stripes: f32,
    texture: f32,
    patches: f32,
    trees: f32,
}

const fn kind(base: [f32; 3], stripes: f32, texture: f32, patches: f32, trees: f32) -> FieldKind {
    FieldKind {
        base: Vec3A::from_array(base),
        stripes,
        texture,
        patches,
        trees,
    }
}

/// Field kinds: green crop, young crop (soil between the rows), ripe cereal, ploughed soil,
/// dark soil, pasture, dry meadow, woodland; drawn by hash (`FIELD_DRAW`, per 16th).
const FIELD_KINDS: [FieldKind; 8] = [
    kind([82.0, 104.0, 52.0], 0.10, 0.9, 0.10, 0.0),
    kind([120.0, 124.0, 78.0], 0.20, 0.8, 0.15, 0.0),
    kind([178.0, 160.0, 106.0], 0.07, 0.6, 0.05, 0.0),
    kind([124.0, 102.0, 78.0], 0.16, 1.0, 0.0, 0.0),
    kind([98.0, 83.0, 66.0], 0.09, 1.0, 0.0, 0.0),
    kind([98.0, 116.0, 64.0], 0.0, 1.1, 0.30, 0.05),
    kind([146.0, 138.0, 94.0], 0.02, 1.0, 0.20, 0.08),
    kind([70.0, 86.0, 50.0], 0.0, 1.2, 0.0, 0.45),
];
const FIELD_DRAW: [u8; 16] = [0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 5, 5, 5, 6, 7, 7];
/// Bare soil showing through grass and crops.
const SOIL: Vec3A = Vec3A::new(128.0, 110.0, 86.0);
const ASPHALT: Vec3A = Vec3A::new(72.0, 73.0, 76.0);
const PAINT: Vec3A = Vec3A::new(222.0, 222.0, 214.0);
const GRAVEL: Vec3A = Vec3A::new(140.0, 133.0, 118.0);
const VERGE: Vec3A = Vec3A::new(104.0, 116.0, 70.0);
const TRACK: Vec3A = Vec3A::new(132.0, 120.0, 96.0);
const TREE_DARK: Vec3A = Vec3A::new(30.0, 44.0, 26.0);
const TREE_LIGHT: Vec3A = Vec3A::new(62.0, 84.0, 44.0);

/// Half the asphalt width, metres.
const ROAD_HALF_M: f32 = 0.5 * ROAD_WIDTH_M as f32;
/// Offset of the edge lines' centre from the centre line, metres.
const EDGE_LINE_M: f32 = ROAD_HALF_M - 0.3;
/// Width of the edge lines, metres.
const EDGE_LINE_WIDTH_M: f32 = 0.2;
/// Width of the centre line, metres.
const CENTRE_LINE_WIDTH_M: f32 = 0.15;
/// Centre-line dash, metres.
const DASH_M: f64 = 3.0;
/// Centre-line dash plus gap, metres.
const DASH_PERIOD_M: f64 = 12.0;
/// Default pixel footprint of [`SyntheticRoute::imagery`], metres (the default pack GSD).
pub const DEFAULT_PIXEL_M: f64 = 0.15;

/// The 3x3 jittered Voronoi sites around the last field cell looked up, with each field's
/// hash and row vector (direction over spacing, per metre).
#[derive(Clone, Copy)]
struct FieldSites {
    cell: Option<(i32, i32)>,
    /// Relative to the cell's corner, cells.
    sites: [Vec2; 9],
    hashes: [u32; 9],
    rows: [DVec2; 9],
    /// The last nearest and second-nearest sites, and the bisector distance per unit of
    /// their squared-distance difference, metres.
    pair: (usize, usize),
    edge_scale: f32,
}

/// What [`SyntheticRouteImagery::field`] finds at a point.
struct FieldAt {
    hash: u32,
    /// Distance to the field's boundary, metres.
    edge_m: f32,
    /// Across-row direction over the row spacing, per metre.
    rows: DVec2,
}

/// Noise values at one point (see [`OCTAVE_PERIODS_M`]).
struct Noise {
    /// Octave 0: warp x, warp y, moisture, large tree density.
    coarse: Vec4,
    /// Octave 1: small tree density, bare-soil patches.
    mid: Vec4,
    /// Octaves 1..3 (z, x, x): texture, coarse to fine.
    tex: Vec3A,
    /// Octaves 1..3 (w, y, y): canopy texture, coarse to fine.
    crown: Vec3A,
    /// Per-0.25 m grain in [-0.5, 0.5).
    grain: f32,
}

/// Satellite-like imagery of a [`SyntheticRoute`]'s surroundings; source coordinates are
/// route-frame metres. Caches the last grid cells looked up (samples arrive row by row).
pub struct SyntheticRouteImagery<'a> {
    route: &'a SyntheticRoute,
    frame: EnuFrame,
    seed: u32,
    lattice: Box<Lattice>,
    octaves: [Octave; 4],
    lanes: OctaveLanes,
    /// The current road cell's corner, metres, and the octaves' lattice coordinates there
    /// (modulo the lattice side).
    corner: DVec2,
    base_x: Vec4,
    base_y: Vec4,
    /// Pixel footprint the paint and the asphalt's edges are box-filtered over, metres.
    pixel_m: f32,
    inv_pixel: f32,
    road_cell: (i32, i32),
    road_range: (u32, u32),
    fields: FieldSites,
}

impl<'a> SyntheticRouteImagery<'a> {
    /// The imagery of `route` for packs of `pixel_m` metres per pixel (the road's edges and
    /// markings are box-filtered over one pixel; clamped to 0.01..=10 m).
    #[must_use]
    pub fn new(route: &'a SyntheticRoute, pixel_m: f64) -> Self {
        let mut z = route.seed ^ 0x001a_6e5e_edf1_e1d5_u64;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        let seed = (z ^ (z >> 31)) as u32;
        let lattice: Box<Lattice> = (0..LATTICE_SIDE * LATTICE_SIDE)
            .map(|i| {
                let (x, y) = ((i % LATTICE_SIDE) as i32, (i / LATTICE_SIDE) as i32);
                let (a, b) = (hash2(seed, x, y), hash2(seed ^ 0x7a11_ce5e, x, y));
                let half = |h: u32| (h & 0xffff) as f32 / 65_535.0;
                Vec4::new(half(a), half(a >> 16), half(b), half(b >> 16))
            })
            .collect::<Vec<_>>()
            .into_boxed_slice()
            .try_into()
            .unwrap_or_else(|_| unreachable!("the lattice has LATTICE_SIDE^2 points"));
        let side = LATTICE_SIDE as f64;
        let octaves = std::array::from_fn(|k| {
            let h = hash2(seed ^ 0x00c7_a7e5, k as i32, 0);
            // Rotations spread over the half turn, so no two octaves share a lattice axis.
            let r =
                DVec2::from_angle(PI * (k as f64 * 0.382 + 0.1 * unit(h))) / OCTAVE_PERIODS_M[k];
            Octave {
                row_x: DVec2::new(r.x, -r.y),
                row_y: DVec2::new(r.y, r.x),
                offset: DVec2::new(unit(remix(h)), unit(remix(remix(h)))) * side,
            }
        });
        let lane = |f: fn(&Octave) -> f64| {
            Vec4::from_array(std::array::from_fn(|k| f(&octaves[k]) as f32))
        };
        let lanes = OctaveLanes {
            xx: lane(|o| o.row_x.x),
            xy: lane(|o| o.row_x.y),
            yx: lane(|o| o.row_y.x),
            yy: lane(|o| o.row_y.y),
        };
        // A cell beyond any route (i32::MIN) is empty, so the stale range is right for it;
        // the lattice base is set with the first sample's cell.
        let road_cell = (i32::MIN, i32::MIN);
        let pixel_m = if pixel_m.is_finite() {
            pixel_m.clamp(0.01, 10.0) as f32
        } else {
            DEFAULT_PIXEL_M as f32
        };
        Self {
            route,
            frame: route.frame,
            seed,
            lattice,
            octaves,
            lanes,
            corner: DVec2::NAN,
            base_x: Vec4::ZERO,
            base_y: Vec4::ZERO,
            pixel_m,
            inv_pixel: 1.0 / pixel_m,
            road_cell,
            road_range: route.grid.cell(road_cell.0, road_cell.1),
            fields: FieldSites {
                cell: None,
                sites: [Vec2::ZERO; 9],
                hashes: [0; 9],
                rows: [DVec2::ZERO; 9],
                pair: (usize::MAX, usize::MAX),
                edge_scale: 0.0,
            },
        }
    }

    /// Distance from `p` to the centre line and arc length of the nearest point, if within
    /// [`ROAD_REACH_M`].
    #[inline]
    fn road(&mut self, p: DVec2) -> Option<(f64, f64)> {
        let cell = (floor_i32(p.x / CELL_M), floor_i32(p.y / CELL_M));
        if cell != self.road_cell {
            self.road_cell = cell;
            self.road_range = self.route.grid.cell(cell.0, cell.1);
            self.corner = DVec2::new(f64::from(cell.0), f64::from(cell.1)) * CELL_M;
            let side = LATTICE_SIDE as f64;
            let wrap = |v: f64| (v - side * f64::from(floor_i32(v * (1.0 / side)))) as f32;
            let base = |k: usize| {
                let o = &self.octaves[k];
                let q = DVec2::new(o.row_x.dot(self.corner), o.row_y.dot(self.corner)) + o.offset;
                (wrap(q.x), wrap(q.y))
            };
            let b: [(f32, f32); 4] = std::array::from_fn(base);
            self.base_x = Vec4::new(b[0].0, b[1].0, b[2].0, b[3].0);
            self.base_y = Vec4::new(b[0].1, b[1].1, b[2].1, b[3].1);
        }
        let (start, end) = self.road_range;
        let mut best = ROAD_REACH_M * ROAD_REACH_M;
        let mut s = f64::NAN;
        for seg in &self.route.grid.segments[start as usize..end as usize] {
            let v = p - seg.a;
            let t = v.dot(seg.dir).clamp(0.0, seg.len);
            let d2 = (v - seg.dir * t).length_squared();
            if d2 < best {
                best = d2;
                s = seg.s0 + t;
            }
        }
        s.is_finite().then(|| (best.sqrt(), s))
    }

    /// The field containing `q` (warped metres).
    #[inline]
    fn field(&mut self, q: DVec2) -> FieldAt {
        let g = q * (1.0 / FIELD_CELL_M);
        let cell = (floor_i32(g.x), floor_i32(g.y));
        if self.fields.cell != Some(cell) {
            let salt = self.seed ^ 0x00f1_e1d5;
            for k in 0..9 {
                let (cx, cy) = (
                    cell.0.wrapping_add(k as i32 % 3 - 1),
                    cell.1.wrapping_add(k as i32 / 3 - 1),
                );
                let h = hash2(salt, cx, cy);
                let h2 = remix(h);
                let hash = remix(h2);
                self.fields.sites[k] = Vec2::new(
                    (k % 3) as f32 - 1.0 + 0.1 + 0.8 * unit(h) as f32,
                    (k / 3) as f32 - 1.0 + 0.1 + 0.8 * unit(h2) as f32,
                );
                let r = remix(hash);
                let spacing_m = 1.2 + 2.5 * unit(r);
                self.fields.rows[k] = DVec2::from_angle(PI * unit(remix(r))) / spacing_m;
                self.fields.hashes[k] = hash;
            }
            self.fields.cell = Some(cell);
            self.fields.pair = (usize::MAX, usize::MAX);
        }
        // In f32 about the cell's corner (sites within 2 cells of it).
        let base = DVec2::new(f64::from(cell.0), f64::from(cell.1));
        let local = (g - base).as_vec2();
        let (mut d1, mut d2) = (f32::INFINITY, f32::INFINITY);
        let (mut i1, mut i2) = (0, 0);
        for (k, site) in self.fields.sites.iter().enumerate() {
            let d = (local - *site).length_squared();
            if d < d1 {
                (d2, i2) = (d1, i1);
                (d1, i1) = (d, k);
            } else if d < d2 {
                (d2, i2) = (d, k);
            }
        }
        // Distance to the bisector of the two nearest sites (the pair rarely changes from one
        // sample to the next: its scale is kept).
        if self.fields.pair != (i1, i2) {
            let gap = (self.fields.sites[i2] - self.fields.sites[i1]).length();
            self.fields.pair = (i1, i2);
            self.fields.edge_scale = FIELD_CELL_M as f32 / (2.0 * gap.max(1e-6));
        }
        FieldAt {
            hash: self.fields.hashes[i1],
            edge_m: (d2 - d1) * self.fields.edge_scale,
            rows: self.fields.rows[i1],
        }
    }

    /// Value noise of the four octaves at `p` (in the road cell of the last [`Self::road`]
    /// call): four channels each, in [0, 1].
    #[inline]
    fn octaves(&self, p: DVec2) -> [Vec4; 4] {
        /// 1.5 * 2^23: adding it rounds an f32 to an integer held in the low mantissa bits.
        const MAGIC: f32 = 12_582_912.0;
        let l = (p - self.corner).as_vec2();
        let o = &self.lanes;
        let x = self.base_x + o.xx * l.x + o.xy * l.y;
        let y = self.base_y + o.yx * l.x + o.yy * l.y;
        // Floors by rounding x - 0.5 (a tie gives the cell below with a fraction of 1: the
        // same value, as value noise is continuous).
        let (rx, ry) = ((x - 0.5) + MAGIC, (y - 0.5) + MAGIC);
        let (fx, fy) = (x - (rx - MAGIC), y - (ry - MAGIC));
        let u = fx * fx * (3.0 - 2.0 * fx);
        let v = fy * fy * (3.0 - 2.0 * fy);
        let (rx, ry, u, v) = (rx.to_array(), ry.to_array(), u.to_array(), v.to_array());
        [
            self.lattice_at(rx[0], ry[0], u[0], v[0]),
            self.lattice_at(rx[1], ry[1], u[1], v[1]),
            self.lattice_at(rx[2], ry[2], u[2], v[2]),
            self.lattice_at(rx[3], ry[3], u[3], v[3]),
        ]
    }

    /// Bilinear blend of the lattice cell whose corner is held in the low bits of `rx`, `ry`
    /// (see [`Self::octaves`]), at smoothed fractions `u`, `v`.
    #[inline(always)]
    fn lattice_at(&self, rx: f32, ry: f32, u: f32, v: f32) -> Vec4 {
        // Two's complement masking is the lattice's wrap-around.
        let mask = LATTICE_SIDE as u32 - 1;
        let (x0, y0) = (rx.to_bits() & mask, ry.to_bits() & mask);
        let (x1, y1) = ((x0 + 1) & mask, (y0 + 1) & mask);
        let at = |x: u32, y: u32| self.lattice[(y * LATTICE_SIDE as u32 + x) as usize];
        let top = at(x0, y0).lerp(at(x1, y0), u);
        let bottom = at(x0, y1).lerp(at(x1, y1), u);
        top.lerp(bottom, v)
    }

    /// Colour of the ground at route-frame point `p`, 0..255 per channel (unclamped).
    fn colour(&mut self, p: DVec2) -> Vec3A {
        let road = self.road(p);
        let (g, ig) = (self.pixel_m, self.inv_pixel);
        let [coarse, mid, n2, n3] = self.octaves(p);
        let noise = Noise {
            coarse,
            mid,
            tex: Vec3A::new(mid.z, n2.x, n3.x),
            crown: Vec3A::new(mid.w, n2.y, n3.y),
            // Sensor-like grain: one hash on a 0.25 m lattice (offset by half a cell from the
            // road grid's corners).
            grain: unit(hash2(
                self.seed ^ 0x6a1e,
                floor_i32(p.x * 4.0 + 0.5),
                floor_i32(p.y * 4.0 + 0.5),
            )) as f32
                - 0.5,
        };
        let Some((d, s)) = road else {
            return self.terrain(p, f32::INFINITY, &noise);
        };
        let d32 = d as f32;
        let (moist, tex) = (noise.coarse.z, noise.tex);
        // Under full asphalt the terrain is not seen: skip it.
        let mut c = if d32 < ROAD_HALF_M - 0.5 * g {
            ASPHALT
        } else {
            let t = self.terrain(p, d32, &noise);
            let verge = 1.0 + 0.25 * (tex.z - 0.5) + 0.1 * noise.grain;
            let t = t.lerp(VERGE * verge, smoothstep(7.5, 5.0, d32));
            t.lerp(GRAVEL * verge, smoothstep(4.7, 4.1, d32))
        };
        let wheel = smoothstep(0.35, 0.1, ((d32 - 0.5 * ROAD_HALF_M).abs() - 0.85).abs());
        let asphalt = ASPHALT
            * (1.0 + 0.12 * (tex.z - 0.5) + 0.08 * (tex.x - 0.5) + 0.06 * (moist - 0.5)
                - 0.05 * wheel
                + 0.08 * noise.grain);
        c = c.lerp(asphalt, box_cover(d32, ROAD_WIDTH_M as f32, g, ig));
        // Dash centres at 1.5 m of each 12 m period; `along` is wrapped to [-6, 6) m.
        let u = (s - 0.5 * DASH_M) * (1.0 / DASH_PERIOD_M) + 0.5;
        let along = ((u - f64::from(floor_i32(u)) - 0.5) * DASH_PERIOD_M) as f32;
        let paint = box_cover(d32 - EDGE_LINE_M, EDGE_LINE_WIDTH_M, g, ig).max(
            box_cover(d32, CENTRE_LINE_WIDTH_M, g, ig) * box_cover(along, DASH_M as f32, g, ig),
        );
        if paint > 0.0 {
            c = c.lerp(PAINT * (0.92 + 0.12 * tex.y), paint);
        }
        c
    }

    /// The farmland at `p`, `road_d` metres from the centre line.
    #[inline]
    fn terrain(&mut self, p: DVec2, road_d: f32, n: &Noise) -> Vec3A {
        let [warp_x, warp_y, moist, trees_big] = n.coarse.to_array();
        let (trees_small, patch) = (n.mid.x, n.mid.y);
        let q = p + DVec2::new(f64::from(warp_x) - 0.5, f64::from(warp_y) - 0.5) * 60.0;
        let field = self.field(q);
        let kind = &FIELD_KINDS[usize::from(FIELD_DRAW[(field.hash >> 28) as usize])];
        let mut c = kind.base * (0.9 + 0.2 * unit(remix(field.hash)) as f32);
        c = c.lerp(SOIL, kind.patches * smoothstep(0.45, 0.75, patch));
        // Rows: a triangle wave across the field's own direction and spacing.
        let t = q.dot(field.rows);
        let tri = (2.0 * (t - f64::from(floor_i32(t))) - 1.0).abs() as f32;
        let texture = Vec3A::new(0.25, 0.35, 0.45).dot(n.tex - 0.5) + 0.3 * n.grain;
        c *= 1.0 + kind.stripes * (tri - 0.5) + 0.4 * kind.texture * texture + 0.12 * (moist - 0.5);
        // Field edges: a narrow worn track or grass strip.
        c = c.lerp(TRACK, 0.7 * smoothstep(1.6, 0.6, field.edge_m));

        // Trees: blobs with ragged edges, denser along field edges and in woodland, none by
        // the road.
        let density = 0.55 * trees_big + 0.45 * trees_small + kind.trees - 0.12
            + 0.18 * smoothstep(8.0, 1.0, field.edge_m)
            + Vec3A::new(0.0, 0.08, 0.05).dot(n.crown - 0.5)
            - smoothstep(9.0, 6.5, road_d);
        if density > 0.555 {
            c *= 1.0 - 0.3 * smoothstep(0.555, 0.58, density);
            let tree = smoothstep(0.58, 0.6, density);
            let canopy = Vec3A::new(0.5, 0.3, 0.2).dot(n.crown) + 0.1 * n.grain;
            let leaves = TREE_DARK.lerp(TREE_LIGHT, smoothstep(0.25, 0.75, canopy));
            c = c.lerp(leaves, tree);
        }
        c
    }
}

impl Imagery for SyntheticRouteImagery<'_> {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        self.frame
            .geodetic_to_enu(&Geodetic::new(lat_deg, lon_deg, 0.0))
            .truncate()
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        // Clamped, then rounded by adding 2^23: the integer lands in the low mantissa bits.
        let c = self.colour(p).clamp(Vec3A::ZERO, Vec3A::splat(255.0)) + 8_388_608.0;
        Ok(Ok(c.to_array().map(|v| v.to_bits() as u8)))
    }

    fn gap_error(&self, _gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        BuildError::Option(format!(
            "the synthetic route imagery has no gap, yet one was reported at {lat_deg}, {lon_deg}"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route_pack_builder::{BuildOptions, MAX_ROUTE_RADIUS_M, build_pack};
    use satmap_runtime::satellite::CropSpec;

    const ANCHOR: Geodetic = Geodetic::new(48.137, 11.575, 0.0);

    fn rgb(img: &mut SyntheticRouteImagery<'_>, p: DVec2) -> [u8; 3] {
        img.sample(p).unwrap().unwrap()
    }

    /// Vertex `i`, its left normal.
    fn normal(route: &[DVec2], i: usize) -> DVec2 {
        let d = route[(i + 1).min(route.len() - 1)] - route[i.saturating_sub(1)];
        d.normalize().perp()
    }

    fn dist_to_route(route: &[DVec2], p: DVec2) -> f64 {
        route
            .windows(2)
            .map(|w| {
                let d = w[1] - w[0];
                let t = ((p - w[0]).dot(d) / d.length_squared()).clamp(0.0, 1.0);
                (p - (w[0] + d * t)).length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn is_asphalt(c: [u8; 3]) -> bool {
        let (lo, hi) = (*c.iter().min().unwrap(), *c.iter().max().unwrap());
        let mean = c.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0;
        hi - lo <= 10 && (50.0..=100.0).contains(&mean)
    }

    fn is_paint(c: [u8; 3]) -> bool {
        c.iter().all(|&v| v >= 150)
    }

    /// Asphalt, paint, or a blend of the two (at the end of a dash): grey, not dark.
    fn is_road(c: [u8; 3]) -> bool {
        let (lo, hi) = (*c.iter().min().unwrap(), *c.iter().max().unwrap());
        hi - lo <= 12 && lo >= 45
    }

    #[test]
    fn floor_without_libm() {
        for v in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            0.999_999_9,
            -0.999_999_9,
            1e-12,
            -1e-12,
            2.5,
            -2.5,
            123_456.75,
            -123_456.75,
            2e9,
            -2e9,
        ] {
            assert_eq!(floor_i32(v), v.floor() as i32, "{v}");
        }
        // Out of range or NaN: some value, no panic.
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300] {
            let _ = floor_i32(v);
        }
    }

    #[test]
    fn rejects_bad_lengths() {
        for km in [0.0, -1.0, 200.5, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                SyntheticRoute::new(1, km, ANCHOR),
                Err(BuildError::Option(_))
            ));
        }
        assert!(SyntheticRoute::new(1, 200.0, ANCHOR).is_ok());
        assert!(SyntheticRoute::new(1, 1.0, Geodetic::new(f64::NAN, 0.0, 0.0)).is_err());
    }

    #[test]
    fn deterministic_from_the_seed() {
        let a = SyntheticRoute::new(7, 3.0, ANCHOR).unwrap();
        let b = SyntheticRoute::new(7, 3.0, ANCHOR).unwrap();
        let c = SyntheticRoute::new(8, 3.0, ANCHOR).unwrap();
        assert_eq!(a.route_m(), b.route_m());
        assert_ne!(a.route_m(), c.route_m());
        let (mut ia, mut ib, mut ic) = (a.imagery(), b.imagery(), c.imagery());
        let mut differ = 0;
        for k in 0..2000 {
            let p = DVec2::new(
                f64::from(k % 50) * 3.7 - 90.0,
                f64::from(k / 50) * 4.1 - 80.0,
            );
            assert_eq!(rgb(&mut ia, p), rgb(&mut ib, p));
            differ += usize::from(rgb(&mut ia, p) != rgb(&mut ic, p));
        }
        assert!(differ > 1000, "{differ}");
        // The caches do not change a colour: the same point after a jump elsewhere.
        let p = DVec2::new(12.3, -4.5);
        let first = rgb(&mut ia, p);
        rgb(&mut ia, DVec2::new(5000.0, 5000.0));
        assert_eq!(rgb(&mut ia, p), first);
        assert_eq!(rgb(&mut b.imagery(), p), first);
    }

    #[test]
    fn length_and_spacing() {
        for (seed, km) in [(1, 0.05), (2, 1.0), (3, 12.345), (4, 100.0)] {
            let r = SyntheticRoute::new(seed, km, ANCHOR).unwrap();
            let len: f64 = r.route_m().windows(2).map(|w| w[0].distance(w[1])).sum();
            assert!((len / (km * 1000.0) - 1.0).abs() < 0.005, "{seed}: {len}");
            assert!((r.length_m() - len).abs() < 1e-6);
            assert_eq!(r.route_m()[0], DVec2::ZERO);
            for w in r.route_m().windows(2) {
                let step = w[0].distance(w[1]);
                assert!(step <= VERTEX_STEP_M + 1e-9 && step > 0.5 * VERTEX_STEP_M);
            }
        }
    }

    #[test]
    fn curvature_bounded_and_winding() {
        for seed in 1..=4 {
            let r = SyntheticRoute::new(seed, 30.0, ANCHOR).unwrap();
            let pts = r.route_m();
            let mut turned = 0.0;
            for w in pts.windows(3) {
                let (a, b) = (w[1] - w[0], w[2] - w[1]);
                let angle = a.angle_to(b).abs();
                let ds = 0.5 * (a.length() + b.length());
                assert!(angle / ds <= 1.0 / MIN_RADIUS_M * (1.0 + 1e-9), "{seed}");
                turned += angle;
            }
            // Not a straight line: several full turns' worth of curves over 30 km.
            assert!(turned > 4.0 * TAU, "{seed}: {turned}");
            assert!(
                r.max_distance_from_start_m() < 0.5 * r.length_m(),
                "{seed}: {}",
                r.max_distance_from_start_m()
            );
        }
    }

    #[test]
    fn long_routes_stay_inside_the_builders_frame() {
        for seed in 1..=3 {
            let r = SyntheticRoute::new(seed, MAX_ROUTE_KM, ANCHOR).unwrap();
            assert!(
                r.max_distance_from_start_m() < 0.5 * MAX_ROUTE_RADIUS_M,
                "{seed}: {}",
                r.max_distance_from_start_m()
            );
        }
    }

    #[test]
    fn wgs84_round_trips_to_the_route_frame() {
        let r = SyntheticRoute::new(5, 20.0, ANCHOR).unwrap();
        let frame = EnuFrame::new(r.anchor());
        let wgs = r.route_wgs84();
        assert_eq!(wgs.len(), r.route_m().len());
        let img = r.imagery();
        for (g, p) in wgs.iter().zip(r.route_m()) {
            assert_eq!(g.height_m, 0.0);
            let back = frame.geodetic_to_enu(g).truncate();
            assert!(back.distance(*p) < 1e-4, "{back} vs {p}");
            assert!(img.project(g.lat_deg, g.lon_deg).distance(*p) < 1e-4);
        }
        // Far out too (the builder allows 105 km), and off the equator and at it.
        for anchor in [
            ANCHOR,
            Geodetic::new(0.0, 30.0, 120.0),
            Geodetic::new(-60.0, -70.0, 0.0),
        ] {
            let frame = EnuFrame::new(anchor);
            for p in [DVec2::new(100_000.0, 0.0), DVec2::new(-40_000.0, 90_000.0)] {
                let g = on_ellipsoid(&frame, p);
                let back = frame.geodetic_to_enu(&g).truncate();
                assert!(back.distance(p) < 1e-4, "{anchor:?} {p}: {back}");
            }
        }
    }

    #[test]
    fn road_on_the_centre_line_fields_far_off() {
        let r = SyntheticRoute::new(3, 10.0, ANCHOR).unwrap();
        let pts = r.route_m().to_vec();
        let mut img = r.imagery();
        let mut far = 0;
        for i in (5..pts.len() - 5).step_by(17) {
            let n = normal(&pts, i);
            let centre = rgb(&mut img, pts[i]);
            assert!(is_road(centre), "{i}: {centre:?} at {}", pts[i]);
            for side in [-1.0, 1.0] {
                let lane = rgb(&mut img, pts[i] + n * side * 1.75);
                assert!(is_asphalt(lane), "{i}: {lane:?}");
                let off = pts[i] + n * side * 100.0;
                if dist_to_route(&pts, off) > 60.0 {
                    far += 1;
                    let c = rgb(&mut img, off);
                    assert!(!is_road(c), "{i}: {c:?} at {off}");
                }
            }
        }
        assert!(far > 50, "{far}");
    }

    #[test]
    fn markings_dashes_and_edges() {
        let r = SyntheticRoute::new(9, 2.0, ANCHOR).unwrap();
        let pts = r.route_m().to_vec();
        let mut img = r.imagery();
        let (mut centre_paint, mut edge_paint, mut n) = (0, 0, 0);
        // Along a straight-ish stretch: dense samples on the centre line and an edge line.
        for i in 10..pts.len() - 10 {
            for k in 0..10 {
                let f = f64::from(k) / 10.0;
                let p = pts[i].lerp(pts[i + 1], f);
                let nrm = normal(&pts, i);
                n += 1;
                centre_paint += usize::from(is_paint(rgb(&mut img, p)));
                edge_paint +=
                    usize::from(is_paint(rgb(&mut img, p + nrm * f64::from(EDGE_LINE_M))));
            }
        }
        let (centre, edge) = (centre_paint as f64 / n as f64, edge_paint as f64 / n as f64);
        // Dashes 3 m of every 12 m; edge lines solid (the polyline's corners aside).
        assert!((0.15..0.35).contains(&centre), "{centre}");
        assert!(edge > 0.9, "{edge}");
    }

    #[test]
    fn continuous_across_grid_cells() {
        let r = SyntheticRoute::new(4, 2.0, ANCHOR).unwrap();
        let mut img = r.imagery();
        // Either side of road-grid cell corners (where the noise's local frame changes): at
        // most rounding apart.
        for (cx, cy) in [(0, 0), (3, -2), (-7, 5), (40, 40), (-300, 120)] {
            let corner = DVec2::new(f64::from(cx), f64::from(cy)) * CELL_M;
            for d in [DVec2::X, DVec2::Y, DVec2::ONE] {
                let (a, b) = (corner - d * 1e-7, corner + d * 1e-7);
                let (ca, cb) = (rgb(&mut img, a), rgb(&mut img, b));
                for k in 0..3 {
                    assert!(ca[k].abs_diff(cb[k]) <= 1, "{corner} {d}: {ca:?} vs {cb:?}");
                }
            }
        }
    }

    #[test]
    fn samples_bounded_and_varied() {
        let r = SyntheticRoute::new(11, 1.0, ANCHOR).unwrap();
        let mut img = r.imagery();
        let (mut sum, mut sum2, mut n) = ([0.0f64; 3], [0.0f64; 3], 0.0);
        for k in 0..40_000 {
            let p = DVec2::new(f64::from(k % 200) * 0.3, f64::from(k / 200) * 0.3 + 400.0);
            let c = rgb(&mut img, p);
            for ch in 0..3 {
                sum[ch] += f64::from(c[ch]);
                sum2[ch] += f64::from(c[ch]).powi(2);
            }
            n += 1.0;
        }
        for ch in 0..3 {
            let mean = sum[ch] / n;
            let sd = (sum2[ch] / n - mean * mean).sqrt();
            assert!((20.0..220.0).contains(&mean), "{ch}: {mean}");
            assert!(sd > 3.0, "{ch}: sd {sd}");
        }
        // Far away, odd inputs: still a colour.
        for p in [
            DVec2::new(1e7, -1e7),
            DVec2::new(-3.0e5, 2.0e5),
            DVec2::new(f64::NAN, 0.0),
            DVec2::new(f64::INFINITY, 1.0),
        ] {
            assert!(img.sample(p).unwrap().is_ok());
        }
    }

    #[test]
    fn builds_a_pack() {
        let r = SyntheticRoute::new(2, 5.0, ANCHOR).unwrap();
        let opts = BuildOptions {
            origin: Some(r.anchor()),
            gsd_m: 0.3,
            crop: CropSpec {
                height_px: 200,
                width_px: 100,
                gsd_m: 0.3,
                x_min_m: -15.0,
                y_min_m: -30.0,
            },
            ..BuildOptions::default()
        };
        let built = build_pack(&mut r.imagery_at(0.3), &r.route_wgs84(), &opts).unwrap();
        assert!(built.tiles > 0);
        assert_eq!(built.skipped_tiles, 0);
        assert!((built.route_length_m / r.length_m() - 1.0).abs() < 0.01);
        assert!((built.route_length_m / 5000.0 - 1.0).abs() < 0.01);
    }
}
