//! Chamfer-AP evaluator against hand-computed answers (issue 4, "Must show").

use satmap_sim::eval::{
    MapClass, MapVector, ResultsFile, SampleSet,
    average_precision::{distance_matrix, match_sample, of_class},
    evaluate, evaluate_at,
};

fn line(class: MapClass, x_m: f64, score: f64) -> MapVector {
    // A 20 m line along ego y at lateral x_m.
    MapVector {
        class,
        points_m: vec![[x_m, -10.0], [x_m, 0.0], [x_m, 10.0]],
        score,
    }
}

fn ring(x_m: f64, score: f64) -> MapVector {
    let p = vec![
        [x_m, 5.0],
        [x_m + 4.0, 5.0],
        [x_m + 4.0, 8.0],
        [x_m, 8.0],
        [x_m, 5.0],
    ];
    MapVector {
        class: MapClass::PedCrossing,
        points_m: p,
        score,
    }
}

fn one(token: &str, v: Vec<MapVector>) -> SampleSet {
    SampleSet::from([(token.to_owned(), v)])
}

fn all_classes_gt() -> Vec<MapVector> {
    vec![
        line(MapClass::Divider, 0.0, 1.0),
        line(MapClass::Divider, 3.5, 1.0),
        ring(-6.0, 1.0),
        line(MapClass::Boundary, 7.0, 1.0),
        line(MapClass::Boundary, -7.0, 1.0),
    ]
}

#[test]
fn perfect_predictions_score_one() {
    let gt = one("a", all_classes_gt());
    let report = evaluate(&gt.clone(), &gt);
    for c in &report.classes {
        assert_eq!(c.ap_per_threshold, vec![1.0, 1.0, 1.0], "{}", c.class);
    }
    assert_eq!(report.mean_ap, 1.0);
}

#[test]
fn shift_of_0_75_m_is_tp_at_1_and_1_5_fp_at_0_5() {
    // Every one of the 100 resampled points is 0.75 m from the other line: chamfer = 0.75.
    let gt = one("a", vec![line(MapClass::Divider, 0.0, 1.0)]);
    let pred = one("a", vec![line(MapClass::Divider, 0.75, 0.9)]);
    let report = evaluate(&pred, &gt);
    let div = &report.classes[MapClass::Divider.index()];
    // t = 0.5: one FP, recall 0 -> AP 0; t = 1.0, 1.5: one TP -> AP 1.
    assert_eq!(div.ap_per_threshold, vec![0.0, 1.0, 1.0]);
    assert!((div.ap - 2.0 / 3.0).abs() < 1e-12);
}

#[test]
fn duplicate_of_a_matched_prediction_is_fp() {
    let gt_v = vec![line(MapClass::Divider, 0.0, 1.0)];
    let preds_v = vec![
        line(MapClass::Divider, 0.0, 0.9),
        line(MapClass::Divider, 0.0, 0.8),
    ];
    let preds = of_class(Some(&preds_v), MapClass::Divider);
    let gts = of_class(Some(&gt_v), MapClass::Divider);
    let d = distance_matrix(&preds, &gts);
    let m = match_sample(&preds, &d, gts.len(), 0.5);
    assert!(m[0].is_tp);
    assert!(!m[1].is_tp, "the duplicate must be FP");
    // Ranked TP, FP: recall [1, 1], precision [1, 0.5]; the envelope is 1 up to recall 1.
    let report = evaluate(&one("a", preds_v), &one("a", gt_v));
    assert_eq!(report.classes[0].ap_per_threshold, vec![1.0, 1.0, 1.0]);
}

#[test]
fn class_with_predictions_but_no_gt_scores_zero_and_counts_in_the_mean() {
    let mut gt_v = all_classes_gt();
    gt_v.retain(|v| v.class != MapClass::PedCrossing);
    let mut pred_v = gt_v.clone();
    pred_v.push(ring(-6.0, 0.7));
    let report = evaluate(&one("a", pred_v), &one("a", gt_v));
    let ped = &report.classes[MapClass::PedCrossing.index()];
    assert_eq!(ped.num_gt, 0);
    assert_eq!(ped.num_predictions, 1);
    assert_eq!(ped.ap, 0.0);
    // Divider and boundary are perfect: mAP = (1 + 0 + 1) / 3.
    assert!((report.mean_ap - 2.0 / 3.0).abs() < 1e-12);
}

