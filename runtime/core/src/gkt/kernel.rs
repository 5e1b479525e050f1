//! The native GKT gather-sum: `gathered[q] = (sum over participating cameras c, heads k, kernel
//! points p of w[q,k,p] * value[c][index[c,q,k,p], head k channels]) / max(1, count[q])`.
//!
//! Camera dropout: only cameras in the step's [`CameraMask`] take part; `count[q]` is then the
//! number of cameras that see `q` *and* are in the mask (the reference's `mask_cameras`), and a
//! left-out camera's value features are never read.
//!
//! Determinism: every output element sees exactly the sequence of f32 operations of the
//! contract (`acc = 0`; for c ascending, k, p ascending: `acc += w * v` as a multiply then an
//! add; finally one division), so the result is bit-identical to the numpy reference whatever
//! the vector width. The traversal is camera-major (the look-up table's order) with the
//! accumulator living in the output row; that changes which output is touched when, never the
//! order of operations on one output element. No FMA (`mul_add`) anywhere: Rust never contracts
//! `a + w * v` on its own. Nothing is allocated and the gathered tensor `[Q, 4, 15, D/4]` is
//! never formed.

use core::fmt;

use super::lut::Lut;
use crate::calibration::NUM_CAMERAS;
use crate::capacity::NUM_HEADS;
use crate::frame::CameraMask;

/// A buffer handed to [`gather_sum`] does not have the length the look-up table implies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum KernelError {
    /// `values` is not `6 * F * D` long.
    ValueLength {
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// `weights` is not `Q * 4 * kernel_points` long.
    WeightsLength {
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// `out` is not `Q * D` long.
    OutputLength {
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
}

impl fmt::Display for KernelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (what, expected, got) = match *self {
            Self::ValueLength { expected, got } => ("value", expected, got),
            Self::WeightsLength { expected, got } => ("weights", expected, got),
            Self::OutputLength { expected, got } => ("output", expected, got),
        };
        write!(
            f,
            "gather-sum {what} buffer has {got} floats, expected {expected}"
        )
    }
}

impl core::error::Error for KernelError {}

/// Run the gather-sum.
///
/// `values`: the six cameras' value features, `[6, F, D]` contiguous. `weights`: `[Q, 4, kp]`.
/// `out`: `[Q, D]`, overwritten. `cameras`: the cameras that take part ([`CameraMask::ALL`]
/// normally); the value features of the others are not read.
///
/// # Errors
/// A [`KernelError`] when a buffer length does not match the table's dimensions (nothing is
/// written then).
pub fn gather_sum(
    lut: &Lut,
    values: &[f32],
    weights: &[f32],
    out: &mut [f32],
    cameras: CameraMask,
) -> Result<(), KernelError> {
    let dims = lut.dims();
    let value_len = dims.value_len();
    if values.len() != NUM_CAMERAS * value_len {
        return Err(KernelError::ValueLength {
            expected: NUM_CAMERAS * value_len,
            got: values.len(),
        });
    }
    if weights.len() != dims.weights_len() {
        return Err(KernelError::WeightsLength {
            expected: dims.weights_len(),
            got: weights.len(),
        });
    }
    if out.len() != dims.bev_len() {
        return Err(KernelError::OutputLength {
            expected: dims.bev_len(),
            got: out.len(),
        });
    }
    // Monomorphised head widths keep the accumulator in registers; others take the generic path.
    match dims.head_dims() {
        8 => run::<8>(lut, values, weights, out, cameras),
        16 => run::<16>(lut, values, weights, out, cameras),
        32 => run::<32>(lut, values, weights, out, cameras),
        64 => run::<64>(lut, values, weights, out, cameras),
        _ => run_any(lut, values, weights, out, cameras),
    }
    finish(lut, out, cameras);
    Ok(())
}

/// Divide every row by its camera count (a division, as the contract says, not a reciprocal).
fn finish(lut: &Lut, out: &mut [f32], cameras: CameraMask) {
    let d = lut.dims().embed_dims;
    if cameras == CameraMask::ALL {
        for (row, &n) in out.chunks_exact_mut(d).zip(lut.count()) {
            divide(row, n);
        }
        return;
    }
    // Each camera's query ids ascend, so one cursor per camera counts the cameras of the mask
    // that see q, without a count buffer.
    let mut cursor = [0usize; NUM_CAMERAS];
    for (q, row) in out.chunks_exact_mut(d).enumerate() {
        let mut n = 0u8;
        for (c, at) in cursor.iter_mut().enumerate() {
            if !cameras.contains(c) {
                continue;
            }
            if lut.camera_entries(c).0.get(*at).map(|&id| usize::from(id)) == Some(q) {
                n += 1;
                *at += 1;
            }
        }
        divide(row, n);
    }
}

