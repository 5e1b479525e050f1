//! The engine's native ops, each in a module with the pass that puts it into a plan (the op,
//! then the pattern it replaces): products on the native GEMM ([`linear`], [`pointwise`],
//! [`conv_unfold`], [`batched`], [`attention`]), with what their last store does ([`finish`]);
//! the int8 products ([`quant_linear`], [`quant_conv`]) and the calibration's probes
//! ([`range_probe`]);
//! row kernels ([`softmax`], [`layer_norm`], [`gelu`], [`max_pool`], [`broadcast`]); and the
//! deformable samplers ([`bilinear`], [`weighted_sum`]). Ops import the product driver, the pool
//! and the graph helpers, never a pass.

pub mod attention;
pub mod batched;
pub mod bilinear;
pub mod broadcast;
pub mod conv_layer;
pub mod conv_unfold;
pub mod finish;
pub mod gelu;
pub mod layer_norm;
pub mod linear;
pub mod max_pool;
pub mod pointwise;
pub mod quant_conv;
pub mod quant_linear;
pub mod range_probe;
pub mod softmax;
pub mod unfold;
pub mod weighted_sum;
