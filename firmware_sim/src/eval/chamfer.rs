//! Geometry of the metric: arc-length resampling and the two-sided mean chamfer distance
//! (`SATMAP_SPEC.md`, "Metric"; MapTR `mean_ap.py` `get_cls_results` and `tpfp_chamfer.py`).
//! All float64, ego metres. The buffer pre-test is `eval::buffer`.

/// Points every polyline is resampled to before it is compared.
pub const RESAMPLE_POINTS: usize = 100;

/// Resample a polyline to `n` points equally spaced by arc length, first and last points kept
/// (shapely `interpolate` at `linspace(0, length, n)`). `None` when the polyline has fewer than
/// 2 points or `n < 2`. A polyline of zero length gives `n` copies of its first point.
#[must_use]
pub fn resample_by_arc_length(points_m: &[[f64; 2]], n: usize) -> Option<Vec<[f64; 2]>> {
    if points_m.len() < 2 || n < 2 {
        return None;
    }
    let mut cumulative_m = Vec::with_capacity(points_m.len());
    let mut total_m = 0.0;
    cumulative_m.push(0.0);
    for w in points_m.windows(2) {
        total_m += distance_m(w[0], w[1]);
        cumulative_m.push(total_m);
    }
    let mut out = Vec::with_capacity(n);
    let mut segment = 0usize;
    for k in 0..n {
        // shapely's `interpolate` at the full length returns the last vertex itself; keeping it
        // bit-exact keeps a closed ring closed (the buffer treats rings apart).
        if k + 1 == n {
            out.push(points_m[points_m.len() - 1]);
            break;
        }
        let target_m = total_m * k as f64 / (n - 1) as f64;
        while segment + 2 < points_m.len() && cumulative_m[segment + 1] < target_m {
            segment += 1;
        }
        let (a, b) = (points_m[segment], points_m[segment + 1]);
        let length_m = cumulative_m[segment + 1] - cumulative_m[segment];
        let t = if length_m > 0.0 {
            ((target_m - cumulative_m[segment]) / length_m).clamp(0.0, 1.0)
        } else {
            0.0
        };
        out.push([a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]);
    }
    Some(out)
}

/// Two-sided mean chamfer distance: `(mean_i min_j |a_i - b_j| + mean_j min_i |a_i - b_j|) / 2`.
/// Infinite when either side is empty.
#[must_use]
pub fn chamfer_distance_m(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    let mut min_a = vec![f64::INFINITY; a.len()];
    let mut min_b = vec![f64::INFINITY; b.len()];
    for (i, &p) in a.iter().enumerate() {
        for (j, &q) in b.iter().enumerate() {
            let d = distance_m(p, q);
            if d < min_a[i] {
                min_a[i] = d;
            }
            if d < min_b[j] {
                min_b[j] = d;
            }
        }
    }
    let mean_a = min_a.iter().sum::<f64>() / a.len() as f64;
    let mean_b = min_b.iter().sum::<f64>() / b.len() as f64;
    (mean_a + mean_b) / 2.0
}

fn distance_m(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resample_keeps_ends_and_spacing() {
        let r = resample_by_arc_length(&[[0.0, 0.0], [3.0, 0.0], [3.0, 6.0]], 4).unwrap();
        assert_eq!(r, vec![[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [3.0, 6.0]]);
    }

    #[test]
    fn single_point_is_skipped() {
        assert!(resample_by_arc_length(&[[1.0, 2.0]], 100).is_none());
    }

    #[test]
    fn closed_ring_stays_exactly_closed() {
        // Interpolating the closing edge at t = 1 gives -10 + (-3.9 + 10) = -3.9000000000000004
        // in f64: the end must be the vertex itself.
        let ring = [
            [-3.9, 0.0],
            [5.0, 0.0],
            [5.0, 5.0],
            [-10.0, 5.0],
            [-3.9, 0.0],
        ];
        let r = resample_by_arc_length(&ring, 100).unwrap();
        assert_eq!(r[0], r[99]);
        assert_eq!(r.len(), 100);
    }

    #[test]
    fn parallel_shift_gives_shift_distance() {
        let a = resample_by_arc_length(&[[0.0, 0.0], [0.0, 10.0]], 100).unwrap();
        let b = resample_by_arc_length(&[[0.75, 0.0], [0.75, 10.0]], 100).unwrap();
        assert!((chamfer_distance_m(&a, &b) - 0.75).abs() < 1e-12);
    }
}
