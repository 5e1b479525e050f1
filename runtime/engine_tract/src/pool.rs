//! The engine's pool as the native ops use it: how an op splits its work over the engine's
//! threads (`on_threads`, `on_pool`, and `DisjointParts` for tasks that write their own parts of
//! one output), when a product is worth it, and the mark that keeps a
//! product inside a task on its thread. The pool is tract's executor of the running plan
//! (`TractEngine::set_threads`), never rayon's global one.

use rayon::prelude::*;
use tract_linalg::multithread::{Executor, current_tract_executor};

/// `task(i)` for `i` in `0..tasks`, on the engine's pool where there is one; `false` when a
/// task returned it.
pub fn on_pool(tasks: usize, task: impl Fn(usize) -> bool + Sync + Send) -> bool {
    match current_tract_executor() {
        Executor::MultiThread(pool) => {
            pool.install(|| (0..tasks).into_par_iter().all(|t| as_task(|| task(t))))
        }
        // The engine never runs on rayon's global pool (see `TractEngine::set_threads`).
        _ => (0..tasks).all(task),
    }
}

std::thread_local! {
    /// Whether this thread is running one task of an op's split ([`as_task`]).
    static IN_TASK: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run one task of an op's split on a pool thread: the vector state cleared first (tract's
/// kernels may have left it dirty on this worker, see `vector_state`), and marked, so that a
/// product inside it stays on its thread ([`in_task`]). The plan itself runs on a worker of the
/// same pool (`on_engine_threads`), so being on a worker does not tell a task from the plan.
pub(crate) fn as_task<R>(task: impl FnOnce() -> R) -> R {
    crate::vector_state::clear_upper();
    let outer = IN_TASK.replace(true);
    let result = task();
    IN_TASK.set(outer);
    result
}

/// Whether this thread is inside a task of an op's split (then it does not split again).
pub(crate) fn in_task() -> bool {
    IN_TASK.get()
}

/// Threads of the engine's pool (1 outside one).
pub(crate) fn threads() -> usize {
    match current_tract_executor() {
        Executor::MultiThread(pool) => pool.current_num_threads(),
        _ => 1,
    }
}

/// Multiply-adds from which a product is worth the pool's dispatch (a few microseconds a call):
/// the Swin windows' 49 x 49 x 32 products run on the calling thread.
pub const PARALLEL_MIN_MACS: usize = 1 << 20;

/// Whether a product of `macs` multiply-adds (and its packing) goes to the pool.
#[must_use]
pub fn worth_threads(macs: usize) -> bool {
    macs >= PARALLEL_MIN_MACS
}

/// `task(index, chunk)` over `data` in chunks of `chunk` values, on the engine's pool when
/// `parallel`, else on this thread; `false` when a task returned it.
pub fn on_threads<F>(parallel: bool, data: &mut [f32], chunk: usize, task: F) -> bool
where
    F: Fn(usize, &mut [f32]) -> bool + Sync,
{
    let chunk = chunk.max(1);
    match current_tract_executor() {
        Executor::MultiThread(pool) if parallel => pool.install(|| {
            data.par_chunks_mut(chunk)
                .enumerate()
                .all(|(i, c)| as_task(|| task(i, c)))
        }),
        // The engine never runs on rayon's global pool (see `TractEngine::set_threads`).
        _ => data.chunks_mut(chunk).enumerate().all(|(i, c)| task(i, c)),
    }
}

/// An op's output, shared by the tasks of its split, each of which writes its own part only
/// (the native product's column panels, the int8 convolution's pixel blocks): the tasks copy
/// their results into place through this pointer while the op holds the output's mutable borrow.
pub(crate) struct DisjointParts(pub(crate) *mut f32);

impl DisjointParts {
    /// The pointer to value `i` of the output (a method, so that a closure captures the whole
    /// `Sync` wrapper rather than its raw pointer field).
    ///
    /// # Safety
    /// `i` within the output.
    pub(crate) unsafe fn at(&self, i: usize) -> *mut f32 {
        // SAFETY: the caller keeps `i` within the output.
        unsafe { self.0.add(i) }
    }
}

// SAFETY: the pointer is only written through by the tasks of one op's split, each at its own
// part of the output, while that op holds the output's mutable borrow and reads none of it.
unsafe impl Sync for DisjointParts {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tasks_are_marked_and_the_plan_thread_is_not() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let pool = std::sync::Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap(),
        );
        let marked = AtomicUsize::new(0);
        let plan_marked = pool.install(|| {
            tract_linalg::multithread::multithread_tract_scope(
                Executor::MultiThread(pool.clone()),
                || {
                    let before = in_task();
                    assert!(on_pool(8, |_| {
                        marked.fetch_add(usize::from(in_task()), Ordering::Relaxed);
                        true
                    }));
                    let mut data = [0.0f32; 64];
                    assert!(on_threads(true, &mut data, 8, |_, _| {
                        marked.fetch_add(usize::from(in_task()), Ordering::Relaxed);
                        true
                    }));
                    before || in_task()
                },
            )
        });
        // A product on the plan's thread may split; one inside a task stays on its thread.
        assert!(!plan_marked);
        assert_eq!(marked.load(Ordering::Relaxed), 16);
    }
}
