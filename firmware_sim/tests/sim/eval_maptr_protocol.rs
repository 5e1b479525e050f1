//! The evaluator follows MapTR's own code (issue 13): the flat-cap, mitre-join 2 m buffer
//! pre-test, zero-length lines, the stable tie rule, and MapTR's results and GT files. Every
//! expected value is computed by hand in the comments.

use std::path::{Path, PathBuf};
use std::process::Command;

use satmap_sim::eval::{
    Layout, MapClass, MapVector, ResultsFileError, SampleSet,
    average_precision::{distance_matrix, match_sample, of_class},
    chamfer::{chamfer_distance_m, resample_by_arc_length},
    evaluate, evaluate_at, read_file, read_samples, write_maptr_pair,
};

fn vector(class: MapClass, points_m: &[[f64; 2]], score: f64) -> MapVector {
    MapVector {
        class,
        points_m: points_m.to_vec(),
        score,
    }
}

fn vertical(class: MapClass, x_m: f64, score: f64) -> MapVector {
    vector(class, &[[x_m, -10.0], [x_m, 10.0]], score)
}

fn one(token: &str, v: Vec<MapVector>) -> SampleSet {
    SampleSet::from([(token.to_owned(), v)])
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("satmap_eval_{}_{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

const D: usize = 0; // MapClass::Divider.index()

#[test]
fn end_to_end_segments_with_a_gap_never_match_however_close() {
    // GT [0, 0]-[1, 0], prediction [1.5, 0]-[2.5, 0]: collinear, 0.5 m apart end to end. Flat
    // caps stop each buffer at its segment's ends: x in [0, 1] and x in [1.5, 2.5], so the
    // buffers are disjoint. Yet the chamfer distance is only 1.0 m: GT point x_i = i/99 has its
    // nearest prediction point at 1.5, mean over i of (1.5 - i/99) = 1.5 - 0.5 = 1.0, and the
    // same the other way. A 4 m polyline-distance test would have made it TP at 1.0 and 1.5.
    let gt = [[0.0, 0.0], [1.0, 0.0]];
    let pred = [[1.5, 0.0], [2.5, 0.0]];
    let chamfer = chamfer_distance_m(
        &resample_by_arc_length(&gt, 100).unwrap(),
        &resample_by_arc_length(&pred, 100).unwrap(),
    );
    assert!((chamfer - 1.0).abs() < 1e-12, "{chamfer}");
    let report = evaluate(
        &one("a", vec![vector(MapClass::Divider, &pred, 0.9)]),
        &one("a", vec![vector(MapClass::Divider, &gt, 1.0)]),
    );
    assert_eq!(report.classes[D].ap_per_threshold, vec![0.0, 0.0, 0.0]);
}

#[test]
fn end_to_end_segments_that_overlap_match() {
    // Prediction [0.9, 0]-[1.9, 0] overlaps the GT [0, 1] by 0.1 m: the buffers share the
    // 0.1 x 4 m strip. Chamfer ~ the mean of max(0, 0.9 - x) over x in [0, 1] = 0.405 (both
    // ways, up to the 1/99 m sampling): TP at 0.5, 1.0 and 1.5.
    let report = evaluate(
        &one(
            "a",
            vec![vector(MapClass::Divider, &[[0.9, 0.0], [1.9, 0.0]], 0.9)],
        ),
        &one(
            "a",
            vec![vector(MapClass::Divider, &[[0.0, 0.0], [1.0, 0.0]], 1.0)],
        ),
    );
    assert_eq!(report.classes[D].ap_per_threshold, vec![1.0, 1.0, 1.0]);
}

#[test]
fn side_by_side_lines_meet_below_4_m_only() {
    // Buffers reach 2 m each side: parallel lines 3.9 m apart overlap (chamfer 3.9, so TP only
    // at a threshold >= 3.9), 4.1 m apart do not (unmatched even at 10 m).
    let gt = one("a", vec![vertical(MapClass::Divider, 0.0, 1.0)]);
    let near = one("a", vec![vertical(MapClass::Divider, 3.9, 0.9)]);
    let far = one("a", vec![vertical(MapClass::Divider, 4.1, 0.9)]);
    assert_eq!(evaluate_at(&near, &gt, &[4.0]).classes[D].ap, 1.0);
    assert_eq!(evaluate_at(&far, &gt, &[10.0]).classes[D].ap, 0.0);
}

#[test]
fn non_overlapping_pairs_sit_at_100_m_as_in_maptr() {
    // MapTR fills the score matrix with -100 for pairs whose buffers miss: the gap pair of the
    // first test is TP at a 100 m threshold (100 <= 100) and FP at 99.9 m.
    let gt = one(
        "a",
        vec![vector(MapClass::Divider, &[[0.0, 0.0], [1.0, 0.0]], 1.0)],
    );
    let pred = one(
        "a",
        vec![vector(MapClass::Divider, &[[1.5, 0.0], [2.5, 0.0]], 0.9)],
    );
    let ap = evaluate_at(&pred, &gt, &[99.9, 100.0]).classes[D]
        .ap_per_threshold
        .clone();
    assert_eq!(ap, vec![0.0, 1.0]);
}

#[test]
fn zero_length_prediction_on_a_zero_length_gt_is_fp() {
    // Both are the point (2, 3) twice: chamfer 0, but a zero-length line has no buffer, so the
    // pair is never scored. One GT, one FP: AP 0 at every threshold (the GT still counts).
    let p = [[2.0, 3.0], [2.0, 3.0]];
    let report = evaluate(
        &one("a", vec![vector(MapClass::Divider, &p, 0.9)]),
        &one("a", vec![vector(MapClass::Divider, &p, 1.0)]),
    );
    let div = &report.classes[D];
    assert_eq!((div.num_gt, div.num_predictions), (1, 1));
    assert_eq!(div.ap_per_threshold, vec![0.0, 0.0, 0.0]);
}

#[test]
fn zero_length_prediction_on_a_real_gt_is_fp() {
    // The prediction is the point (0, 5) on the GT line x = 0: no buffer, FP; AP 0.
    let report = evaluate(
        &one(
            "a",
            vec![vector(MapClass::Divider, &[[0.0, 5.0], [0.0, 5.0]], 0.9)],
        ),
        &one("a", vec![vertical(MapClass::Divider, 0.0, 1.0)]),
    );
    assert_eq!(report.classes[D].ap_per_threshold, vec![0.0, 0.0, 0.0]);
}

#[test]
fn zero_length_gt_can_never_be_recalled() {
    // GT: the line x = 0 and a zero-length line at (5, 0). A perfect prediction of the line and
    // one lying on the point (its buffer meets nothing of the point's, which has none).
    // Ranked TP (0.9), FP (0.8); n_gt = 2: recall [1/2, 1/2], precision [1, 1/2];
    // AP = 1/2 * 1 = 0.5 at every threshold.
    let gt = one(
        "a",
        vec![
            vertical(MapClass::Divider, 0.0, 1.0),
            vector(MapClass::Divider, &[[5.0, 0.0], [5.0, 0.0]], 1.0),
        ],
    );
    let pred = one(
        "a",
        vec![
            vertical(MapClass::Divider, 0.0, 0.9),
            vector(MapClass::Divider, &[[4.0, 0.0], [6.0, 0.0]], 0.8),
        ],
    );
    assert_eq!(
        evaluate(&pred, &gt).classes[D].ap_per_threshold,
        vec![0.5, 0.5, 0.5]
    );
}

#[test]
fn tied_scores_rank_in_input_order() {
    // One GT x = 0; A on it (TP), B at x = 3 (buffers overlap, chamfer 3: FP), both score 0.5.
    // B listed first: ranked FP, TP: recall [0, 1], precision [0, 1/2] -> envelope 1/2,
    // AP = 0.5. A listed first: TP, FP -> AP = 1.
    let gt = one("a", vec![vertical(MapClass::Divider, 0.0, 1.0)]);
    let a = vertical(MapClass::Divider, 0.0, 0.5);
    let b = vertical(MapClass::Divider, 3.0, 0.5);
    let b_first = one("a", vec![b.clone(), a.clone()]);
    let a_first = one("a", vec![a, b]);
    assert_eq!(evaluate_at(&b_first, &gt, &[1.0]).classes[D].ap, 0.5);
    assert_eq!(evaluate_at(&a_first, &gt, &[1.0]).classes[D].ap, 1.0);
}

#[test]
fn tied_scores_are_matched_in_input_order() {
    // One GT x = 0; A at x = 0.3 (chamfer 0.3) and B at x = 0 (chamfer 0), both score 0.5, at
    // threshold 0.2. A first: A is visited first and is FP (0.3 > 0.2) without taking the GT,
    // then B takes it: flags [FP, TP], ranked FP, TP -> AP 0.5. B first: B takes the GT, A is
    // FP: ranked TP, FP -> AP 1.
    let gt_v = vec![vertical(MapClass::Divider, 0.0, 1.0)];
    let a = vertical(MapClass::Divider, 0.3, 0.5);
    let b = vertical(MapClass::Divider, 0.0, 0.5);
    let preds_v = vec![a.clone(), b.clone()];
    let preds = of_class(Some(&preds_v), MapClass::Divider);
    let gts = of_class(Some(&gt_v), MapClass::Divider);
    let m = match_sample(&preds, &distance_matrix(&preds, &gts), 1, 0.2);
    assert_eq!((m[0].is_tp, m[1].is_tp), (false, true));
    let gt = one("a", gt_v);
    assert_eq!(
        evaluate_at(&one("a", preds_v), &gt, &[0.2]).classes[D].ap,
        0.5
    );
    assert_eq!(
        evaluate_at(&one("a", vec![b, a]), &gt, &[0.2]).classes[D].ap,
        1.0
    );

    // At 0.5 both are within: the first listed takes the GT, the other is FP; AP 1 both ways.
    let m = match_sample(&preds, &distance_matrix(&preds, &gts), 1, 0.5);
    assert_eq!((m[0].is_tp, m[1].is_tp), (true, false));
}

#[test]
fn tied_scores_across_samples_rank_in_file_order() {
    // Sample "a": a prediction and no GT (FP). Sample "b": a perfect prediction (TP). Both 0.5.
    // Issue 38: MapTR stacks the samples in its results file's order; so do we, whatever the
    // tokens sort as. "a" listed first: FP, TP -> AP 0.5. "b" listed first: TP, FP -> AP 1
    // (until then both gave 0.5: the tokens were ranked in ascending order).
    let fp = vertical(MapClass::Divider, 0.0, 0.5);
    let tp = vertical(MapClass::Divider, 0.0, 0.5);
    let gt = one("b", vec![vertical(MapClass::Divider, 0.0, 1.0)]);
    let a_first = SampleSet::from([
        ("a".to_owned(), vec![fp.clone()]),
        ("b".to_owned(), vec![tp.clone()]),
    ]);
    assert_eq!(evaluate_at(&a_first, &gt, &[1.0]).classes[D].ap, 0.5);
    let b_first = SampleSet::from([("b".to_owned(), vec![tp]), ("a".to_owned(), vec![fp])]);
    assert_eq!(evaluate_at(&b_first, &gt, &[1.0]).classes[D].ap, 1.0);

    // Through files: MapTR's list layout and our keyed layout keep the file's order, and
    // `--write-maptr` writes the order the evaluation ranked in.
    let dir = scratch("file_order");
    let line = r#"{"pts": [[0.0, -10.0], [0.0, 10.0]], "pts_num": 2, "cls_name": "divider",
        "type": 0, "confidence_level": 0.5}"#;
    let maptr = write(
        &dir,
        "maptr.json",
        &format!(
            r#"{{"meta": {{}}, "results": [{{"sample_token": "b", "vectors": [{line}]}},
            {{"sample_token": "a", "vectors": [{line}]}}]}}"#
        ),
    );
    let keyed = write(
        &dir,
        "keyed.json",
        r#"{"results": {"b": {"vectors": [{"pts": [[0.0, -10.0], [0.0, 10.0]],
            "cls_name": "divider", "confidence_level": 0.5}]},
            "a": {"vectors": [{"pts": [[0.0, -10.0], [0.0, 10.0]], "cls_name": "divider",
            "confidence_level": 0.5}]}}}"#,
    );
    for path in [&maptr, &keyed] {
        let read = read_samples(path).unwrap();
        let order: Vec<&str> = read.keys().map(String::as_str).collect();
        assert_eq!(order, ["b", "a"], "{}", path.display());
        assert_eq!(evaluate_at(&read, &gt, &[1.0]).classes[D].ap, 1.0);
    }
    let (results, gts) = (dir.join("r.json"), dir.join("g.json"));
    write_maptr_pair(
        &read_samples(&maptr).unwrap(),
        &gt,
        serde_json::Value::Null,
        &results,
        &gts,
    )
    .unwrap();
    let back: Vec<String> = read_samples(&results).unwrap().keys().cloned().collect();
    assert_eq!(back, ["b", "a"]);
    let back: Vec<String> = read_samples(&gts).unwrap().keys().cloned().collect();
    assert_eq!(back, ["b", "a"]);
    let _ = std::fs::remove_dir_all(dir);
}

