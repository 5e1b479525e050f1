//! The MapTR JSON harness: results and ground-truth files in all three layouts (ours keyed by
//! token, MapTR's two list layouts) through `read_file`, then an evaluation with the file as
//! predictions and as ground truth.

use std::path::Path;

use proptest::prelude::*;
use satmap_sim::eval::{MapVector, ResultsFile, SampleSet, evaluate, read_file, write_maptr_pair};
use satmap_sim::synth::scenario::frame_dir_name;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz, work_dir};
use crate::seeds::seed_drive;

fn maptr_case(input: &Input, file: &Path, gt: &SampleSet, predictions: &SampleSet) -> CaseResult {
    std::fs::write(file, &input.bytes).unwrap();
    let Ok(loaded) = read_file(file) else {
        return Ok(Refused);
    };
    // `satmap-sim evaluate` next: the file as predictions, and as ground truth.
    for report in [
        evaluate(&loaded.samples, gt),
        evaluate(predictions, &loaded.samples),
    ] {
        for class in &report.classes {
            for ap in &class.ap_per_threshold {
                prop_assert!((0.0..=1.0).contains(ap), "AP {ap} outside [0, 1]");
            }
        }
        prop_assert!(
            (0.0..=1.0).contains(&report.mean_ap),
            "mAP {}",
            report.mean_ap
        );
    }
    Ok(Accepted)
}

#[test]
fn maptr_json_never_panics() {
    let tmp = work_dir("maptr");
    let dir = tmp.path();
    // One sample: the cost of a case grows with the evaluation behind the reader.
    let first = seed_drive().frame(0).ground_truth;
    assert!(!first.is_empty(), "the seed frame needs ground truth");
    let gt = SampleSet::from([(frame_dir_name(0), first)]);
    // Predictions: the ground truth moved 0.3 m with falling scores, so matches are partial.
    let predictions: SampleSet = gt
        .iter()
        .map(|(token, vs)| {
            let moved = vs
                .iter()
                .enumerate()
                .map(|(i, v)| MapVector {
                    points_m: v.points_m.iter().map(|[x, y]| [x + 0.3, *y]).collect(),
                    score: 0.9 - 0.05 * i as f64,
                    ..v.clone()
                })
                .collect();
            (token.clone(), moved)
        })
        .collect();
    let keyed_gt = dir.join("keyed_gt.json");
    let keyed_pred = dir.join("keyed_pred.json");
    let (maptr_pred, maptr_gt) = (dir.join("nuscmap_results.json"), dir.join("map_anns.json"));
    ResultsFile::from_samples(&gt, serde_json::Value::Null, false)
        .write(&keyed_gt)
        .unwrap();
    ResultsFile::from_samples(&predictions, serde_json::json!({"use_camera": true}), true)
        .write(&keyed_pred)
        .unwrap();
    write_maptr_pair(
        &predictions,
        &gt,
        serde_json::Value::Null,
        &maptr_pred,
        &maptr_gt,
    )
    .unwrap();
    let seeds: Vec<Vec<u8>> = [&keyed_gt, &keyed_pred, &maptr_pred, &maptr_gt]
        .iter()
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    let file = dir.join("case.json");
    let body = |input: &Input| maptr_case(input, &file, &gt, &predictions);
    assert_seeds_accepted(&seeds, body);
    fuzz("maptr_json", inputs(seeds, true), body);
}
