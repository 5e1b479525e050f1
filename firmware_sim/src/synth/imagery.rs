//! How far the satellite imagery of a synthetic world is from the truth: registration error
//! (the imagery is shifted and turned against the ground truth, as orthophotos are) and stale
//! imagery (captured before some markings were painted). Without these the satellite prior
//! would be a perfect map and a model trained on it would learn to trace the picture.
//!
//! Both are drawn per drive from the drive seed, so a seed still gives one world bit for bit.
//! The errors are baked into the satellite raster (and so into the tiles and route packs made
//! from it); the cameras and the ground truth see the world as it is now.
//!
//! Frame: route frame (x east, y north, metres).

use glam::DVec2;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use super::world::{DividerPaint, World};

/// Knobs of the imagery error model. Defaults are set for imagery like web-map orthophotos
/// over a city: registration within ~1.5 m and half a degree, a quarter of drives stale.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ImageryConfig {
    /// Smallest registration offset, metres (drawn uniformly in `[min, max]`, uniform direction).
    pub registration_offset_min_m: f64,
    /// Largest registration offset, metres.
    pub registration_offset_max_m: f64,
    /// Largest registration rotation, radians (drawn uniformly in `[-max, max]`), about the
    /// middle of the drive.
    pub registration_yaw_max_rad: f64,
    /// Share of drives whose imagery is stale, 0..1.
    pub stale_share: f64,
    /// In a stale drive, the chance that a crossing is missing from the imagery (added since
    /// capture); at least one crossing is missing when the world has any.
    pub stale_crossing_missing: f64,
    /// In a stale drive, the chance that a dashed lane line is missing from the imagery
    /// (repainted since capture).
    pub stale_lane_line_missing: f64,
}

impl Default for ImageryConfig {
    fn default() -> Self {
        Self {
            registration_offset_min_m: 0.2,
            registration_offset_max_m: 1.5,
            registration_yaw_max_rad: 0.5_f64.to_radians(),
            stale_share: 0.25,
            stale_crossing_missing: 0.5,
            stale_lane_line_missing: 0.3,
        }
    }
}

impl ImageryConfig {
    /// Imagery that is exactly the world: no registration error, never stale.
    #[must_use]
    pub const fn perfect() -> Self {
        Self {
            registration_offset_min_m: 0.0,
            registration_offset_max_m: 0.0,
            registration_yaw_max_rad: 0.0,
            stale_share: 0.0,
            stale_crossing_missing: 0.0,
            stale_lane_line_missing: 0.0,
        }
    }

    /// Why the knobs are out of range, if they are.
    #[must_use]
    pub fn check(&self) -> Option<&'static str> {
        let unit = |v: f64| (0.0..=1.0).contains(&v);
        if !(self.registration_offset_min_m >= 0.0
            && self.registration_offset_min_m <= self.registration_offset_max_m
            && self.registration_offset_max_m <= 10.0)
        {
            return Some("registration offsets must satisfy 0 <= min <= max <= 10 m");
        }
        if !(self.registration_yaw_max_rad >= 0.0 && self.registration_yaw_max_rad <= 0.1) {
            return Some("registration_yaw_max_rad must be in [0, 0.1]");
        }
        if !(unit(self.stale_share)
            && unit(self.stale_crossing_missing)
            && unit(self.stale_lane_line_missing))
        {
            return Some("stale shares must be in [0, 1]");
        }
        None
    }
}

/// The rigid error of the imagery: an imagery pixel showing true route point `p` sits at
/// `pivot + R(yaw) (p - pivot) + offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Registration {
    /// Shift, metres (route frame).
    pub offset_m: DVec2,
    /// Rotation, radians, counter-clockwise.
    pub yaw_rad: f64,
    /// Point the rotation turns about, route frame.
    pub pivot_m: DVec2,
}

impl Registration {
    /// No error.
    pub const NONE: Self = Self {
        offset_m: DVec2::ZERO,
        yaw_rad: 0.0,
        pivot_m: DVec2::ZERO,
    };

    /// True when the imagery is exactly registered.
    #[must_use]
    pub fn is_none(&self) -> bool {
        self.offset_m == DVec2::ZERO && self.yaw_rad == 0.0
    }

    /// Where true route point `p` appears in the imagery.
    #[must_use]
    pub fn apply(&self, p: DVec2) -> DVec2 {
        self.pivot_m + DVec2::from_angle(self.yaw_rad).rotate(p - self.pivot_m) + self.offset_m
    }
}

/// The imagery errors drawn for one drive.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageryErrors {
    /// Registration error.
    pub registration: Registration,
    /// True when the imagery predates some markings.
    pub stale: bool,
    /// Crossings of the world missing from the imagery.
    pub missing_crossings: usize,
    /// Dashed lane lines of the world missing from the imagery.
    pub missing_lane_lines: usize,
}

