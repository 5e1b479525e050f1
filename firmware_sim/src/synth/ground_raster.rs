//! Top-down rasters of the world: the ground texture the cameras see (asphalt, sidewalks,
//! markings, kerbs, grass, shadows) and the satellite view (the same plus roofs, tree canopies
//! and car roofs), painted once per world with tiny-skia and then sampled.
//!
//! Raster layout: u8 RGB, row 0 at the north edge (route y = `y_max_m`), column 0 at the west
//! edge (route x = `x_min_m`); pixel `(row, col)` covers route points
//! `x in [x_min + col * gsd, x_min + (col + 1) * gsd)`, `y in (y_max - (row + 1) * gsd, y_max - row * gsd]`.

use glam::DVec2;
use tiny_skia::{
    Color, FillRule, LineCap, LineJoin, Paint, PathBuilder, Pixmap, Stroke, StrokeDash, Transform,
};

use super::imagery::Registration;
use super::world::{DividerPaint, OccluderKind, World};

/// One raster.
#[derive(Clone, Debug)]
pub struct GroundRaster {
    /// Route x of the west edge, metres.
    pub x_min_m: f64,
    /// Route y of the north edge, metres.
    pub y_max_m: f64,
    /// Metres per pixel.
    pub gsd_m: f64,
    /// Columns.
    pub width_px: usize,
    /// Rows.
    pub height_px: usize,
    /// RGB bytes, row-major.
    pub rgb: Vec<u8>,
    /// Colour returned outside the raster.
    pub outside: [u8; 3],
}

/// Errors painting the rasters.
#[derive(Clone, Debug, thiserror::Error)]
pub enum RasterError {
    /// The world is too large for one raster at this resolution.
    #[error("world raster of {width_px} x {height_px} px at {gsd_m} m/px is too large")]
    TooLarge {
        /// Columns needed.
        width_px: usize,
        /// Rows needed.
        height_px: usize,
        /// Requested resolution.
        gsd_m: f64,
    },
}

/// Most pixels a raster may have (keeps memory near 100 MB per raster pair).
pub const MAX_RASTER_PIXELS: usize = 16_000_000;

/// Grass / terrain colour outside roads.
const GRASS: [u8; 3] = [92, 104, 66];

impl GroundRaster {
    /// Bilinear sample at route point `(x_m, y_m)`, channels 0..255 as f32.
    #[inline]
    #[must_use]
    pub fn sample_bilinear(&self, x_m: f32, y_m: f32) -> [f32; 3] {
        let inv = 1.0 / self.gsd_m as f32;
        let fx = (x_m - self.x_min_m as f32) * inv - 0.5;
        let fy = (self.y_max_m as f32 - y_m) * inv - 0.5;
        if !(fx >= 0.0 && fy >= 0.0) {
            return self.outside.map(f32::from);
        }
        // `as usize` saturates (an infinite `fx` gives usize::MAX), so compare without adding.
        let (x0, y0) = (fx as usize, fy as usize);
        if x0 >= self.width_px.saturating_sub(1) || y0 >= self.height_px.saturating_sub(1) {
            return self.outside.map(f32::from);
        }
        let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
        let i = (y0 * self.width_px + x0) * 3;
        let j = i + self.width_px * 3;
        let p = &self.rgb;
        let mut out = [0.0f32; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let top = f32::from(p[i + k]) * (1.0 - tx) + f32::from(p[i + 3 + k]) * tx;
            let bottom = f32::from(p[j + k]) * (1.0 - tx) + f32::from(p[j + 3 + k]) * tx;
            *o = top * (1.0 - ty) + bottom * ty;
        }
        out
    }
}

/// The two rasters of a world.
#[derive(Clone, Debug)]
pub struct WorldRasters {
    /// What the cameras see on the ground.
    pub ground: GroundRaster,
    /// What a satellite sees from above.
    pub satellite: GroundRaster,
    /// Unit route-frame direction shadows fall in (away from the sun).
    pub shadow_dir: DVec2,
}

/// Paint both rasters of `world` at `gsd_m` metres per pixel with perfect imagery; `seed`
/// drives the texture noise and sun direction.
pub fn paint_world(world: &World, gsd_m: f64, seed: u64) -> Result<WorldRasters, RasterError> {
    paint_world_with_imagery(world, None, &Registration::NONE, gsd_m, seed)
}

