//! The x86 vector registers' upper bits, cleared between the ops of a plan and before each
//! task the engine's pool runs.
//!
//! tract 0.23.9's AVX-512 kernels (its matrix products, `max` for ReLU, `erf` for GELU, `tanh`,
//! `sigmoid`) return without `vzeroupper`, leaving the upper bits of the vector registers
//! dirty; every legacy-SSE instruction after them (code compiled for the x86-64 baseline:
//! tract's own scalar ops, small copies, the patch gathering of [`crate::ops::conv_unfold`]) then
//! runs far slower until something clears them. Measured on `nano`'s satellite encoder (an
//! Intel Xeon with AVX-512): gathering the patches of one 256-channel convolution took 4.9 ms
//! right after a GELU and 0.34 ms after a `vzeroupper`. The engine evaluates each node through
//! [`eval_node`], which clears the bits after the op; the pool's tasks clear them first
//! (`pool::on_threads`, `pool::on_pool`). Clearing changes no value: the upper bits are dead
//! across these calls (the ABI's vector registers are all caller-saved).

use tract_nnef::internal::*;
use tract_nnef::tract_core::plan;

/// Clear the upper bits of the vector registers (`vzeroupper`) where the CPU has AVX; nothing
/// elsewhere.
#[inline]
pub fn clear_upper() {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present (checked above).
        unsafe { zero_upper() }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn zero_upper() {
    std::arch::x86_64::_mm256_zeroupper();
}

/// tract's evaluation of one node of a plan, the vector registers' upper bits cleared after it
/// ([`clear_upper`]): the `eval` the engine runs its plans with.
///
/// # Errors
/// The op's, as tract reports them.
pub fn eval_node(
    ctx: &EvalContext,
    op_state: Option<&mut (dyn OpState + 'static)>,
    node: &TypedNode,
    inputs: TVec<TValue>,
) -> TractResult<TVec<TValue>> {
    let out = plan::eval(ctx, op_state, node, inputs);
    clear_upper();
    out
}
