//! The patches of a 2-D convolution or pooling ([`Unfold`]): which input value each tap of
//! each output pixel reads, gathered row by row (a channel and tap over a run of output
//! pixels), as the f32 product's packed panels ([`crate::ops::conv_unfold::UnfoldConv`]), as
//! the int8 product's quad-map values ([`crate::ops::quant_conv::QuantConv`]), or as the max
//! pooling's windows ([`crate::ops::max_pool::MaxPool2d`]).

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::cnn::PoolSpec;

use crate::gemm::{self, NR};

/// The patches of a 2-D convolution of `[1, C, H, W]`, as a `[C * kh * kw, OH * OW]` matrix
/// would hold them: row `(c * kh + ky) * kw + kx`, zeros where a tap falls in the padding.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Unfold {
    /// Input channels, rows, columns.
    pub input: [usize; 3],
    /// Kernel rows, columns.
    pub kernel: [usize; 2],
    /// Strides (rows, columns).
    pub strides: [usize; 2],
    /// Dilations (rows, columns).
    pub dilations: [usize; 2],
    /// Padding before (rows, columns).
    pub pad_before: [usize; 2],
    /// Output rows, columns.
    pub output: [usize; 2],
}

impl Unfold {
    /// Rows of the patch matrix (input channels times taps): a convolution's summed axis.
    #[must_use]
    pub fn depth(&self) -> usize {
        let [c, _, _] = self.input;
        let [kh, kw] = self.kernel;
        c * kh * kw
    }

    /// The windows of a 2-D `spec` over a `[c, h, w]` input (a convolution's or a pooling's);
    /// `None` for another rank or an empty output.
    pub fn of_pool(spec: &PoolSpec, [c, h, w]: [usize; 3]) -> Option<Self> {
        if spec.kernel_shape.len() != 2 {
            return None;
        }
        let pads = spec.computed_padding(&[h, w]);
        let (oh, ow) = (pads[0].convoluted, pads[1].convoluted);
        let (strides, dil) = (spec.strides(), spec.dilations());
        (oh * ow > 0).then(|| Self {
            input: [c, h, w],
            kernel: [spec.kernel_shape[0], spec.kernel_shape[1]],
            strides: [strides[0], strides[1]],
            dilations: [dil[0], dil[1]],
            pad_before: [pads[0].pad_before, pads[1].pad_before],
            output: [oh, ow],
        })
    }

    /// Depth rows `pc..pc + kc` of B panels `j..` (output pixels `j * NR..`) into `dst`, one
    /// panel after the other, [`NR`] values a row ([`gemm::BSource::Fill`]).
    pub(crate) fn fill_panels(
        &self,
        xs: &[f32],
        (j, pc, kc): (usize, usize, usize),
        dst: &mut [f32],
    ) {
        let mut row = [0.0f32; gemm::FILL_PANELS * NR];
        let panels = dst.len() / (kc * NR);
        let row = &mut row[..panels * NR];
        for r in 0..kc {
            self.patch_row(xs, pc + r, j * NR, row);
            for (jl, piece) in row.chunks_exact(NR).enumerate() {
                dst[(jl * kc + r) * NR..][..NR].copy_from_slice(piece);
            }
        }
    }

