//! The step's output: a fixed-capacity list of map polylines in the ego frame, health flags and
//! a digest for replay comparison; its protected serialised form is in [`wire`].
//!
//! Frame: points are ego metres, x right, y forward (the BEV range of the model).

pub mod wire;

use glam::Vec2;
use heapless::Vec;
use xxhash_rust::xxh3::Xxh3;

use crate::calibration::NUM_CAMERAS;
use crate::capacity::{MAX_TOP_K, NUM_POINTS};
use crate::frame::CameraState;

/// Map element class, in head order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MapClass {
    /// Lane divider (class 0).
    Divider = 0,
    /// Pedestrian crossing (class 1).
    PedCrossing = 1,
    /// Road boundary (class 2).
    Boundary = 2,
}

impl MapClass {
    /// Class of head label `label` (`0..3`); `None` outside.
    #[must_use]
    pub const fn from_label(label: usize) -> Option<Self> {
        match label {
            0 => Some(Self::Divider),
            1 => Some(Self::PedCrossing),
            2 => Some(Self::Boundary),
            _ => None,
        }
    }
}

/// One decoded polyline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapElement {
    /// Predicted class.
    pub class: MapClass,
    /// Sigmoid score in `[0, 1]`.
    pub score: f32,
    /// Decoder instance the polyline came from (one instance may appear under several classes).
    pub instance: u16,
    /// Polyline vertices, ego metres (x right, y forward).
    pub points_m: [Vec2; NUM_POINTS],
}

/// State of the satellite prior for one step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SatellitePrior {
    /// Fully covered by verified imagery.
    #[default]
    Present,
    /// Partly covered; the rest of the crop is fill.
    Partial {
        /// Covered fraction, in thousandths.
        covered_permille: u16,
    },
    /// No imagery: the satellite stage was skipped and zeros were fed to the decoder.
    Missing,
    /// Imagery failed verification: it was not used (zeros fed to the decoder).
    Corrupt,
}

/// Health flags of one output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Health {
    /// Satellite prior state.
    pub satellite: SatellitePrior,
    /// True when the map was computed without the satellite prior (camera only).
    pub degraded: bool,
    /// Set by the caller (via `SatMap::mark_deadline_overrun`) when the step missed its deadline.
    pub deadline_overrun: bool,
    /// How each camera took part (model order): a camera not [`CameraState::Used`] was left
    /// out of the view transform for this step.
    pub cameras: [CameraState; NUM_CAMERAS],
}

impl Health {
    /// Cameras left out of this step, bit `c` for camera `c`.
    #[must_use]
    pub fn cameras_dropped(&self) -> u8 {
        self.cameras
            .iter()
            .enumerate()
            .filter(|(_, s)| **s != CameraState::Used)
            .fold(0, |bits, (c, _)| bits | (1 << c))
    }
}

/// The map of one step.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct MapFrame {
    /// Sequence counter of the frame this map was computed from.
    pub sequence: u64,
    /// Timestamp of that frame, microseconds.
    pub timestamp_us: u64,
    /// Elements in descending score order (at most `top_k`).
    pub elements: Vec<MapElement, MAX_TOP_K>,
    /// Health flags.
    pub health: Health,
    /// [`digest`] of `elements`.
    pub digest: u64,
    /// End-to-end counter of the published map: +1 for every published map, wrapping
    /// (the `counter` of the serialised frame, [`wire`]).
    pub e2e_counter: u16,
}

/// Bytes one element contributes to the digest.
const ELEMENT_BYTES: usize = 1 + 2 + 4 + NUM_POINTS * 8;

/// XXH3-64 (seed 0) of the elements, serialised in order as, per element: class `u8`, instance
/// `u16` LE, score bits `u32` LE, then for each point x bits `u32` LE and y bits `u32` LE.
/// An empty list hashes the empty input. Health, sequence and timestamp are not included.
#[must_use]
pub fn digest(elements: &[MapElement]) -> u64 {
    let mut hasher = Xxh3::new();
    let mut buf = [0u8; ELEMENT_BYTES];
    for e in elements {
        buf[0] = e.class as u8;
        buf[1..3].copy_from_slice(&e.instance.to_le_bytes());
        buf[3..7].copy_from_slice(&e.score.to_bits().to_le_bytes());
        for (i, p) in e.points_m.iter().enumerate() {
            let at = 7 + i * 8;
            buf[at..at + 4].copy_from_slice(&p.x.to_bits().to_le_bytes());
            buf[at + 4..at + 8].copy_from_slice(&p.y.to_bits().to_le_bytes());
        }
        hasher.update(&buf);
    }
    hasher.digest()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn element(score: f32) -> MapElement {
        MapElement {
            class: MapClass::Boundary,
            score,
            instance: 3,
            points_m: core::array::from_fn(|i| Vec2::new(i as f32, -(i as f32))),
        }
    }

    #[test]
    fn digest_is_the_documented_serialisation() {
        let e = element(0.5);
        let mut bytes = alloc::vec::Vec::new();
        bytes.push(2u8);
        bytes.extend_from_slice(&3u16.to_le_bytes());
        bytes.extend_from_slice(&0.5f32.to_bits().to_le_bytes());
        for i in 0..NUM_POINTS {
            bytes.extend_from_slice(&(i as f32).to_le_bytes());
            bytes.extend_from_slice(&(-(i as f32)).to_le_bytes());
        }
        assert_eq!(digest(&[e]), xxhash_rust::xxh3::xxh3_64(&bytes));
        assert_eq!(digest(&[]), xxhash_rust::xxh3::xxh3_64(&[]));
        // Any bit changes the digest.
        assert_ne!(
            digest(&[e]),
            digest(&[element(f32::from_bits(0.5f32.to_bits() + 1))])
        );
    }
}
