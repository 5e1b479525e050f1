//! Where the runtime's fixed buffers live: a [`Slab`] is either reserved on the heap once at
//! init (a failed reservation is a [`MemoryError`], never an abort) or placed by the integrator
//! (a `'static` region of `memory_layout.toml`, see [`crate::placement`]). Either way its length
//! never changes after init. [`MemoryError`] is also what the region checks
//! ([`crate::regions`], [`crate::placement`]) return: the runtime's one memory failure.

use alloc::vec::Vec;
use core::fmt;
use core::ops::{Deref, DerefMut};

/// Why a buffer of the runtime has no memory: a region too small or misaligned, or a
/// reservation refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum MemoryError {
    /// The model needs more bytes in a region than `memory_layout.toml` gives it.
    RegionTooSmall {
        /// Region name, as in `memory_layout.toml`.
        region: &'static str,
        /// Bytes the model's dimensions need.
        needed_bytes: usize,
        /// Capacity of the region, bytes.
        capacity_bytes: usize,
    },
    /// A caller-placed region does not start on the alignment the runtime needs.
    RegionMisaligned {
        /// Region name, as in `memory_layout.toml`.
        region: &'static str,
        /// Required alignment, bytes.
        align: usize,
    },
    /// A fixed buffer could not be reserved.
    OutOfMemory {
        /// Bytes requested.
        bytes: usize,
    },
}

impl fmt::Display for MemoryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::RegionTooSmall {
                region,
                needed_bytes,
                capacity_bytes,
            } => write!(
                f,
                "region `{region}` does not fit: the model needs {needed_bytes} bytes, \
                 memory_layout.toml gives {capacity_bytes}"
            ),
            Self::RegionMisaligned { region, align } => {
                write!(f, "region `{region}` must start on a {align}-byte boundary")
            }
            Self::OutOfMemory { bytes } => write!(f, "cannot reserve a buffer of {bytes} bytes"),
        }
    }
}

impl core::error::Error for MemoryError {}

/// A fixed-length buffer the runtime owns for its whole life.
#[derive(Debug)]
pub(crate) enum Slab<T: 'static> {
    /// Reserved on the heap at init.
    Heap(Vec<T>),
    /// A caller-placed region (already cut to length and zeroed).
    Placed(&'static mut [T]),
}

impl<T: Copy + Default + 'static> Slab<T> {
    /// `len` copies of `T::default()` on the heap, or [`MemoryError::OutOfMemory`].
    pub(crate) fn zeroed(len: usize) -> Result<Self, MemoryError> {
        zeroed(len).map(Self::Heap)
    }

    /// Take over a placed region, filled with `T::default()`.
    pub(crate) fn placed(region: &'static mut [T]) -> Self {
        region.fill(T::default());
        Self::Placed(region)
    }
}

impl<T: 'static> Deref for Slab<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        match self {
            Self::Heap(v) => v,
            Self::Placed(s) => s,
        }
    }
}

impl<T: 'static> DerefMut for Slab<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        match self {
            Self::Heap(v) => v,
            Self::Placed(s) => s,
        }
    }
}

/// A vector of `len` copies of `T::default()`, or [`MemoryError::OutOfMemory`].
pub(crate) fn zeroed<T: Copy + Default>(len: usize) -> Result<Vec<T>, MemoryError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| MemoryError::OutOfMemory {
            bytes: len.saturating_mul(size_of::<T>()),
        })?;
    v.resize(len, T::default());
    Ok(v)
}
