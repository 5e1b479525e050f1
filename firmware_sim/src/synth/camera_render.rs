//! The six camera images of a frame: every pixel's ray is cast onto the ground plane (z = 0 in
//! the ego frame) and samples the world's ground raster; vertical boxes (buildings, trees,
//! parked cars) are intersected on top; rays above the horizon see the sky; lighting adds gain,
//! contrast, haze and sensor noise.
//!
//! Rays are computed once per calibration and image size ([`CameraRig::new`]): because the rig
//! is fixed to the ego, each pixel's ground hit in the ego frame is a constant, and a frame only
//! rotates it into the route frame. Frames: ego x right, y forward, z up; camera x right, y down,
//! z optical axis; intrinsics scaled by `image_scale = width_px / raw_width_px`, pixel centres at
//! `u + 0.5` (the convention of `Calibration::lidar2img`).

use glam::{DMat3, DVec3, Vec3};
use satmap_runtime::calibration::{Calibration, NUM_CAMERAS};
use satmap_runtime::pose::EgoPose;

use super::ground_raster::{GroundRaster, hash01};
use super::lighting::Lighting;
use super::world::{Occluder, OccluderKind};

/// Ground hits farther than this are drawn as haze, metres.
pub const MAX_GROUND_RANGE_M: f32 = 250.0;
/// Occluders farther than this from the ego are not drawn, metres.
pub const MAX_OCCLUDER_RANGE_M: f64 = 120.0;

/// Precomputed rays of one camera.
#[derive(Clone, Debug)]
struct CameraRays {
    origin_m: Vec3,
    /// Rows of camera<-ego rotation (R^T).
    cam_from_ego: [Vec3; 3],
    fx_px: f32,
    fy_px: f32,
    cx_px: f32,
    cy_px: f32,
    /// Unit ray direction per pixel, ego frame.
    dirs: Vec<Vec3>,
    /// Ground hit per pixel: ego x, ego y, range; range = infinity when the ray misses.
    ground: Vec<[f32; 3]>,
}

/// The rig's ray tables at one image size.
#[derive(Clone, Debug)]
pub struct CameraRig {
    width_px: usize,
    height_px: usize,
    cameras: Vec<CameraRays>,
}

/// An occluder in the ego frame of one frame.
#[derive(Clone, Copy, Debug)]
struct EgoBox {
    centre: Vec3,
    /// Local x (across) and y (along) unit axes in the ego frame (horizontal).
    axis_x: Vec3,
    axis_y: Vec3,
    half: Vec3,
    kind: OccluderKind,
    colour: [f32; 3],
}

impl CameraRig {
    /// Ray tables for `calibration` at `width_px` x `height_px`.
    #[must_use]
    pub fn new(calibration: &Calibration, width_px: usize, height_px: usize) -> Self {
        let scale = width_px as f64 / f64::from(calibration.raw_width_px);
        let cameras = calibration
            .cameras
            .iter()
            .map(|cam| {
                let r = DMat3::from_quat(cam.rotation);
                let rt = r.transpose();
                let t = cam.translation_m;
                let mut dirs = Vec::with_capacity(width_px * height_px);
                let mut ground = Vec::with_capacity(width_px * height_px);
                for v in 0..height_px {
                    for u in 0..width_px {
                        let x_raw = (u as f64 + 0.5) / scale;
                        let y_raw = (v as f64 + 0.5) / scale;
                        let ray_cam = DVec3::new(
                            (x_raw - cam.cx_px) / cam.fx_px,
                            (y_raw - cam.cy_px) / cam.fy_px,
                            1.0,
                        );
                        let d = (r * ray_cam).normalize();
                        dirs.push(d.as_vec3());
                        let hit = if d.z < -1e-6 {
                            let range = -t.z / d.z;
                            if range < f64::from(MAX_GROUND_RANGE_M) {
                                [
                                    (t.x + d.x * range) as f32,
                                    (t.y + d.y * range) as f32,
                                    range as f32,
                                ]
                            } else {
                                [0.0, 0.0, f32::INFINITY]
                            }
                        } else {
                            [0.0, 0.0, f32::INFINITY]
                        };
                        ground.push(hit);
                    }
                }
                CameraRays {
                    origin_m: t.as_vec3(),
                    cam_from_ego: [
                        rt.row(0).as_vec3(),
                        rt.row(1).as_vec3(),
                        rt.row(2).as_vec3(),
                    ],
                    fx_px: (cam.fx_px * scale) as f32,
                    fy_px: (cam.fy_px * scale) as f32,
                    cx_px: (cam.cx_px * scale) as f32,
                    cy_px: (cam.cy_px * scale) as f32,
                    dirs,
                    ground,
                }
            })
            .collect();
        Self {
            width_px,
            height_px,
            cameras,
        }
    }

