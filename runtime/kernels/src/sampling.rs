//! The deformable samplers' kernels, in a fixed summation order: the weighted corner sum over
//! one middle axis ([`weighted_axis_sum`], the engine's `WeightedAxisSum`) and the whole
//! bilinear sampler from the sampling coordinates ([`bilinear_corner_sums`], the engine's
//! `BilinearCornerSum`). Both are the Python reference's bits (`satmap_ref.sampling`, checked
//! by the engine's tests on the committed kernel goldens). Portable Rust, one implementation:
//! each output is a chain of f32 multiply-adds in a fixed order that any vector width keeps.

/// How one operand of [`weighted_axis_sum`] is read: its offset for outer block `o`, summed
/// index `k`, inner index `i` is `(o * k_len + k) * inner_len + i`, with `i` dropped when the
/// operand is broadcast over the inner dims (`inner_len == 1`).
#[derive(Clone, Copy, Debug)]
pub struct Operand<'a> {
    /// The values.
    pub data: &'a [f32],
    /// Values a row holds: the inner length, or 1 for an operand broadcast over it.
    pub inner_len: usize,
    /// For a gathered operand: the data row of each `(o, k)` row (checked in range by the
    /// caller; [`weighted_axis_sum`] checks again and refuses an operand that is not).
    pub rows: Option<&'a [i64]>,
}

impl Operand<'_> {
    /// Row `r`, or `None` beyond the data.
    fn row(&self, r: usize) -> Option<&[f32]> {
        let start = match self.rows {
            Some(rows) => usize::try_from(*rows.get(r)?)
                .ok()?
                .checked_mul(self.inner_len)?,
            None => r.checked_mul(self.inner_len)?,
        };
        self.data.get(start..)?.get(..self.inner_len)
    }
}

/// `out[o, i] = sum_k a[o, k, i] * b[o, k, i]`, `k` ascending from `out`'s zeros: each
/// product rounded, then added (no fused multiply-add, as the reference). `out` holds
/// `outer x inner` values. Returns false (with `out` partly written) when an operand row lies
/// beyond its data or has neither `inner` values nor one.
pub fn weighted_axis_sum(
    a: &Operand<'_>,
    b: &Operand<'_>,
    k_len: usize,
    inner: usize,
    out: &mut [f32],
) -> bool {
    if inner == 0 {
        return true;
    }
    for (o, acc) in out.chunks_exact_mut(inner).enumerate() {
        for k in 0..k_len {
            let row = o * k_len + k;
            let (Some(ra), Some(rb)) = (a.row(row), b.row(row)) else {
                return false;
            };
            match (ra.len() == inner, rb.len() == inner) {
                (true, true) => {
                    for ((s, x), y) in acc.iter_mut().zip(ra).zip(rb) {
                        *s += *x * *y;
                    }
                }
                (true, false) if rb.len() == 1 => {
                    let y = rb[0];
                    for (s, x) in acc.iter_mut().zip(ra) {
                        *s += *x * y;
                    }
                }
                (false, true) if ra.len() == 1 => {
                    let x = ra[0];
                    for (s, y) in acc.iter_mut().zip(rb) {
                        *s += x * *y;
                    }
                }
                (false, false) if ra.len() == 1 && rb.len() == 1 => {
                    let p = ra[0] * rb[0];
                    for s in acc.iter_mut() {
                        *s += p;
                    }
                }
                _ => return false,
            }
        }
    }
    true
}

/// The map a bilinear sampler reads: `heads` planes of `h x w` rows of `dh` values, one after
/// the other (`[heads * h * w, dh]`).
#[derive(Clone, Copy, Debug)]
pub struct SampledMap<'a> {
    /// `heads * h * w * dh` values.
    pub data: &'a [f32],
    /// Plane rows (y), at least 1.
    pub h: usize,
    /// Plane columns (x), at least 1.
    pub w: usize,
    /// Values a map row holds (a head's channels).
    pub dh: usize,
}

