//! `satmap-sim build-pack`: build a route pack from slippy-map tiles (or one georeferenced
//! image) and a GeoJSON route, and write it to a file.

use std::path::PathBuf;

use anyhow::{Context, Result};
use satmap_runtime::geo::Geodetic;

use crate::route_pack_builder::{
    BuildOptions, DEFAULT_JPEG_QUALITY, Imagery, PAPER_CROP, SlippyTiles, SyntheticRoute,
    TileCompression, WorldCrs, WorldFileImage, build_pack, read_route_geojson,
};
use satmap_runtime::satellite::CropSpec;

/// Arguments of `build-pack`.
#[derive(clap::Args, Clone, Debug)]
pub struct Args {
    /// Route: GeoJSON LineString in WGS84 (bare geometry, Feature or FeatureCollection).
    #[arg(long, required_unless_present = "synthetic_km")]
    pub route: Option<PathBuf>,
    /// Folder of slippy-map tiles `z/x/y.png|jpg` (Web Mercator).
    #[arg(
        long,
        conflicts_with = "image",
        required_unless_present_any = ["image", "synthetic_km"]
    )]
    pub tiles: Option<PathBuf>,
    /// Instead of `--route` and imagery: a procedural winding road of this many kilometres
    /// (up to 200) with satellite-like imagery around it, anchored at `--origin` (default
    /// 48.137, 11.575), from `--seed`. How a 100 km route pack is made without map data.
    #[arg(long, conflicts_with_all = ["route", "tiles", "image"])]
    pub synthetic_km: Option<f64>,
    /// Seed of `--synthetic-km`.
    #[arg(long, default_value_t = 1, requires = "synthetic_km")]
    pub seed: u64,
    /// Zoom level to read from `--tiles` (default: the highest present).
    #[arg(long, requires = "tiles")]
    pub zoom: Option<u8>,
    /// One georeferenced image (PNG or JPEG) with a world file.
    #[arg(long)]
    pub image: Option<PathBuf>,
    /// World file of `--image` (default: next to it, `.pgw`/`.pngw`/`.jgw`/`.jpgw`/`.wld`).
    #[arg(long, requires = "image")]
    pub world_file: Option<PathBuf>,
    /// Coordinate system of the world file.
    #[arg(long, value_enum, default_value_t = WorldCrs::WebMercator, requires = "image")]
    pub world_crs: WorldCrs,
    /// Output pack file.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Corridor width around the route to cover, metres.
    #[arg(long, default_value_t = 60.0)]
    pub corridor_m: f64,
    /// Ground sampling distance of the pack, metres per pixel.
    #[arg(long, default_value_t = 0.15)]
    pub gsd_m: f64,
    /// Pack tile side, pixels (power of two, 8..=1024; large enough that one crop spans at most
    /// the runtime's 36 tiles).
    #[arg(long, default_value_t = 256)]
    pub tile_px: u16,
    /// Rows of the crop the model takes from the pack (`sat_h`).
    #[arg(long, default_value_t = PAPER_CROP.height_px)]
    pub crop_h_px: usize,
    /// Columns of the crop (`sat_w`).
    #[arg(long, default_value_t = PAPER_CROP.width_px)]
    pub crop_w_px: usize,
    /// Ground sampling distance of the crop, metres per pixel (`sat_gsd_m`).
    #[arg(long, default_value_t = PAPER_CROP.gsd_m)]
    pub crop_gsd_m: f64,
    /// Leave out pack tiles without imagery instead of failing.
    #[arg(long)]
    pub allow_missing: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Route-frame origin as `LAT,LON[,HEIGHT]` (WGS84 degrees, metres); default: the route's
    /// first point at height 0. Use a synthetic world's anchor to keep its frame.
    #[arg(long, value_parser = parse_origin, allow_hyphen_values = true)]
    pub origin: Option<Geodetic>,
    /// How tiles are stored: `raw` (format version 1, read in place), `jpeg` or `deflate`
    /// (version 2, decoded on the vehicle into the `tile_pixels` region).
    #[arg(long, value_enum, default_value_t = CodecArg::Raw)]
    pub codec: CodecArg,
    /// JPEG quality with `--codec jpeg`, 1..=100.
    #[arg(long, default_value_t = DEFAULT_JPEG_QUALITY)]
    pub jpeg_quality: u8,
}

