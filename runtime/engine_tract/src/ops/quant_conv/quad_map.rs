//! The quantised input map of [`super::QuantConv`] (the *quad map*) and the weight order that
//! goes with it.
//!
//! The map's form: `[ceil(C / 4), H, W]` values of four bytes, value `(c4, y, x)` holding
//! channels `4 * c4 .. 4 * c4 + 4` at pixel `(y, x)` (zeros past `C`). A patch row of such a
//! map is, for each pixel, four summed `k` values at once: a line of the product's panel (16
//! pixels' four bytes) is 16 consecutive values of it, so a block is packed by the f32
//! convolution's own gathering ([`Unfold::patch_row`], here over `u32`) and a copy, with no
//! byte shuffling. The summed axis is ordered (channel group, kernel row, kernel column, channel
//! in group); the weights are laid out in that order at load ([`quad_order`]), and an exact
//! integer sum does not depend on the order. The map itself is written by
//! `satmap_kernels::qgemm::quantize::quads` (vectorised per instruction set).

use crate::ops::unfold::Unfold;

/// `unfold` over the quad map's four-channel values.
pub(super) fn quad_unfold(unfold: &Unfold) -> Unfold {
    let [c, h, w] = unfold.input;
    Unfold {
        input: [c.div_ceil(4), h, w],
        ..unfold.clone()
    }
}

/// OIHW weights `w` of `m` output channels in the order of the quad map's summed axis, zeros
/// for the channels past `C`.
pub(super) fn quad_order(unfold: &Unfold, w: &[f32], m: usize) -> Vec<f32> {
    let [c, _, _] = unfold.input;
    let [kh, kw] = unfold.kernel;
    let taps = kh * kw;
    let k4 = c.div_ceil(4) * 4 * taps;
    let mut out = vec![0.0f32; m * k4];
    for (o, dst) in out.chunks_exact_mut(k4.max(1)).enumerate() {
        for ch in 0..c {
            for t in 0..taps {
                if let Some(&v) = w.get((o * c + ch) * taps + t) {
                    dst[((ch / 4) * taps + t) * 4 + ch % 4] = v;
                }
            }
        }
    }
    out
}
