//! Pictures and GeoJSON of the predicted map.
//!
//! - `map_picture`: the satellite crop with ground truth (left) and predictions (right) drawn
//!   as anti-aliased polylines in class colours, forward up.
//! - `contact_sheet`: grids of pictures, and the six camera images in rig layout.
//! - `prediction_geojson`: map elements moved from the ego frame into the route frame.
//! - `drive_mcap`: every step of a replay into an MCAP file (`drive --mcap`).

pub mod contact_sheet;
pub mod drive_mcap;
pub mod map_picture;
pub mod prediction_geojson;

pub use contact_sheet::{camera_sheet, contact_sheet};
pub use drive_mcap::McapRecorder;
pub use map_picture::{RenderStyle, class_colour, render_frame, render_frame_with};
pub use prediction_geojson::{frame_features, route_frame_geojson};
