//! How the runtime stores the two BEV feature maps it hands from the encoders to the decoder
//! (camera BEV and satellite BEV, `[bev_h, bev_w, D]` each, two of the four largest model-sized
//! buffers): f32, or IEEE half (`half::f16`) when the memory layout gives both regions
//! `dtype = "f16"` (`layouts/nano-f16-bev.toml`), which halves their RAM.
//!
//! The engines compute in f32 either way: a stage writing a BEV rounds its f32 output to the
//! storage once ([`FeaturesMut::store`], round to nearest even), the decoder widens it back
//! exactly ([`FeaturesRef::load`]). A value of magnitude 65520 or more (past f16's largest,
//! 65504, by half an ulp) becomes infinite and the step's finiteness check refuses it
//! ([`crate::StepError::NonFiniteOutput`]): the storage never saturates silently. The other
//! buffers stay f32: the value features are read sixty times a query by the gather-sum's hot loop
//! and are a ninth of one BEV's bytes (368,640 against 3,276,800 at nano's size); queries, GKT
//! weights and the gathered sum feed float arithmetic of the core itself.

use half::f16;
use half::slice::{HalfBitsSliceExt, HalfFloatSliceExt};

use crate::buffers::{MemoryError, Slab};
use crate::capacity::layout;

/// Element type of the BEV feature maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FeatureStorage {
    /// 4 bytes an element: the engines' output bits, kept.
    F32,
    /// 2 bytes an element: each value rounded once to IEEE half.
    F16,
}

impl FeatureStorage {
    /// The storage the memory layout of this build gives the BEV regions (`camera_bev` and
    /// `satellite_bev`, which `satmap-layout` requires to agree).
    pub const LAYOUT: Self = Self::of_layout_dtype(layout::CAMERA_BEV_DTYPE);

    /// The storage of a BEV region's layout dtype. satmap-layout refuses any dtype but these
    /// two; called in a const, the panic fails the build, never a run.
    const fn of_layout_dtype(dtype: &str) -> Self {
        match dtype.as_bytes() {
            b"f16" => Self::F16,
            b"f32" => Self::F32,
            _ => panic!("the layout's BEV regions are neither f32 nor f16"),
        }
    }

    /// Bytes of one element.
    #[must_use]
    pub const fn elem_bytes(self) -> usize {
        match self {
            Self::F32 => 4,
            Self::F16 => 2,
        }
    }

    /// `f32` or `f16`, as in `memory_layout.toml`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::F16 => "f16",
        }
    }

    /// The storage named `name` (`f32` or `f16`).
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "f32" => Some(Self::F32),
            "f16" => Some(Self::F16),
            _ => None,
        }
    }
}

// Both BEV regions have one storage (`satmap-layout` checks it; this is the build's own guard).
const _: () = assert!(matches!(
    (
        FeatureStorage::LAYOUT,
        FeatureStorage::of_layout_dtype(layout::SATELLITE_BEV_DTYPE)
    ),
    (FeatureStorage::F32, FeatureStorage::F32) | (FeatureStorage::F16, FeatureStorage::F16)
));

/// A feature map's length differs from what was written into it or read out of it (engines
/// report it as their stage's `EngineErrorKind::ShapeMismatch`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LengthMismatch {
    /// Elements of the feature map.
    pub expected: usize,
    /// Elements given.
    pub got: usize,
}

impl core::fmt::Display for LengthMismatch {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "a feature map of {} elements given {} values",
            self.expected, self.got
        )
    }
}

impl core::error::Error for LengthMismatch {}

fn same_len(expected: usize, got: usize) -> Result<(), LengthMismatch> {
    if expected == got {
        Ok(())
    } else {
        Err(LengthMismatch { expected, got })
    }
}

