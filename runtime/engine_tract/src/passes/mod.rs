//! The load-time passes: [`rewrite`] runs every pass of the engine in its one order (those of
//! [`crate::ops`] included), and the passes here only reshape tract's own graph: several-axis
//! contractions into linear layers ([`contraction`]), image stems to im2col ([`conv_direct`]),
//! residual `Add` and `ReLU` into a product's last store ([`epilogue`]), weight-only parts
//! evaluated at load ([`fold`]), constants re-laid with natural strides ([`natural_consts`]), an
//! int8 bundle's large weights widened once for the int8 passes ([`widened_weights`]).

pub mod contraction;
pub mod conv_direct;
pub mod epilogue;
pub mod fold;
pub mod natural_consts;
pub mod rewrite;
pub mod widened_weights;
