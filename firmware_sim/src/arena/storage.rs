//! [`ArenaStorage`]: the static, aligned byte arrays the arena allocator's heaps are laid over.

use core::cell::UnsafeCell;

/// Backing storage of the arena: a static, 16-byte aligned byte array.
#[repr(C, align(16))]
pub struct ArenaStorage<const BYTES: usize>(UnsafeCell<[u8; BYTES]>);

// SAFETY: the storage is only ever handed out once, to the allocator, by `ArenaAllocator::init`;
// every access after that goes through the TLSF heap, which serialises with a critical section.
unsafe impl<const BYTES: usize> Sync for ArenaStorage<BYTES> {}

impl<const BYTES: usize> ArenaStorage<BYTES> {
    /// Zeroed storage (placed in .bss, so it costs no file size).
    #[must_use]
    pub const fn new() -> Self {
        Self(UnsafeCell::new([0; BYTES]))
    }

    /// Size in bytes.
    #[must_use]
    pub const fn len(&self) -> usize {
        BYTES
    }

    /// True for a zero-sized storage.
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        BYTES == 0
    }

    pub(crate) fn start(&self) -> usize {
        self.0.get() as usize
    }
}

impl<const BYTES: usize> Default for ArenaStorage<BYTES> {
    fn default() -> Self {
        Self::new()
    }
}
