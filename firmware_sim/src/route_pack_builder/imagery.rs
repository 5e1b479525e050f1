//! Imagery sources the builder resamples: slippy-map tile folders and georeferenced images.
//!
//! Source pixel coordinates: pixel `(col i, row j)` covers `[i, i + 1) x [j, j + 1)`, so its
//! centre is at `(i + 0.5, j + 0.5)`; rows run south (image convention).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use glam::DVec2;
use image::RgbImage;
use satmap_runtime::geo::web_mercator::{TILE_SIZE_PX, lat_lon_to_world_px};

use super::error::BuildError;

/// Decoded slippy tiles kept in memory at once (about 200 KB each at 256 px).
const TILE_CACHE_LEN: usize = 512;

/// Why a sample has no colour.
#[derive(Clone, Debug, PartialEq)]
pub enum Gap {
    /// The slippy tile `zoom/x/y` is not in the folder.
    MissingTile {
        /// Zoom level.
        zoom: u8,
        /// Column.
        x: u32,
        /// Row.
        y: u32,
    },
    /// Outside the georeferenced image.
    OutsideImage,
}

/// A source of WGS84-referenced RGB imagery.
pub trait Imagery {
    /// Source pixel coordinates of a WGS84 latitude/longitude (degrees).
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2;
    /// Bilinear colour at source pixel coordinates `p`, or the gap that prevents it.
    ///
    /// # Errors
    /// An image that exists but cannot be decoded, or has the wrong size.
    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError>;
    /// The error to report for a gap at `(lat_deg, lon_deg)`.
    fn gap_error(&self, gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError;
}

/// Bilinear blend of the four pixels around `p` fetched by `texel` (which gets integer pixel
/// indices and may fail).
fn bilinear<E>(
    p: DVec2,
    mut texel: impl FnMut(i64, i64) -> Result<[u8; 3], E>,
) -> Result<[u8; 3], E> {
    let (u, v) = (p.x - 0.5, p.y - 0.5);
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (u - x0, v - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let a = texel(x0, y0)?;
    let b = texel(x0 + 1, y0)?;
    let c = texel(x0, y0 + 1)?;
    let d = texel(x0 + 1, y0 + 1)?;
    Ok(std::array::from_fn(|k| {
        let top = f64::from(a[k]) + (f64::from(b[k]) - f64::from(a[k])) * fx;
        let bottom = f64::from(c[k]) + (f64::from(d[k]) - f64::from(c[k])) * fx;
        (top + (bottom - top) * fy).round().clamp(0.0, 255.0) as u8
    }))
}

/// A folder of slippy-map tiles `zoom/x/y.png` (or `.jpg`, `.jpeg`) in Web Mercator.
pub struct SlippyTiles {
    dir: PathBuf,
    zoom: u8,
    tile_px: u32,
    cache: HashMap<(u32, u32), Option<Rc<RgbImage>>>,
    last: Option<((u32, u32), Rc<RgbImage>)>,
}

impl SlippyTiles {
    /// Open `dir` at `zoom` (default: the highest zoom folder present). The tile size is taken
    /// from the first tile found.
    ///
    /// # Errors
    /// No zoom folder, no tile at that zoom, or an unreadable first tile.
    pub fn open(dir: &Path, zoom: Option<u8>) -> Result<Self, BuildError> {
        let folder = |reason: String| BuildError::TileFolder {
            dir: dir.to_owned(),
            reason,
        };
        let entries = std::fs::read_dir(dir).map_err(|source| BuildError::Io {
            path: dir.to_owned(),
            source,
        })?;
        let zooms: Vec<u8> = entries
            .filter_map(Result::ok)
            .filter(|e| e.path().is_dir())
            .filter_map(|e| e.file_name().to_str()?.parse::<u8>().ok())
            .collect();
        let zoom = match zoom {
            Some(z) if zooms.contains(&z) => z,
            Some(z) => return Err(folder(format!("no zoom folder {z}/ (found {zooms:?})"))),
            None => *zooms
                .iter()
                .max()
                .ok_or_else(|| folder("no numeric zoom folder z/".into()))?,
        };
        if zoom > satmap_runtime::geo::web_mercator::MAX_ZOOM {
            return Err(folder(format!(
                "zoom {zoom} is beyond the supported {}",
                satmap_runtime::geo::web_mercator::MAX_ZOOM
            )));
        }
        let first = first_tile(&dir.join(zoom.to_string()))
            .ok_or_else(|| folder(format!("no x/y.png or x/y.jpg tile under {zoom}/")))?;
        let img = decode(&first)?;
        if img.width() != img.height() || img.width() == 0 {
            return Err(BuildError::TileSize {
                path: first,
                width: img.width(),
                height: img.height(),
                expected: img.width(),
            });
        }
        Ok(Self {
            dir: dir.to_owned(),
            zoom,
            tile_px: img.width(),
            cache: HashMap::new(),
            last: None,
        })
    }

    /// The zoom level in use.
    #[must_use]
    pub const fn zoom(&self) -> u8 {
        self.zoom
    }

    /// Tile side, pixels.
    #[must_use]
    pub const fn tile_px(&self) -> u32 {
        self.tile_px
    }

    fn tile(&mut self, x: u32, y: u32) -> Result<Option<Rc<RgbImage>>, BuildError> {
        if let Some((key, img)) = &self.last
            && *key == (x, y)
        {
            return Ok(Some(Rc::clone(img)));
        }
        if let Some(hit) = self.cache.get(&(x, y)) {
            if let Some(img) = hit {
                self.last = Some(((x, y), Rc::clone(img)));
            }
            return Ok(hit.clone());
        }
        if self.cache.len() >= TILE_CACHE_LEN {
            // Pack tiles are filled row by row along the corridor: the working set is a band,
            // so dropping everything now and then costs little and keeps memory bounded.
            self.cache.clear();
        }
        let base = self.dir.join(self.zoom.to_string()).join(x.to_string());
        let path = ["png", "jpg", "jpeg"]
            .iter()
            .map(|ext| base.join(format!("{y}.{ext}")))
            .find(|p| p.is_file());
        let img = match path {
            None => None,
            Some(path) => {
                let img = decode(&path)?;
                if img.width() != self.tile_px || img.height() != self.tile_px {
                    return Err(BuildError::TileSize {
                        path,
                        width: img.width(),
                        height: img.height(),
                        expected: self.tile_px,
                    });
                }
                Some(Rc::new(img))
            }
        };
        if let Some(img) = &img {
            self.last = Some(((x, y), Rc::clone(img)));
        }
        self.cache.insert((x, y), img.clone());
        Ok(img)
    }
}

impl Imagery for SlippyTiles {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        let w = lat_lon_to_world_px(lat_deg, lon_deg, self.zoom);
        DVec2::new(w.x_px, w.y_px) * (f64::from(self.tile_px) / TILE_SIZE_PX)
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        let size = i64::from(self.tile_px);
        let tiles = 1i64 << self.zoom;
        let zoom = self.zoom;
        let mut err = None;
        let out = bilinear(p, |x, y| {
            let (tx, ty) = (x.div_euclid(size), y.div_euclid(size));
            if ty < 0 || ty >= tiles {
                return Err(Gap::OutsideImage);
            }
            // Longitude wraps around the antimeridian.
            let tx = tx.rem_euclid(tiles);
            let key = (tx as u32, ty as u32);
            match self.tile(key.0, key.1) {
                Ok(Some(img)) => {
                    let (lx, ly) = (x.rem_euclid(size) as u32, y.rem_euclid(size) as u32);
                    Ok(img.get_pixel(lx, ly).0)
                }
                Ok(None) => Err(Gap::MissingTile {
                    zoom,
                    x: key.0,
                    y: key.1,
                }),
                Err(e) => {
                    err = Some(e);
                    Err(Gap::OutsideImage)
                }
            }
        });
        match err {
            Some(e) => Err(e),
            None => Ok(out),
        }
    }

    fn gap_error(&self, gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        match gap {
            Gap::MissingTile { zoom, x, y } => BuildError::MissingTile {
                dir: self.dir.clone(),
                zoom: *zoom,
                x: *x,
                y: *y,
            },
            Gap::OutsideImage => BuildError::OutsideImage {
                path: self.dir.clone(),
                lat_deg,
                lon_deg,
            },
        }
    }
}

fn first_tile(zoom_dir: &Path) -> Option<PathBuf> {
    let mut cols: Vec<PathBuf> = std::fs::read_dir(zoom_dir)
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .collect();
    cols.sort();
    cols.into_iter().filter(|p| p.is_dir()).find_map(|col| {
        let mut files: Vec<PathBuf> = std::fs::read_dir(col)
            .ok()?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .collect();
        files.sort();
        files.into_iter().find(|f| {
            f.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
    })
}

fn decode(path: &Path) -> Result<RgbImage, BuildError> {
    image::open(path)
        .map(|img| img.to_rgb8())
        .map_err(|source| BuildError::UnreadableImage {
            path: path.to_owned(),
            source,
        })
}

/// The coordinate system of a world file's map coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum WorldCrs {
    /// EPSG:3857 Web Mercator, metres (what slippy-map tiles use).
    #[default]
    WebMercator,
    /// EPSG:4326 WGS84, x = longitude and y = latitude in degrees.
    Wgs84,
}

/// One georeferenced image: a PNG (or JPEG) plus a world file (six lines `A D B E C F`: map
/// `x = A col + B row + C`, `y = D col + E row + F` at pixel centres, `(C, F)` being the centre of
/// the top-left pixel).
pub struct WorldFileImage {
    path: PathBuf,
    image: RgbImage,
    crs: WorldCrs,
    /// Inverse of the 2x2 part, row-major.
    inverse: [f64; 4],
    offset: DVec2,
}

impl WorldFileImage {
    /// Open `image` with its world file (default: the image path with extension `.pgw`,
    /// `.pngw`, `.jgw`, `.jpgw` or `.wld`, the first that exists).
    ///
    /// # Errors
    /// Unreadable image or world file, not six numbers, or a singular affine map.
    pub fn open(
        image: &Path,
        world_file: Option<&Path>,
        crs: WorldCrs,
    ) -> Result<Self, BuildError> {
        let world = match world_file {
            Some(p) => p.to_owned(),
            None => ["pgw", "pngw", "jgw", "jpgw", "wld"]
                .iter()
                .map(|ext| image.with_extension(ext))
                .find(|p| p.is_file())
                .ok_or_else(|| BuildError::WorldFile {
                    path: image.with_extension("pgw"),
                    reason: "no world file next to the image (.pgw, .pngw, .jgw, .jpgw, .wld)"
                        .into(),
                })?,
        };
        let text = satmap_runtime::host_files::read_text_capped(
            &world,
            satmap_runtime::host_files::MAX_CONFIG_BYTES,
        )
        .map_err(|source| BuildError::Io {
            path: world.clone(),
            source,
        })?;
        let numbers: Vec<f64> = text
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|e| BuildError::WorldFile {
                path: world.clone(),
                reason: format!("not a number: {e}"),
            })?;
        let [a, d, b, e, c, f] = numbers[..] else {
            return Err(BuildError::WorldFile {
                path: world,
                reason: format!("{} numbers, expected 6", numbers.len()),
            });
        };
        let det = a * e - b * d;
        if !det.is_finite() || det.abs() < 1e-300 || ![c, f].iter().all(|v| v.is_finite()) {
            return Err(BuildError::WorldFile {
                path: world,
                reason: "the affine map is singular or not finite".into(),
            });
        }
        Ok(Self {
            path: image.to_owned(),
            image: decode(image)?,
            crs,
            inverse: [e / det, -b / det, -d / det, a / det],
            offset: DVec2::new(c, f),
        })
    }
}

impl Imagery for WorldFileImage {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        let map = match self.crs {
            WorldCrs::Wgs84 => DVec2::new(lon_deg, lat_deg),
            WorldCrs::WebMercator => {
                let r = satmap_runtime::geo::ellipsoid::WGS84_A_M;
                DVec2::new(
                    r * lon_deg.to_radians(),
                    r * lat_deg.to_radians().tan().asinh(),
                )
            }
        };
        let d = map - self.offset;
        let [i00, i01, i10, i11] = self.inverse;
        // (col, row) of the pixel centre, then + 0.5 for this module's convention.
        DVec2::new(i00 * d.x + i01 * d.y + 0.5, i10 * d.x + i11 * d.y + 0.5)
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        let (w, h) = (
            i64::from(self.image.width()),
            i64::from(self.image.height()),
        );
        Ok(bilinear(p, |x, y| {
            if x < 0 || y < 0 || x >= w || y >= h {
                return Err(Gap::OutsideImage);
            }
            Ok(self.image.get_pixel(x as u32, y as u32).0)
        }))
    }

    fn gap_error(&self, _gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        BuildError::OutsideImage {
            path: self.path.clone(),
            lat_deg,
            lon_deg,
        }
    }
}
