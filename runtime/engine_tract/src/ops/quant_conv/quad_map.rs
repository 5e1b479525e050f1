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
//! integer sum does not depend on the order.

use satmap_kernels::qgemm::quantize;

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

/// `x` (`[C, H, W]` f32) quantised with `inv_scale` into the quad map `out` (`ceil(C / 4)`
/// planes of `H x W` values).
///
/// A group of four present channels (all but a ragged last one) is one zipped pass over four
/// equal slices with the branch-free [`quantize::quantize`], which the compiler vectorises: the
/// per-value channel checks and indexing of the ragged path cost ~1 ns a value, 1.7 ms a step on
/// `nano`'s decoder convolution (docs/int8.md).
pub(super) fn quantise_quads(x: &[f32], [c, h, w]: [usize; 3], inv_scale: f32, out: &mut [u32]) {
    let plane = h * w;
    let q = |v: f32| u32::from(quantize::quantize(v, inv_scale) as u8);
    for (c4, dst) in out.chunks_exact_mut(plane.max(1)).enumerate() {
        let group = x.get(4 * c4 * plane..(4 * c4 + 4) * plane);
        if let (true, Some(group)) = (4 * c4 + 4 <= c, group) {
            let (a, rest) = group.split_at(plane);
            let (b, rest) = rest.split_at(plane);
            let (cc, d) = rest.split_at(plane);
            for ((((v, &a), &b), &cc), &d) in dst.iter_mut().zip(a).zip(b).zip(cc).zip(d) {
                *v = q(a) | q(b) << 8 | q(cc) << 16 | q(d) << 24;
            }
            continue;
        }
        let chan = |j: usize| -> Option<&[f32]> {
            let ch = 4 * c4 + j;
            (ch < c)
                .then(|| x.get(ch * plane..(ch + 1) * plane))
                .flatten()
        };
        let [a, b, cc, d] = [chan(0), chan(1), chan(2), chan(3)];
        for (i, v) in dst.iter_mut().enumerate() {
            let q = |p: Option<&[f32]>| p.and_then(|p| p.get(i)).map_or(0, |&x| q(x));
            *v = q(a) | q(b) << 8 | q(cc) << 16 | q(d) << 24;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both paths (whole groups of four channels, the ragged last group) give each channel's
    /// quantised byte at its place, zeros past `C`, for channel counts 1..=9.
    #[test]
    fn every_channel_lands_in_its_byte() {
        let (h, w) = (3, 5);
        let plane = h * w;
        for c in 1usize..=9 {
            let x: Vec<f32> = (0..c * plane)
                .map(|i| (i as f32 * 0.37).sin() * 2.0)
                .collect();
            let inv_scale = 127.0 / 2.0;
            let mut out = vec![u32::MAX; c.div_ceil(4) * plane];
            quantise_quads(&x, [c, h, w], inv_scale, &mut out);
            for (i, &v) in out.iter().enumerate() {
                let (c4, p) = (i / plane, i % plane);
                for (j, byte) in v.to_le_bytes().into_iter().enumerate() {
                    let ch = 4 * c4 + j;
                    let want = if ch < c {
                        quantize::quantize(x[ch * plane + p], inv_scale) as u8
                    } else {
                        0
                    };
                    assert_eq!(byte, want, "c {c}, channel {ch}, pixel {p}");
                }
            }
        }
    }
}
