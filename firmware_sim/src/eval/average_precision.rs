//! Chamfer-AP over a set of samples: per-sample greedy matching and VOC "area" AP, exactly as
//! `SATMAP_SPEC.md` "Metric" and MapTR's code (`map_utils/tpfp.py` `custom_tpfp_gen`,
//! `map_utils/mean_ap.py` `eval_map` and `average_precision`) do it. Float64 throughout (MapTR
//! stores each AP as float32; the two differ by float32 rounding only).
//!
//! Ties in score: MapTR orders predictions with `np.argsort(-scores)` over the detections of
//! all samples stacked in the order it read them: the results file's order, its GT list paired
//! with it by position. Here both sorts (visiting order within a sample, ranking over all
//! samples) are stable by descending score: equal scores keep input order, which is the order
//! of the vectors in their sample and, across samples, [`sample_order`]: the predictions file's
//! order, then samples only the ground truth has in its order. (numpy's default sort is not
//! stable; for the tie counts of real results it keeps this order, but a numpy version may
//! differ on long runs of equal scores.) That order can change AP: an FP ranked before a TP of
//! the same score lowers it.

use indexmap::{IndexMap, IndexSet};
use serde::Serialize;

use super::buffer::LineBuffer;
use super::chamfer::{RESAMPLE_POINTS, chamfer_distance_m, resample_by_arc_length};
use super::map_vector::{MapClass, MapVector};

/// Chamfer thresholds of the protocol, metres.
pub const DEFAULT_THRESHOLDS_M: [f64; 3] = [0.5, 1.0, 1.5];

/// Distance given to a pair whose buffers do not intersect, metres: MapTR fills its score matrix
/// with -100 and scores only intersecting pairs, so such a pair is unmatched at every threshold
/// below 100 m (and, as in MapTR, matched above it).
pub const NO_OVERLAP_DISTANCE_M: f64 = 100.0;

/// Map elements of every sample, keyed by sample token, in the order they were read (a file's
/// order, or the drive's frames): the order ties in score are ranked in across samples.
pub type SampleSet = IndexMap<String, Vec<MapVector>>;

/// Every sample token of an evaluation, in ranking order: the predictions' order, then the
/// tokens only the ground truth has, in its order.
#[must_use]
pub fn sample_order<'a>(
    predictions: &'a SampleSet,
    ground_truth: &'a SampleSet,
) -> Vec<&'a String> {
    let order: IndexSet<&String> = predictions.keys().chain(ground_truth.keys()).collect();
    order.into_iter().collect()
}

/// Per-class result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClassAp {
    /// The class.
    pub class: MapClass,
    /// AP at each threshold, in the order of [`EvalReport::thresholds_m`].
    pub ap_per_threshold: Vec<f64>,
    /// Mean of `ap_per_threshold`.
    pub ap: f64,
    /// Ground-truth elements of this class over all samples (those with at least 2 points).
    pub num_gt: usize,
    /// Predictions of this class over all samples (those with at least 2 points).
    pub num_predictions: usize,
}

/// Result of an evaluation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvalReport {
    /// Thresholds used, metres.
    pub thresholds_m: Vec<f64>,
    /// One entry per class, in label order.
    pub classes: Vec<ClassAp>,
    /// Mean of the class APs (classes without ground truth count, with their AP).
    pub mean_ap: f64,
    /// Samples evaluated (union of prediction and ground-truth tokens).
    pub num_samples: usize,
}

/// Outcome of one prediction at one threshold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScoredMatch {
    /// Prediction score.
    pub score: f64,
    /// True positive at this threshold.
    pub is_tp: bool,
}

/// Evaluate `predictions` against `ground_truth` at the protocol's thresholds.
#[must_use]
pub fn evaluate(predictions: &SampleSet, ground_truth: &SampleSet) -> EvalReport {
    evaluate_at(predictions, ground_truth, &DEFAULT_THRESHOLDS_M)
}

/// Evaluate at the given thresholds (metres).
#[must_use]
pub fn evaluate_at(
    predictions: &SampleSet,
    ground_truth: &SampleSet,
    thresholds_m: &[f64],
) -> EvalReport {
    let tokens = sample_order(predictions, ground_truth);
    let classes: Vec<ClassAp> = MapClass::ALL
        .into_iter()
        .map(|class| {
            let mut per_threshold: Vec<Vec<ScoredMatch>> = vec![Vec::new(); thresholds_m.len()];
            let mut num_gt = 0usize;
            let mut num_predictions = 0usize;
            for token in &tokens {
                let preds = of_class(predictions.get(*token), class);
                let gts = of_class(ground_truth.get(*token), class);
                num_gt += gts.len();
                num_predictions += preds.len();
                let distances = distance_matrix(&preds, &gts);
                for (t, matches) in per_threshold.iter_mut().enumerate() {
                    matches.extend(match_sample(&preds, &distances, gts.len(), thresholds_m[t]));
                }
            }
            let ap_per_threshold: Vec<f64> = per_threshold
                .iter()
                .map(|m| average_precision(m, num_gt))
                .collect();
            let ap = if ap_per_threshold.is_empty() {
                0.0
            } else {
                ap_per_threshold.iter().sum::<f64>() / ap_per_threshold.len() as f64
            };
            ClassAp {
                class,
                ap_per_threshold,
                ap,
                num_gt,
                num_predictions,
            }
        })
        .collect();
    let mean_ap = classes.iter().map(|c| c.ap).sum::<f64>() / classes.len() as f64;
    EvalReport {
        thresholds_m: thresholds_m.to_vec(),
        classes,
        mean_ap,
        num_samples: tokens.len(),
    }
}

