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
//! - [`frame`]: the route frame: the ground point a pack pixel shows ([`ground_point`]) and the
//!   farthest a route may reach from the origin ([`MAX_ROUTE_RADIUS_M`], tested distortion
//!   bound; [`check_route_radius`]).
//! - [`resample`]: filling the pack tiles from the imagery.
//! - [`compress`]: the tile codecs of version 2 packs ([`TileCompression`]), each tile decoded
//!   back by the runtime's decoder before it is written.
//! - [`error`]: the error enum, [`BuildError`].
//! - [`synthetic_route`]: a procedural winding road ([`SyntheticRoute`]) and satellite-like
//!   imagery around it ([`SyntheticRouteImagery`]), for packs of any length without a raster.

pub mod compress;
pub mod corridor;
pub mod error;
pub mod frame;
pub mod imagery;
pub mod options;
pub mod resample;
pub mod route;
pub mod synthetic_route;

pub use compress::{DEFAULT_JPEG_QUALITY, TileCompression, compress_tile, psnr_db};
pub use corridor::{MAX_CORRIDOR_RUNS, corridor_tiles};
pub use error::BuildError;
pub use frame::{EARTH_RADIUS_M, MAX_ROUTE_RADIUS_M, check_route_radius, ground_point};
pub use imagery::{Imagery, SlippyTiles, WorldCrs, WorldFileImage};
pub use options::{BuildOptions, PAPER_CROP};
pub use resample::{BuiltPack, build_pack};
pub use route::{parse_route_geojson, read_route_geojson};
pub use synthetic_route::{SyntheticRoute, SyntheticRouteImagery};
