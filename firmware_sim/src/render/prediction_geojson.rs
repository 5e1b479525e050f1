//! Map elements as GeoJSON in the route frame: each element's ego-frame points are moved by the
//! frame's pose (`EgoPose::ego_to_route`), so a whole drive's predictions overlay in one map.
//!
//! Coordinates are route-frame metres `[x east, y north]` (local ENU of the route pack), not
//! WGS84; the collection says so in a top-level `"frame"` member.

use glam::DVec2;
use satmap_runtime::pose::EgoPose;

use crate::eval::MapVector;

/// One Feature per element: a LineString (crossing rings stay closed) with properties
/// `cls_name`, `confidence_level`, `sequence`.
#[must_use]
pub fn frame_features(
    pose: &EgoPose,
    vectors: &[MapVector],
    sequence: u32,
) -> Vec<geojson::Feature> {
    vectors
        .iter()
        .filter(|v| v.points_m.len() >= 2)
        .map(|v| {
            let coords: Vec<[f64; 2]> = v
                .points_m
                .iter()
                .map(|p| {
                    let q = pose.ego_to_route(DVec2::new(p[0], p[1]));
                    [q.x, q.y]
                })
                .collect();
            let mut f = geojson::Feature::from(geojson::Geometry::new_line_string(coords));
            f.set_property("cls_name", v.class.name());
            f.set_property("confidence_level", v.score);
            f.set_property("sequence", sequence);
            f
        })
        .collect()
}

/// A FeatureCollection of many frames' features, marked as route-frame metres.
#[must_use]
pub fn route_frame_geojson(features: Vec<geojson::Feature>) -> geojson::FeatureCollection {
    let mut fc = geojson::FeatureCollection::new(features);
    let mut members = geojson::JsonObject::new();
    members.insert(
        "frame".to_owned(),
        "route frame: local ENU metres, [x east, y north]".into(),
    );
    fc.foreign_members = Some(members);
    fc
}
