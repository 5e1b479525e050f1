//! A step's buffers and decoded map against the PyTorch/onnxruntime goldens.
//!
//! Tolerances: stage outputs 1e-4 max abs (tract against onnxruntime on the same graphs, any
//! kernel family); CAN-bus vector 1e-6; decoded points 1e-3 m; scores 1e-5.

use satmap_runtime::engine_tract::TractEngine;
use satmap_runtime::{MapClass, MapFrame, SatMap, SatelliteSource};

use crate::golden::{GoldenFrame, max_abs_diff};

/// Stage outputs against the reference, max abs.
pub const STAGE_TOL: f32 = 1e-4;
/// Decoded polyline points against the reference, metres.
pub const POINT_TOL_M: f32 = 1e-3;
/// Decoded scores against the reference.
pub const SCORE_TOL: f32 = 1e-5;
/// The CAN-bus vector against the reference.
pub const CAN_BUS_TOL: f32 = 1e-6;

/// `map`'s stage buffers in [`STAGE_BUFFERS`]' order, the BEVs widened from their storage.
fn buffers<S: SatelliteSource>(map: &SatMap<TractEngine, S>) -> [Vec<f32>; 8] {
    let b = map.buffers();
    [
        b.value().to_vec(),
        b.query().to_vec(),
        b.weights().to_vec(),
        b.gathered().to_vec(),
        b.camera_bev().iter().collect(),
        b.satellite_bev().iter().collect(),
        b.logits().to_vec(),
        b.points().to_vec(),
    ]
}

/// A fresh runtime over `engine` with `f`'s satellite crop, after stepping `f` once with every
/// camera; returns it with the published map.
///
/// # Panics
/// When the runtime cannot be built or the step fails.
fn stepped(
    engine: TractEngine,
    f: &GoldenFrame,
) -> (
    SatMap<TractEngine, satmap_runtime::satellite::FixedCrop<'_>>,
    MapFrame,
) {
    let mut map = SatMap::new(
        engine,
        &crate::golden::calibration(),
        satmap_runtime::satellite::FixedCrop(&f.satellite),
    )
    .unwrap();
    let (w, h) = (map.dims().image_w as u32, map.dims().image_h as u32);
    let out = map.step(&f.frame(1, w, h)).unwrap().clone();
    (map, out)
}

/// Every stage buffer of `map` after stepping `f` against the golden's, within [`STAGE_TOL`];
/// returns the largest difference per stage (for the log).
///
/// # Panics
/// When a stage is out of tolerance.
pub fn check_stages<S: SatelliteSource>(
    map: &SatMap<TractEngine, S>,
    f: &GoldenFrame,
    what: &str,
) -> Vec<(&'static str, f32)> {
    let g = &f.golden;
    let can = max_abs_diff(
        &satmap_runtime::can_bus::can_bus(&f.pose, &f.motion),
        &g.f32s("can_bus"),
    );
    assert!(can <= CAN_BUS_TOL, "{what} can_bus: {can:e}");
    let mut out = Vec::new();
    // The gather-sum is fed tract's weights and values here, so it inherits their 1e-4;
    // bit-exactness on identical inputs is shown by the LUT kernel tests.
    for (name, got) in STAGE_BUFFERS.into_iter().zip(buffers(map)) {
        let d = max_abs_diff(&got, &g.f32s(name));
        assert!(
            d <= STAGE_TOL,
            "{what} {name}: max abs diff {d:e} > {STAGE_TOL:e}"
        );
        out.push((name, d));
    }
    out
}

/// The decoded map against the golden's `<prefix>decoded_*` tensors: same elements in the same
/// order, classes and instances equal, scores within [`SCORE_TOL`], points within
/// [`POINT_TOL_M`].
///
/// # Panics
/// When the map differs.
pub fn check_decoded(map: &MapFrame, f: &GoldenFrame, prefix: &str) {
    let scores = f.golden.f32s(&format!("{prefix}decoded_scores"));
    let labels = f.golden.i64s(&format!("{prefix}decoded_labels"));
    let instances = f.golden.i64s(&format!("{prefix}decoded_instances"));
    let points = f.golden.f32s(&format!("{prefix}decoded_points_m"));
    assert_eq!(map.elements.len(), scores.len());
    for (k, e) in map.elements.iter().enumerate() {
        assert!(
            (e.score - scores[k]).abs() <= SCORE_TOL,
            "score {k}: {} vs {}",
            e.score,
            scores[k]
        );
        assert_eq!(
            Some(e.class),
            usize::try_from(labels[k])
                .ok()
                .and_then(MapClass::from_label),
            "label {k}"
        );
        assert_eq!(i64::from(e.instance), instances[k], "instance {k}");
        for (p, pt) in e.points_m.iter().enumerate() {
            let (gx, gy) = (points[(k * 20 + p) * 2], points[(k * 20 + p) * 2 + 1]);
            assert!(
                (pt.x - gx).abs() <= POINT_TOL_M && (pt.y - gy).abs() <= POINT_TOL_M,
                "element {k} point {p}: ({}, {}) vs ({gx}, {gy})",
                pt.x,
                pt.y
            );
        }
    }
}

