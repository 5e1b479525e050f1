//! `satmap-core-check` (no_std): the core end to end on golden frame 0, with the digests every
//! target must reproduce. May import: `satmap-runtime` without features (the core).
//!
//! The no_std core of the SatMap runtime run end to end on golden frame 0
//! (`models/golden/test/frame_000.safetensors`, embedded), with the digests every target must
//! reproduce. One function, [`run`], three callers: this crate's host test (x86-64 with std),
//! the no_std link check (`runtime/nostd_check`) and the bare-metal images that run it under
//! emulation (`targets/baremetal`, aarch64-unknown-none and thumbv7em-none-eabihf): each compares
//! with [`EXPECTED`], so equal digests mean equal bits on every target.
//!
//! What runs: the GKT look-up table from the golden rig, the native gather-sum on the golden
//! values and weights (bit for bit the golden `gathered`), the CAN-bus vector (within 1e-6 of the
//! golden), the frame checks (the golden frame accepted, a non-finite pose refused), decode of
//! the golden logits and points, the map frame's wire form and its CRC check, a route pack of the
//! golden satellite crop parsed, cropped and verified, and a zlib tile decoded (a JPEG stream
//! refused).
#![no_std]

extern crate alloc;

mod steps;

pub use satmap_runtime::calibration_rig::NUSCENES_LIKE;
pub use steps::run;

/// The embedded golden frame 0 (the trained `test` model's goldens).
pub static GOLDEN_FRAME: &[u8] =
    include_bytes!("../../../models/golden/test/frame_000.safetensors");

/// The digests of one run, each an XXH3-64 of the bytes named.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoreDigests {
    /// The dense GKT table (mask, count, index, lidar2img bits).
    pub lut: u64,
    /// The gather-sum's output bits.
    pub gathered: u64,
    /// The CAN-bus vector's bits.
    pub can_bus: u64,
    /// The frame checks' camera states and mask.
    pub frame_checks: u64,
    /// The decoded map ([`satmap_runtime::map_frame::digest`]).
    pub decoded_map: u64,
    /// The serialised map frame (header, CRC, elements).
    pub map_wire: u64,
    /// The satellite crop from the route pack.
    pub route_crop: u64,
    /// The decoded zlib tile.
    pub tile: u64,
}

impl CoreDigests {
    /// Every digest with its name, in declaration order.
    #[must_use]
    pub const fn named(&self) -> [(&'static str, u64); 8] {
        [
            ("lut", self.lut),
            ("gathered", self.gathered),
            ("can_bus", self.can_bus),
            ("frame_checks", self.frame_checks),
            ("decoded_map", self.decoded_map),
            ("map_wire", self.map_wire),
            ("route_crop", self.route_crop),
            ("tile", self.tile),
        ]
    }
}

/// The digests the x86-64 host computes (this crate's test asserts it; first recorded on an AMD
/// EPYC, 2026-12-06), which every other target must reproduce bit for bit. The core has no
/// per-CPU code paths (scalar f32 in a fixed order, integer crops and codecs), so one set serves
/// every target.
pub const EXPECTED: CoreDigests = CoreDigests {
    lut: 0xba72_09a9_507a_5abb,
    gathered: 0x0106_a4be_a756_cb6a,
    can_bus: 0x6997_cbfe_8dc2_2036,
    frame_checks: 0x52f1_e866_2bc8_267f,
    decoded_map: 0x77bb_65f8_14ed_a264,
    map_wire: 0x9f27_3ce5_1024_a9d0,
    route_crop: 0x437c_23b1_9126_f302,
    tile: 0x981e_b7df_4a49_11d7,
};

/// Why a run stopped before its digests: the step that failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CheckFault {
    /// The golden file did not parse, or a tensor is missing or of another type or size.
    Golden(&'static str),
    /// The model dimensions or the rig were refused.
    Setup,
    /// The look-up table could not be built.
    Lut,
    /// The gather-sum failed or differs from the golden `gathered`.
    Gathered,
    /// The CAN-bus vector is more than 1e-6 from the golden.
    CanBus,
    /// The golden frame was refused, or a non-finite pose accepted.
    FrameChecks,
    /// The map frame did not serialise or its check failed.
    MapWire,
    /// The route pack did not encode, parse or crop in full.
    RoutePack,
    /// The zlib tile did not decode exactly, or a JPEG stream was accepted.
    Tile,
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn the_host_computes_the_expected_digests() {
        let got = run(GOLDEN_FRAME).unwrap();
        for (name, d) in got.named() {
            std::println!("{name} = 0x{d:016x}");
        }
        assert_eq!(
            got, EXPECTED,
            "update EXPECTED only for an intended change of the core"
        );
    }

    #[test]
    fn the_transcribed_rig_is_the_calibration_file() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../models/calibration/nuscenes_like.toml");
        let file = satmap_runtime::calibration::from_toml_file(&path).unwrap();
        assert_eq!(file.raw_width_px, NUSCENES_LIKE.raw_width_px);
        assert_eq!(file.raw_height_px, NUSCENES_LIKE.raw_height_px);
        for (a, b) in file.cameras.iter().zip(&NUSCENES_LIKE.cameras) {
            // Bits, not values: -0.0 and 0.0 are equal values.
            let bits = |c: &satmap_runtime::calibration::CameraCalibration| {
                let mut v = std::vec![c.fx_px, c.fy_px, c.cx_px, c.cy_px];
                v.extend(c.translation_m.to_array());
                v.extend(c.rotation.to_array());
                v.iter().map(|x| x.to_bits()).collect::<std::vec::Vec<_>>()
            };
            assert_eq!(bits(a), bits(b));
        }
    }

    #[test]
    fn a_damaged_golden_is_a_fault_not_a_panic() {
        assert!(matches!(
            run(&GOLDEN_FRAME[..100]),
            Err(CheckFault::Golden(_))
        ));
    }
}