    /// Image width, pixels.
    #[must_use]
    pub fn width_px(&self) -> usize {
        self.width_px
    }

    /// Image height, pixels.
    #[must_use]
    pub fn height_px(&self) -> usize {
        self.height_px
    }

    /// Bytes of one frame's six images (`6 * height * width * 3`).
    #[must_use]
    pub fn frame_bytes(&self) -> usize {
        NUM_CAMERAS * self.height_px * self.width_px * 3
    }

    /// Render the six images of the ego at `pose` into `out` (camera-major, each u8 RGB HWC;
    /// `out.len()` must be [`Self::frame_bytes`], else nothing is written and false returned).
    /// `noise_seed` varies the sensor noise per frame.
    pub fn render(
        &self,
        ground: &GroundRaster,
        occluders: &[Occluder],
        pose: &EgoPose,
        lighting: &Lighting,
        noise_seed: u64,
        out: &mut [u8],
    ) -> bool {
        if out.len() != self.frame_bytes() {
            return false;
        }
        let boxes = ego_boxes(occluders, pose);
        let (sin, cos) = pose.yaw_rad.sin_cos();
        let (fwd_x, fwd_y) = (cos as f32, sin as f32);
        let (right_x, right_y) = (sin as f32, -cos as f32);
        let (px, py) = (pose.position_m.x as f32, pose.position_m.y as f32);
        let n = self.width_px * self.height_px;
        let mut depth = vec![0.0f32; n];
        for (c, cam) in self.cameras.iter().enumerate() {
            let image = &mut out[c * n * 3..(c + 1) * n * 3];
            let cam_seed = noise_seed.wrapping_mul(31).wrapping_add(c as u64);
            for (i, slot) in depth.iter_mut().enumerate() {
                let [gx, gy, range] = cam.ground[i];
                let colour = if range.is_finite() {
                    let x = px + right_x * gx + fwd_x * gy;
                    let y = py + right_y * gx + fwd_y * gy;
                    lighting.surface(ground.sample_bilinear(x, y), range)
                } else if cam.dirs[i].z < 0.0 {
                    lighting.fog
                } else {
                    lighting.sky(cam.dirs[i].z)
                };
                *slot = range;
                write_pixel(image, i, colour, lighting, cam_seed, i as u64);
            }
            for b in &boxes {
                let Some((u0, u1, v0, v1)) = self.project_bounds(cam, b) else {
                    continue;
                };
                for v in v0..v1 {
                    for u in u0..u1 {
                        let i = v * self.width_px + u;
                        let Some((t, albedo)) = intersect(cam.origin_m, cam.dirs[i], b) else {
                            continue;
                        };
                        if t < depth[i] {
                            depth[i] = t;
                            write_pixel(
                                image,
                                i,
                                lighting.surface(albedo, t),
                                lighting,
                                cam_seed,
                                i as u64,
                            );
                        }
                    }
                }
            }
        }
        true
    }

    /// Pixel rectangle `[u0, u1) x [v0, v1)` that can contain the box, `None` when it is
    /// entirely behind the camera or off the image.
    fn project_bounds(&self, cam: &CameraRays, b: &EgoBox) -> Option<(usize, usize, usize, usize)> {
        let mut lo = [f32::INFINITY; 2];
        let mut hi = [f32::NEG_INFINITY; 2];
        let mut in_front = 0;
        let mut behind = 0;
        for corner in 0..8 {
            let sx = if corner & 1 == 0 { -1.0 } else { 1.0 };
            let sy = if corner & 2 == 0 { -1.0 } else { 1.0 };
            let z = if corner & 4 == 0 { 0.0 } else { 2.0 * b.half.z };
            let p =
                b.centre + b.axis_x * (sx * b.half.x) + b.axis_y * (sy * b.half.y) + Vec3::Z * z;
            let rel = p - cam.origin_m;
            let pc = Vec3::new(
                cam.cam_from_ego[0].dot(rel),
                cam.cam_from_ego[1].dot(rel),
                cam.cam_from_ego[2].dot(rel),
            );
            if pc.z <= 0.05 {
                behind += 1;
                continue;
            }
            in_front += 1;
            let u = cam.fx_px * pc.x / pc.z + cam.cx_px;
            let v = cam.fy_px * pc.y / pc.z + cam.cy_px;
            lo = [lo[0].min(u), lo[1].min(v)];
            hi = [hi[0].max(u), hi[1].max(v)];
        }
        if in_front == 0 {
            return None;
        }
        let (w, h) = (self.width_px as f32, self.height_px as f32);
        if behind > 0 {
            // Straddles the camera plane: the projection is unbounded, scan the whole image.
            return Some((0, self.width_px, 0, self.height_px));
        }
        let u0 = lo[0].floor().clamp(0.0, w) as usize;
        let u1 = (hi[0].ceil() + 1.0).clamp(0.0, w) as usize;
        let v0 = lo[1].floor().clamp(0.0, h) as usize;
        let v1 = (hi[1].ceil() + 1.0).clamp(0.0, h) as usize;
        (u0 < u1 && v0 < v1).then_some((u0, u1, v0, v1))
    }
}

