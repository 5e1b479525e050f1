//! Symmetric int8 quantisation, the product's operands' form: weights per output column,
//! activations per tensor (one scale from calibration), both with zero point 0 and the range
//! `[-127, 127]`, so a product needs no zero-point term and `-128` never occurs (its square
//! would be the only one that is not `<= 127^2`).
//!
//! The bits: `q = round_half_even(clamp(x * inv_scale, -127, 127))` with `inv_scale = 1 /
//! scale` in f32, rounded by adding and subtracting `1.5 * 2^23` (exact for `|v| <= 127`, no
//! library call, the same on every instruction set); a NaN becomes 0. Every tier's build of
//! [`activations`] computes these IEEE operations in this order, so every tier gives these bits.

use super::padded_k;

/// The largest magnitude of a quantised value.
pub const Q_MAX: f32 = 127.0;

/// `1.5 * 2^23`: added and subtracted, rounds an f32 of magnitude below `2^22` to an integer,
/// halves to even.
const ROUNDER: f32 = 12_582_912.0;

/// One value's quantisation (the definition every build of [`activations`] computes).
#[inline(always)]
#[must_use]
pub fn quantize(x: f32, inv_scale: f32) -> i8 {
    let v = x * inv_scale;
    // Branch-free selects, so the compiler vectorises the loop: NaN to 0, then the clamp.
    let v = if v.is_nan() { 0.0 } else { v };
    let v = if v < -Q_MAX { -Q_MAX } else { v };
    let v = if v > Q_MAX { Q_MAX } else { v };
    let r = (v + ROUNDER) - ROUNDER;
    // SAFETY: `r` is an integer in [-127, 127] (finite, not NaN: selected above).
    unsafe { r.to_int_unchecked::<i32>() as i8 }
}

/// The scale a symmetric range `[-abs_max, abs_max]` maps onto `[-127, 127]` with (1 for an
/// all-zero or non-finite range, so that no scale is 0 or NaN).
#[must_use]
pub fn scale_for(abs_max: f32) -> f32 {
    if abs_max.is_finite() && abs_max > 0.0 {
        abs_max / Q_MAX
    } else {
        1.0
    }
}

/// Weights `w [k][n]` (row-major f32) as int8 with one scale per column: `(q, scales)`,
/// `w[k][c] ~= q[k][c] * scales[c]`. Weights that are already int8 times a per-column scale
/// (an int8 bundle's) come back as exactly those int8 values.
#[must_use]
pub fn weights_per_column(w: &[f32], k: usize, n: usize) -> (Vec<i8>, Vec<f32>) {
    let mut abs_max = vec![0.0f32; n];
    for row in w.chunks_exact(n.max(1)).take(k) {
        for (m, &v) in abs_max.iter_mut().zip(row) {
            *m = m.max(v.abs());
        }
    }
    let scales: Vec<f32> = abs_max.iter().map(|&m| scale_for(m)).collect();
    let mut q = vec![0i8; k * n];
    for (qrow, row) in q.chunks_exact_mut(n.max(1)).zip(w.chunks_exact(n.max(1))) {
        for ((o, &v), &s) in qrow.iter_mut().zip(row).zip(&scales) {
            // The division, not a reciprocal: an int8 bundle's `q * s` divided by `s` is `q`
            // again.
            *o = quantize(v / s, 1.0);
        }
    }
    (q, scales)
}

/// The largest `|x|` of `x` (NaN ignored): a calibration's observation of one tensor.
#[must_use]
pub fn abs_max(x: &[f32]) -> f32 {
    x.iter().fold(0.0f32, |m, v| m.max(v.abs()))
}

/// Rows of `x` (`rows x k`, row-major) quantised with `inv_scale` into `out`, row `r` at
/// `r * padded_k(k)`, the padding zeroed. Returns `false` (nothing written) when a slice is
/// shorter than the sizes.
pub fn activations(x: &[f32], rows: usize, k: usize, inv_scale: f32, out: &mut [i8]) -> bool {
    let kp = padded_k(k);
    if x.len() < rows * k || out.len() < rows * kp {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512bw") {
        // SAFETY: the features are present; the body only indexes checked slices.
        unsafe { activations_avx512(x, rows, k, inv_scale, out) };
        return true;
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is present; the body only indexes checked slices.
        unsafe { activations_avx2(x, rows, k, inv_scale, out) };
        return true;
    }
    activations_body(x, rows, k, inv_scale, out);
    true
}

