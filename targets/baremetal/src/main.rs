//! The core check on a safety core: `satmap_core_check::run` on the embedded golden frame, its
//! digests printed and compared with the host's (`satmap_core_check::EXPECTED`), the result as
//! the exit status. Bare metal (`target_os = "none"`): a TLSF heap over a static array, output
//! and exit through semihosting, startup by `aarch64-rt` (qemu `virt`) or `cortex-m-rt`
//! (MPS2-AN386, Cortex-M4F). On the host the same code runs as a plain program.
//!
//! Run by `make test-baremetal` (targets/baremetal.sh); exit status 0 only when every digest
//! equals the host's.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
extern crate alloc;

#[cfg(target_os = "none")]
use semihosting::println;

/// The golden frame the check reads (the `test` model's frame 0).
const GOLDEN_LEN: usize = include_bytes!("../../../models/golden/test/frame_000.safetensors").len();
/// Placed where the board has room: PSRAM on the Cortex-M4F (`link/mps2_an386.x`), read-only
/// data on `virt`.
#[cfg_attr(
    all(target_os = "none", target_arch = "arm"),
    unsafe(link_section = ".golden")
)]
#[cfg_attr(
    all(target_os = "none", target_arch = "aarch64"),
    unsafe(link_section = ".rodata.golden")
)]
static GOLDEN: [u8; GOLDEN_LEN] =
    *include_bytes!("../../../models/golden/test/frame_000.safetensors");

/// Run the check, print every digest against the host's, return the exit status.
fn check() -> i32 {
    let expected = satmap_core_check::EXPECTED;
    match satmap_core_check::run(&GOLDEN) {
        Ok(got) => {
            let mut equal = 0;
            for ((name, d), (_, want)) in got.named().iter().zip(expected.named()) {
                let verdict = if *d == want { "equal" } else { "DIFFERENT" };
                equal += usize::from(*d == want);
                println!("core check {name}: 0x{d:016x} ({verdict}; host 0x{want:016x})");
            }
            let total = expected.named().len();
            println!("core check: {equal} of {total} digests equal to the host's");
            i32::from(equal != total)
        }
        Err(fault) => {
            // The golden's first bytes (its header length, little-endian) tell a load problem
            // from a parse problem.
            println!(
                "core check failed: {fault:?} (golden at {:p}, {} bytes, starting {:02x?})",
                GOLDEN.as_ptr(),
                GOLDEN.len(),
                &GOLDEN[..16]
            );
            2
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    std::process::exit(check());
}

#[cfg(target_os = "none")]
mod board {
    use core::mem::MaybeUninit;

    use embedded_alloc::TlsfHeap;

    /// Heap: the GKT table (~2.3 MB), its dense form for the digest (~4.7 MB), the golden
    /// tensors as f32 (~1.3 MB) and the route pack.
    const HEAP_BYTES: usize = 12 << 20;

    #[global_allocator]
    static HEAP: TlsfHeap = TlsfHeap::empty();

    #[cfg_attr(target_arch = "arm", unsafe(link_section = ".heap"))]
    static mut HEAP_MEMORY: [MaybeUninit<u8>; HEAP_BYTES] = [MaybeUninit::uninit(); HEAP_BYTES];

    /// Hand the static array to the allocator and run the check; never returns.
    pub fn run() -> ! {
        // SAFETY: called once, first thing after startup, before any allocation; the array is
        // used by nothing else.
        unsafe {
            HEAP.init(core::ptr::addr_of_mut!(HEAP_MEMORY) as usize, HEAP_BYTES);
        }
        semihosting::process::exit(super::check())
    }

    /// One core, no interrupts taken: nothing to exclude (Cortex-M gets its own from `cortex-m`).
    #[cfg(target_arch = "aarch64")]
    struct SingleCore;
    #[cfg(target_arch = "aarch64")]
    critical_section::set_impl!(SingleCore);
    // SAFETY: the image runs on one core with interrupts masked from reset, so there is nothing
    // to exclude.
    #[cfg(target_arch = "aarch64")]
    unsafe impl critical_section::Impl for SingleCore {
        unsafe fn acquire() -> critical_section::RawRestoreState {}
        unsafe fn release(_restore: critical_section::RawRestoreState) {}
    }
}

#[cfg(all(target_os = "none", target_arch = "aarch64"))]
use aarch64_rt::initial_pagetable;

/// `virt`'s RAM (the second GiB of the address space) as one level-1 block of normal,
/// write-back cacheable, inner-shareable memory (`aarch64_rt::DEFAULT_MAIR` index 1), identity
/// mapped; nothing else is mapped (semihosting needs no device).
#[cfg(all(target_os = "none", target_arch = "aarch64"))]
const RAM_BLOCK: usize = 0x4000_0000 // output address: 1 GiB
    | 1 << 10 // access flag
    | 0b11 << 8 // inner shareable
    | 1 << 2 // attribute index 1: normal memory, write-back
    | 1; // valid block descriptor

#[cfg(all(target_os = "none", target_arch = "aarch64"))]
initial_pagetable!({
    let mut idmap = [0; 512];
    idmap[1] = RAM_BLOCK;
    aarch64_rt::InitialPagetable(idmap)
});

#[cfg(all(target_os = "none", target_arch = "aarch64"))]
aarch64_rt::entry!(aarch64_main, 64);

#[cfg(all(target_os = "none", target_arch = "aarch64"))]
fn aarch64_main(_x0: u64, _x1: u64, _x2: u64, _x3: u64) -> ! {
    board::run()
}

// The single-core critical section embedded-alloc takes comes from `cortex-m` (its
// `critical-section-single-core` feature): link the crate although no item of it is named.
#[cfg(all(target_os = "none", target_arch = "arm"))]
use cortex_m as _;

#[cfg(all(target_os = "none", target_arch = "arm"))]
#[cortex_m_rt::entry]
fn cortex_m_main() -> ! {
    board::run()
}