/// A feature map an engine writes.
#[derive(Debug)]
pub enum FeaturesMut<'a> {
    /// Stored as f32.
    F32(&'a mut [f32]),
    /// Stored as IEEE half.
    F16(&'a mut [f16]),
}

impl FeaturesMut<'_> {
    /// Elements.
    #[must_use]
    pub fn len(&self) -> usize {
        self.as_ref().len()
    }

    /// No elements.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The storage.
    #[must_use]
    pub fn storage(&self) -> FeatureStorage {
        self.as_ref().storage()
    }

    /// Write `src`, rounded to the storage (round to nearest even for f16; half's conversion,
    /// F16C or Armv8 `fcvt` where the build has them, the same bits everywhere).
    ///
    /// # Errors
    /// [`LengthMismatch`] when `src` is not the map's length (nothing written).
    pub fn store(&mut self, src: &[f32]) -> Result<(), LengthMismatch> {
        same_len(self.len(), src.len())?;
        match self {
            Self::F32(dst) => dst.copy_from_slice(src),
            Self::F16(dst) => dst.convert_from_f32_slice(src),
        }
        Ok(())
    }

    /// Element `i` set to `f(i)` rounded to the storage, for every `i` in order: for an engine
    /// that computes one value at a time (no f32 copy of the map needed).
    pub fn fill_with(&mut self, mut f: impl FnMut(usize) -> f32) {
        match self {
            Self::F32(s) => s.iter_mut().enumerate().for_each(|(i, v)| *v = f(i)),
            Self::F16(s) => s
                .iter_mut()
                .enumerate()
                .for_each(|(i, v)| *v = f16::from_f32(f(i))),
        }
    }

    /// Every element zero.
    pub fn fill_zero(&mut self) {
        match self {
            Self::F32(s) => s.fill(0.0),
            Self::F16(s) => s.fill(f16::ZERO),
        }
    }

    /// A shorter-lived writer of the same map.
    #[must_use]
    pub fn reborrow(&mut self) -> FeaturesMut<'_> {
        match self {
            Self::F32(s) => FeaturesMut::F32(s),
            Self::F16(s) => FeaturesMut::F16(s),
        }
    }

    /// A reader of the same map.
    #[must_use]
    pub fn as_ref(&self) -> FeaturesRef<'_> {
        match self {
            Self::F32(s) => FeaturesRef::F32(s),
            Self::F16(s) => FeaturesRef::F16(s),
        }
    }
}

impl<'a> From<&'a mut [f32]> for FeaturesMut<'a> {
    fn from(s: &'a mut [f32]) -> Self {
        Self::F32(s)
    }
}

/// A feature map an engine or the step reads.
#[derive(Clone, Copy, Debug)]
pub enum FeaturesRef<'a> {
    /// Stored as f32.
    F32(&'a [f32]),
    /// Stored as IEEE half.
    F16(&'a [f16]),
}

impl FeaturesRef<'_> {
    /// Elements.
    #[must_use]
    pub const fn len(&self) -> usize {
        match self {
            Self::F32(s) => s.len(),
            Self::F16(s) => s.len(),
        }
    }

    /// No elements.
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The storage.
    #[must_use]
    pub const fn storage(&self) -> FeatureStorage {
        match self {
            Self::F32(_) => FeatureStorage::F32,
            Self::F16(_) => FeatureStorage::F16,
        }
    }

    /// Element `i` as f32 (widening is exact), `None` past the end.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<f32> {
        match self {
            Self::F32(s) => s.get(i).copied(),
            Self::F16(s) => s.get(i).map(|v| v.to_f32()),
        }
    }

    /// Every element as f32, in order.
    pub fn iter(&self) -> impl Iterator<Item = f32> + '_ {
        let (wide, half) = match self {
            Self::F32(s) => (*s, &[][..]),
            Self::F16(s) => (&[][..], *s),
        };
        wide.iter().copied().chain(half.iter().map(|v| v.to_f32()))
    }

    /// Widen the map into `dst` (exact).
    ///
    /// # Errors
    /// [`LengthMismatch`] when `dst` is not the map's length (nothing written).
    pub fn load(&self, dst: &mut [f32]) -> Result<(), LengthMismatch> {
        same_len(self.len(), dst.len())?;
        match self {
            Self::F32(src) => dst.copy_from_slice(src),
            Self::F16(src) => src.convert_to_f32_slice(dst),
        }
        Ok(())
    }

    /// No NaN and no infinity.
    #[must_use]
    pub fn all_finite(&self) -> bool {
        match self {
            Self::F32(s) => s.iter().all(|v| v.is_finite()),
            Self::F16(s) => s.iter().all(|v| v.is_finite()),
        }
    }
}

impl<'a> From<&'a [f32]> for FeaturesRef<'a> {
    fn from(s: &'a [f32]) -> Self {
        Self::F32(s)
    }
}

/// A feature map the runtime owns for its whole life (heap or placed), in one storage.
#[derive(Debug)]
pub(crate) enum FeatureSlab {
    F32(Slab<f32>),
    F16(Slab<f16>),
}

impl FeatureSlab {
    /// `len` zeros in `storage` on the heap, or [`MemoryError::OutOfMemory`].
    pub(crate) fn zeroed(len: usize, storage: FeatureStorage) -> Result<Self, MemoryError> {
        Ok(match storage {
            FeatureStorage::F32 => Self::F32(Slab::zeroed(len)?),
            FeatureStorage::F16 => Self::F16(Slab::zeroed(len)?),
        })
    }

