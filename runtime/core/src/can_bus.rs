//! The 18-value CAN-bus vector the BEV query stage takes, built from the frame's pose and motion.
//!
//! Layout (spec / `ARCHITECTURE.md`): `[0:3]` position, zeroed; `[3:7]` ego->global quaternion
//! `(w, x, y, z)` of a rotation by `yaw_rad` about z (`w = cos(yaw/2)`, `z = sin(yaw/2)`, f64 then
//! cast); `[7:10]` acceleration; `[10:13]` rotation rate; `[13:16]` velocity (all ego frame);
//! `[16]` yaw wrapped to `[0, 2pi)` (f64, then cast); `[17]` yaw in degrees, zeroed.

use core::f64::consts::TAU;

use crate::capacity::CAN_BUS_LEN;
use crate::pose::{EgoMotion, EgoPose};

/// Build the CAN-bus vector. The quaternion uses the yaw as given (not wrapped).
#[must_use]
pub fn can_bus(pose: &EgoPose, motion: &EgoMotion) -> [f32; CAN_BUS_LEN] {
    let mut v = [0.0f32; CAN_BUS_LEN];
    let (sin_half, cos_half) = libm::sincos(pose.yaw_rad / 2.0);
    v[3] = cos_half as f32;
    v[6] = sin_half as f32;
    v[7..10].copy_from_slice(&motion.acceleration_mps2.to_array());
    v[10..13].copy_from_slice(&motion.rotation_rate_radps.to_array());
    v[13..16].copy_from_slice(&motion.velocity_mps.to_array());
    v[16] = wrap_yaw(pose.yaw_rad) as f32;
    v
}

/// `yaw mod 2pi` with Python's float `%` semantics (the reference's): `fmod`, then add `2pi` to a
/// negative, non-zero remainder.
#[must_use]
pub fn wrap_yaw(yaw_rad: f64) -> f64 {
    let r = libm::fmod(yaw_rad, TAU);
    if r < 0.0 {
        r + TAU
    } else {
        // `+ 0.0` turns -0.0 into +0.0, as Python does.
        r + 0.0
    }
}

#[cfg(test)]
mod tests {
    use core::f64::consts::PI;

    use glam::{DVec2, Vec3};

    use super::*;

    #[test]
    fn layout_and_values() {
        let pose = EgoPose::new(DVec2::new(100.0, -50.0), PI / 2.0);
        let motion = EgoMotion {
            acceleration_mps2: Vec3::new(0.1, 0.2, 0.3),
            rotation_rate_radps: Vec3::new(0.4, 0.5, 0.6),
            velocity_mps: Vec3::new(0.7, 8.0, 0.9),
        };
        let v = can_bus(&pose, &motion);
        assert_eq!(&v[0..3], &[0.0; 3]);
        assert_eq!(v[3], (PI / 4.0).cos() as f32);
        assert_eq!(&v[4..6], &[0.0; 2]);
        assert_eq!(v[6], (PI / 4.0).sin() as f32);
        assert_eq!(&v[7..16], &[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 8.0, 0.9]);
        assert_eq!(v[16], (PI / 2.0) as f32);
        assert_eq!(v[17], 0.0);
    }

    #[test]
    fn yaw_wraps_like_python_modulo() {
        assert_eq!(wrap_yaw(0.0), 0.0);
        assert!(wrap_yaw(-0.0).is_sign_positive());
        assert_eq!(wrap_yaw(-PI / 2.0), -PI / 2.0 + TAU);
        assert_eq!(wrap_yaw(TAU), 0.0);
        assert_eq!(wrap_yaw(7.0), 7.0 - TAU);
        assert!((0.0..TAU).contains(&wrap_yaw(-1e-3)));
        // The quaternion keeps the unwrapped yaw: -pi/2 gives w > 0, z < 0.
        let v = can_bus(&EgoPose::new(DVec2::ZERO, -PI / 2.0), &EgoMotion::default());
        assert!(v[3] > 0.0 && v[6] < 0.0);
    }
}
