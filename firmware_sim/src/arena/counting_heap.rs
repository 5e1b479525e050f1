//! [`CountingHeap`]: embedded-alloc's TLSF heap (O(1), real-time) over one static region,
//! counting live bytes, live blocks, the peak and the allocations served. The arena allocator
//! holds two: the arena itself, and the per-step scratch (`[arena] step_scratch_bytes` of
//! `memory_layout.toml`, a region apart from the arena).
//!
//! Why a step scratch: tract's op interface returns every op output as a freshly allocated
//! tensor, so a step of the graph engine makes a few thousand allocations (2,353 for the `test`
//! bundle). Rather than let them come and go in the arena, where the runtime's regions and the
//! engine's weights live, the arena allocator serves every allocation made while the region
//! label is [`Step`](super::ArenaRegion::Step) from the scratch heap, and the harness checks
//! that it is empty again when the step ends: the arena then sees no allocation in a step, and
//! the scratch's size is known at load (a rehearsal run of every stage measures it before the
//! first step). TLSF merges a freed block with its free neighbours, so an empty heap is back in
//! its initial state: no explicit reset is needed, only the check that nothing outlived the
//! step.

use core::alloc::{GlobalAlloc, Layout};
use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use super::ArenaStorage;

/// Counters of a heap, as read at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HeapStats {
    /// Region size, bytes (0 before [`CountingHeap::init`]).
    pub capacity_bytes: usize,
    /// Bytes requested by live blocks.
    pub current_bytes: usize,
    /// Live blocks.
    pub live_blocks: usize,
    /// Highest `current_bytes` since `init` or the last [`CountingHeap::reset_peak`].
    pub peak_bytes: usize,
    /// Allocations served since `init`.
    pub allocations: usize,
}

/// A counting TLSF heap over one static region.
pub struct CountingHeap {
    heap: embedded_alloc::TlsfHeap,
    ready: AtomicBool,
    start: AtomicUsize,
    end: AtomicUsize,
    current: AtomicUsize,
    live_blocks: AtomicUsize,
    peak: AtomicUsize,
    allocations: AtomicUsize,
}

impl CountingHeap {
    /// An empty, unusable scratch until [`init`](Self::init).
    #[must_use]
    pub const fn new() -> Self {
        Self {
            heap: embedded_alloc::TlsfHeap::empty(),
            ready: AtomicBool::new(false),
            start: AtomicUsize::new(0),
            end: AtomicUsize::new(0),
            current: AtomicUsize::new(0),
            live_blocks: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
            allocations: AtomicUsize::new(0),
        }
    }

    /// True once [`init`](Self::init) succeeded.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.ready.load(Ordering::Acquire)
    }

    /// Lay the heap over the first `size_bytes` of `storage`. Returns `false` (and changes
    /// nothing) if already initialised or if `size_bytes` is zero or larger than the storage.
    pub fn init<const BYTES: usize>(
        &self,
        storage: &'static ArenaStorage<BYTES>,
        size_bytes: usize,
    ) -> bool {
        if size_bytes == 0 || size_bytes > BYTES || self.ready.load(Ordering::Acquire) {
            return false;
        }
        let start = storage.start();
        // SAFETY: `storage` is 'static and handed out once (`ready` guards a second call; the
        // caller passes a storage no other heap uses), and `size_bytes <= BYTES`.
        unsafe { self.heap.init(start, size_bytes) };
        self.start.store(start, Ordering::Relaxed);
        self.end.store(start + size_bytes, Ordering::Relaxed);
        self.ready.store(true, Ordering::Release);
        true
    }

    /// Current counters.
    #[must_use]
    pub fn stats(&self) -> HeapStats {
        let ready = self.ready.load(Ordering::Acquire);
        HeapStats {
            capacity_bytes: if ready {
                self.end.load(Ordering::Relaxed) - self.start.load(Ordering::Relaxed)
            } else {
                0
            },
            current_bytes: self.current.load(Ordering::Relaxed),
            live_blocks: self.live_blocks.load(Ordering::Relaxed),
            peak_bytes: self.peak.load(Ordering::Relaxed),
            allocations: self.allocations.load(Ordering::Relaxed),
        }
    }

    /// Restart the peak from the current use.
    pub fn reset_peak(&self) {
        self.peak
            .store(self.current.load(Ordering::Relaxed), Ordering::Relaxed);
    }

    /// True when `ptr` lies in the region.
    pub(super) fn contains(&self, ptr: *mut u8) -> bool {
        let p = ptr as usize;
        self.ready.load(Ordering::Acquire)
            && p >= self.start.load(Ordering::Relaxed)
            && p < self.end.load(Ordering::Relaxed)
    }

    /// A block of `layout`, or null when the region is full.
    ///
    /// # Safety
    /// As [`GlobalAlloc::alloc`]; the scratch must be [ready](Self::is_ready).
    pub(super) unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's layout; the heap was initialised.
        let ptr = unsafe { GlobalAlloc::alloc(&self.heap, layout) };
        if !ptr.is_null() {
            let now = self.current.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            self.peak.fetch_max(now, Ordering::Relaxed);
            self.live_blocks.fetch_add(1, Ordering::Relaxed);
            self.allocations.fetch_add(1, Ordering::Relaxed);
        }
        ptr
    }

    /// Return a block.
    ///
    /// # Safety
    /// `ptr` came from [`alloc`](Self::alloc) with this `layout` ([`contains`](Self::contains)
    /// is how the arena allocator tells).
    pub(super) unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        self.current.fetch_sub(layout.size(), Ordering::Relaxed);
        self.live_blocks.fetch_sub(1, Ordering::Relaxed);
        // SAFETY: `ptr` came from this heap with this layout (the caller's contract).
        unsafe { GlobalAlloc::dealloc(&self.heap, ptr, layout) }
    }
}

impl Default for CountingHeap {
    fn default() -> Self {
        Self::new()
    }
}
