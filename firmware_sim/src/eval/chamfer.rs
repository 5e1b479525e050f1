//! Geometry of the metric: arc-length resampling, the two-sided mean chamfer distance and the
//! 2.0 m buffer pre-filter of MapTR (`SATMAP_SPEC.md`, "Metric"). All float64, ego metres.

/// Points every polyline is resampled to before it is compared.
pub const RESAMPLE_POINTS: usize = 100;

/// Buffer radius MapTR puts around both polylines before it computes a distance, metres.
pub const BUFFER_RADIUS_M: f64 = 2.0;

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
        // linspace: the last target is exactly the total length.
        let target_m = if k + 1 == n {
            total_m
        } else {
            total_m * k as f64 / (n - 1) as f64
        };
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

/// True when the `BUFFER_RADIUS_M` buffers of the two polylines intersect, i.e. when the
/// minimum distance between them is at most twice the radius.
///
/// MapTR tests shapely buffer polygons (round joins approximated by 16 segments per quarter);
/// we use the exact segment-to-segment distance, which differs from shapely only by that
/// polygon approximation (under 1 cm at 2 m). Since the chamfer distance is a mean of
/// nearest-point distances, it is never below the minimum distance, so for thresholds at most
/// 4 m the filter only saves work and never changes a match.
#[must_use]
pub fn buffers_intersect(a: &[[f64; 2]], b: &[[f64; 2]]) -> bool {
    let reach_m = 2.0 * BUFFER_RADIUS_M;
    let (a_min, a_max) = bounding_box(a);
    let (b_min, b_max) = bounding_box(b);
    if a_min[0] - reach_m > b_max[0]
        || b_min[0] - reach_m > a_max[0]
        || a_min[1] - reach_m > b_max[1]
        || b_min[1] - reach_m > a_max[1]
    {
        return false;
    }
    polyline_distance_m(a, b) <= reach_m
}

/// Minimum distance between two polylines (a single point counts as a degenerate segment).
#[must_use]
pub fn polyline_distance_m(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    let segments = |p: &[[f64; 2]]| -> Vec<([f64; 2], [f64; 2])> {
        if p.len() == 1 {
            vec![(p[0], p[0])]
        } else {
            p.windows(2).map(|w| (w[0], w[1])).collect()
        }
    };
    let (sa, sb) = (segments(a), segments(b));
    let mut best = f64::INFINITY;
    for &(p0, p1) in &sa {
        for &(q0, q1) in &sb {
            best = best.min(segment_distance_m(p0, p1, q0, q1));
        }
    }
    best
}

fn segment_distance_m(p0: [f64; 2], p1: [f64; 2], q0: [f64; 2], q1: [f64; 2]) -> f64 {
    if segments_cross(p0, p1, q0, q1) {
        return 0.0;
    }
    point_segment_distance_m(p0, q0, q1)
        .min(point_segment_distance_m(p1, q0, q1))
        .min(point_segment_distance_m(q0, p0, p1))
        .min(point_segment_distance_m(q1, p0, p1))
}

fn segments_cross(p0: [f64; 2], p1: [f64; 2], q0: [f64; 2], q1: [f64; 2]) -> bool {
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let d1 = orient(q0, q1, p0);
    let d2 = orient(q0, q1, p1);
    let d3 = orient(p0, p1, q0);
    let d4 = orient(p0, p1, q1);
    // Touching and collinear cases are caught by the endpoint distances (they give 0).
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

fn point_segment_distance_m(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    distance_m(p, [a[0] + ab[0] * t, a[1] + ab[1] * t])
}

fn bounding_box(p: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for q in p {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    (lo, hi)
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
    fn parallel_shift_gives_shift_distance() {
        let a = resample_by_arc_length(&[[0.0, 0.0], [0.0, 10.0]], 100).unwrap();
        let b = resample_by_arc_length(&[[0.75, 0.0], [0.75, 10.0]], 100).unwrap();
        assert!((chamfer_distance_m(&a, &b) - 0.75).abs() < 1e-12);
    }

    #[test]
    fn buffers_meet_at_four_metres() {
        let a = [[0.0, 0.0], [0.0, 10.0]];
        assert!(buffers_intersect(&a, &[[4.0, 0.0], [4.0, 10.0]]));
        assert!(!buffers_intersect(&a, &[[4.01, 0.0], [4.01, 10.0]]));
        assert!(buffers_intersect(&a, &[[-5.0, 5.0], [5.0, 5.0]]));
    }
}