/// Tile codec on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodecArg {
    /// Raw RGB (version 1).
    Raw,
    /// JPEG, lossy (version 2).
    Jpeg,
    /// zlib, lossless (version 2).
    Deflate,
}

impl CodecArg {
    /// The builder's compression for this codec.
    #[must_use]
    pub const fn compression(self, jpeg_quality: u8) -> TileCompression {
        match self {
            Self::Raw => TileCompression::Raw,
            Self::Jpeg => TileCompression::Jpeg {
                quality: jpeg_quality,
            },
            Self::Deflate => TileCompression::Deflate,
        }
    }
}

fn parse_origin(text: &str) -> Result<Geodetic, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().map_err(|e| format!("`{s}`: {e}")))
        .collect::<Result<_, _>>()?;
    let g = match v[..] {
        [lat, lon] => Geodetic::new(lat, lon, 0.0),
        [lat, lon, h] => Geodetic::new(lat, lon, h),
        _ => return Err("expected LAT,LON or LAT,LON,HEIGHT".into()),
    };
    if g.is_valid() && (-180.0..=180.0).contains(&g.lon_deg) {
        Ok(g)
    } else {
        Err(format!("{text} is not a WGS84 position"))
    }
}

/// Build the pack and write it; prints a one-line summary.
///
/// # Errors
/// Any [`crate::route_pack_builder::BuildError`], or the output cannot be written.
pub fn run(args: &Args) -> Result<()> {
    // Every numeric option is checked before any file is opened.
    let opts = BuildOptions {
        corridor_width_m: args.corridor_m,
        gsd_m: args.gsd_m,
        tile_size_px: args.tile_px,
        allow_missing: args.allow_missing,
        show_progress: !args.quiet,
        origin: args.origin,
        crop: CropSpec {
            height_px: args.crop_h_px,
            width_px: args.crop_w_px,
            gsd_m: args.crop_gsd_m,
            ..PAPER_CROP
        },
        compression: args.codec.compression(args.jpeg_quality),
    };
    opts.validate()?;
    let started = std::time::Instant::now();
    let built = if let Some(km) = args.synthetic_km {
        let anchor = args.origin.unwrap_or(Geodetic::new(48.137, 11.575, 0.0));
        let road = SyntheticRoute::new(args.seed, km, anchor)?;
        let opts = BuildOptions {
            origin: Some(road.anchor()),
            ..opts
        };
        build_pack(&mut road.imagery_at(opts.gsd_m), &road.route_wgs84(), &opts)?
    } else {
        let Some(route_path) = &args.route else {
            anyhow::bail!("give --route FILE or --synthetic-km KM");
        };
        let route = read_route_geojson(route_path)?;
        let mut imagery: Box<dyn Imagery> = match (&args.tiles, &args.image) {
            (Some(dir), _) => Box::new(SlippyTiles::open(dir, args.zoom)?),
            (None, Some(image)) => Box::new(WorldFileImage::open(
                image,
                args.world_file.as_deref(),
                args.world_crs,
            )?),
            (None, None) => anyhow::bail!("give --tiles DIR or --image FILE"),
        };
        build_pack(imagery.as_mut(), &route, &opts)?
    };
    std::fs::write(&args.out, &built.bytes)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let km = built.route_length_m / 1000.0;
    println!(
        "{}: {} tiles ({} skipped), {:.1} MB ({:.2} MB/km; tiles {:.1}:1 against raw, PSNR {:.1} dB, worst tile {:.1} dB), route {:.2} km, origin {:.7}, {:.7}, built in {:.1} s",
        args.out.display(),
        built.tiles,
        built.skipped_tiles,
        built.bytes.len() as f64 / 1e6,
        built.bytes.len() as f64 / 1e6 / km.max(1e-9),
        built.raw_tile_bytes as f64 / built.payload_bytes.max(1) as f64,
        built.tile_psnr_db,
        built.worst_tile_psnr_db,
        km,
        built.origin.lat_deg,
        built.origin.lon_deg,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
