//! Where the runtime's fixed buffers live: a [`Slab`] is either reserved on the heap once at
//! init (a failed reservation is an [`InitError`], never an abort) or placed by the integrator
//! (a `'static` region of `memory_layout.toml`, see [`crate::placement`]). Either way its length
//! never changes after init.

use alloc::vec::Vec;
use core::ops::{Deref, DerefMut};

use crate::error::InitError;

/// A fixed-length buffer the runtime owns for its whole life.
#[derive(Debug)]
pub(crate) enum Slab<T: 'static> {
    /// Reserved on the heap at init.
    Heap(Vec<T>),
    /// A caller-placed region (already cut to length and zeroed).
    Placed(&'static mut [T]),
}

impl<T: Copy + Default + 'static> Slab<T> {
    /// `len` copies of `T::default()` on the heap, or [`InitError::OutOfMemory`].
    pub(crate) fn zeroed(len: usize) -> Result<Self, InitError> {
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

/// A vector of `len` copies of `T::default()`, or [`InitError::OutOfMemory`].
pub(crate) fn zeroed<T: Copy + Default>(len: usize) -> Result<Vec<T>, InitError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| InitError::OutOfMemory {
            bytes: len.saturating_mul(size_of::<T>()),
        })?;
    v.resize(len, T::default());
    Ok(v)
}