    /// Patch row `r` (input channel, kernel row, kernel column) of the input planes `xs` for
    /// the output pixels `p0..p0 + out.len()` into `out`, each value written once: zeros
    /// (`T::default()`) in the padding and past the last pixel. f32 for [`UnfoldConv`], the
    /// quantised bytes for [`crate::ops::quant_conv::QuantConv`].
    pub(crate) fn patch_row<T: Copy + Default>(
        &self,
        xs: &[T],
        r: usize,
        p0: usize,
        out: &mut [T],
    ) {
        let zero = T::default();
        let [_, h, w] = self.input;
        let [kh, kw] = self.kernel;
        let [oh, ow] = self.output;
        let (kx, ky, c) = (r % kw, (r / kw) % kh, r / (kw * kh));
        let plane = &xs[c * h * w..][..h * w];
        let [sy, sx] = self.strides;
        let [dy, dx] = self.dilations;
        let [pt, pl] = self.pad_before;
        // Output columns whose input column ox * sx + off is inside the row: lo..hi.
        let off = (kx * dx) as isize - pl as isize;
        let lo = if off >= 0 {
            0
        } else {
            off.unsigned_abs().div_ceil(sx)
        };
        let hi = if off >= w as isize {
            0
        } else {
            ((w as isize - 1 - off) as usize / sx + 1).min(ow)
        };
        let end = p0 + out.len();
        let mut p = p0;
        while p < end {
            let d = &mut out[p - p0..];
            if p >= oh * ow {
                d.fill(zero);
                break;
            }
            let (oy, ox0) = (p / ow, p % ow);
            let ox1 = ow.min(ox0 + (end - p));
            let d = &mut d[..ox1 - ox0];
            let iy = (oy * sy + ky * dy) as isize - pt as isize;
            if iy < 0 || iy >= h as isize {
                d.fill(zero);
            } else {
                let a = lo.clamp(ox0, ox1);
                let b = hi.clamp(a, ox1);
                let (head, rest) = d.split_at_mut(a - ox0);
                let (body, tail) = rest.split_at_mut(b - a);
                head.fill(zero);
                tail.fill(zero);
                if a < b {
                    let first = iy as usize * w + (a as isize * sx as isize + off) as usize;
                    if sx == 1 {
                        body.copy_from_slice(&plane[first..][..b - a]);
                    } else if sx == 2 {
                        // Pairs, the first of each: a shape the compiler vectorises (two loads
                        // and a permute for 16 values), where a stepped iterator went value by
                        // value (the stems' gathering, ~1 ns a value).
                        let src = &plane[first..][..2 * (b - a) - 1];
                        let (pairs, last) = body.split_at_mut(src.len() / 2);
                        for (v, pair) in pairs.iter_mut().zip(src.chunks_exact(2)) {
                            *v = pair[0];
                        }
                        if let Some(v) = last.first_mut() {
                            *v = src[src.len() - 1];
                        }
                    } else {
                        for (v, s) in body.iter_mut().zip(plane[first..].iter().step_by(sx)) {
                            *v = *s;
                        }
                    }
                }
            }
            p += ox1 - ox0;
        }
    }
}

/// `[1, C, H, W]` with a batch axis, `[C, H, W]` without: the shapes of the channel-first ops
/// ([`UnfoldConv`], [`crate::ops::max_pool::MaxPool2d`]).
pub(crate) fn with_batch(batch_axis: bool, chw: [usize; 3]) -> TVec<usize> {
    let mut s: TVec<usize> = if batch_axis { tvec![1] } else { tvec![] };
    s.extend(chw);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patch_rows_are_the_shifted_input_with_zero_padding() {
        // 1 channel 3 x 4, 3x3 taps, padding 1, stride 1: tap (0, 0) of output pixel (0, 0)
        // falls in the padding, of pixel (1, 1) on input (0, 0).
        let unfold = Unfold {
            input: [1, 3, 4],
            kernel: [3, 3],
            strides: [1, 1],
            dilations: [1, 1],
            pad_before: [1, 1],
            output: [3, 4],
        };
        let xs: Vec<f32> = (1..=12).map(|v| v as f32).collect();
        let row_from = |p0: usize, len: usize| {
            let mut row = vec![f32::NAN; len];
            unfold.patch_row(&xs, 0, p0, &mut row);
            row
        };
        let row = row_from(0, 16);
        let want = [
            0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 0.0, 5.0, 6.0, 7.0, 0.0, 0.0, 0.0, 0.0,
        ];
        assert_eq!(row, want);
        // The same row from pixel 5 on, past the last pixel zero.
        let part = row_from(5, 9);
        assert_eq!(&part[..7], &want[5..12]);
        assert!(part[7..].iter().all(|&v| v == 0.0));
    }
}
