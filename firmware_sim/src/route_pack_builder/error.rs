//! Errors of the route-pack builder, each with the input it concerns. Causes are chained as
//! `source()` (anyhow prints them with `{:#}`), not repeated in the message.

use std::path::PathBuf;

/// Why a pack could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A file could not be read.
    #[error("cannot read {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The route file is not GeoJSON.
    #[error("route {path} is not valid GeoJSON")]
    RouteGeoJson {
        /// The route file.
        path: PathBuf,
        /// The parser's message.
        source: Box<geojson::Error>,
    },
    /// The GeoJSON holds no usable LineString.
    #[error("route {path}: {reason}")]
    RouteShape {
        /// The route file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// An image could not be decoded.
    #[error("unreadable image {path}")]
    UnreadableImage {
        /// The image.
        path: PathBuf,
        /// The decoder's error.
        source: image::ImageError,
    },
    /// A slippy-map tile is not square, or not the size of the others.
    #[error("tile {path} is {width}x{height} px, expected {expected}x{expected}")]
    TileSize {
        /// The tile.
        path: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The size of the first tile read.
        expected: u32,
    },
    /// The tile folder has no zoom level (numeric sub-folder) or not the one asked for.
    #[error("tile folder {dir}: {reason}")]
    TileFolder {
        /// The folder.
        dir: PathBuf,
        /// What is missing.
        reason: String,
    },
    /// A tile under the corridor is not in the folder.
    #[error("missing tile {zoom}/{x}/{y} (.png or .jpg) in {dir}: the corridor needs it")]
    MissingTile {
        /// Tile folder.
        dir: PathBuf,
        /// Zoom level.
        zoom: u8,
        /// Column.
        x: u32,
        /// Row.
        y: u32,
    },
    /// Part of the corridor lies outside the georeferenced image.
    #[error("the corridor leaves the image {path} near lat {lat_deg:.7}, lon {lon_deg:.7}")]
    OutsideImage {
        /// The image.
        path: PathBuf,
        /// Where, latitude (degrees).
        lat_deg: f64,
        /// Where, longitude (degrees).
        lon_deg: f64,
    },
    /// A route vertex has no imagery under it.
    #[error(
        "route point {index} (lat {lat_deg:.7}, lon {lon_deg:.7}) is outside the imagery: {detail}"
    )]
    RouteOutsideImagery {
        /// Vertex number in the LineString.
        index: usize,
        /// Latitude, degrees.
        lat_deg: f64,
        /// Longitude, degrees.
        lon_deg: f64,
        /// Which tile or image was looked for.
        detail: String,
    },
    /// The world file does not hold six numbers or its affine map is singular.
    #[error("world file {path}: {reason}")]
    WorldFile {
        /// The world file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// An option is out of range.
    #[error("invalid option: {0}")]
    Option(String),
    /// A numeric option is not finite or outside its range.
    #[error("{option} {value} is outside {range}")]
    OptionRange {
        /// The option, as its `build-pack` flag.
        option: &'static str,
        /// The value given.
        value: String,
        /// The accepted range.
        range: &'static str,
    },
    /// The pack's tiles are too small for the model's crop: the runtime samples at most
    /// `MAX_CROP_TILES` tiles a crop, so every crop would fail.
    #[error(
        "--tile-px {tile_size_px} at --gsd-m {gsd_m}: a {crop_h_px}x{crop_w_px} px crop at \
         {crop_gsd_m} m/px spans up to {tiles} tiles, more than the runtime's MAX_CROP_TILES \
         ({max_tiles}); {}",
        match min_tile_px {
            Some(px) => format!("use --tile-px {px} or larger"),
            None => "no tile size up to 1024 px fits: use a coarser --gsd-m".to_string(),
        }
    )]
    TilesTooSmallForCrop {
        /// Tile side asked for, pixels.
        tile_size_px: u16,
        /// Pack ground sampling distance, metres per pixel.
        gsd_m: f64,
        /// Crop rows.
        crop_h_px: usize,
        /// Crop columns.
        crop_w_px: usize,
        /// Crop ground sampling distance, metres per pixel.
        crop_gsd_m: f64,
        /// Most tiles one crop spans at the worst pose.
        tiles: usize,
        /// The runtime's limit.
        max_tiles: usize,
        /// Smallest tile side that fits, if any.
        min_tile_px: Option<u16>,
    },
    /// The pack would exceed a limit of the pack format or of `memory_layout.toml`; found
    /// before any imagery is read.
    #[error("the pack needs {needed} {what}, more than {limit_name} ({limit})")]
    PackTooLarge {
        /// What is counted (`route points`, `tiles`, `bytes`, ...).
        what: &'static str,
        /// How many the pack needs.
        needed: u64,
        /// The limit.
        limit: u64,
        /// Where the limit comes from.
        limit_name: &'static str,
    },
    /// A route point lies farther from the route-frame origin than the frame's tested
    /// distortion bound covers (`frame::MAX_ROUTE_RADIUS_M`).
    #[error(
        "route point {index} is {:.1} km from the route-frame origin, beyond the {:.1} km \
         within which one route frame keeps the crop within its tested distortion bound; \
         put the origin at the route's middle (--origin LAT,LON) or split the route",
        distance_m / 1000.0,
        max_m / 1000.0
    )]
    RouteBeyondFrame {
        /// Vertex number in the route.
        index: usize,
        /// Its distance from the origin in the route frame, metres.
        distance_m: f64,
        /// The limit, metres.
        max_m: f64,
    },
    /// A tile payload could not be compressed.
    #[error("tile ({tile_x}, {tile_y}) could not be compressed: {detail}")]
    TileEncode {
        /// Column of the tile.
        tile_x: i32,
        /// Row of the tile.
        tile_y: i32,
        /// The compressor's message.
        detail: String,
    },
    /// Every pack tile was skipped for missing imagery.
    #[error("no pack tile has imagery: nothing to write")]
    Empty,
    /// The runtime's encoder rejected the pack.
    #[error("pack encoding failed: {0}")]
    Encode(#[from] satmap_runtime::route_pack::PackError),
}