/// MapTR's `nuscmap_results.json` as `_format_bbox` writes it.
const MAPTR_RESULTS: &str = r#"{"meta": {"use_camera": true, "use_lidar": false},
 "results": [
  {"sample_token": "tok_a", "vectors": [
    {"pts": [[0.0, -10.0], [0.0, 10.0]], "pts_num": 2, "cls_name": "divider", "type": 0,
     "confidence_level": 0.9},
    {"pts": [[5.0, -10.0], [5.0, 10.0]], "pts_num": 2, "cls_name": "boundary", "type": 2,
     "confidence_level": 0.8}]},
  {"sample_token": "tok_b", "vectors": []}]}"#;

/// MapTR's ground truth as `_format_gt` writes it.
const MAPTR_GTS: &str = r#"{"GTs": [
  {"sample_token": "tok_a", "vectors": [
    {"pts": [[0.0, -10.0], [0.0, 10.0]], "pts_num": 2, "cls_name": "divider", "type": 0},
    {"pts": [[5.75, -10.0], [5.75, 10.0]], "pts_num": 2, "cls_name": "boundary", "type": 2}]},
  {"sample_token": "tok_b", "vectors": [
    {"pts": [[-3.0, 0.0], [-3.0, 4.0], [-7.0, 4.0], [-7.0, 0.0], [-3.0, 0.0]], "pts_num": 5,
     "cls_name": "ped_crossing", "type": 1}]}]}"#;