/// The loop, inlined into each build so the compiler vectorises it for that build's vectors.
#[inline(always)]
fn activations_body(x: &[f32], rows: usize, k: usize, inv_scale: f32, out: &mut [i8]) {
    let kp = padded_k(k);
    for (xr, or) in x
        .chunks_exact(k.max(1))
        .zip(out.chunks_exact_mut(kp.max(1)))
        .take(rows)
    {
        for (o, &v) in or.iter_mut().zip(xr) {
            *o = quantize(v, inv_scale);
        }
        or[k..].fill(0);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw")]
fn activations_avx512(x: &[f32], rows: usize, k: usize, inv_scale: f32, out: &mut [i8]) {
    activations_body(x, rows, k, inv_scale, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn activations_avx2(x: &[f32], rows: usize, k: usize, inv_scale: f32, out: &mut [i8]) {
    activations_body(x, rows, k, inv_scale, out);
}

/// `x` (`[C, H, W]` f32, channel-first) quantised with `inv_scale` into four-channel values
/// (`ceil(C / 4)` planes of `H x W`; value `(c4, y, x)` holds channels `4 * c4 .. 4 * c4 + 4` at
/// the pixel, channel `4 * c4 + j` in byte `j`, zeros past `C`): the channel-first product's
/// patches are gathered from this map (`channel_product`). Each byte is [`quantize`]'s. Returns
/// `false` (nothing written) when `x` or `out` is shorter than the shape needs.
#[must_use]
pub fn quads(x: &[f32], shape: [usize; 3], inv_scale: f32, out: &mut [u32]) -> bool {
    let [c, h, w] = shape;
    if x.len() < c * h * w || out.len() < c.div_ceil(4) * h * w {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512bw") {
        // SAFETY: the features are present; the body only indexes checked slices.
        unsafe { quads_avx512(x, shape, inv_scale, out) };
        return true;
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is present; the body only indexes checked slices.
        unsafe { quads_avx2(x, shape, inv_scale, out) };
        return true;
    }
    quads_body(x, shape, inv_scale, out);
    true
}

/// The loop of [`quads`], inlined into each build. A whole group of four channels is one zipped
/// pass over four equal slices (vectorised); only a ragged last group takes the per-value path.
#[inline(always)]
fn quads_body(x: &[f32], [c, h, w]: [usize; 3], inv_scale: f32, out: &mut [u32]) {
    let plane = h * w;
    let q = |v: f32| u32::from(quantize(v, inv_scale) as u8);
    for (c4, dst) in out
        .chunks_exact_mut(plane.max(1))
        .take(c.div_ceil(4))
        .enumerate()
    {
        if 4 * c4 + 4 <= c
            && let Some(group) = x.get(4 * c4 * plane..(4 * c4 + 4) * plane)
        {
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

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw")]
fn quads_avx512(x: &[f32], shape: [usize; 3], inv_scale: f32, out: &mut [u32]) {
    quads_body(x, shape, inv_scale, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn quads_avx2(x: &[f32], shape: [usize; 3], inv_scale: f32, out: &mut [u32]) {
    quads_body(x, shape, inv_scale, out);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_is_half_even_and_clamped() {
        let cases = [
            (0.5, 0),
            (1.5, 2),
            (2.5, 2),
            (-0.5, 0),
            (-1.5, -2),
            (126.6, 127),
            (300.0, 127),
            (-300.0, -127),
            (f32::INFINITY, 127),
            (f32::NEG_INFINITY, -127),
            (f32::NAN, 0),
        ];
        for (x, q) in cases {
            assert_eq!(quantize(x, 1.0), q, "{x}");
        }
    }

    #[test]
    fn int8_weights_times_scales_come_back_exactly() {
        let (k, n) = (7, 5);
        let mut q: Vec<i8> = (0..k * n)
            .map(|i| ((i * 37 % 255) as i32 - 127) as i8)
            .collect();
        // Each column reaches +-127, as a per-column symmetric quantiser's output does.
        for c in 0..n {
            q[3 * n + c] = if c % 2 == 0 { 127 } else { -127 };
        }
        let s = [0.013f32, 0.5, 1e-4, 3.0, 0.0071];
        let w: Vec<f32> = (0..k * n).map(|i| f32::from(q[i]) * s[i % n]).collect();
        let (back, scales) = weights_per_column(&w, k, n);
        assert_eq!(back, q);
        for c in 0..n {
            assert!((scales[c] - s[c]).abs() <= s[c] * 1e-6, "column {c}");
        }
    }

    #[test]
    fn activations_pad_rows_and_match_the_scalar_definition() {
        let (rows, k) = (3, 7);
        let x: Vec<f32> = (0..rows * k).map(|i| (i as f32 - 10.0) * 0.37).collect();
        let mut out = vec![99i8; rows * padded_k(k)];
        assert!(activations(&x, rows, k, 1.0 / 0.05, &mut out));
        for r in 0..rows {
            for kk in 0..padded_k(k) {
                let want = if kk < k {
                    quantize(x[r * k + kk], 1.0 / 0.05)
                } else {
                    0
                };
                assert_eq!(out[r * padded_k(k) + kk], want);
            }
        }
        assert!(!activations(&x, rows + 1, k, 1.0, &mut out));
    }

    #[test]
    fn zero_and_non_finite_ranges_get_scale_one() {
        assert_eq!(scale_for(0.0), 1.0);
        assert_eq!(scale_for(f32::NAN), 1.0);
        assert_eq!(scale_for(f32::INFINITY), 1.0);
        assert_eq!(scale_for(127.0), 1.0);
    }

    /// Both paths (whole groups of four channels, a ragged last group) put each channel's
    /// [`quantize`] byte at its place, zeros past `C`, for channel counts 1..=9, with NaN and
    /// out-of-range values among them; short slices are refused with nothing written.
    #[test]
    fn quads_put_every_channel_in_its_byte() {
        let (h, w) = (3, 5);
        let plane = h * w;
        for c in 1usize..=9 {
            let mut x: Vec<f32> = (0..c * plane)
                .map(|i| (i as f32 * 0.37).sin() * 2.5)
                .collect();
            x[0] = f32::NAN;
            let inv_scale = 127.0 / 2.0;
            let mut out = vec![u32::MAX; c.div_ceil(4) * plane];
            assert!(quads(&x, [c, h, w], inv_scale, &mut out));
            for (i, &v) in out.iter().enumerate() {
                let (c4, p) = (i / plane, i % plane);
                for (j, byte) in v.to_le_bytes().into_iter().enumerate() {
                    let ch = 4 * c4 + j;
                    let want = if ch < c {
                        quantize(x[ch * plane + p], inv_scale) as u8
                    } else {
                        0
                    };
                    assert_eq!(byte, want, "c {c}, channel {ch}, pixel {p}");
                }
            }
        }
        let mut out = vec![7u32; plane];
        assert!(!quads(&[0.0; 10], [4, h, w], 1.0, &mut out)); // x short
        assert!(!quads(&[0.0; 75], [5, h, w], 1.0, &mut out)); // out short (2 planes needed)
        assert!(out.iter().all(|&v| v == 7));
    }

    /// Every build of the quad loop this CPU can run (the dispatcher runs only the widest) gives
    /// the portable body's values; a build the CPU lacks is skipped and says so.
    #[test]
    fn every_quads_build_gives_the_portable_values() {
        let (c, h, w) = (7usize, 5, 9);
        let x: Vec<f32> = (0..c * h * w)
            .map(|i| (i as f32 * 0.91).cos() * 3.0)
            .collect();
        let want = {
            let mut out = vec![0u32; c.div_ceil(4) * h * w];
            quads_body(&x, [c, h, w], 127.0 / 2.5, &mut out);
            out
        };
        #[cfg(target_arch = "x86_64")]
        {
            type Build = unsafe fn(&[f32], [usize; 3], f32, &mut [u32]);
            let builds: [(&str, bool, Build); 2] = [
                (
                    "avx512",
                    std::is_x86_feature_detected!("avx512f")
                        && std::is_x86_feature_detected!("avx512bw"),
                    quads_avx512,
                ),
                ("avx2", std::is_x86_feature_detected!("avx2"), quads_avx2),
            ];
            for (name, present, build) in builds {
                if !present {
                    println!("quads build {name}: skipped, not on this CPU");
                    continue;
                }
                let mut out = vec![u32::MAX; want.len()];
                // SAFETY: the build's features were detected just above.
                unsafe { build(&x, [c, h, w], 127.0 / 2.5, &mut out) };
                assert_eq!(out, want, "{name}");
            }
        }
        let mut out = vec![u32::MAX; want.len()];
        assert!(quads(&x, [c, h, w], 127.0 / 2.5, &mut out));
        assert_eq!(out, want);
    }
}
