//! The fixed memory arena the harness runs the whole runtime in.
//!
//! [`ArenaAllocator`] is a global allocator: embedded-alloc's TLSF heap (O(1), real-time) over
//! one static region whose size comes from `memory_layout.toml`, wrapped to count current bytes,
//! peak bytes and allocations. Allocations made before [`ArenaAllocator::init`] (the Rust
//! runtime's own start-up) go to the system allocator and are freed there; every allocation
//! after `init` comes from the arena. When the arena is exhausted the allocator writes a report
//! naming the region and the sizes to stderr (without allocating) and exits with
//! [`EXIT_ARENA_EXHAUSTED`], instead of the standard library's bare abort.
//!
//! The harness labels what is being allocated ([`ArenaRegion`]: graph engine, runtime regions,
//! a step) so that the exhaustion report names the region that did not fit, and it runs the
//! host-side simulation (rendering sensor frames, ground truth, evaluation, the report) inside
//! [`ArenaAllocator::host_side`], which serves from the system allocator: the arena then holds
//! exactly what the ECU would hold. The replay is single-threaded, so one global flag suffices.
//!
//! Once [`ArenaAllocator::init_step_scratch`] gave it the per-step scratch region, everything
//! allocated while the label is [`ArenaRegion::Step`] (on any thread: the engine's worker
//! threads too) comes from that region instead of the arena ([`CountingHeap`] explains why).

mod counting_heap;
mod storage;
pub mod system_malloc;

pub use counting_heap::{CountingHeap, HeapStats};
pub use storage::ArenaStorage;

use core::alloc::{GlobalAlloc, Layout};
use core::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::alloc::System;
use std::io::Write;

/// Process exit code when the arena cannot satisfy an allocation.
pub const EXIT_ARENA_EXHAUSTED: i32 = 3;

/// What the arena is serving at the moment: named in the exhaustion report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum ArenaRegion {
    /// Before the harness labelled anything.
    Unlabelled = 0,
    /// Loading and planning the graph engine (`[arena] graph_engine_bytes`).
    GraphEngine = 1,
    /// The runtime's fixed buffers reserved by `SatMap::new` (the `[region.*]` entries).
    RuntimeRegions = 2,
    /// One replay step (graph engine activations; the runtime itself allocates nothing): served
    /// by the step scratch once it is initialised.
    Step = 3,
}

impl ArenaRegion {
    /// Name used in reports, as in `memory_layout.toml`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Unlabelled => "arena",
            Self::GraphEngine => "graph_engine",
            Self::RuntimeRegions => "runtime regions",
            Self::Step => "step activations (in the arena: no step scratch given)",
        }
    }

    const fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::GraphEngine,
            2 => Self::RuntimeRegions,
            3 => Self::Step,
            _ => Self::Unlabelled,
        }
    }
}

/// Counters of the arena, as read at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ArenaStats {
    /// Arena size, bytes (0 before `init`).
    pub capacity_bytes: usize,
    /// Bytes requested by live allocations.
    pub current_bytes: usize,
    /// Highest `current_bytes` since `init` or the last `reset_peak`.
    pub peak_bytes: usize,
    /// Number of allocations (including reallocations) the arena served since `init`.
    pub allocations: usize,
    /// The per-step scratch region's counters.
    pub step_scratch: HeapStats,
}

impl ArenaStats {
    /// Allocations served by the arena and the step scratch together.
    #[must_use]
    pub const fn all_allocations(&self) -> usize {
        self.allocations + self.step_scratch.allocations
    }
}

/// Counting TLSF global allocator over a fixed arena, with a second heap for steps.
pub struct ArenaAllocator {
    arena: CountingHeap,
    step_scratch: CountingHeap,
    host_side: AtomicBool,
    region: AtomicU8,
}

impl ArenaAllocator {
    /// An allocator that serves from the system until [`init`](Self::init).
    #[must_use]
    pub const fn new() -> Self {
        Self {
            arena: CountingHeap::new(),
            step_scratch: CountingHeap::new(),
            host_side: AtomicBool::new(false),
            region: AtomicU8::new(0),
        }
    }

