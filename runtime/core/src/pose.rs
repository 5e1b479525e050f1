//! Ego pose and ego motion: the vehicle state a frame carries.
//!
//! Frames: the *route frame* is the local metric ENU tangent plane of a route pack (x east,
//! y north, metres). The *ego frame* is x right, y forward, z up. `yaw_rad` is the heading of the
//! ego forward axis (ego +y), counter-clockwise from route +x (east). So ego point `(x_e, y_e)`
//! lies at `position + x_e * right + y_e * forward` with `forward = (cos yaw, sin yaw)` and
//! `right = (sin yaw, -cos yaw)`.

use core::fmt;

use glam::{DVec2, Vec3};

/// Vehicle pose in the route frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EgoPose {
    /// Position of the ego origin in the route frame, metres (x east, y north).
    pub position_m: DVec2,
    /// Heading of the ego forward axis, counter-clockwise from route +x, radians.
    pub yaw_rad: f64,
}

impl EgoPose {
    /// Pose at `position_m` with heading `yaw_rad`.
    #[must_use]
    pub const fn new(position_m: DVec2, yaw_rad: f64) -> Self {
        Self {
            position_m,
            yaw_rad,
        }
    }

    /// True when every field is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.position_m.is_finite() && self.yaw_rad.is_finite()
    }

    /// Route-frame position of the ego-frame point `ego_m` (x right, y forward).
    #[must_use]
    pub fn ego_to_route(&self, ego_m: DVec2) -> DVec2 {
        let (sin, cos) = libm::sincos(self.yaw_rad);
        let forward = DVec2::new(cos, sin);
        let right = DVec2::new(sin, -cos);
        self.position_m + right * ego_m.x + forward * ego_m.y
    }
}

/// Ego motion from the vehicle bus, in the ego frame: the CAN-bus fields of the spec.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct EgoMotion {
    /// Linear acceleration, m/s^2.
    pub acceleration_mps2: Vec3,
    /// Angular rate, rad/s.
    pub rotation_rate_radps: Vec3,
    /// Linear velocity, m/s.
    pub velocity_mps: Vec3,
}

impl EgoMotion {
    /// True when every field is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.acceleration_mps2.is_finite()
            && self.rotation_rate_radps.is_finite()
            && self.velocity_mps.is_finite()
    }
}

/// An axis of a pose or motion vector, for error context.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// x (route frame: east; ego frame: right).
    X,
    /// y (route frame: north; ego frame: forward).
    Y,
    /// z (ego frame: up).
    Z,
}

impl Axis {
    /// The three axes, in vector component order.
    pub const ALL: [Self; 3] = [Self::X, Self::Y, Self::Z];

    /// `"x"`, `"y"` or `"z"`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::X => "x",
            Self::Y => "y",
            Self::Z => "z",
        }
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