impl ImageryErrors {
    /// Perfect imagery.
    #[must_use]
    pub fn none() -> Self {
        Self {
            registration: Registration::NONE,
            stale: false,
            missing_crossings: 0,
            missing_lane_lines: 0,
        }
    }
}

/// Draw the errors of a drive and the world as the imagery shows it (`None` when the imagery
/// shows the world as it is). `pivot_m` is where the rotation error is centred (the middle of
/// the drive, so the crops of the drive see about the drawn offset).
#[must_use]
pub fn draw_errors(
    world: &World,
    config: &ImageryConfig,
    seed: u64,
    pivot_m: DVec2,
) -> (ImageryErrors, Option<World>) {
    // A stream of its own, so the world and camera streams stay as they were.
    let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x1a6e_7e12_5a7e_11e5);
    let offset_len = rng.random_range(0.0..=1.0f64)
        * (config.registration_offset_max_m - config.registration_offset_min_m)
        + config.registration_offset_min_m;
    let offset_dir = rng.random_range(0.0..std::f64::consts::TAU);
    let yaw = (rng.random_range(0.0..=1.0f64) * 2.0 - 1.0) * config.registration_yaw_max_rad;
    let registration = Registration {
        offset_m: DVec2::from_angle(offset_dir) * offset_len,
        yaw_rad: yaw,
        pivot_m,
    };
    let stale = rng.random_range(0.0..1.0f64) < config.stale_share;
    let mut errors = ImageryErrors {
        registration,
        stale,
        missing_crossings: 0,
        missing_lane_lines: 0,
    };
    if !stale {
        return (errors, None);
    }
    let mut past = world.clone();
    let n = past.crossings.len();
    let mut keep: Vec<bool> = (0..n)
        .map(|_| rng.random_range(0.0..1.0f64) >= config.stale_crossing_missing)
        .collect();
    if n > 0 && keep.iter().all(|&k| k) && config.stale_crossing_missing > 0.0 {
        let i = rng.random_range(0..n);
        keep[i] = false;
    }
    let mut it = keep.iter();
    past.crossings.retain(|_| *it.next().unwrap_or(&true));
    errors.missing_crossings = n - past.crossings.len();
    let before = past.dividers.len();
    past.dividers.retain(|d| {
        d.paint != DividerPaint::DashedLane
            || rng.random_range(0.0..1.0f64) >= config.stale_lane_line_missing
    });
    errors.missing_lane_lines = before - past.dividers.len();
    (errors, Some(past))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::world::WorldConfig;

    #[test]
    fn perfect_config_draws_no_error() {
        let world = World::generate(3, &WorldConfig::default());
        let (e, past) = draw_errors(&world, &ImageryConfig::perfect(), 3, DVec2::ZERO);
        assert!(e.registration.is_none());
        assert!(!e.stale);
        assert!(past.is_none());
    }

    #[test]
    fn default_offsets_stay_in_range_and_stale_share_is_near_a_quarter() {
        let cfg = ImageryConfig::default();
        let world = World::generate(5, &WorldConfig::default());
        let mut stale = 0;
        for seed in 0..200 {
            let (e, past) = draw_errors(&world, &cfg, seed, DVec2::new(10.0, 20.0));
            let d = e.registration.offset_m.length();
            assert!((0.2 - 1e-9..=1.5 + 1e-9).contains(&d), "offset {d}");
            assert!(e.registration.yaw_rad.abs() <= 0.5f64.to_radians() + 1e-12);
            // The pivot itself moves by exactly the offset.
            let moved = e.registration.apply(DVec2::new(10.0, 20.0)) - DVec2::new(10.0, 20.0);
            assert!((moved - e.registration.offset_m).length() < 1e-9);
            if e.stale {
                stale += 1;
                let past = past.expect("a stale drive has a past world");
                assert!(past.crossings.len() < world.crossings.len() || world.crossings.is_empty());
                assert_eq!(
                    past.crossings.len() + e.missing_crossings,
                    world.crossings.len()
                );
            }
        }
        assert!((30..=70).contains(&stale), "{stale} of 200 stale");
    }

    #[test]
    fn out_of_range_knobs_are_named() {
        let mut cfg = ImageryConfig::default();
        assert_eq!(cfg.check(), None);
        cfg.stale_share = 1.5;
        assert!(cfg.check().is_some());
        cfg = ImageryConfig {
            registration_offset_min_m: 2.0,
            registration_offset_max_m: 1.0,
            ..ImageryConfig::default()
        };
        assert!(cfg.check().is_some());
    }
}