fn divide(row: &mut [f32], n: u8) {
    let n = f32::from(n.max(1));
    for v in row {
        *v /= n;
    }
}

#[inline(always)]
fn run_const<const HD: usize>(
    lut: &Lut,
    values: &[f32],
    weights: &[f32],
    out: &mut [f32],
    cameras: CameraMask,
) {
    let dims = lut.dims();
    let d = dims.embed_dims;
    let kp = dims.kernel_points();
    let n = lut.entry_len();
    out.fill(0.0);
    for (c, value) in values.chunks_exact(dims.value_len()).enumerate() {
        if !cameras.contains(c) {
            continue;
        }
        let (queries, indices) = lut.camera_entries(c);
        for (&q, idx) in queries.iter().zip(indices.chunks_exact(n)) {
            let q = usize::from(q);
            let w = &weights[q * n..][..n];
            let row = &mut out[q * d..][..d];
            for k in 0..NUM_HEADS {
                let Some(acc_slice) = row.get_mut(k * HD..(k + 1) * HD) else {
                    continue;
                };
                let mut acc = [0.0f32; HD];
                acc.copy_from_slice(acc_slice);
                for p in 0..kp {
                    let wv = w[k * kp + p];
                    let f = usize::from(idx[k * kp + p]);
                    let Some(v) = value.get(f * d + k * HD..f * d + (k + 1) * HD) else {
                        continue;
                    };
                    for (a, &x) in acc.iter_mut().zip(v) {
                        *a += wv * x;
                    }
                }
                acc_slice.copy_from_slice(&acc);
            }
        }
    }
}

fn run<const HD: usize>(
    lut: &Lut,
    values: &[f32],
    weights: &[f32],
    out: &mut [f32],
    cameras: CameraMask,
) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    {
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { run_avx2::<HD>(lut, values, weights, out, cameras) };
            return;
        }
    }
    run_const::<HD>(lut, values, weights, out, cameras);
}

/// The same loop compiled for AVX2 (wider vectors only: the `fma` feature is not enabled, and
/// Rust never fuses a separate multiply and add, so the bits are those of the portable path).
#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[target_feature(enable = "avx2")]
fn run_avx2<const HD: usize>(
    lut: &Lut,
    values: &[f32],
    weights: &[f32],
    out: &mut [f32],
    cameras: CameraMask,
) {
    run_const::<HD>(lut, values, weights, out, cameras);
}

