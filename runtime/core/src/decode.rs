//! Decode of the map head (NMS-free, MapTR v1): sigmoid scores, top-k over instances x classes,
//! de-normalisation of the points to ego metres.
//!
//! `score = 1 / (1 + exp(-logit))` (f32); flat index `idx = instance * 3 + label`; the `top_k`
//! highest scores in descending order, ties broken by the lower flat index; `x_m = px * (xmax -
//! xmin) + xmin`, `y_m = py * (ymax - ymin) + ymin` in f32 (a multiply, then an add).
//! No allocation: selection is an insertion into the fixed-capacity output.

use glam::Vec2;
use heapless::Vec;

use crate::capacity::{MAX_TOP_K, NUM_CLASSES, NUM_POINTS};
use crate::map_frame::{MapClass, MapElement};
use crate::model_dims::ModelDims;

/// `1 / (1 + exp(-x))` in f32.
#[must_use]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + libm::expf(-x))
}

/// Decode `logits` `[num_vec, 3]` and normalised `points` `[num_vec, num_pts, 2]` into `out`.
///
/// Requires `dims` validated (`top_k <= 50`, `num_pts == 20`) and buffers of the documented
/// lengths; shorter buffers decode only the instances they hold. Scores that are NaN rank below
/// every number (the step rejects non-finite logits before decoding).
pub fn decode(
    dims: &ModelDims,
    logits: &[f32],
    points: &[f32],
    out: &mut Vec<MapElement, MAX_TOP_K>,
) {
    out.clear();
    let top_k = dims.top_k.min(MAX_TOP_K);
    let [xmin, ymin, _, xmax, ymax, _] = dims.pc_range_m;
    let (x_span, y_span) = (xmax - xmin, ymax - ymin);
    let per_instance = dims.num_pts * 2;
    let n = logits.len().min(dims.num_vec * NUM_CLASSES);
    // (score, flat index), kept sorted: descending score, ascending index among equals.
    let mut best: Vec<(f32, usize), MAX_TOP_K> = Vec::new();
    for (idx, &logit) in logits[..n].iter().enumerate() {
        let score = sigmoid(logit);
        let score = if score.is_nan() {
            f32::NEG_INFINITY
        } else {
            score
        };
        if best.len() == top_k && best.last().is_none_or(|&(s, _)| score <= s) {
            continue;
        }
        // First slot whose score is strictly lower: equal scores keep their earlier index first.
        let at = best
            .iter()
            .position(|&(s, _)| s < score)
            .unwrap_or(best.len());
        if best.len() == top_k {
            best.pop();
        }
        // Cannot fail: one slot is free (top_k <= capacity).
        let _ = best.insert(at, (score, idx));
    }
    for &(score, idx) in &best {
        let (instance, label) = (idx / NUM_CLASSES, idx % NUM_CLASSES);
        let Some(class) = MapClass::from_label(label) else {
            continue;
        };
        let Some(pts) = points.get(instance * per_instance..(instance + 1) * per_instance) else {
            continue;
        };
        let mut points_m = [Vec2::ZERO; NUM_POINTS];
        for (p, xy) in points_m.iter_mut().zip(pts.chunks_exact(2)) {
            *p = Vec2::new(xy[0] * x_span + xmin, xy[1] * y_span + ymin);
        }
        let element = MapElement {
            class,
            score,
            instance: instance as u16,
            points_m,
        };
        // Cannot fail: best.len() <= top_k <= capacity.
        let _ = out.push(element);
    }
}

#[cfg(test)]
mod tests {
    use alloc::vec;

    use super::*;

    fn dims() -> ModelDims {
        ModelDims {
            num_vec: 4,
            top_k: 5,
            ..ModelDims::test_config()
        }
    }

    #[test]
    fn orders_by_score_with_index_tie_break() {
        let d = dims();
        // idx:          0     1    2    3    4    5    6    7    8    9    10   11
        let logits = [
            -1.0, 2.0, 0.5, 2.0, -3.0, 0.5, 1.0, 0.0, 2.0, -9.0, 0.5, 0.5,
        ];
        let points = vec![0.5f32; d.points_len()];
        let mut out = Vec::new();
        decode(&d, &logits, &points, &mut out);
        let got: alloc::vec::Vec<(u16, MapClass)> =
            out.iter().map(|e| (e.instance, e.class)).collect();
        // 2.0 at 1, 3, 8; 1.0 at 6; 0.5 at 2 (first of four ties).
        assert_eq!(
            got,
            [
                (0, MapClass::PedCrossing),
                (1, MapClass::Divider),
                (2, MapClass::Boundary),
                (2, MapClass::Divider),
                (0, MapClass::Boundary),
            ]
        );
        assert_eq!(out[0].score, sigmoid(2.0));
        assert!(out.windows(2).all(|w| w[0].score >= w[1].score));
    }

    #[test]
    fn denormalises_to_the_range() {
        let d = dims();
        let logits = [
            5.0, -5.0, -5.0, -6.0, -6.0, -6.0, -7.0, -7.0, -7.0, -8.0, -8.0, -8.0,
        ];
        let mut points = vec![0.0f32; d.points_len()];
        points[0] = 0.0;
        points[1] = 1.0;
        points[2] = 0.25;
        points[3] = 0.75;
        let mut out = Vec::new();
        decode(&d, &logits, &points, &mut out);
        assert_eq!(out.len(), 5);
        assert_eq!(out[0].points_m[0], Vec2::new(-15.0, 30.0));
        assert_eq!(
            out[0].points_m[1],
            Vec2::new(0.25 * 30.0 - 15.0, 0.75 * 60.0 - 30.0)
        );
        assert_eq!(out[0].points_m[2], Vec2::new(-15.0, -30.0));
    }

    #[test]
    fn full_size_top_k_is_a_stable_sort() {
        let d = ModelDims::test_config();
        let logits: alloc::vec::Vec<f32> = (0..d.logits_len())
            .map(|i| ((i * 37) % 11) as f32 * 0.5 - 2.0)
            .collect();
        let points = vec![0.5f32; d.points_len()];
        let mut out = Vec::new();
        decode(&d, &logits, &points, &mut out);
        let mut expected: alloc::vec::Vec<(f32, usize)> = logits
            .iter()
            .enumerate()
            .map(|(i, &l)| (sigmoid(l), i))
            .collect();
        expected.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        expected.truncate(50);
        let got: alloc::vec::Vec<(f32, usize)> = out
            .iter()
            .map(|e| (e.score, usize::from(e.instance) * 3 + e.class as usize))
            .collect();
        assert_eq!(got, expected);
    }

    #[test]
    fn nan_scores_rank_last() {
        let d = ModelDims {
            num_vec: 1,
            top_k: 3,
            ..ModelDims::test_config()
        };
        let logits = [f32::NAN, -1.0, 1.0];
        let mut out = Vec::new();
        decode(&d, &logits, &vec![0.5; d.points_len()], &mut out);
        assert_eq!(
            out.iter().map(|e| e.class).collect::<alloc::vec::Vec<_>>(),
            [MapClass::Boundary, MapClass::PedCrossing, MapClass::Divider]
        );
    }
}