/// Paint both rasters of `world`: the ground the cameras see as the world is now, and the
/// satellite view of `imaged` (the world when the imagery was taken; `None` = now) displaced by
/// `registration` (see `synth::imagery`).
pub fn paint_world_with_imagery(
    world: &World,
    imaged: Option<&World>,
    registration: &Registration,
    gsd_m: f64,
    seed: u64,
) -> Result<WorldRasters, RasterError> {
    let (lo, hi) = world.bounds_m;
    let width_px = ((hi.x - lo.x) / gsd_m).ceil().max(1.0) as usize;
    let height_px = ((hi.y - lo.y) / gsd_m).ceil().max(1.0) as usize;
    let too_large = RasterError::TooLarge {
        width_px,
        height_px,
        gsd_m,
    };
    if width_px.saturating_mul(height_px) > MAX_RASTER_PIXELS {
        return Err(too_large);
    }
    let new_pixmap = || {
        let mut pixmap = Pixmap::new(width_px as u32, height_px as u32)?;
        pixmap.fill(Color::from_rgba8(GRASS[0], GRASS[1], GRASS[2], 255));
        Some(pixmap)
    };
    let mut pixmap = new_pixmap().ok_or(too_large.clone())?;
    // Route (x east, y north) -> pixel (col right, row down).
    let to_px = Transform::from_row(
        (1.0 / gsd_m) as f32,
        0.0,
        0.0,
        (-1.0 / gsd_m) as f32,
        (-lo.x / gsd_m) as f32,
        (hi.y / gsd_m) as f32,
    );
    // Sun from a seeded azimuth; shadows fall away from it.
    let shadow_angle = (hash01(seed, 17, 3) * std::f64::consts::TAU as f32) as f64;
    let shadow_dir = DVec2::from_angle(shadow_angle);
    paint_ground(&mut pixmap, world, shadow_dir, to_px);
    let mut ground = to_raster(&pixmap, lo, hi, gsd_m);

    // Satellite: roofs, canopies and car roofs on top of the ground (of the imaged world,
    // displaced by the registration error).
    if imaged.is_some() || !registration.is_none() {
        pixmap = new_pixmap().ok_or(too_large)?;
        let t = to_px.pre_concat(registration_transform(registration));
        paint_ground(&mut pixmap, imaged.unwrap_or(world), shadow_dir, t);
        paint_roofs(&mut pixmap, world, t);
    } else {
        paint_roofs(&mut pixmap, world, to_px);
    }
    let mut satellite = to_raster(&pixmap, lo, hi, gsd_m);
    add_texture_noise(&mut ground, seed);
    add_texture_noise(&mut satellite, seed ^ 0x5a5a);
    Ok(WorldRasters {
        ground,
        satellite,
        shadow_dir,
    })
}

/// The registration error as a route-frame transform (true point -> imaged point).
fn registration_transform(r: &Registration) -> Transform {
    let (sin, cos) = r.yaw_rad.sin_cos();
    let c = r.pivot_m;
    let tx = c.x - (cos * c.x - sin * c.y) + r.offset_m.x;
    let ty = c.y - (sin * c.x + cos * c.y) + r.offset_m.y;
    Transform::from_row(
        cos as f32,
        sin as f32,
        -sin as f32,
        cos as f32,
        tx as f32,
        ty as f32,
    )
}

