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
//! - [`resample`]: choosing the pack tiles along the corridor and filling them.
//! - [`error`]: the error enum, [`BuildError`].

pub mod error;
pub mod imagery;
pub mod resample;
pub mod route;

pub use error::BuildError;
pub use imagery::{Imagery, SlippyTiles, WorldCrs, WorldFileImage};
pub use resample::{BuildOptions, BuiltPack, build_pack};
pub use route::{parse_route_geojson, read_route_geojson};
