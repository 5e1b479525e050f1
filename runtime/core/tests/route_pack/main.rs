//! The route pack's integration tests (cropping, the cursor along a route, fuzzing, geodesy,
//! integrity) in one test binary, over the packs `common` draws.

mod common;
mod crop;
mod cursor;
mod fuzz;
mod geo;
mod integrity;