/// Sidewalks, asphalt, kerbs, markings and the occluders' shadows, through `to_px`.
fn paint_ground(pixmap: &mut Pixmap, world: &World, shadow_dir: DVec2, to_px: Transform) {
    let cfg = world.config;
    let walk = cfg.sidewalk_width_m;

    let sidewalk = world.main_polygon(walk);
    fill(pixmap, &sidewalk, [168, 166, 158, 255], to_px);
    for road in &world.side_roads {
        let len = road.centerline.length_m();
        let w = road.half_width_m + walk;
        let poly: Vec<DVec2> = road
            .centerline
            .offset_polyline(-2.0, len, 2.0, |_| w)
            .into_iter()
            .chain(
                road.centerline
                    .offset_polyline(-2.0, len, 2.0, |_| -w)
                    .into_iter()
                    .rev(),
            )
            .collect();
        fill(pixmap, &poly, [168, 166, 158, 255], to_px);
    }
    let asphalt = [68, 70, 74, 255];
    fill(pixmap, &world.main_polygon(0.0), asphalt, to_px);
    for road in &world.side_roads {
        let len = road.centerline.length_m();
        let w = road.half_width_m;
        let poly: Vec<DVec2> = road
            .centerline
            .offset_polyline(-1.0, len, 2.0, |_| w)
            .into_iter()
            .chain(
                road.centerline
                    .offset_polyline(-1.0, len, 2.0, |_| -w)
                    .into_iter()
                    .rev(),
            )
            .collect();
        fill(pixmap, &poly, asphalt, to_px);
    }
    for f in &world.corner_fills {
        fill(pixmap, f, asphalt, to_px);
    }
    for b in &world.boundaries {
        stroke(pixmap, b, [196, 194, 186, 255], 0.25, None, to_px);
    }
    for d in &world.dividers {
        match d.paint {
            DividerPaint::SolidCentre => {
                stroke(pixmap, &d.points_m, [222, 186, 60, 255], 0.2, None, to_px);
            }
            DividerPaint::DashedLane => {
                stroke(
                    pixmap,
                    &d.points_m,
                    [232, 232, 228, 255],
                    0.18,
                    Some([3.0, 4.0]),
                    to_px,
                );
            }
        }
    }
    for c in &world.crossings {
        // Bars run along the road, 0.5 m wide, every metre across it.
        let across = c.road_dir.perp();
        let bars = (c.width_across_m / 1.0).floor() as i32;
        let first = -f64::from(bars - 1) / 2.0;
        for k in 0..bars {
            let centre = c.centre_m + across * (first + f64::from(k));
            let a = c.road_dir * (c.length_along_m / 2.0);
            let w = across * 0.25;
            fill(
                pixmap,
                &[
                    centre - a - w,
                    centre + a - w,
                    centre + a + w,
                    centre - a + w,
                ],
                [236, 236, 232, 255],
                to_px,
            );
        }
    }

    for o in &world.occluders {
        let footprint = o.corners_m();
        let offset = shadow_dir * (o.height_m * 0.7);
        let mut pts: Vec<DVec2> = footprint
            .iter()
            .copied()
            .chain(footprint.iter().map(|&p| p + offset))
            .collect();
        let hull = convex_hull(&mut pts);
        let alpha = if o.kind == OccluderKind::Tree { 70 } else { 95 };
        fill(pixmap, &hull, [10, 12, 20, alpha], to_px);
    }
}

/// Roofs, tree canopies and car roofs: what a satellite sees above the ground.
fn paint_roofs(pixmap: &mut Pixmap, world: &World, to_px: Transform) {
    for o in &world.occluders {
        let c = o.colour.map(|v| (v * 255.0).clamp(0.0, 255.0) as u8);
        let corners = o.corners_m();
        match o.kind {
            OccluderKind::Building => {
                let roof = [c[0] / 2 + 40, c[1] / 2 + 38, c[2] / 2 + 36, 255];
                fill(pixmap, &corners, roof, to_px);
                let mut ring = corners.to_vec();
                ring.push(corners[0]);
                stroke(
                    pixmap,
                    &ring,
                    [c[0] / 3, c[1] / 3, c[2] / 3, 255],
                    0.6,
                    None,
                    to_px,
                );
            }
            OccluderKind::Tree => {
                let mut pb = PathBuilder::new();
                pb.push_circle(
                    o.centre_m.x as f32,
                    o.centre_m.y as f32,
                    (o.half_width_m * 1.15) as f32,
                );
                if let Some(path) = pb.finish() {
                    pixmap.fill_path(
                        &path,
                        &paint([c[0], c[1], c[2], 240]),
                        FillRule::Winding,
                        to_px,
                        None,
                    );
                }
            }
            OccluderKind::ParkedCar => {
                fill(pixmap, &corners, [c[0], c[1], c[2], 255], to_px);
                // Windscreen band across the middle of the car.
                let a = o.axis * 0.45;
                let x = -o.axis.perp() * (o.half_width_m * 0.8);
                let m = o.centre_m + o.axis * 0.5;
                fill(
                    pixmap,
                    &[m - x - a, m + x - a, m + x + a, m - x + a],
                    [30, 34, 40, 255],
                    to_px,
                );
            }
        }
    }
}

