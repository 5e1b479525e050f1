//! [`run`]: each step of the core on the golden frame, in the order a step of the runtime takes
//! them, each folded into its digest.

use alloc::vec::Vec;

use safetensors::{Dtype, SafeTensors};
use satmap_runtime::can_bus::can_bus;
use satmap_runtime::decode::decode;
use satmap_runtime::frame::{FrameError, FrameLimits, check_frame};
use satmap_runtime::geo::Geodetic;
use satmap_runtime::gkt::{Lut, gather_sum};
use satmap_runtime::glam::{DVec2, Vec3};
use satmap_runtime::map_frame::{MapElement, MapFrame, digest, wire};
use satmap_runtime::route_pack::{
    PackHeader, PackSource, PackTile, TileCodec, TileKey, decode_tile, encode_pack,
};
use satmap_runtime::{CameraImage, CameraMask, CropSpec, EgoMotion, EgoPose, Frame, ModelDims};
use xxhash_rust::xxh3::Xxh3;

use crate::{CheckFault, CoreDigests, NUSCENES_LIKE};

/// Golden camera image size (the `test` model's input), pixels.
const IMAGE_W_PX: u32 = 320;
const IMAGE_H_PX: u32 = 180;
/// The golden satellite crop: 200 rows x 100 columns, RGB.
const SAT_H_PX: usize = 200;
const SAT_W_PX: usize = 100;
/// Route-pack tiles cut from the satellite crop (a power of two, as the format requires): three
/// 64 px tiles stacked along the route from its first 64 columns, 0.5 m a pixel.
const TILE_PX: usize = 64;
const PACK_TILES: usize = 3;
const PACK_GSD_M: f64 = 0.5;

/// An 8 x 8 RGB route-pack tile (bytes 0..192) as zlib (Python's `zlib.compress`, level 6).
const ZLIB_TILE_8PX: [u8; 203] = [
    0x78, 0x9c, 0x01, 0xc0, 0x00, 0x3f, 0xff, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08,
    0x09, 0x0a, 0x0b, 0x0c, 0x0d, 0x0e, 0x0f, 0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18,
    0x19, 0x1a, 0x1b, 0x1c, 0x1d, 0x1e, 0x1f, 0x20, 0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28,
    0x29, 0x2a, 0x2b, 0x2c, 0x2d, 0x2e, 0x2f, 0x30, 0x31, 0x32, 0x33, 0x34, 0x35, 0x36, 0x37, 0x38,
    0x39, 0x3a, 0x3b, 0x3c, 0x3d, 0x3e, 0x3f, 0x40, 0x41, 0x42, 0x43, 0x44, 0x45, 0x46, 0x47, 0x48,
    0x49, 0x4a, 0x4b, 0x4c, 0x4d, 0x4e, 0x4f, 0x50, 0x51, 0x52, 0x53, 0x54, 0x55, 0x56, 0x57, 0x58,
    0x59, 0x5a, 0x5b, 0x5c, 0x5d, 0x5e, 0x5f, 0x60, 0x61, 0x62, 0x63, 0x64, 0x65, 0x66, 0x67, 0x68,
    0x69, 0x6a, 0x6b, 0x6c, 0x6d, 0x6e, 0x6f, 0x70, 0x71, 0x72, 0x73, 0x74, 0x75, 0x76, 0x77, 0x78,
    0x79, 0x7a, 0x7b, 0x7c, 0x7d, 0x7e, 0x7f, 0x80, 0x81, 0x82, 0x83, 0x84, 0x85, 0x86, 0x87, 0x88,
    0x89, 0x8a, 0x8b, 0x8c, 0x8d, 0x8e, 0x8f, 0x90, 0x91, 0x92, 0x93, 0x94, 0x95, 0x96, 0x97, 0x98,
    0x99, 0x9a, 0x9b, 0x9c, 0x9d, 0x9e, 0x9f, 0xa0, 0xa1, 0xa2, 0xa3, 0xa4, 0xa5, 0xa6, 0xa7, 0xa8,
    0xa9, 0xaa, 0xab, 0xac, 0xad, 0xae, 0xaf, 0xb0, 0xb1, 0xb2, 0xb3, 0xb4, 0xb5, 0xb6, 0xb7, 0xb8,
    0xb9, 0xba, 0xbb, 0xbc, 0xbd, 0xbe, 0xbf, 0x01, 0xae, 0x47, 0xa1,
];

/// The golden tensors the run reads.
struct Golden<'a> {
    st: SafeTensors<'a>,
}

