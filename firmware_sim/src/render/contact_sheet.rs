//! Grids of pictures: a contact sheet of step pictures, and the six camera images of a frame
//! in rig layout (front-left, front, front-right over back-left, back, back-right).

use image::{Rgb, RgbImage};
use satmap_runtime::calibration::NUM_CAMERAS;

/// Camera indices (model order) in sheet order: top row left to right, then bottom row.
pub const CAMERA_SHEET_ORDER: [usize; NUM_CAMERAS] = [2, 0, 1, 4, 3, 5];

/// Lay `images` out in rows of `columns`, cells as large as the largest image, `gap_px` dark
/// grey between cells. An empty list gives a 1x1 image.
#[must_use]
pub fn contact_sheet(images: &[RgbImage], columns: usize, gap_px: u32) -> RgbImage {
    if images.is_empty() {
        return RgbImage::new(1, 1);
    }
    let columns = columns.clamp(1, images.len());
    let rows = images.len().div_ceil(columns);
    let cell_w = images.iter().map(RgbImage::width).max().unwrap_or(1);
    let cell_h = images.iter().map(RgbImage::height).max().unwrap_or(1);
    let width = columns as u32 * cell_w + (columns as u32 + 1) * gap_px;
    let height = rows as u32 * cell_h + (rows as u32 + 1) * gap_px;
    let mut sheet = RgbImage::from_pixel(width, height, Rgb([32, 32, 36]));
    for (k, img) in images.iter().enumerate() {
        let x0 = gap_px + (k % columns) as u32 * (cell_w + gap_px);
        let y0 = gap_px + (k / columns) as u32 * (cell_h + gap_px);
        image::imageops::replace(&mut sheet, img, i64::from(x0), i64::from(y0));
    }
    sheet
}

/// The six camera images (camera-major u8 RGB HWC, `width_px` x `height_px` each) as a 3x2
/// sheet; a buffer of the wrong length gives black cells.
#[must_use]
pub fn camera_sheet(images: &[u8], width_px: usize, height_px: usize) -> RgbImage {
    let n = width_px * height_px * 3;
    let cells: Vec<RgbImage> = CAMERA_SHEET_ORDER
        .iter()
        .map(|&c| {
            images
                .get(c * n..(c + 1) * n)
                .and_then(|b| RgbImage::from_raw(width_px as u32, height_px as u32, b.to_vec()))
                .unwrap_or_else(|| RgbImage::new(width_px as u32, height_px as u32))
        })
        .collect();
    contact_sheet(&cells, 3, 4)
}