    /// True once [`init`](Self::init) succeeded.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.arena.is_ready()
    }

    /// Label what the following allocations are for (named if the arena runs out).
    pub fn set_region(&self, region: ArenaRegion) {
        self.region.store(region as u8, Ordering::Relaxed);
    }

    /// The current label.
    #[must_use]
    pub fn region(&self) -> ArenaRegion {
        ArenaRegion::from_u8(self.region.load(Ordering::Relaxed))
    }

    /// Run `f` with allocations served by the system allocator and not counted: the host-side
    /// simulation around the runtime (sensor frames, ground truth, reports). Blocks it allocates
    /// may be freed later from anywhere; `dealloc` routes them by address.
    pub fn host_side<T>(&self, f: impl FnOnce() -> T) -> T {
        let was = self.host_side.swap(true, Ordering::AcqRel);
        let out = f();
        self.host_side.store(was, Ordering::Release);
        out
    }

    /// Hand the first `size_bytes` of `storage` to the heap; from now on every allocation comes
    /// from the arena. Returns `false` (and changes nothing) if already initialised or if
    /// `size_bytes` is zero or larger than the storage.
    pub fn init<const BYTES: usize>(
        &self,
        storage: &'static ArenaStorage<BYTES>,
        size_bytes: usize,
    ) -> bool {
        self.arena.init(storage, size_bytes)
    }

    /// Give steps their own region: from now on allocations labelled [`ArenaRegion::Step`]
    /// come from the first `size_bytes` of `storage`. Returns `false` (and changes nothing) if
    /// already initialised or if `size_bytes` is zero or larger than the storage.
    pub fn init_step_scratch<const BYTES: usize>(
        &self,
        storage: &'static ArenaStorage<BYTES>,
        size_bytes: usize,
    ) -> bool {
        self.step_scratch.init(storage, size_bytes)
    }

    /// Restart the step scratch's peak from its current use (before each step).
    pub fn reset_step_scratch_peak(&self) {
        self.step_scratch.reset_peak();
    }

    /// Current counters.
    #[must_use]
    pub fn stats(&self) -> ArenaStats {
        let a = self.arena.stats();
        ArenaStats {
            capacity_bytes: a.capacity_bytes,
            current_bytes: a.current_bytes,
            peak_bytes: a.peak_bytes,
            allocations: a.allocations,
            step_scratch: self.step_scratch.stats(),
        }
    }

    /// Restart the peak from the current usage (e.g. after warm-up).
    pub fn reset_peak(&self) {
        self.arena.reset_peak();
    }

    /// Report the heap that could not serve `layout` (the step scratch when `in_scratch`,
    /// else the arena) and exit.
    fn exhausted(&self, layout: Layout, in_scratch: bool) -> ! {
        let (s, region, key, flag) = if in_scratch {
            let s = self.step_scratch.stats();
            (
                s,
                "step_scratch",
                "step_scratch_bytes",
                "--step-scratch-bytes",
            )
        } else {
            let s = self.arena.stats();
            (s, self.region().name(), "bytes", "--arena-bytes")
        };
        let mut buf = FixedBuf::<512>::new();
        let _ = core::fmt::write(
            &mut buf,
            format_args!(
                "ERROR(arena): region `{}` does not fit: it needs {} more bytes, its {} bytes have \
                 {} in use (peak {}). Raise [arena] {} in memory_layout.toml or pass a larger \
                 {}.\n",
                region,
                layout.size(),
                s.capacity_bytes,
                s.current_bytes,
                s.peak_bytes,
                key,
                flag,
            ),
        );
        let _ = std::io::stderr().write_all(buf.as_bytes());
        std::process::exit(EXIT_ARENA_EXHAUSTED)
    }
}

impl Default for ArenaAllocator {
    fn default() -> Self {
        Self::new()
    }
}

// SAFETY: allocations after `init` come from the TLSF heap over the arena (or, labelled as a step,
// from the step scratch's heap over its own region), earlier ones from the system allocator;
// `dealloc` routes each pointer back by address range, so every block returns to the allocator
// that made it.
unsafe impl GlobalAlloc for ArenaAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !self.arena.is_ready() || self.host_side.load(Ordering::Acquire) {
            // SAFETY: forwarded with the caller's layout.
            return unsafe { System.alloc(layout) };
        }
        let in_scratch = self.region() == ArenaRegion::Step && self.step_scratch.is_ready();
        let heap = if in_scratch {
            &self.step_scratch
        } else {
            &self.arena
        };
        // SAFETY: forwarded with the caller's layout; the heap is ready.
        let ptr = unsafe { heap.alloc(layout) };
        if ptr.is_null() {
            self.exhausted(layout, in_scratch);
        }
        ptr
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if self.step_scratch.contains(ptr) {
            // SAFETY: `ptr` came from the step scratch with this layout.
            unsafe { self.step_scratch.dealloc(ptr, layout) }
        } else if self.arena.contains(ptr) {
            // SAFETY: `ptr` came from the arena with this layout.
            unsafe { self.arena.dealloc(ptr, layout) }
        } else {
            // SAFETY: `ptr` came from the system allocator with this layout.
            unsafe { System.dealloc(ptr, layout) }
        }
    }
}

/// A stack buffer that `core::fmt` can write into without allocating.
struct FixedBuf<const N: usize> {
    bytes: [u8; N],
    len: usize,
}

impl<const N: usize> FixedBuf<N> {
    const fn new() -> Self {
        Self {
            bytes: [0; N],
            len: 0,
        }
    }

    fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl<const N: usize> core::fmt::Write for FixedBuf<N> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let room = N - self.len;
        let take = s.len().min(room);
        self.bytes[self.len..self.len + take].copy_from_slice(&s.as_bytes()[..take]);
        self.len += take;
        Ok(())
    }
}