fn run_any(lut: &Lut, values: &[f32], weights: &[f32], out: &mut [f32], cameras: CameraMask) {
    let dims = lut.dims();
    let (d, hd, kp, n) = (
        dims.embed_dims,
        dims.head_dims(),
        dims.kernel_points(),
        lut.entry_len(),
    );
    out.fill(0.0);
    for (c, value) in values.chunks_exact(dims.value_len()).enumerate() {
        if !cameras.contains(c) {
            continue;
        }
        let (queries, indices) = lut.camera_entries(c);
        for (&q, idx) in queries.iter().zip(indices.chunks_exact(n)) {
            let q = usize::from(q);
            let w = &weights[q * n..][..n];
            let row = &mut out[q * d..][..d];
            for k in 0..NUM_HEADS {
                for p in 0..kp {
                    let wv = w[k * kp + p];
                    let f = usize::from(idx[k * kp + p]);
                    let v = &value[f * d + k * hd..][..hd];
                    for (a, &x) in row[k * hd..][..hd].iter_mut().zip(v) {
                        *a += wv * x;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use alloc::vec;
    use alloc::vec::Vec;

    use super::*;
    use crate::model_dims::ModelDims;

    /// The contract, written as plainly as possible over the dense table: query-major.
    fn naive(lut: &Lut, values: &[f32], weights: &[f32], cameras: CameraMask) -> Vec<f32> {
        let dims = lut.dims();
        let (q_n, d, hd, kp, f_n) = (
            dims.num_queries(),
            dims.embed_dims,
            dims.head_dims(),
            dims.kernel_points(),
            dims.num_features(),
        );
        let dense = lut.to_dense();
        let mut out = vec![0.0f32; q_n * d];
        for q in 0..q_n {
            let mut acc = vec![0.0f32; d];
            for c in 0..6 {
                if dense.mask[c * q_n + q] == 0 || !cameras.contains(c) {
                    continue;
                }
                for k in 0..4 {
                    for p in 0..kp {
                        let w = weights[(q * 4 + k) * kp + p];
                        let f = dense.index[((c * q_n + q) * 4 + k) * kp + p] as usize;
                        for ch in k * hd..(k + 1) * hd {
                            let prod = w * values[(c * f_n + f) * d + ch];
                            acc[ch] += prod;
                        }
                    }
                }
            }
            let seen = (0..6)
                .filter(|&c| cameras.contains(c) && dense.mask[c * q_n + q] != 0)
                .count();
            let n = seen.max(1) as f32;
            for ch in 0..d {
                out[q * d + ch] = acc[ch] / n;
            }
        }
        out
    }

    /// Deterministic pseudo-random floats in [-1, 1) (xorshift), varied exponents.
    pub(crate) fn noise(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed | 1;
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    fn check(dims: &ModelDims) {
        let lut = Lut::new(dims, &crate::test_support::nuscenes_like()).unwrap();
        let values = noise(6 * dims.value_len(), 7);
        let weights = noise(dims.weights_len(), 11);
        let mut out = vec![f32::NAN; dims.bev_len()];
        gather_sum(&lut, &values, &weights, &mut out, CameraMask::ALL).unwrap();
        let expected = naive(&lut, &values, &weights, CameraMask::ALL);
        let same = out
            .iter()
            .zip(&expected)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "kernel differs from the naive contract");
        // And the portable path agrees with the dispatched one.
        let mut portable = vec![0.0f32; dims.bev_len()];
        run_any(&lut, &values, &weights, &mut portable, CameraMask::ALL);
        finish(&lut, &mut portable, CameraMask::ALL);
        assert!(
            portable
                .iter()
                .zip(&out)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }

    #[test]
    fn dropped_cameras_are_left_out_bit_identically() {
        let dims = ModelDims::test_config();
        let lut = Lut::new(&dims, &crate::test_support::nuscenes_like()).unwrap();
        let weights = noise(dims.weights_len(), 11);
        let mut full = vec![0.0f32; dims.bev_len()];
        let values = noise(6 * dims.value_len(), 7);
        gather_sum(&lut, &values, &weights, &mut full, CameraMask::ALL).unwrap();
        for c in 0..6 {
            let cameras = CameraMask::ALL.without(c);
            // The dropped camera's features are never read: NaN there changes nothing.
            let mut values = values.clone();
            values[c * dims.value_len()..][..dims.value_len()].fill(f32::NAN);
            let mut out = vec![0.0f32; dims.bev_len()];
            gather_sum(&lut, &values, &weights, &mut out, cameras).unwrap();
            let expected = naive(&lut, &values, &weights, cameras);
            assert!(
                out.iter()
                    .zip(&expected)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "camera {c} dropped: kernel differs from the naive contract"
            );
            assert_ne!(out, full, "dropping camera {c} changed nothing");
            let mut portable = vec![0.0f32; dims.bev_len()];
            run_any(&lut, &values, &weights, &mut portable, cameras);
            finish(&lut, &mut portable, cameras);
            assert!(
                portable
                    .iter()
                    .zip(&out)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
        // Only the front camera: the monocular configuration.
        let mut out = vec![0.0f32; dims.bev_len()];
        gather_sum(&lut, &values, &weights, &mut out, CameraMask::only(0)).unwrap();
        let expected = naive(&lut, &values, &weights, CameraMask::only(0));
        assert!(
            out.iter()
                .zip(&expected)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }

    #[test]
    fn bit_identical_to_naive_test_shapes() {
        check(&ModelDims::test_config());
    }

    #[test]
    fn bit_identical_to_naive_paper_shapes() {
        check(&ModelDims::paper_config());
    }

    #[test]
    fn bit_identical_to_naive_odd_head_width() {
        // D = 40: head width 10 takes the generic path.
        let dims = ModelDims {
            embed_dims: 40,
            ..ModelDims::test_config()
        };
        check(&dims);
    }

    #[test]
    fn unseen_queries_are_zero_and_lengths_are_checked() {
        let dims = ModelDims::test_config();
        let lut = Lut::new(&dims, &crate::test_support::nuscenes_like()).unwrap();
        let values = noise(6 * dims.value_len(), 3);
        let weights = noise(dims.weights_len(), 5);
        let mut out = vec![1.0f32; dims.bev_len()];
        gather_sum(&lut, &values, &weights, &mut out, CameraMask::ALL).unwrap();
        let d = dims.embed_dims;
        for (q, &n) in lut.count().iter().enumerate() {
            if n == 0 {
                assert!(out[q * d..][..d].iter().all(|&v| v == 0.0));
            }
        }
        assert_eq!(
            gather_sum(&lut, &values[1..], &weights, &mut out, CameraMask::ALL),
            Err(KernelError::ValueLength {
                expected: values.len(),
                got: values.len() - 1
            })
        );
        assert!(matches!(
            gather_sum(&lut, &values, &weights[1..], &mut out, CameraMask::ALL),
            Err(KernelError::WeightsLength { .. })
        ));
        assert!(matches!(
            gather_sum(&lut, &values, &weights, &mut out[1..], CameraMask::ALL),
            Err(KernelError::OutputLength { .. })
        ));
    }
}
