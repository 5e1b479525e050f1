//! Max pooling of one channel plane, separable, in exactly the order tract 0.23.9's `MaxPool`
//! folds a window, so the engine's `MaxPool2d` gives tract's bits. Portable Rust, one
//! implementation: the contiguous row passes vectorise as they are.
//!
//! The rule: tract folds each window from `f32::MIN`, kernel row by kernel row and column by
//! column, replacing the running value only by a strictly greater tap; so the result is the
//! first tap, in that order, of the greatest value (a later `+0.0` does not replace a `-0.0`; a
//! NaN never replaces anything), and a window wholly in the padding gives `f32::MIN`. Per input
//! row the maximum over the kernel columns at every column, kept at the stride's columns, then
//! per output row the maximum of the kernel rows' results: the maximum of the rows' maxima, with
//! the same rule, is that same first tap.

/// The windows of a 2-D pooling over one `H x W` plane (the geometry a convolution's patches
/// have): `[rows, columns]` pairs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PoolWindow {
    /// Input plane, `[H, W]`.
    pub input: [usize; 2],
    /// Kernel, `[KH, KW]`.
    pub kernel: [usize; 2],
    /// Strides, `[SY, SX]`, at least 1.
    pub strides: [usize; 2],
    /// Dilations, `[DY, DX]`, at least 1.
    pub dilations: [usize; 2],
    /// Padding before, `[top, left]`.
    pub pad_before: [usize; 2],
    /// Output plane, `[OH, OW]`.
    pub output: [usize; 2],
}

impl PoolWindow {
    /// Input columns a kernel row's horizontal pass covers: `(OW - 1) * SX + 1` (0 for an
    /// empty output).
    #[must_use]
    pub const fn span(&self) -> usize {
        match self.output[1] {
            0 => 0,
            ow => (ow - 1) * self.strides[1] + 1,
        }
    }

    /// Scratch values [`max_pool_plane`] needs: `H x OW` row maxima, then [`Self::span`].
    #[must_use]
    pub const fn scratch_len(&self) -> usize {
        self.input[0] * self.output[1] + self.span()
    }
}

/// The running maximum `acc` and a tap `v`, as tract folds them: `v` replaces `acc` only when
/// strictly greater (compiles to one `max` instruction, whose operand order is this rule).
#[inline(always)]
fn fold(acc: f32, v: f32) -> f32 {
    if acc < v { v } else { acc }
}