/// The sampling points of a block of queries: for query `q`, head `j`, point `p`, the value at
/// `(q * heads + j) * points + p` of each slice.
#[derive(Clone, Copy, Debug)]
pub struct SamplePoints<'a> {
    /// x, in map columns (pixel centres at integers).
    pub x: &'a [f32],
    /// y, in map rows.
    pub y: &'a [f32],
    /// The attention weight of each point.
    pub attention: &'a [f32],
    /// Heads a query has.
    pub heads: usize,
    /// Points a head samples.
    pub points: usize,
}

/// A sample fell outside the map: only when the inputs disagree with their shapes (a clamped
/// corner is always inside a map of the stated size).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleOutOfRange {
    /// The map row the sample addressed.
    pub row: i64,
    /// Rows the map has.
    pub rows: usize,
}

/// Bilinear corner sums of queries `first_query..` into `out` (`dh` values per query and head,
/// as many whole queries as `out` holds): per head, for each corner (x0 y0, x1 y0, x0 y1,
/// x1 y1) and each point in order, `acc += map[row] * ((wx * wy) * attention)`, the weight zero
/// for a corner outside the plane (whose row is clamped inside). `corners` is scratch of at
/// least `points` entries.
///
/// # Errors
/// [`SampleOutOfRange`] when a sample row is outside the map, or a slice is shorter than the
/// shapes say (reported as the row that could not be read).
pub fn bilinear_corner_sums(
    map: &SampledMap<'_>,
    samples: &SamplePoints<'_>,
    first_query: usize,
    out: &mut [f32],
    corners: &mut [[f32; 9]],
) -> Result<(), SampleOutOfRange> {
    let (heads, points, dh) = (samples.heads, samples.points, map.dh);
    let rows = heads * map.h * map.w;
    let query_len = heads * dh;
    if query_len == 0 || map.h == 0 || map.w == 0 {
        return Ok(());
    }
    let corners = corners
        .get_mut(..points)
        .ok_or(SampleOutOfRange { row: -1, rows })?;
    let wf = map.w as f32;
    let (w_max, h_max) = ((map.w - 1) as f32, (map.h - 1) as f32);
    let plane = (map.h * map.w) as f32;
    for (i, acc_q) in out.chunks_exact_mut(query_len).enumerate() {
        let q = first_query + i;
        for (head, acc) in acc_q.chunks_exact_mut(dh).enumerate() {
            let base = (q * heads + head) * points;
            let head_off = head as f32 * plane;
            for (p, pt) in corners.iter_mut().enumerate() {
                let at = base + p;
                let (Some(&x), Some(&y), Some(&a)) = (
                    samples.x.get(at),
                    samples.y.get(at),
                    samples.attention.get(at),
                ) else {
                    return Err(SampleOutOfRange { row: -1, rows });
                };
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                *pt = [x0, x0 + 1.0, y0, y0 + 1.0, 1.0 - fx, fx, 1.0 - fy, fy, a];
            }
            for corner in 0..4 {
                let (cx, cy) = (corner & 1, corner >> 1);
                for pt in corners.iter() {
                    let (xc, yc) = (pt[cx], pt[2 + cy]);
                    let wx = if cx == 0 { pt[4] } else { pt[5] };
                    let wy = if cy == 0 { pt[6] } else { pt[7] };
                    let inside = xc >= 0.0 && xc <= w_max && yc >= 0.0 && yc <= h_max;
                    let wt = ((wx * wy) * pt[8]) * if inside { 1.0 } else { 0.0 };
                    let xi = xc.max(0.0).min(w_max);
                    let yi = yc.max(0.0).min(h_max);
                    let row = ((yi * wf + xi) + head_off) as i64;
                    let r = usize::try_from(row)
                        .ok()
                        .filter(|&r| r < rows)
                        .and_then(|r| map.data.get(r * dh..)?.get(..dh))
                        .ok_or(SampleOutOfRange { row, rows })?;
                    for (s, v) in acc.iter_mut().zip(r) {
                        *s += *v * wt;
                    }
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_weighted_sum_adds_k_in_order_in_every_layout() {
        // a [2, 3, 4] against b full, b broadcast over the inner axis, and both broadcast.
        let a: Vec<f32> = (0..24).map(|i| (i as f32 * 0.37).sin()).collect();
        let b_full: Vec<f32> = (0..24).map(|i| (i as f32 * 0.11).cos()).collect();
        let b_row: Vec<f32> = (0..6).map(|i| 1.0 + i as f32 * 0.5).collect();
        let want = |b_at: &dyn Fn(usize, usize) -> f32| -> Vec<f32> {
            let mut out = vec![0.0f32; 8];
            for o in 0..2 {
                for k in 0..3 {
                    for i in 0..4 {
                        out[o * 4 + i] += a[(o * 3 + k) * 4 + i] * b_at(o * 3 + k, i);
                    }
                }
            }
            out
        };
        let op = |data, inner_len| Operand {
            data,
            inner_len,
            rows: None,
        };
        let mut out = vec![0.0f32; 8];
        assert!(weighted_axis_sum(
            &op(&a, 4),
            &op(&b_full, 4),
            3,
            4,
            &mut out
        ));
        assert_eq!(out, want(&|r, i| b_full[r * 4 + i]));
        let mut out = vec![0.0f32; 8];
        assert!(weighted_axis_sum(
            &op(&a, 4),
            &op(&b_row, 1),
            3,
            4,
            &mut out
        ));
        assert_eq!(out, want(&|r, _| b_row[r]));
        // A gathered operand reads its rows through the indices; an index beyond is refused.
        let rows = [5i64, 4, 3, 2, 1, 0];
        let gathered = Operand {
            data: &a,
            inner_len: 4,
            rows: Some(&rows),
        };
        let mut out = vec![0.0f32; 8];
        assert!(weighted_axis_sum(&gathered, &op(&b_row, 1), 3, 4, &mut out));
        let mut expect = vec![0.0f32; 8];
        for o in 0..2 {
            for k in 0..3 {
                for i in 0..4 {
                    expect[o * 4 + i] += a[rows[o * 3 + k] as usize * 4 + i] * b_row[o * 3 + k];
                }
            }
        }
        assert_eq!(out, expect);
        let bad = [0i64, 1, 2, 3, 4, 6];
        let gathered = Operand {
            data: &a,
            inner_len: 4,
            rows: Some(&bad),
        };
        assert!(!weighted_axis_sum(
            &gathered,
            &op(&b_row, 1),
            3,
            4,
            &mut [0.0; 8]
        ));
    }

    #[test]
    fn a_sample_on_a_pixel_reads_that_pixel_and_outside_weighs_zero() {
        // 1 head, a 3 x 4 plane of dh = 2, rows holding (row, -row).
        let data: Vec<f32> = (0..12).flat_map(|r| [r as f32, -(r as f32)]).collect();
        let map = SampledMap {
            data: &data,
            h: 3,
            w: 4,
            dh: 2,
        };
        let (x, y, attn) = ([2.0f32, -5.0], [1.0f32, 1.0], [0.5f32, 1.0]);
        let samples = SamplePoints {
            x: &x,
            y: &y,
            attention: &attn,
            heads: 1,
            points: 2,
        };
        let mut out = [0.0f32; 2];
        let mut corners = [[0.0f32; 9]; 2];
        bilinear_corner_sums(&map, &samples, 0, &mut out, &mut corners).unwrap();
        // Point 0 sits on (x 2, y 1): row 6, weight 0.5; point 1 is outside: weight 0.
        assert_eq!(out, [3.0, -3.0]);
        // A query beyond the points given is refused, not read out of bounds.
        let mut two = [0.0f32; 4];
        assert!(bilinear_corner_sums(&map, &samples, 0, &mut two, &mut corners).is_err());
    }
}
