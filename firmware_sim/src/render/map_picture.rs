//! One picture per step: the ego-centred satellite crop twice, side by side, with the ground
//! truth drawn on the left panel and the predictions on the right, forward at the top.
//!
//! The crop layout is `ARCHITECTURE.md`'s (row 0 = rear edge, column 0 = left edge), so the
//! panel flips it vertically; ego point `(x, y)` lands at panel pixel
//! `((x - x_min) / gsd, height - (y - y_min) / gsd)` times the scale.

use image::RgbImage;
use satmap_runtime::satellite::CropSpec;
use tiny_skia::{LineCap, LineJoin, Paint, PathBuilder, Pixmap, Stroke, Transform};

use crate::eval::{MapClass, MapVector};

/// Class colours (RGB): divider orange-red, crossing blue, boundary green (MapTR's r/b/g).
#[must_use]
pub const fn class_colour(class: MapClass) -> [u8; 3] {
    match class {
        MapClass::Divider => [255, 80, 40],
        MapClass::PedCrossing => [40, 120, 255],
        MapClass::Boundary => [40, 220, 90],
    }
}

/// Drawing options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderStyle {
    /// Output pixels per crop pixel.
    pub scale: u32,
    /// Predictions below this score are not drawn.
    pub min_score: f64,
    /// Line width, output pixels.
    pub line_width_px: f32,
    /// Gap between the two panels, pixels.
    pub gap_px: u32,
}

impl Default for RenderStyle {
    fn default() -> Self {
        Self {
            scale: 3,
            min_score: 0.3,
            line_width_px: 2.5,
            gap_px: 6,
        }
    }
}

/// [`render_frame_with`] with the default style.
#[must_use]
pub fn render_frame(
    crop_rgb: &[u8],
    crop: &CropSpec,
    predictions: &[MapVector],
    gt: &[MapVector],
) -> RgbImage {
    render_frame_with(crop_rgb, crop, predictions, gt, &RenderStyle::default())
}

/// The two-panel picture. A crop of the wrong length is drawn as mid-grey (a missing prior).
#[must_use]
pub fn render_frame_with(
    crop_rgb: &[u8],
    crop: &CropSpec,
    predictions: &[MapVector],
    gt: &[MapVector],
    style: &RenderStyle,
) -> RgbImage {
    let s = style.scale.max(1);
    let (cw, ch) = (crop.width_px as u32, crop.height_px as u32);
    let panel_w = cw * s;
    let panel_h = ch * s;
    let width = panel_w * 2 + style.gap_px;
    let Some(mut pixmap) = Pixmap::new(width.max(1), panel_h.max(1)) else {
        return RgbImage::new(width, panel_h);
    };
    let valid = crop_rgb.len() == crop.width_px * crop.height_px * 3;
    {
        let data = pixmap.data_mut();
        for y in 0..panel_h {
            // Forward up: output row 0 is the crop's last (front) row.
            let r = (ch - 1 - y / s) as usize;
            for x in 0..width {
                let i = ((y * width + x) * 4) as usize;
                let px = if x >= panel_w && x < panel_w + style.gap_px {
                    [255, 255, 255]
                } else if valid {
                    let c = ((if x >= panel_w {
                        x - panel_w - style.gap_px
                    } else {
                        x
                    }) / s) as usize;
                    let j = (r * crop.width_px + c) * 3;
                    // Dim the imagery a little so the lines stand out.
                    [crop_rgb[j], crop_rgb[j + 1], crop_rgb[j + 2]]
                        .map(|v| (u16::from(v) * 3 / 4) as u8)
                } else {
                    [110, 110, 110]
                };
                data[i..i + 4].copy_from_slice(&[px[0], px[1], px[2], 255]);
            }
        }
    }
    let to_panel = |offset_x: f32| {
        // Ego metres -> panel pixels.
        let k = s as f32 / crop.gsd_m as f32;
        Transform::from_row(
            k,
            0.0,
            0.0,
            -k,
            offset_x - crop.x_min_m as f32 * k,
            panel_h as f32 + crop.y_min_m as f32 * k,
        )
    };
    let left = to_panel(0.0);
    let right = to_panel((panel_w + style.gap_px) as f32);
    for t in [left, right] {
        draw_ego(&mut pixmap, t);
    }
    for v in gt {
        draw_vector(&mut pixmap, v, 1.0, style, left);
    }
    for v in predictions.iter().filter(|v| v.score >= style.min_score) {
        draw_vector(
            &mut pixmap,
            v,
            (0.35 + 0.65 * v.score).clamp(0.0, 1.0) as f32,
            style,
            right,
        );
    }
    let rgb: Vec<u8> = pixmap
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    RgbImage::from_raw(width, panel_h, rgb).unwrap_or_else(|| RgbImage::new(width, panel_h))
}

fn draw_ego(pixmap: &mut Pixmap, t: Transform) {
    let mut pb = PathBuilder::new();
    pb.move_to(-0.9, -2.2);
    pb.line_to(0.9, -2.2);
    pb.line_to(0.9, 1.6);
    pb.line_to(0.0, 2.6);
    pb.line_to(-0.9, 1.6);
    pb.close();
    if let Some(path) = pb.finish() {
        let mut paint = Paint::default();
        paint.set_color_rgba8(255, 255, 255, 230);
        paint.anti_alias = true;
        pixmap.fill_path(&path, &paint, tiny_skia::FillRule::Winding, t, None);
    }
}

fn draw_vector(pixmap: &mut Pixmap, v: &MapVector, alpha: f32, style: &RenderStyle, t: Transform) {
    let mut pb = PathBuilder::new();
    let mut points = v
        .points_m
        .iter()
        .filter(|p| p[0].is_finite() && p[1].is_finite());
    let Some(first) = points.next() else { return };
    pb.move_to(first[0] as f32, first[1] as f32);
    for p in points {
        pb.line_to(p[0] as f32, p[1] as f32);
    }
    let Some(path) = pb.finish() else { return };
    let c = class_colour(v.class);
    let mut paint = Paint::default();
    paint.set_color_rgba8(c[0], c[1], c[2], (alpha * 255.0) as u8);
    paint.anti_alias = true;
    // Width in ego metres, so it survives the transform's scale.
    let k = t.sx.abs().max(f32::EPSILON);
    let stroke = Stroke {
        width: style.line_width_px / k,
        line_cap: LineCap::Round,
        line_join: LineJoin::Round,
        ..Stroke::default()
    };
    pixmap.stroke_path(&path, &paint, &stroke, t, None);
}
