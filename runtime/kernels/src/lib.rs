//! `satmap-kernels` (std): the engine's numeric kernels, each a portable `generic` implementation that
//! defines the bits with per-instruction-set implementations beside it, and the one rule that
//! chooses the tier ([`tier`]). May import: std only (no tract, no runtime crate).
//!
//! The f32 product's micro-kernel and its packed operand formats ([`gemm`]), with tiers for
//! AVX-512F, AVX2 + FMA and NEON; the int8 product ([`qgemm`]: exact i32 sums, so its tiers,
//! AVX-512 VNNI, AVX-VNNI, AVX2 and aarch64 `sdot`, give its generic tier's bits); and the row kernels of the engine's other native ops, each one
//! portable implementation that defines the bits (its order is the contract; the compiler
//! vectorises it): the softmax's reductions in tract's orders ([`softmax`]), max pooling
//! ([`pooling`]) and the deformable samplers ([`sampling`]). Every tier computes every output as the same fused
//! multiply-add chain (`k` ascending from zero or from the stored partial sum) followed by the
//! same f32 finish, so every tier gives the generic tier's bits (NaN payloads aside, which each
//! instruction set picks its own way); `tests/gemm_tiers.rs` runs the same tests for every tier.
//! A tier whose instructions this CPU lacks is never called: [`gemm::run`] refuses it. The
//! default is AVX-512F where present ([`Tier::default_here`]); the others run when forced.

pub mod gemm;
pub mod pooling;
pub mod qgemm;
pub mod sampling;
pub mod softmax;
pub mod tier;

pub use tier::{Tier, TierError};