#[test]
fn reads_maptr_results_and_gt_files_and_scores_them() {
    // Divider: exact, AP [1, 1, 1]. Boundary: 0.75 m off, AP [0, 1, 1] = 2/3. Ped crossing: one
    // GT, no prediction, AP 0. mAP = (1 + 0 + 2/3) / 3 = 5/9.
    let dir = scratch("read_maptr");
    let results = read_file(&write(&dir, "nuscmap_results.json", MAPTR_RESULTS)).unwrap();
    let gts = read_file(&write(&dir, "map_anns.json", MAPTR_GTS)).unwrap();
    assert_eq!(results.layout, Layout::MaptrResults);
    assert_eq!(gts.layout, Layout::MaptrGts);
    assert_eq!(results.meta["use_camera"], serde_json::json!(true));
    assert_eq!(results.samples["tok_a"][1].class, MapClass::Boundary);
    assert_eq!(results.samples["tok_a"][1].score, 0.8);
    assert_eq!(gts.samples["tok_b"][0].class, MapClass::PedCrossing);
    assert_eq!(gts.samples["tok_b"][0].score, 1.0);
    let report = evaluate(&results.samples, &gts.samples);
    assert_eq!(report.classes[0].ap_per_threshold, vec![1.0, 1.0, 1.0]);
    assert_eq!(report.classes[1].ap_per_threshold, vec![0.0, 0.0, 0.0]);
    assert_eq!(report.classes[2].ap_per_threshold, vec![0.0, 1.0, 1.0]);
    assert!((report.mean_ap - 5.0 / 9.0).abs() < 1e-12);
    assert_eq!(report.num_samples, 2);
}

