//! The bounds a frame is checked against ([`FrameLimits`]), and the check of the bounds
//! themselves at init.

use core::fmt;

#[cfg(doc)]
use super::CameraState;

/// What a frame must respect beyond finiteness and image sizes: how far its sequence counter and
/// timestamp may jump ahead of the last successful step, and the plausible ranges of pose and
/// ego motion. Every bound is inclusive; a float bound may be `INFINITY` (no bound).
///
/// The defaults ([`FrameLimits::DEFAULT`]) suit a 2-20 Hz camera rig on a road vehicle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameLimits {
    /// Largest accepted `sequence - previous sequence`, at least 1. Default 1000: 500 s of
    /// dropped frames at 2 Hz, 50 s at 20 Hz, both past the timestamp gap, which is then the
    /// bound that trips first.
    pub max_sequence_gap: u64,
    /// Largest accepted `timestamp_us - previous timestamp_us`, µs, at least 1. Default
    /// 10_000_000 (10 s = 20 periods at 2 Hz): a longer pause is an outage, and the integrator
    /// restarts with `SatMap::reset` rather than the runtime guessing.
    pub max_timestamp_gap_us: u64,
    /// Largest `|x|` and `|y|` of the route-frame position, metres. Default 1e7: beyond the
    /// Earth's radius from the route pack origin, so only a corrupt pose exceeds it.
    pub max_abs_position_m: f64,
    /// Largest `|yaw|`, radians. Default 1e4 (about 1600 turns): the runtime wraps yaw itself,
    /// so an unwrapped heading from a long drive still passes, while an absurd one (at 1e16 the
    /// f64 spacing exceeds a full turn) does not.
    pub max_abs_yaw_rad: f64,
    /// Largest `|component|` of the velocity, m/s. Default 100 (360 km/h).
    pub max_abs_velocity_mps: f32,
    /// Largest `|component|` of the acceleration, m/s^2. Default 100 (about 10 g; the z
    /// component carries gravity, 9.81 at rest).
    pub max_abs_acceleration_mps2: f32,
    /// Largest `|component|` of the rotation rate, rad/s. Default 10 (about 570 deg/s, well
    /// past a spinning car).
    pub max_abs_rotation_rate_radps: f32,
    /// Largest accepted age of a camera image, `timestamp_us - capture_us`, µs, at least 1.
    /// Default 250_000: half a period of a 2 Hz rig; an older image shows another place and is
    /// left out ([`CameraState::Stale`]).
    pub max_camera_age_us: u64,
}

impl FrameLimits {
    /// The documented defaults of every field.
    pub const DEFAULT: Self = Self {
        max_sequence_gap: 1000,
        max_timestamp_gap_us: 10_000_000,
        max_abs_position_m: 1e7,
        max_abs_yaw_rad: 1e4,
        max_abs_velocity_mps: 100.0,
        max_abs_acceleration_mps2: 100.0,
        max_abs_rotation_rate_radps: 10.0,
        max_camera_age_us: 250_000,
    };

    /// Check the limits themselves: gaps at least 1, float bounds positive and not NaN (a NaN
    /// bound would silently accept everything, a zero one refuse every moving vehicle).
    ///
    /// # Errors
    /// [`InvalidLimits`] naming the first bad field.
    pub fn validate(&self) -> Result<(), InvalidLimits> {
        let bad = |field| Err(InvalidLimits { field });
        if self.max_sequence_gap == 0 {
            return bad("max_sequence_gap");
        }
        if self.max_timestamp_gap_us == 0 {
            return bad("max_timestamp_gap_us");
        }
        if self.max_abs_position_m.is_nan() || self.max_abs_position_m <= 0.0 {
            return bad("max_abs_position_m");
        }
        if self.max_abs_yaw_rad.is_nan() || self.max_abs_yaw_rad <= 0.0 {
            return bad("max_abs_yaw_rad");
        }
        if self.max_abs_velocity_mps.is_nan() || self.max_abs_velocity_mps <= 0.0 {
            return bad("max_abs_velocity_mps");
        }
        if self.max_abs_acceleration_mps2.is_nan() || self.max_abs_acceleration_mps2 <= 0.0 {
            return bad("max_abs_acceleration_mps2");
        }
        if self.max_abs_rotation_rate_radps.is_nan() || self.max_abs_rotation_rate_radps <= 0.0 {
            return bad("max_abs_rotation_rate_radps");
        }
        if self.max_camera_age_us == 0 {
            return bad("max_camera_age_us");
        }
        Ok(())
    }
}

impl Default for FrameLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A field of [`FrameLimits`] is unusable (a zero gap, a NaN, zero or negative bound).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InvalidLimits {
    /// Field name, as in `FrameLimits`.
    pub field: &'static str,
}

impl fmt::Display for InvalidLimits {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "frame limit `{}` must be positive and not NaN",
            self.field
        )
    }
}

impl core::error::Error for InvalidLimits {}