/// Both golden frames stepped through a fresh runtime over `engine()`: every stage and the
/// decoded map match the reference, with the satellite present and the health clean.
///
/// # Panics
/// When anything differs beyond its tolerance.
pub fn golden_frames_match(engine: impl Fn() -> TractEngine, what: &str) {
    use satmap_runtime::SatellitePrior;
    for index in 0..2 {
        let f = GoldenFrame::load(index);
        let (map, out) = stepped(engine(), &f);
        for (name, d) in check_stages(&map, &f, &format!("{what} frame {index}")) {
            println!("{what} frame {index} {name}: max abs diff {d:.2e} (tolerance {STAGE_TOL:e})");
        }
        assert_eq!(map.buffers().crop(), &f.satellite[..]);
        assert_eq!(out.health.satellite, SatellitePrior::Present);
        assert!(!out.health.degraded);
        check_decoded(&out, &f, "");
    }
}

/// Golden frame 0 without a satellite prior through a fresh runtime over `engine()`: the step
/// is degraded, feeds zeros and matches the reference's degraded outputs.
///
/// # Panics
/// When anything differs beyond its tolerance.
pub fn degraded_frame_matches(engine: impl Fn() -> TractEngine, what: &str) {
    use satmap_runtime::SatellitePrior;
    use satmap_runtime::satellite::NoSatellite;
    let f = GoldenFrame::load(0);
    let mut map = SatMap::new(engine(), &crate::golden::calibration(), NoSatellite).unwrap();
    let (w, h) = (map.dims().image_w as u32, map.dims().image_h as u32);
    let out = map.step(&f.frame(1, w, h)).unwrap().clone();
    assert!(out.health.degraded);
    assert_eq!(out.health.satellite, SatellitePrior::Missing);
    assert!(map.buffers().satellite_bev().iter().all(|v| v == 0.0));
    let d = max_abs_diff(
        map.buffers().logits(),
        &f.golden.f32s("degraded_class_logits"),
    );
    assert!(d <= STAGE_TOL, "{what} degraded logits {d:e}");
    let d = max_abs_diff(map.buffers().points(), &f.golden.f32s("degraded_points"));
    assert!(d <= STAGE_TOL, "{what} degraded points {d:e}");
}

/// The digests of `steps` steps over `engine()` alternating the two golden frames.
///
/// # Panics
/// When a step fails.
#[must_use]
pub fn alternating_digests(engine: TractEngine, steps: usize) -> Vec<u64> {
    use satmap_runtime::satellite::FixedCrop;
    let frames = [GoldenFrame::load(0), GoldenFrame::load(1)];
    let mut map = SatMap::new(
        engine,
        &crate::golden::calibration(),
        FixedCrop(&frames[0].satellite),
    )
    .unwrap();
    let (w, h) = (map.dims().image_w as u32, map.dims().image_h as u32);
    (0..steps)
        .map(|i| {
            map.step(&frames[i % 2].frame(i as u64 + 1, w, h))
                .unwrap()
                .digest
        })
        .collect()
}

/// The stage buffers `check_stages` compares, in that order, by name.
pub const STAGE_BUFFERS: [&str; 8] = [
    "value",
    "bev_query",
    "gkt_weights",
    "gathered",
    "camera_bev",
    "satellite_bev",
    "class_logits",
    "points",
];

/// Every stage buffer after stepping each golden frame through a fresh runtime over
/// `engine()`: (`frame <i> <buffer>`, the runtime's values, the golden's), frames in order,
/// buffers in [`STAGE_BUFFERS`]' order.
///
/// # Panics
/// When a step fails.
#[must_use]
pub fn stage_buffers(engine: impl Fn() -> TractEngine) -> Vec<(String, Vec<f32>, Vec<f32>)> {
    let mut out = Vec::new();
    for index in 0..2 {
        let f = GoldenFrame::load(index);
        let (map, _) = stepped(engine(), &f);
        for (name, got) in STAGE_BUFFERS.iter().zip(buffers(&map)) {
            out.push((
                format!("frame {index} {name}"),
                got.to_vec(),
                f.golden.f32s(name),
            ));
        }
    }
    out
}
