//! The host's system allocator (glibc's malloc) told to keep what it is given back, the way the
//! ECU's fixed arena does.
//!
//! Outside the fixed arena (`bench-stages`, the tools, a drive before `init`) the engine's
//! activations come from glibc's malloc, which by default hands large freed blocks back to the
//! kernel: each run's outputs were then fresh pages, and a page fault costs ~12 us on this kind
//! of virtual machine (the first pass over a fresh 256 MiB buffer ran at 0.7 GB/s, the next
//! at 24). Two ways it did:
//! - per-thread arenas: since the engine runs each plan on a worker of its own pool
//!   (`TractEngine::set_threads`), glibc gave those threads arenas of their own, which trim
//!   freed memory. `test`'s decoder on two threads read 18-23 ms in most runs against 11-13
//!   ms in the others, and 10.7-12.8 ms in every run with one arena (2026-12-05);
//! - blocks above the mmap threshold (grown to 32 MiB at most), mapped for each allocation and
//!   unmapped when freed: `paper`'s image encoder has 24 MiB maps. 8,400 page faults a run of
//!   its five stages, 1,500 with every block from the heap and the heap never trimmed
//!   (`perf stat -e page-faults`, `bench-stages --repeats 1` against `5`).
//!
//! The ECU build allocates from the TLSF arena, which does neither; this is the host's
//! equivalent (what onnxruntime's own arena does for it, too).

/// Ask glibc's malloc for one arena shared by all threads (`M_ARENA_MAX = 1`), every block from
/// that arena's heap (`M_MMAP_MAX = 0`: no block mapped on its own) and the heap never
/// trimmed (`M_TRIM_THRESHOLD` at its maximum): freed memory is reused, never handed back.
/// Call at start-up, before the engine's threads have arenas of their own; a no-op off glibc.
/// Returns whether glibc took all three.
pub fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt sets an allocator parameter under glibc's own lock; it takes no
        // pointers and touches no memory of ours.
        unsafe {
            libc::mallopt(libc::M_ARENA_MAX, 1) == 1
                && libc::mallopt(libc::M_MMAP_MAX, 0) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glibc_takes_the_settings() {
        assert_eq!(
            keep_freed_memory(),
            cfg!(all(target_os = "linux", target_env = "gnu"))
        );
    }
}
