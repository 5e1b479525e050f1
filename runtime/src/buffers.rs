//! Fallible allocation of the runtime's fixed buffers: every buffer is reserved once at init,
//! and a failed reservation is an [`InitError`], never an abort.

use alloc::vec::Vec;

use crate::error::InitError;

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