impl<'a> Golden<'a> {
    /// Tensor `name`'s bytes: of type `dtype` and exactly `len_bytes` long.
    fn raw(
        &self,
        name: &'static str,
        dtype: Dtype,
        len_bytes: usize,
    ) -> Result<&'a [u8], CheckFault> {
        let t = self.st.tensor(name).map_err(|_| CheckFault::Golden(name))?;
        if t.dtype() != dtype || t.data().len() != len_bytes {
            return Err(CheckFault::Golden(name));
        }
        Ok(t.data())
    }

    /// Tensor `name` as `len` little-endian values of `W` bytes.
    fn values<T, const W: usize>(
        &self,
        name: &'static str,
        dtype: Dtype,
        len: usize,
        from_le: fn([u8; W]) -> T,
    ) -> Result<Vec<T>, CheckFault> {
        let d = self.raw(name, dtype, len * W)?;
        Ok(d.chunks_exact(W)
            .map(|b| {
                let mut bytes = [0u8; W];
                bytes.copy_from_slice(b);
                from_le(bytes)
            })
            .collect())
    }

    fn f32s(&self, name: &'static str, len: usize) -> Result<Vec<f32>, CheckFault> {
        self.values(name, Dtype::F32, len, f32::from_le_bytes)
    }

    fn vec3(&self, name: &'static str) -> Result<Vec3, CheckFault> {
        match self.values(name, Dtype::F64, 3, f64::from_le_bytes)?[..] {
            [x, y, z] => Ok(Vec3::new(x as f32, y as f32, z as f32)),
            _ => Err(CheckFault::Golden(name)),
        }
    }
}

fn hash_f32s(h: &mut Xxh3, v: &[f32]) {
    for x in v {
        h.update(&x.to_bits().to_le_bytes());
    }
}

