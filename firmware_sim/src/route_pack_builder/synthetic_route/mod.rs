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

mod geometry;
mod imagery;
mod noise;
mod segment_grid;
#[cfg(test)]
mod tests;

use self::{geometry::*, noise::*, segment_grid::*};
pub use imagery::{DEFAULT_PIXEL_M, SyntheticRouteImagery};

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
