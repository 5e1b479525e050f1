//! The host's system allocator (glibc's malloc) told to keep one arena for every thread.
//!
//! Outside the fixed arena (`bench-stages`, the tools, a drive before `init`) the engine's
//! activations come from glibc's malloc. Since the engine runs each plan on a worker of its own
//! pool (`TractEngine::set_threads`), glibc gave those threads arenas of their own, which hand
//! large freed blocks back to the kernel: the next run's outputs were fresh pages again. `test`'s
//! decoder on two threads read 18-23 ms in most runs against 11-13 ms in the others (the
//! self-attention's `[4, 1000, 1000]` scores product 4-5 ms against 1 ms), and 10.7-12.8 ms in
//! every run with one arena (`GLIBC_TUNABLES=glibc.malloc.arena_max=1`, 2026-12-05). The ECU
//! build allocates from the TLSF arena, which has no per-thread arenas; this is the host's
//! equivalent.

/// Ask glibc's malloc for a single arena shared by all threads (`M_ARENA_MAX = 1`). Call at
/// start-up, before the engine's threads have arenas of their own; a no-op off glibc. Returns
/// whether glibc took it.
pub fn share_one_arena() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt sets an allocator parameter under glibc's own lock; it takes no
        // pointers and touches no memory of ours.
        unsafe { libc::mallopt(libc::M_ARENA_MAX, 1) == 1 }
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
    fn glibc_takes_the_setting() {
        assert_eq!(
            share_one_arena(),
            cfg!(all(target_os = "linux", target_env = "gnu"))
        );
    }
}