#[test]
fn maptr_files_round_trip_with_the_union_of_tokens_in_both() {
    // Predictions cover "x" only, GT "x" and "y", and GT has a 1-point vector (left out).
    let dir = scratch("round_trip");
    let preds = one("x", vec![vertical(MapClass::Boundary, 1.0, 0.25)]);
    let mut gt = one("x", vec![vertical(MapClass::Boundary, 1.0, 1.0)]);
    gt.insert(
        "y".to_owned(),
        vec![
            vertical(MapClass::Divider, 2.0, 1.0),
            vector(MapClass::Divider, &[[0.0, 0.0]], 1.0),
        ],
    );
    let (rp, gp) = (dir.join("r.json"), dir.join("g.json"));
    write_maptr_pair(&preds, &gt, serde_json::Value::Null, &rp, &gp).unwrap();

    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rp).unwrap()).unwrap();
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&gp).unwrap()).unwrap();
    assert_eq!(r["meta"], serde_json::json!({}));
    let tokens = |list: &serde_json::Value| -> Vec<String> {
        list.as_array()
            .unwrap()
            .iter()
            .map(|s| s["sample_token"].as_str().unwrap().to_owned())
            .collect()
    };
    assert_eq!(tokens(&r["results"]), ["x", "y"]);
    assert_eq!(tokens(&g["GTs"]), ["x", "y"]);
    let v = &r["results"][0]["vectors"][0];
    assert_eq!(v["type"], 2);
    assert_eq!(v["cls_name"], "boundary");
    assert_eq!(v["pts_num"], 2);
    assert_eq!(v["confidence_level"], 0.25);
    assert!(g["GTs"][0]["vectors"][0].get("confidence_level").is_none());
    assert_eq!(g["GTs"][1]["vectors"].as_array().unwrap().len(), 1);

    let back_preds = read_samples(&rp).unwrap();
    let back_gt = read_samples(&gp).unwrap();
    assert_eq!(back_preds["x"], preds["x"]);
    assert!(back_preds["y"].is_empty());
    assert_eq!(back_gt["x"], gt["x"]);
    assert_eq!(back_gt["y"], gt["y"][..1]);
}

