//! Local East-North-Up tangent plane: the metric route frame of a pack.
//!
//! Frame: origin at a WGS84 point on (or above) the ellipsoid, x east, y north, z up along the
//! ellipsoid normal, metres. Over a 20 km route the plane departs from the ground by up to
//! ~31 m in height (curvature), but horizontal positions round-trip exactly: the map is a
//! rigid rotation of ECEF, not a projection.

use glam::DVec3;

use super::ellipsoid::{Geodetic, ecef_to_geodetic, geodetic_to_ecef};

/// A local ENU frame anchored at `origin`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnuFrame {
    origin: Geodetic,
    origin_ecef_m: DVec3,
    east: DVec3,
    north: DVec3,
    up: DVec3,
}

impl EnuFrame {
    /// The ENU frame whose origin is `origin`.
    #[must_use]
    pub fn new(origin: Geodetic) -> Self {
        let (sin_lat, cos_lat) = libm::sincos(origin.lat_deg.to_radians());
        let (sin_lon, cos_lon) = libm::sincos(origin.lon_deg.to_radians());
        Self {
            origin,
            origin_ecef_m: geodetic_to_ecef(&origin),
            east: DVec3::new(-sin_lon, cos_lon, 0.0),
            north: DVec3::new(-sin_lat * cos_lon, -sin_lat * sin_lon, cos_lat),
            up: DVec3::new(cos_lat * cos_lon, cos_lat * sin_lon, sin_lat),
        }
    }

    /// The frame's origin.
    #[must_use]
    pub const fn origin(&self) -> Geodetic {
        self.origin
    }

    /// ENU coordinates (metres) of an ECEF position (metres).
    #[must_use]
    pub fn ecef_to_enu(&self, ecef_m: DVec3) -> DVec3 {
        let d = ecef_m - self.origin_ecef_m;
        DVec3::new(self.east.dot(d), self.north.dot(d), self.up.dot(d))
    }

    /// ECEF position (metres) of ENU coordinates (metres).
    #[must_use]
    pub fn enu_to_ecef(&self, enu_m: DVec3) -> DVec3 {
        self.origin_ecef_m + self.east * enu_m.x + self.north * enu_m.y + self.up * enu_m.z
    }

    /// ENU coordinates (metres) of a geodetic position.
    #[must_use]
    pub fn geodetic_to_enu(&self, p: &Geodetic) -> DVec3 {
        self.ecef_to_enu(geodetic_to_ecef(p))
    }

    /// Geodetic position of ENU coordinates (metres).
    #[must_use]
    pub fn enu_to_geodetic(&self, enu_m: DVec3) -> Geodetic {
        ecef_to_geodetic(self.enu_to_ecef(enu_m))
    }

    /// Heading in the ENU frame (counter-clockwise from east, radians) of a compass heading
    /// (clockwise from true north, degrees) at the origin.
    #[must_use]
    pub fn yaw_rad_from_heading_deg(heading_deg: f64) -> f64 {
        core::f64::consts::FRAC_PI_2 - heading_deg.to_radians()
    }
}
