//! Synthetic drives with ground truth: a seeded world generator, its satellite tiles and camera
//! images, per-frame ground truth cut to the perception patch, and the scenario folder format
//! (`SCENARIO.md`).
//!
//! - `centerline`: straights and arcs, evaluated at any arc length and lateral offset.
//! - `world`: road network, ground-truth polylines in the route frame, occluders.
//! - `ground_raster`: the top-down ground and satellite rasters, painted once per world.
//! - `imagery`: registration error and staleness of the satellite imagery.
//! - `camera_render`: six camera images per frame by ray casting onto the ground plane.
//! - `lighting`: day / dusk / rain-like conditions.
//! - `patch_gt`: ground truth of a frame in the ego frame, cut to the patch.
//! - `drive`: [`SyntheticDrive`], the in-memory frame generator, and a [`WorldSatellite`]
//!   crop source.
//! - `slippy_tiles`: `z/x/y.png` tiles around a WGS84 anchor.
//! - `scenario`: writing and reading the scenario folder.
//!
//! Determinism: every random choice comes from PCG64 seeded with the drive seed, and texture
//! noise from an integer hash, so a seed gives the same world on every platform.

pub mod camera_render;
pub mod centerline;
pub mod drive;
pub mod ground_raster;
pub mod imagery;
pub mod lighting;
pub mod patch_gt;
pub mod scenario;
pub mod slippy_tiles;
pub mod world;

pub use drive::{DriveConfig, SynthError, SynthFrame, SyntheticDrive, WorldSatellite};
pub use imagery::{ImageryConfig, ImageryErrors, Registration};
pub use lighting::LightingPreset;
pub use patch_gt::Patch;
pub use scenario::{Scenario, ScenarioManifest, ScenarioPlacement, write_scenario};
