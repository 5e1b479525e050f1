//! `satmap-nostd-check` (no_std staticlib): links the core without std. May import:
//! `satmap-core-check`.
//!
//! no_std canary: links the satmap-runtime core through the core check (`satmap-core-check`:
//! look-up table, gather-sum kernel, CAN-bus vector, frame checks, decode, map-frame wire, route
//! pack, tile decode) into a `staticlib` with its own `#[panic_handler]` and a TLSF global
//! allocator over a static array, the way an ECU image would. If any dependency pulls std in, the
//! build fails with a duplicate `panic_impl` lang item.
//!
//! Build (stable, no nightly): `cargo rustc -p satmap-nostd-check -- -C panic=abort`.
//! Plain `cargo build -p satmap-nostd-check` fails on this host (x86_64 Linux, rustc 1.95) with
//! "unwinding panics are not supported without std": the workspace's dev profile is
//! `panic = "unwind"` and a no_std artifact has no unwinder. `-C panic=abort` on this final crate
//! alone is enough (dependencies stay as built; a staticlib is not linked by rustc, so core's
//! unwind tables are never resolved). A `panic = "abort"` dev profile would also work but would
//! rebuild every host crate of the workspace with another panic strategy. Build it on its own:
//! in a workspace-wide build cargo unifies features with the host crates and std gets linked in.
//! Checked: `nm -C target/debug/libsatmap_nostd_check.a | grep ' std::'` finds nothing.
#![no_std]

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, Ordering};

use embedded_alloc::TlsfHeap;

/// Heap for the check: the test-config look-up table (~2.3 MB at its worst-case capacity), its
/// dense form for the digest (~4.7 MB), the golden tensors and the kernel's buffers.
const HEAP_BYTES: usize = 12 << 20;

#[global_allocator]
static HEAP: TlsfHeap = TlsfHeap::empty();

static HEAP_READY: AtomicBool = AtomicBool::new(false);

/// Single-core critical section: this canary runs on one thread and takes no interrupts.
struct SingleCore;
critical_section::set_impl!(SingleCore);

// SAFETY: the canary is single-threaded and interrupt-free, so there is nothing to exclude.
unsafe impl critical_section::Impl for SingleCore {
    unsafe fn acquire() -> critical_section::RawRestoreState {}
    unsafe fn release(_restore: critical_section::RawRestoreState) {}
}

#[panic_handler]
fn panic(_info: &PanicInfo<'_>) -> ! {
    loop {
        core::hint::spin_loop();
    }
}

/// Run the core check (`satmap_core_check::run`: look-up table, gather-sum, CAN-bus vector,
/// frame checks, decode, map-frame wire, route pack, tile decode) on its embedded golden frame
/// and return the XOR of its digests (0 on any fault). Exists to be linked without std; the
/// digests themselves are compared by the core check's host test and the bare-metal images.
#[unsafe(no_mangle)]
pub extern "C" fn satmap_nostd_check() -> u64 {
    if !HEAP_READY.swap(true, Ordering::AcqRel) {
        // SAFETY: runs once (guarded by HEAP_READY), before any allocation.
        unsafe {
            embedded_alloc::init!(HEAP, HEAP_BYTES);
        }
    }
    match satmap_core_check::run(satmap_core_check::GOLDEN_FRAME) {
        Ok(d) => d.named().iter().fold(0, |acc, (_, v)| acc ^ v),
        Err(_) => 0,
    }
}
