//! The WGS84 ellipsoid and the geodetic <-> Earth-centred Earth-fixed (ECEF) conversion.
//!
//! ECEF: origin at the Earth's centre, x through (lat 0, lon 0), z through the north pole,
//! metres. Geodetic: latitude and longitude in degrees (WGS84), height above the ellipsoid in
//! metres.

use glam::DVec3;

/// WGS84 semi-major axis, metres.
pub const WGS84_A_M: f64 = 6_378_137.0;
/// WGS84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS84 semi-minor axis, metres.
pub const WGS84_B_M: f64 = WGS84_A_M * (1.0 - WGS84_F);
/// WGS84 first eccentricity squared.
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// A WGS84 geodetic position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geodetic {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the ellipsoid, metres.
    pub height_m: f64,
}

impl Geodetic {
    /// Position at `lat_deg`, `lon_deg`, `height_m`.
    #[must_use]
    pub const fn new(lat_deg: f64, lon_deg: f64, height_m: f64) -> Self {
        Self {
            lat_deg,
            lon_deg,
            height_m,
        }
    }

    /// True when every field is finite and latitude is within [-90, 90].
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.lat_deg.is_finite()
            && self.lon_deg.is_finite()
            && self.height_m.is_finite()
            && (-90.0..=90.0).contains(&self.lat_deg)
    }
}

/// ECEF position (metres) of a geodetic position.
#[must_use]
pub fn geodetic_to_ecef(p: &Geodetic) -> DVec3 {
    let (sin_lat, cos_lat) = libm::sincos(p.lat_deg.to_radians());
    let (sin_lon, cos_lon) = libm::sincos(p.lon_deg.to_radians());
    // Prime vertical radius of curvature.
    let n_m = WGS84_A_M / libm::sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat);
    DVec3::new(
        (n_m + p.height_m) * cos_lat * cos_lon,
        (n_m + p.height_m) * cos_lat * sin_lon,
        (n_m * (1.0 - WGS84_E2) + p.height_m) * sin_lat,
    )
}

/// Geodetic position of an ECEF position (metres).
///
/// Heikkinen's closed form (no iteration, sub-millimetre for any point outside the inner
/// few kilometres of the Earth's centre), so the cost is fixed.
#[must_use]
pub fn ecef_to_geodetic(ecef_m: DVec3) -> Geodetic {
    let (x, y, z) = (ecef_m.x, ecef_m.y, ecef_m.z);
    let a = WGS84_A_M;
    let b = WGS84_B_M;
    let e2 = WGS84_E2;
    let ep2 = (a * a - b * b) / (b * b);
    let p = libm::hypot(x, y);
    let lon_rad = libm::atan2(y, x);
    let f = 54.0 * b * b * z * z;
    let g = p * p + (1.0 - e2) * z * z - e2 * (a * a - b * b);
    let c = e2 * e2 * f * p * p / (g * g * g);
    let s = libm::cbrt(1.0 + c + libm::sqrt((c * c + 2.0 * c).max(0.0)));
    let k = s + 1.0 + 1.0 / s;
    let big_p = f / (3.0 * k * k * g * g);
    let q = libm::sqrt(1.0 + 2.0 * e2 * e2 * big_p);
    let r0 = -(big_p * e2 * p) / (1.0 + q)
        + libm::sqrt(
            (0.5 * a * a * (1.0 + 1.0 / q)
                - big_p * (1.0 - e2) * z * z / (q * (1.0 + q))
                - 0.5 * big_p * p * p)
                .max(0.0),
        );
    let t = p - e2 * r0;
    let u = libm::sqrt(t * t + z * z);
    let v = libm::sqrt(t * t + (1.0 - e2) * z * z);
    let z0 = b * b * z / (a * v);
    let height_m = u * (1.0 - b * b / (a * v));
    let lat_rad = libm::atan2(z + ep2 * z0, p);
    Geodetic {
        lat_deg: lat_rad.to_degrees(),
        lon_deg: lon_rad.to_degrees(),
        height_m,
    }
}