#[test]
fn type_alone_names_the_class_and_must_agree_with_cls_name() {
    let dir = scratch("type_rule");
    let only_type = r#"{"GTs": [{"sample_token": "t", "vectors": [
        {"pts": [[0, 0], [0, 1]], "type": 1}]}]}"#;
    let s = read_samples(&write(&dir, "only_type.json", only_type)).unwrap();
    assert_eq!(s["t"][0].class, MapClass::PedCrossing);

    let clash = r#"{"GTs": [{"sample_token": "t", "vectors": [
        {"pts": [[0, 0], [0, 1]], "pts_num": 2, "type": 0, "cls_name": "boundary"}]}]}"#;
    let path = write(&dir, "clash.json", clash);
    let err = read_samples(&path).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("clash.json"), "{text}");
    assert!(text.contains("type 0 but cls_name \"boundary\""), "{text}");
}

#[test]
fn malformed_files_give_errors_naming_the_file() {
    let dir = scratch("malformed");
    let cases: [(&str, &str, &str); 10] = [
        (
            "truncated.json",
            r#"{"results": [{"sample_token": "#,
            "invalid results JSON",
        ),
        ("array.json", "[1, 2]", "found an array"),
        (
            "number_results.json",
            r#"{"results": 5}"#,
            "\"results\" is a number",
        ),
        ("no_keys.json", r#"{"foo": 1}"#, "keys [foo]"),
        (
            "bad_type.json",
            r#"{"GTs": [{"sample_token": "t", "vectors": [{"pts": [[0, 0], [1, 1]], "type": 7}]}]}"#,
            "unknown class \"7\"",
        ),
        (
            "dup.json",
            r#"{"GTs": [{"sample_token": "t", "vectors": []}, {"sample_token": "t", "vectors": []}]}"#,
            "sample_token \"t\" appears more than once",
        ),
        // Our object layout: serde kept the last of two equal keys.
        (
            "dup_object.json",
            r#"{"results": {"t": {"vectors": []}, "t": {"vectors": []}}}"#,
            "sample_token \"t\" appears more than once",
        ),
        // A null score was read as absent and scored 1.0.
        (
            "null_score.json",
            r#"{"results": {"t": {"vectors": [{"pts": [[0, 0], [1, 1]], "cls_name": "divider", "confidence_level": null}]}}}"#,
            "confidence_level is null",
        ),
        (
            "three_coords.json",
            r#"{"results": [{"sample_token": "t", "vectors": [{"pts": [[0, 0, 0]], "type": 0}]}]}"#,
            "invalid results JSON",
        ),
        (
            "pts_num.json",
            r#"{"results": {"t": {"vectors": [{"pts": [[0, 0]], "pts_num": 3, "cls_name": "divider"}]}}}"#,
            "pts_num 3 but 1 points",
        ),
    ];
    for (name, text, expected) in cases {
        let err = read_samples(&write(&dir, name, text)).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains(name), "{name}: {msg}");
        assert!(msg.contains(expected), "{name}: {msg}");
    }
    let missing = dir.join("missing.json");
    assert!(matches!(
        read_samples(&missing),
        Err(ResultsFileError::Io { path, .. }) if path == missing
    ));
}

#[test]
fn cli_scores_maptr_files_and_writes_them_back() {
    let dir = scratch("cli");
    let results = write(&dir, "nuscmap_results.json", MAPTR_RESULTS);
    let gts = write(&dir, "map_anns.json", MAPTR_GTS);
    let out_dir = dir.join("again");
    let out = Command::new(env!("CARGO_BIN_EXE_satmap-sim"))
        .arg("evaluate")
        .arg("--predictions")
        .arg(&results)
        .arg("--gt")
        .arg(&gts)
        .arg("--write-maptr")
        .arg(&out_dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // 5/9 = 55.56 %.
    assert!(stdout.contains("mAP 55.56 over 2 samples"), "{stdout}");
    assert_eq!(
        read_samples(&out_dir.join("nuscmap_results.json")).unwrap(),
        read_samples(&results).unwrap()
    );
    assert_eq!(
        read_samples(&out_dir.join("map_anns.json")).unwrap(),
        read_samples(&gts).unwrap()
    );

    let broken = write(&dir, "broken.json", "{\"GTs\": [");
    let out = Command::new(env!("CARGO_BIN_EXE_satmap-sim"))
        .arg("evaluate")
        .arg("--predictions")
        .arg(&results)
        .arg("--gt")
        .arg(&broken)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("broken.json"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