#[test]
fn reversing_score_order_changes_ap_as_computed_by_hand() {
    // One GT line; prediction A lies on it, prediction B is 3 m away (buffers intersect, chamfer
    // 3 m: FP at every threshold).
    //
    // Order 1: A = 0.9, B = 0.1 -> ranked TP, FP.
    //   recall    [1, 1], precision [1, 1/2]
    //   padded    mrec [0, 1, 1, 1], mpre [0, 1, 1/2, 0] -> envelope [1, 1, 1/2, 0]
    //   AP = (1 - 0) * 1 = 1.
    // Order 2: A = 0.1, B = 0.9 -> ranked FP, TP.
    //   recall    [0, 1], precision [0, 1/2]
    //   padded    mrec [0, 0, 1, 1], mpre [0, 0, 1/2, 0] -> envelope [1/2, 1/2, 1/2, 0]
    //   recall changes only between index 1 and 2: AP = (1 - 0) * 1/2 = 1/2.
    let gt = one("a", vec![line(MapClass::Boundary, 0.0, 1.0)]);
    let first = one(
        "a",
        vec![
            line(MapClass::Boundary, 0.0, 0.9),
            line(MapClass::Boundary, 3.0, 0.1),
        ],
    );
    let reversed = one(
        "a",
        vec![
            line(MapClass::Boundary, 0.0, 0.1),
            line(MapClass::Boundary, 3.0, 0.9),
        ],
    );
    let b = MapClass::Boundary.index();
    assert_eq!(evaluate_at(&first, &gt, &[1.0]).classes[b].ap, 1.0);
    assert_eq!(evaluate_at(&reversed, &gt, &[1.0]).classes[b].ap, 0.5);
}

#[test]
fn no_fallback_to_second_best_gt_and_pooling_over_samples() {
    // Sample "a": two GT lines at x = 0 and x = 1.2; predictions P1 (0.9) at x = 0.1 and P2
    // (0.8) at x = 0.2. Both have GT x = 0 as best; P1 takes it, P2 is FP even though GT 1.2 is
    // within 1.5 m of it (no fallback). Sample "b": one GT, one perfect prediction at 0.85.
    // Pooled at t = 1.5: ranked P1 TP (0.9), b TP (0.85), P2 FP (0.8); n_gt = 3.
    //   recall [1/3, 2/3, 2/3], precision [1, 1, 2/3]
    //   AP = 1/3 * 1 + 1/3 * 1 + (1 - 2/3) * 0 = 2/3.
    let gt = SampleSet::from([
        (
            "a".to_owned(),
            vec![
                line(MapClass::Divider, 0.0, 1.0),
                line(MapClass::Divider, 1.2, 1.0),
            ],
        ),
        ("b".to_owned(), vec![line(MapClass::Divider, 0.0, 1.0)]),
    ]);
    let pred = SampleSet::from([
        (
            "a".to_owned(),
            vec![
                line(MapClass::Divider, 0.1, 0.9),
                line(MapClass::Divider, 0.2, 0.8),
            ],
        ),
        ("b".to_owned(), vec![line(MapClass::Divider, 0.0, 0.85)]),
    ]);
    let ap = evaluate_at(&pred, &gt, &[1.5]).classes[0].ap;
    assert!((ap - 2.0 / 3.0).abs() < 1e-12, "{ap}");
}

#[test]
fn far_apart_pairs_are_unmatched_even_at_large_thresholds() {
    // 5 m apart: the 2 m buffers do not meet, so even a 10 m threshold gives no TP.
    let gt = one("a", vec![line(MapClass::Divider, 0.0, 1.0)]);
    let pred = one("a", vec![line(MapClass::Divider, 5.0, 0.9)]);
    assert_eq!(evaluate_at(&pred, &gt, &[10.0]).classes[0].ap, 0.0);
}

#[test]
fn maptr_json_round_trips_and_rejects_unknown_classes() {
    let samples = one("tok", all_classes_gt());
    let file = ResultsFile::from_samples(&samples, serde_json::json!({"use_camera": true}), true);
    let text = serde_json::to_string(&file).unwrap();
    assert!(text.contains("\"cls_name\":\"ped_crossing\""));
    assert!(text.contains("\"confidence_level\":1.0"));
    let back: ResultsFile = serde_json::from_str(&text).unwrap();
    assert_eq!(back.to_samples().unwrap(), samples);

    let gt_text = r#"{"results": {"t": {"vectors": [
        {"pts": [[0, 0], [0, 1]], "pts_num": 2, "cls_name": "lane"}]}}}"#;
    let bad: ResultsFile = serde_json::from_str(gt_text).unwrap();
    assert!(matches!(
        bad.to_samples(),
        Err(satmap_sim::eval::ResultsFileError::UnknownClass { index: 0, .. })
    ));
}