/// Run the core on `golden` (the bytes of `frame_000.safetensors`) and return its digests.
///
/// # Errors
/// The first step that failed ([`CheckFault`]); nothing panics on a damaged golden.
pub fn run(golden: &[u8]) -> Result<CoreDigests, CheckFault> {
    let g = Golden {
        st: SafeTensors::deserialize(golden).map_err(|_| CheckFault::Golden("header"))?,
    };
    let dims = ModelDims::test_config();
    dims.validate().map_err(|_| CheckFault::Setup)?;
    NUSCENES_LIKE.validate().map_err(|_| CheckFault::Setup)?;

    // The GKT look-up table from the rig.
    let lut = Lut::new(&dims, &NUSCENES_LIKE).map_err(|_| CheckFault::Lut)?;
    let dense = lut.to_dense();
    let mut h = Xxh3::new();
    h.update(&dense.mask);
    for v in dense.count.iter().chain(&dense.index) {
        h.update(&v.to_le_bytes());
    }
    hash_f32s(&mut h, &dense.lidar2img);
    let lut_digest = h.digest();

    // The native gather-sum on the golden values and weights: the golden's bits exactly.
    let value = g.f32s(
        "value",
        dims.value_len() * satmap_runtime::calibration::NUM_CAMERAS,
    )?;
    let weights = g.f32s("gkt_weights", dims.weights_len())?;
    let want = g.f32s("gathered", dims.bev_len())?;
    let mut gathered = alloc::vec![f32::NAN; dims.bev_len()];
    gather_sum(&lut, &value, &weights, &mut gathered, CameraMask::ALL)
        .map_err(|_| CheckFault::Gathered)?;
    if gathered
        .iter()
        .zip(&want)
        .any(|(a, b)| a.to_bits() != b.to_bits())
    {
        return Err(CheckFault::Gathered);
    }
    let mut h = Xxh3::new();
    hash_f32s(&mut h, &gathered);
    let gathered_digest = h.digest();

    // The CAN-bus vector from the golden pose and motion.
    let &[yaw_rad] = &g.values("ego_yaw_rad", Dtype::F64, 1, f64::from_le_bytes)?[..] else {
        return Err(CheckFault::Golden("ego_yaw_rad"));
    };
    let pose = EgoPose::new(DVec2::ZERO, yaw_rad);
    let motion = EgoMotion {
        acceleration_mps2: g.vec3("acceleration_mps2")?,
        rotation_rate_radps: g.vec3("rotation_rate_radps")?,
        velocity_mps: g.vec3("velocity_mps")?,
    };
    let bus = can_bus(&pose, &motion);
    let want_bus = g.f32s("can_bus", bus.len())?;
    if bus.iter().zip(&want_bus).any(|(a, b)| (a - b).abs() > 1e-6) {
        return Err(CheckFault::CanBus);
    }
    let mut h = Xxh3::new();
    hash_f32s(&mut h, &bus);
    let can_bus_digest = h.digest();

    // The frame checks: the golden frame is accepted with every camera, a NaN yaw is refused.
    let per_image = (IMAGE_W_PX * IMAGE_H_PX * 3) as usize;
    let images = g.raw("images", Dtype::U8, per_image * 6)?;
    let mut frame = Frame {
        sequence: 1,
        timestamp_us: 1_100_000,
        pose,
        motion,
        images: core::array::from_fn(|c| {
            Some(CameraImage {
                width_px: IMAGE_W_PX,
                height_px: IMAGE_H_PX,
                rgb: &images[c * per_image..(c + 1) * per_image],
                capture_us: 1_100_000,
                valid: true,
            })
        }),
    };
    let used = check_frame(&frame, &dims, &FrameLimits::DEFAULT, None)
        .map_err(|_| CheckFault::FrameChecks)?;
    let mut h = Xxh3::new();
    h.update(&[used.mask.bits()]);
    h.update(&used.states.map(|s| s as u8));
    frame.pose.yaw_rad = f64::NAN;
    if check_frame(&frame, &dims, &FrameLimits::DEFAULT, None) != Err(FrameError::NonFinitePose) {
        return Err(CheckFault::FrameChecks);
    }
    let frame_checks_digest = h.digest();

    // Decode of the golden logits and points.
    let logits = g.f32s("class_logits", dims.logits_len())?;
    let points = g.f32s("points", dims.points_len())?;
    let mut elements: heapless::Vec<MapElement, 50> = heapless::Vec::new();
    decode(&dims, &logits, &points, &mut elements);
    let decoded_map_digest = digest(&elements);

    // The map frame on the wire: serialised, its CRC accepted, one flipped bit refused.
    let map = MapFrame {
        sequence: 1,
        timestamp_us: 1_100_000,
        digest: decoded_map_digest,
        elements,
        e2e_counter: 1,
        ..MapFrame::default()
    };
    let mut buf = alloc::vec![0u8; wire::MAX_WIRE_BYTES];
    let n =
        wire::serialise(&map, wire::DEFAULT_DATA_ID, &mut buf).map_err(|_| CheckFault::MapWire)?;
    let bytes = &mut buf[..n];
    match wire::check(bytes, wire::DEFAULT_DATA_ID) {
        Ok(c) if c.sequence == 1 && c.counter == 1 => {}
        _ => return Err(CheckFault::MapWire),
    }
    let mut h = Xxh3::new();
    h.update(bytes);
    let map_wire_digest = h.digest();
    bytes[n / 2] ^= 0x10;
    if wire::check(bytes, wire::DEFAULT_DATA_ID).is_ok() {
        return Err(CheckFault::MapWire);
    }

    // A route pack of the golden satellite crop: two tiles along the route, parsed and cropped.
    let satellite = g.raw("satellite", Dtype::U8, SAT_H_PX * SAT_W_PX * 3)?;
    let payloads: Vec<Vec<u8>> = (0..PACK_TILES)
        .map(|t| {
            (0..TILE_PX)
                .flat_map(|r| {
                    let row = (t * TILE_PX + r) * SAT_W_PX * 3;
                    satellite[row..row + TILE_PX * 3].iter().copied()
                })
                .collect()
        })
        .collect();
    let tiles: Vec<PackTile<'_>> = payloads
        .iter()
        .zip(0i32..)
        .map(|(payload, ty)| PackTile {
            key: TileKey::new(0, ty),
            payload,
        })
        .collect();
    let header = PackHeader {
        tile_size_px: TILE_PX as u16,
        origin: Geodetic::new(42.336, -71.057, 12.0),
        gsd_m: PACK_GSD_M,
        corridor_width_m: 50.0,
        tile_count: 0,
        route_point_count: 0,
        codec: TileCodec::Raw,
    };
    // The tiles cover x in [0, 32) m and y in [0, 96) m of the route frame.
    let route = [DVec2::new(16.0, 0.0), DVec2::new(16.0, 96.0)];
    let pack = encode_pack(&header, &route, &tiles).map_err(|_| CheckFault::RoutePack)?;
    let mut source = PackSource::from_bytes(&pack).map_err(|_| CheckFault::RoutePack)?;
    let spec = CropSpec {
        height_px: 40,
        width_px: 20,
        gsd_m: PACK_GSD_M,
        x_min_m: -5.0,
        y_min_m: -10.0,
    };
    let mut crop = alloc::vec![0u8; spec.height_px * spec.width_px * 3];
    let report =
        source.crop_with_report(&EgoPose::new(DVec2::new(16.0, 48.0), 0.3), &spec, &mut crop);
    if report.fault.is_some() || report.covered_px != report.total_px || report.total_px == 0 {
        return Err(CheckFault::RoutePack);
    }
    let mut h = Xxh3::new();
    h.update(&crop);
    let route_crop_digest = h.digest();

    // Tile codecs: a zlib tile inflates exactly; a stream that is not a JPEG is refused.
    let mut tile = [0u8; 8 * 8 * 3];
    if decode_tile(TileCodec::Deflate, &ZLIB_TILE_8PX, 8, &mut tile).is_err()
        || tile.iter().enumerate().any(|(i, &v)| usize::from(v) != i)
        || decode_tile(TileCodec::Jpeg, &ZLIB_TILE_8PX, 8, &mut tile).is_ok()
    {
        return Err(CheckFault::Tile);
    }
    let mut h = Xxh3::new();
    h.update(&tile);

    Ok(CoreDigests {
        lut: lut_digest,
        gathered: gathered_digest,
        can_bus: can_bus_digest,
        frame_checks: frame_checks_digest,
        decoded_map: decoded_map_digest,
        map_wire: map_wire_digest,
        route_crop: route_crop_digest,
        tile: h.digest(),
    })
}
