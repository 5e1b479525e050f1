//! Host builder of route packs (`satmap_runtime::route_pack`, byte layout in the runtime's
//! `route_pack/FORMAT.md`).
//!
//! Inputs: imagery as a folder of slippy-map tiles `z/x/y.png|jpg` in Web Mercator, or one
//! georeferenced image with a world file; a route as a GeoJSON LineString in WGS84; a corridor
//! width and a target ground sampling distance. The builder resamples the imagery **once** into
//! the route frame, the local ENU tangent plane at the route's first point (at ellipsoid height
//! 0) unless an origin is given, so the vehicle never projects per pixel.
//!
//! - [`route`]: reading the GeoJSON route.
//! - [`imagery`]: the imagery sources ([`SlippyTiles`], [`WorldFileImage`]) behind [`Imagery`].
//! - [`options`]: [`BuildOptions`] and their checks (ranges, tiles large enough for the crop).
//! - [`corridor`]: the corridor's tiles, counted and checked against the pack format and the
//!   `route_pack` region of `memory_layout.toml` before any imagery is read.
//! - [`resample`]: filling the pack tiles from the imagery.
//! - [`error`]: the error enum, [`BuildError`].

pub mod corridor;
pub mod error;
pub mod imagery;
pub mod options;
pub mod resample;
pub mod route;

pub use corridor::{MAX_CORRIDOR_RUNS, corridor_tiles};
pub use error::BuildError;
pub use imagery::{Imagery, SlippyTiles, WorldCrs, WorldFileImage};
pub use options::{BuildOptions, PAPER_CROP};
pub use resample::{BuiltPack, build_pack};
pub use route::{parse_route_geojson, read_route_geojson};