    /// Take over a placed region cut to the map's length, as f32 or as f16's bits.
    pub(crate) fn placed(region: PlacedFeatures) -> Self {
        match region {
            PlacedFeatures::F32(s) => Self::F32(Slab::placed(s)),
            PlacedFeatures::F16(bits) => Self::F16(Slab::placed(bits.reinterpret_cast_mut())),
        }
    }

    pub(crate) fn as_mut(&mut self) -> FeaturesMut<'_> {
        match self {
            Self::F32(s) => FeaturesMut::F32(s),
            Self::F16(s) => FeaturesMut::F16(s),
        }
    }

    pub(crate) fn as_ref(&self) -> FeaturesRef<'_> {
        match self {
            Self::F32(s) => FeaturesRef::F32(s),
            Self::F16(s) => FeaturesRef::F16(s),
        }
    }
}

/// A BEV region cut from caller memory in the layout's storage.
pub(crate) enum PlacedFeatures {
    F32(&'static mut [f32]),
    /// f16 elements as their bits (`u16` has bytemuck's casts; half reinterprets them).
    F16(&'static mut [u16]),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f16_storage_rounds_once_to_nearest_even_and_widens_exactly() {
        // 1 + 2^-11 and 1 + 3 * 2^-11 are both halfway between two halves: ties go to the even
        // one, 1.0 for the first, 1 + 2^-9 (above) for the second.
        let src = [
            1.0 + 2f32.powi(-11),
            1.0 + 3.0 * 2f32.powi(-11),
            -0.1,
            65504.0,
        ];
        let mut slab = FeatureSlab::zeroed(4, FeatureStorage::F16).unwrap();
        slab.as_mut().store(&src).unwrap();
        let mut back = [0f32; 4];
        slab.as_ref().load(&mut back).unwrap();
        assert_eq!(back[0], 1.0);
        assert_eq!(back[1], 1.0 + 2.0 * 2f32.powi(-10));
        assert_eq!(back[2], f16::from_f32(-0.1).to_f32());
        assert_eq!(back[3], 65504.0);
        assert!(slab.as_ref().all_finite());
        assert_eq!(slab.as_ref().iter().collect::<alloc::vec::Vec<_>>(), back);
        assert_eq!(slab.as_ref().get(2), Some(back[2]));
        assert_eq!(slab.as_ref().get(4), None);
    }

    #[test]
    fn a_value_beyond_half_range_is_stored_infinite_so_the_finite_check_sees_it() {
        let mut slab = FeatureSlab::zeroed(2, FeatureStorage::F16).unwrap();
        slab.as_mut().store(&[1.0, 70000.0]).unwrap();
        assert!(!slab.as_ref().all_finite());
        // The edge: below 65520 rounds to the largest half, from 65520 on it is infinite.
        slab.as_mut().store(&[65519.0, -65519.0]).unwrap();
        assert_eq!(
            slab.as_ref().iter().collect::<alloc::vec::Vec<_>>(),
            [65504.0, -65504.0]
        );
        slab.as_mut().store(&[65520.0, 1.0]).unwrap();
        assert_eq!(slab.as_ref().get(0), Some(f32::INFINITY));
        assert!(!slab.as_ref().all_finite());
        let mut wide = FeatureSlab::zeroed(2, FeatureStorage::F32).unwrap();
        wide.as_mut().store(&[1.0, 70000.0]).unwrap();
        assert!(wide.as_ref().all_finite());
    }

    #[test]
    fn a_length_mismatch_is_an_error_and_writes_nothing() {
        for storage in [FeatureStorage::F32, FeatureStorage::F16] {
            let mut slab = FeatureSlab::zeroed(3, storage).unwrap();
            assert_eq!(
                slab.as_mut().store(&[1.0; 4]),
                Err(LengthMismatch {
                    expected: 3,
                    got: 4
                })
            );
            let mut dst = [7.0f32; 2];
            assert_eq!(
                slab.as_ref().load(&mut dst),
                Err(LengthMismatch {
                    expected: 3,
                    got: 2
                })
            );
            assert_eq!(dst, [7.0; 2]);
            assert!(slab.as_ref().iter().all(|v| v == 0.0));
        }
    }

    #[test]
    fn storage_names_round_trip_and_sizes_are_the_elements() {
        for s in [FeatureStorage::F32, FeatureStorage::F16] {
            assert_eq!(FeatureStorage::from_name(s.name()), Some(s));
        }
        assert_eq!(FeatureStorage::from_name("bf16"), None);
        assert_eq!(FeatureStorage::F16.elem_bytes(), 2);
        assert_eq!(FeatureStorage::F32.elem_bytes(), 4);
    }
}