/// One plane: `plane` (`H x W`) into `out` (`OH x OW`), with `scratch` of at least
/// [`PoolWindow::scratch_len`] values. Returns false, writing nothing, when a slice is shorter
/// than the window says.
pub fn max_pool_plane(
    window: &PoolWindow,
    plane: &[f32],
    out: &mut [f32],
    scratch: &mut [f32],
) -> bool {
    let [h, w] = window.input;
    let [kh, kw] = window.kernel;
    let [sy, sx] = window.strides;
    let [dy, dx] = window.dilations;
    let [pt, pl] = window.pad_before;
    let [oh, ow] = window.output;
    if plane.len() < h * w
        || out.len() < oh * ow
        || scratch.len() < window.scratch_len()
        || sx == 0
        || sy == 0
    {
        return false;
    }
    if oh == 0 || ow == 0 {
        return true;
    }
    let (rows, full) = scratch.split_at_mut(h * ow);
    let full = &mut full[..window.span()];
    for (irow, row) in plane
        .chunks_exact(w.max(1))
        .zip(rows.chunks_exact_mut(ow))
        .take(h)
    {
        full.fill(f32::MIN);
        for kx in 0..kw {
            // Input column of span column x: x + off, kept inside the row.
            let off = (kx * dx) as isize - pl as isize;
            let lo = (-off).max(0) as usize;
            let hi = (w as isize - off).clamp(0, full.len() as isize) as usize;
            if lo >= hi {
                continue;
            }
            let src = &irow[(lo as isize + off) as usize..][..hi - lo];
            for (a, &v) in full[lo..hi].iter_mut().zip(src) {
                *a = fold(*a, v);
            }
        }
        for (r, &v) in row.iter_mut().zip(full.iter().step_by(sx)) {
            *r = v;
        }
    }
    for (oy, o) in out.chunks_exact_mut(ow).enumerate().take(oh) {
        o.fill(f32::MIN);
        for ky in 0..kh {
            let iy = (oy * sy + ky * dy) as isize - pt as isize;
            if iy < 0 || iy >= h as isize {
                continue;
            }
            let r = &rows[iy as usize * ow..][..ow];
            for (a, &v) in o.iter_mut().zip(r) {
                *a = fold(*a, v);
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window rule folded tap by tap, row by row: the definition the separable passes keep.
    fn direct(window: &PoolWindow, plane: &[f32]) -> Vec<f32> {
        let [h, w] = window.input;
        let [oh, ow] = window.output;
        let mut out = vec![f32::MIN; oh * ow];
        for oy in 0..oh {
            for ox in 0..ow {
                let mut acc = f32::MIN;
                for ky in 0..window.kernel[0] {
                    for kx in 0..window.kernel[1] {
                        let iy = (oy * window.strides[0] + ky * window.dilations[0]) as isize
                            - window.pad_before[0] as isize;
                        let ix = (ox * window.strides[1] + kx * window.dilations[1]) as isize
                            - window.pad_before[1] as isize;
                        if (0..h as isize).contains(&iy) && (0..w as isize).contains(&ix) {
                            acc = fold(acc, plane[iy as usize * w + ix as usize]);
                        }
                    }
                }
                out[oy * ow + ox] = acc;
            }
        }
        out
    }

    fn output_len(input: usize, k: usize, s: usize, d: usize, pad: usize) -> usize {
        (input + 2 * pad - (d * (k - 1) + 1)) / s + 1
    }

    #[test]
    fn separable_passes_give_the_direct_fold_bit_for_bit() {
        // Signed zeros and NaNs where the first-tap rule shows.
        let specials = [0.0f32, -0.0, f32::NAN, 1.0, -1.0, f32::MIN, 3.5];
        for (k, s, d, pad) in [
            (3, 2, 1, 1),
            (3, 1, 1, 0),
            (2, 2, 1, 0),
            (3, 2, 2, 2),
            (1, 1, 1, 0),
        ] {
            let (h, w) = (9, 11);
            let window = PoolWindow {
                input: [h, w],
                kernel: [k, k],
                strides: [s, s],
                dilations: [d, d],
                pad_before: [pad, pad],
                output: [output_len(h, k, s, d, pad), output_len(w, k, s, d, pad)],
            };
            let plane: Vec<f32> = (0..h * w)
                .map(|i| specials[(i * 5 + i / 3) % specials.len()])
                .collect();
            let mut out = vec![0.0; window.output[0] * window.output[1]];
            let mut scratch = vec![0.0; window.scratch_len()];
            assert!(max_pool_plane(&window, &plane, &mut out, &mut scratch));
            let want = direct(&window, &plane);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&out), bits(&want), "{window:?}");
        }
    }

    #[test]
    fn short_slices_are_refused() {
        let window = PoolWindow {
            input: [4, 4],
            kernel: [2, 2],
            strides: [2, 2],
            dilations: [1, 1],
            pad_before: [0, 0],
            output: [2, 2],
        };
        let (plane, mut out, mut scratch) =
            (vec![0.0; 16], vec![0.0; 4], vec![0.0; window.scratch_len()]);
        assert!(!max_pool_plane(
            &window,
            &plane[..15],
            &mut out,
            &mut scratch
        ));
        assert!(!max_pool_plane(
            &window,
            &plane,
            &mut out[..3],
            &mut scratch
        ));
        assert!(!max_pool_plane(
            &window,
            &plane,
            &mut out,
            &mut scratch[..1]
        ));
        assert!(max_pool_plane(&window, &plane, &mut out, &mut scratch));
    }
}