impl World {
    /// Polygon of the main carriageway widened by `extra_m` on both sides.
    #[must_use]
    pub fn main_polygon(&self, extra_m: f64) -> Vec<DVec2> {
        let length = self.main.length_m();
        let left = self.main.offset_polyline(-2.0, length + 2.0, 1.0, |s| {
            self.half_widths_at(s).0 + extra_m
        });
        let right = self.main.offset_polyline(-2.0, length + 2.0, 1.0, |s| {
            -self.half_widths_at(s).1 - extra_m
        });
        left.into_iter().chain(right.into_iter().rev()).collect()
    }
}

fn paint(rgba: [u8; 4]) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(rgba[0], rgba[1], rgba[2], rgba[3]);
    p.anti_alias = true;
    p
}

fn path_of(points: &[DVec2], closed: bool) -> Option<tiny_skia::Path> {
    let mut pb = PathBuilder::new();
    let (first, rest) = points.split_first()?;
    pb.move_to(first.x as f32, first.y as f32);
    for p in rest {
        pb.line_to(p.x as f32, p.y as f32);
    }
    if closed {
        pb.close();
    }
    pb.finish()
}

fn fill(pixmap: &mut Pixmap, polygon: &[DVec2], rgba: [u8; 4], t: Transform) {
    if let Some(path) = path_of(polygon, true) {
        pixmap.fill_path(&path, &paint(rgba), FillRule::Winding, t, None);
    }
}

fn stroke(
    pixmap: &mut Pixmap,
    line: &[DVec2],
    rgba: [u8; 4],
    width_m: f32,
    dash_m: Option<[f32; 2]>,
    t: Transform,
) {
    if let Some(path) = path_of(line, false) {
        let s = Stroke {
            width: width_m,
            line_cap: LineCap::Butt,
            line_join: LineJoin::Round,
            dash: dash_m.and_then(|d| StrokeDash::new(d.to_vec(), 0.0)),
            ..Stroke::default()
        };
        pixmap.stroke_path(&path, &paint(rgba), &s, t, None);
    }
}

fn to_raster(pixmap: &Pixmap, lo: DVec2, hi: DVec2, gsd_m: f64) -> GroundRaster {
    let data = pixmap.data();
    let mut rgb = Vec::with_capacity(data.len() / 4 * 3);
    // The background is opaque, so premultiplied = straight colour.
    for px in data.chunks_exact(4) {
        rgb.extend_from_slice(&px[..3]);
    }
    GroundRaster {
        x_min_m: lo.x,
        y_max_m: hi.y,
        gsd_m,
        width_px: pixmap.width() as usize,
        height_px: pixmap.height() as usize,
        rgb,
        outside: GRASS,
    }
}

/// Multiplicative texture: a 4 m value-noise field (patches) and per-pixel grain.
fn add_texture_noise(r: &mut GroundRaster, seed: u64) {
    let cell_px = (4.0 / r.gsd_m).max(1.0) as usize;
    for row in 0..r.height_px {
        let gy = row / cell_px;
        let ty = (row % cell_px) as f32 / cell_px as f32;
        for col in 0..r.width_px {
            let gx = col / cell_px;
            let tx = (col % cell_px) as f32 / cell_px as f32;
            let n00 = hash01(seed, gx as u64, gy as u64);
            let n10 = hash01(seed, gx as u64 + 1, gy as u64);
            let n01 = hash01(seed, gx as u64, gy as u64 + 1);
            let n11 = hash01(seed, gx as u64 + 1, gy as u64 + 1);
            let coarse =
                (n00 * (1.0 - tx) + n10 * tx) * (1.0 - ty) + (n01 * (1.0 - tx) + n11 * tx) * ty;
            let fine = hash01(seed ^ 0xfeed, col as u64, row as u64);
            let gain = 0.9 + 0.16 * coarse + 0.12 * (fine - 0.5);
            let i = (row * r.width_px + col) * 3;
            for k in 0..3 {
                r.rgb[i + k] = (f32::from(r.rgb[i + k]) * gain).clamp(0.0, 255.0) as u8;
            }
        }
    }
}

/// Deterministic hash of `(seed, a, b)` to [0, 1).
#[inline]
#[must_use]
pub fn hash01(seed: u64, a: u64, b: u64) -> f32 {
    let mut z = seed
        .wrapping_add(a.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

/// Convex hull (Andrew's monotone chain), counter-clockwise.
fn convex_hull(points: &mut [DVec2]) -> Vec<DVec2> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(points.len() * 2);
    for &p in points.iter() {
        while hull.len() >= 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len() + 1;
    for &p in points.iter().rev().skip(1) {
        while hull.len() >= lower && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop();
    hull
}