#[inline]
fn write_pixel(
    image: &mut [u8],
    i: usize,
    colour: [f32; 3],
    lighting: &Lighting,
    seed: u64,
    salt: u64,
) {
    let noise = (hash01(seed, salt, 7) - 0.5) * 2.0 * lighting.noise_amplitude;
    for k in 0..3 {
        image[i * 3 + k] = (colour[k] + noise).clamp(0.0, 255.0) as u8;
    }
}

fn ego_boxes(occluders: &[Occluder], pose: &EgoPose) -> Vec<EgoBox> {
    let (sin, cos) = pose.yaw_rad.sin_cos();
    let fwd = glam::DVec2::new(cos, sin);
    let right = glam::DVec2::new(sin, -cos);
    let to_ego = |v: glam::DVec2| Vec3::new(v.dot(right) as f32, v.dot(fwd) as f32, 0.0);
    occluders
        .iter()
        .filter(|o| (o.centre_m - pose.position_m).length() < MAX_OCCLUDER_RANGE_M)
        .map(|o| {
            let rel = o.centre_m - pose.position_m;
            let axis_y = to_ego(o.axis);
            EgoBox {
                centre: to_ego(rel),
                axis_x: Vec3::new(axis_y.y, -axis_y.x, 0.0),
                axis_y,
                half: Vec3::new(
                    o.half_width_m as f32,
                    o.half_length_m as f32,
                    (o.height_m / 2.0) as f32,
                ),
                kind: o.kind,
                colour: o.colour.map(|v| v * 255.0),
            }
        })
        .collect()
}

/// Ray/box intersection (slabs in the box's local frame): range and albedo of the entry face.
#[inline]
fn intersect(origin: Vec3, dir: Vec3, b: &EgoBox) -> Option<(f32, [f32; 3])> {
    let rel = origin - b.centre;
    let o = [b.axis_x.dot(rel), b.axis_y.dot(rel), rel.z - b.half.z];
    let d = [b.axis_x.dot(dir), b.axis_y.dot(dir), dir.z];
    let half = [b.half.x, b.half.y, b.half.z];
    let mut t_in = 0.0f32;
    let mut t_out = f32::INFINITY;
    let mut face = 3usize;
    for k in 0..3 {
        if d[k].abs() < 1e-9 {
            if o[k].abs() > half[k] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[k];
        let (mut t0, mut t1) = ((-half[k] - o[k]) * inv, (half[k] - o[k]) * inv);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        if t0 > t_in {
            t_in = t0;
            face = k;
        }
        t_out = t_out.min(t1);
        if t_in > t_out {
            return None;
        }
    }
    if face == 3 {
        // The camera is inside the box.
        return None;
    }
    let hit = [
        o[0] + d[0] * t_in,
        o[1] + d[1] * t_in,
        o[2] + d[2] * t_in + half[2],
    ];
    Some((t_in, albedo(b, face, hit)))
}

/// Surface colour of a box face at local hit point `p` (x across, y along, z up from ground).
fn albedo(b: &EgoBox, face: usize, p: [f32; 3]) -> [f32; 3] {
    let shade = match face {
        0 => 0.82,
        1 => 0.68,
        _ => 1.0,
    };
    let mut c = b.colour.map(|v| v * shade);
    let along = if face == 0 { p[1] } else { p[0] };
    match b.kind {
        OccluderKind::Building if face != 2 => {
            let wu = along.rem_euclid(3.0);
            let wz = p[2].rem_euclid(3.2);
            if p[2] > 2.5 && (0.8..2.2).contains(&wu) && (1.0..2.3).contains(&wz) {
                c = [c[0] * 0.35 + 20.0, c[1] * 0.4 + 28.0, c[2] * 0.45 + 40.0];
            }
        }
        OccluderKind::Tree => {
            let n = hash01(
                11,
                (along * 3.0).floor() as i64 as u64,
                (p[2] * 3.0).floor() as i64 as u64,
            );
            c = c.map(|v| v * (0.7 + 0.6 * n));
            if p[2] < 2.0 && (along.abs() > 0.35 || face == 2) {
                // Below the canopy only the trunk is solid; show it as a dark column.
                c = [c[0] * 0.5, c[1] * 0.45, c[2] * 0.4];
            }
        }
        OccluderKind::ParkedCar => {
            if p[2] < 0.35 {
                c = [25.0, 25.0, 28.0];
            } else if (0.95..1.4).contains(&p[2]) {
                c = [40.0, 48.0, 58.0];
            }
        }
        OccluderKind::Building => {}
    }
    c
}
