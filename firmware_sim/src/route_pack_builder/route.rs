//! The route: a GeoJSON LineString in WGS84 (`[lon, lat]` or `[lon, lat, height]` positions),
//! given as a bare geometry, a Feature, or the first LineString Feature of a FeatureCollection.

use std::path::Path;
use std::str::FromStr;

use geojson::{GeoJson, GeometryValue};
use satmap_runtime::geo::Geodetic;

use super::error::BuildError;

/// Read the route from a GeoJSON file.
///
/// # Errors
/// Unreadable file, invalid GeoJSON, no LineString, fewer than two points, or a position out of
/// range.
pub fn read_route_geojson(path: &Path) -> Result<Vec<Geodetic>, BuildError> {
    let text = satmap_runtime::host_files::read_text_capped(
        path,
        satmap_runtime::host_files::MAX_DATA_BYTES,
    )
    .map_err(|source| BuildError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_route_geojson(&text, path)
}

/// Parse a route from GeoJSON text; `path` only labels errors.
///
/// # Errors
/// As [`read_route_geojson`].
pub fn parse_route_geojson(text: &str, path: &Path) -> Result<Vec<Geodetic>, BuildError> {
    let shape = |reason: String| BuildError::RouteShape {
        path: path.to_owned(),
        reason,
    };
    let doc = GeoJson::from_str(text).map_err(|source| BuildError::RouteGeoJson {
        path: path.to_owned(),
        source: Box::new(source),
    })?;
    let geometries: Vec<geojson::Geometry> = match doc {
        GeoJson::Geometry(g) => vec![g],
        GeoJson::Feature(f) => f.geometry.into_iter().collect(),
        GeoJson::FeatureCollection(fc) => {
            fc.features.into_iter().filter_map(|f| f.geometry).collect()
        }
    };
    let line = geometries
        .into_iter()
        .find_map(|g| match g.value {
            GeometryValue::LineString { coordinates } => Some(coordinates),
            _ => None,
        })
        .ok_or_else(|| shape("no LineString geometry found".into()))?;
    if line.len() < 2 {
        return Err(shape(format!(
            "the LineString has {} point(s), need at least 2",
            line.len()
        )));
    }
    line.iter()
        .enumerate()
        .map(|(i, pos)| match pos.as_slice() {
            [lon, lat, ..] if (-180.0..=180.0).contains(lon) && (-85.0..=85.0).contains(lat) => {
                Ok(Geodetic::new(*lat, *lon, 0.0))
            }
            other => Err(shape(format!(
                "position {i} {other:?} is not [lon, lat] within lon -180..180, lat -85..85 (WGS84 degrees)"
            ))),
        })
        .collect()
}
