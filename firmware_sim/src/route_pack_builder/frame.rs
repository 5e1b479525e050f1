//! The route frame on the builder's side: which ground point a pack pixel shows
//! ([`ground_point`]), and how far from the frame origin a route may reach
//! ([`MAX_ROUTE_RADIUS_M`], checked by [`check_route_radius`]).
//!
//! One frame serves a whole route (no segments, so no seams to cross). The builder and the
//! vehicle use the same tangent plane, so the plane's own distortion against the ground
//! (about `d^3 / 6R^2` in position, 4 m at 100 km) cancels: a fix maps to the plane point whose
//! pixels were filled from that very ground. What remains is the vertical drop of
//! [`ground_point`] (a sphere of radius [`EARTH_RADIUS_M`] where the vehicle sees the
//! ellipsoid) and the plane's local scale; `tests/integration/route_frame_distortion.rs` measures both on
//! the ground and bounds them for routes within [`MAX_ROUTE_RADIUS_M`].

use glam::{DVec2, DVec3};
use satmap_runtime::geo::{EnuFrame, Geodetic};

use super::error::BuildError;

/// Mean Earth radius for the tangent-plane drop, metres.
pub const EARTH_RADIUS_M: f64 = 6_371_000.0;

/// Farthest a route point may lie from the route-frame origin, metres (distance in the plane).
///
/// Within it (and 2.5 km beyond, for a vehicle off the route) every point of the crop lands at
/// most 12 cm from its true ground position: measured 7.3 cm at 100 km and 9.1 cm at
/// 107.5 km, at the equator north-south, the worst case (the drop's sphere is farthest from
/// the ellipsoid there); `tests/integration/route_frame_distortion.rs`. The error grows as `d^3`: 25 cm
/// at 150 km. 105 km leaves a 100 km route built from its first point (the default origin)
/// 5 km of margin; with the origin at the route's middle, routes up to 210 km fit.
pub const MAX_ROUTE_RADIUS_M: f64 = 105_000.0;

/// The ground point that pack pixel centre `p_m` (route-frame x east, y north, metres) shows:
/// the ENU point `(x, y, -h0 - (x^2 + y^2) / 2R)` (h0 the origin's height above the
/// ellipsoid, R = [`EARTH_RADIUS_M`]), in WGS84.
///
/// Why the drop: the vehicle maps a fix at height 0 (`RoutePack::pose_from_wgs84`) to the
/// plane x, y of that ground point, whose ENU z is about `-h0 - d^2 / 2R` (-785 m at 100 km).
/// Taking the plane point itself (z = 0) would read the imagery along a line of sight that
/// leaves the tangent plane `d^2 / 2R` above the ground, tilted by `d / R` from the local
/// vertical: 12 m off at 100 km. Dropping back to the ellipsoid along the origin's up undoes
/// the vehicle's projection up to the sphere-vs-ellipsoid difference of the drop (at most
/// 4.4 m vertical at 100 km), which moves the point only by that times `d / R` on the ground
/// (7 cm at 100 km). Imagery heights (terrain) are ignored, on both sides.
#[must_use]
pub fn ground_point(frame: &EnuFrame, p_m: DVec2) -> Geodetic {
    let z_m = -frame.origin().height_m - p_m.length_squared() / (2.0 * EARTH_RADIUS_M);
    frame.enu_to_geodetic(DVec3::new(p_m.x, p_m.y, z_m))
}

/// Check that every route point (route frame, metres) lies within [`MAX_ROUTE_RADIUS_M`] of
/// the frame origin.
///
/// # Errors
/// [`BuildError::RouteBeyondFrame`] for the first point farther away or not finite.
pub fn check_route_radius(route_m: &[DVec2]) -> Result<(), BuildError> {
    for (index, p) in route_m.iter().enumerate() {
        let distance_m = p.length();
        if !distance_m.is_finite() || distance_m > MAX_ROUTE_RADIUS_M {
            return Err(BuildError::RouteBeyondFrame {
                index,
                distance_m,
                max_m: MAX_ROUTE_RADIUS_M,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn beyond(route: &[DVec2]) -> Option<(usize, f64)> {
        match check_route_radius(route) {
            Ok(()) => None,
            Err(BuildError::RouteBeyondFrame {
                index,
                distance_m,
                max_m,
            }) => {
                assert_eq!(max_m, MAX_ROUTE_RADIUS_M);
                Some((index, distance_m))
            }
            Err(e) => panic!("unexpected error {e}"),
        }
    }

    #[test]
    fn points_inside_and_at_the_bound_are_accepted() {
        assert_eq!(beyond(&[]), None);
        let diagonal = MAX_ROUTE_RADIUS_M / 2f64.sqrt();
        assert_eq!(
            beyond(&[
                DVec2::ZERO,
                DVec2::new(1_000.0, -2_000.0),
                DVec2::new(MAX_ROUTE_RADIUS_M, 0.0),
                DVec2::new(0.0, -MAX_ROUTE_RADIUS_M),
                DVec2::new(-diagonal, diagonal) * (1.0 - 1e-12),
            ]),
            None
        );
    }

    #[test]
    fn the_first_point_outside_is_reported() {
        let just_out = DVec2::new(0.0, MAX_ROUTE_RADIUS_M + 0.01);
        let far = DVec2::new(-150_000.0, 20_000.0);
        assert_eq!(
            beyond(&[DVec2::ZERO, just_out, far]),
            Some((1, just_out.length()))
        );
        assert_eq!(beyond(&[DVec2::ZERO, far]), Some((1, far.length())));
        // Diagonal: the plane distance counts, not each coordinate.
        let corner = DVec2::splat(MAX_ROUTE_RADIUS_M * 0.75);
        assert_eq!(beyond(&[corner]), Some((0, corner.length())));
    }

    #[test]
    fn non_finite_points_are_refused() {
        for bad in [
            DVec2::new(f64::NAN, 0.0),
            DVec2::new(0.0, f64::NAN),
            DVec2::new(f64::INFINITY, 0.0),
            DVec2::new(0.0, f64::NEG_INFINITY),
        ] {
            let (index, distance_m) = beyond(&[DVec2::ZERO, bad]).unwrap();
            assert_eq!(index, 1);
            assert!(!distance_m.is_finite());
        }
    }

    #[test]
    fn the_error_names_the_bound_and_suggests_a_middle_origin() {
        let e = check_route_radius(&[DVec2::new(120_000.0, 0.0)]).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("route point 0"), "{text}");
        assert!(text.contains("120.0 km"), "{text}");
        assert!(text.contains("105.0 km"), "{text}");
        assert!(text.contains("--origin"), "{text}");
    }

    #[test]
    fn ground_point_is_the_origin_ground_under_the_origin() {
        let origin = Geodetic::new(52.0, 13.0, 500.0);
        let frame = EnuFrame::new(origin);
        let g = ground_point(&frame, DVec2::ZERO);
        assert!((g.lat_deg - 52.0).abs() < 1e-12, "{g:?}");
        assert!((g.lon_deg - 13.0).abs() < 1e-12, "{g:?}");
        assert!(g.height_m.abs() < 1e-6, "{g:?}");
        // 100 km out the drop leaves the point within the drop's sphere-vs-ellipsoid error of
        // the ground (a few metres), not the 785 m of the tangent plane.
        let far = ground_point(&frame, DVec2::new(60_000.0, -80_000.0));
        assert!(far.height_m.abs() < 5.0, "{far:?}");
    }
}