/// A resampled element: its score, its 100 points and their buffer.
#[derive(Clone, Debug)]
pub struct Resampled {
    /// Score of the element.
    pub score: f64,
    /// Points after arc-length resampling.
    pub points_m: Vec<[f64; 2]>,
    /// Buffer of the resampled points (MapTR buffers the resampled line, not the input).
    pub buffer: LineBuffer,
}

/// Elements of `class`, resampled; those with fewer than 2 points are skipped.
#[must_use]
pub fn of_class(vectors: Option<&Vec<MapVector>>, class: MapClass) -> Vec<Resampled> {
    vectors
        .map(|v| {
            v.iter()
                .filter(|e| e.class == class)
                .filter_map(|e| {
                    resample_by_arc_length(&e.points_m, RESAMPLE_POINTS).map(|points_m| Resampled {
                        score: e.score,
                        buffer: LineBuffer::of_polyline(&points_m),
                        points_m,
                    })
                })
                .collect()
        })
        .unwrap_or_default()
}

/// `distances[i][j]` = chamfer distance of prediction i to GT j, or [`NO_OVERLAP_DISTANCE_M`]
/// when their buffers do not intersect (`eval::buffer`; a zero-length line intersects nothing).
#[must_use]
pub fn distance_matrix(preds: &[Resampled], gts: &[Resampled]) -> Vec<Vec<f64>> {
    preds
        .iter()
        .map(|p| {
            gts.iter()
                .map(|g| {
                    if p.buffer.intersects(&g.buffer) {
                        chamfer_distance_m(&p.points_m, &g.points_m)
                    } else {
                        NO_OVERLAP_DISTANCE_M
                    }
                })
                .collect()
        })
        .collect()
}

/// Greedy matching in one sample and class: each prediction's best GT is its nearest (first on
/// ties, like numpy's `argmax`); predictions are visited by descending score, equal scores in
/// input order (stable; see the module doc for MapTR's order); a prediction is TP when its
/// distance is within `threshold_m` and its best GT is not yet taken, else FP (no fallback to a
/// second-best GT). With no GT every prediction is FP. Output is in the input order.
#[must_use]
pub fn match_sample(
    preds: &[Resampled],
    distances: &[Vec<f64>],
    num_gt: usize,
    threshold_m: f64,
) -> Vec<ScoredMatch> {
    let mut out: Vec<ScoredMatch> = preds
        .iter()
        .map(|p| ScoredMatch {
            score: p.score,
            is_tp: false,
        })
        .collect();
    if num_gt == 0 {
        return out;
    }
    let mut order: Vec<usize> = (0..preds.len()).collect();
    order.sort_by(|&a, &b| preds[b].score.total_cmp(&preds[a].score));
    let mut taken = vec![false; num_gt];
    for i in order {
        let mut best = 0usize;
        for j in 1..num_gt {
            if distances[i][j] < distances[i][best] {
                best = j;
            }
        }
        if distances[i][best] <= threshold_m && !taken[best] {
            taken[best] = true;
            out[i].is_tp = true;
        }
    }
    out
}

/// VOC "area" AP of scored matches pooled over samples: sort by score descending, equal scores
/// in input order (stable),
/// cumulative TP/FP, recall = tp / max(n_gt, eps), precision = tp / max(tp + fp, eps), pad
/// recall [0, r, 1] and precision [0, p, 0], running max of precision from the right, and sum
/// delta-recall * precision where recall changes.
#[must_use]
pub fn average_precision(matches: &[ScoredMatch], num_gt: usize) -> f64 {
    let eps = f64::EPSILON;
    let mut sorted = matches.to_vec();
    sorted.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut recall = Vec::with_capacity(sorted.len() + 2);
    let mut precision = Vec::with_capacity(sorted.len() + 2);
    recall.push(0.0);
    precision.push(0.0);
    let (mut tp, mut fp) = (0.0f64, 0.0f64);
    for m in &sorted {
        if m.is_tp {
            tp += 1.0;
        } else {
            fp += 1.0;
        }
        recall.push(tp / (num_gt as f64).max(eps));
        precision.push(tp / (tp + fp).max(eps));
    }
    recall.push(1.0);
    precision.push(0.0);
    for i in (1..precision.len()).rev() {
        precision[i - 1] = precision[i - 1].max(precision[i]);
    }
    let mut ap = 0.0;
    for i in 0..recall.len() - 1 {
        if recall[i + 1] != recall[i] {
            ap += (recall[i + 1] - recall[i]) * precision[i + 1];
        }
    }
    ap
}
