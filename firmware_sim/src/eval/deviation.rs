//! How far a lower-precision bundle's maps are from the f32 bundle's over one replay: the figures
//! the precision table reports (docs/bundles.md, "Precision").
//!
//! Elements are matched by decoder instance, the identity both runs share: an f32 element
//! (instance, class) in a step's top-k is *kept* when the other run's top-k holds the same
//! instance under the same class (their polylines' Chamfer distance is then counted), *flipped*
//! when it holds that instance only under another class, and *dropped* when the instance left the
//! top-k. Polylines are compared as the metric compares them: resampled to
//! [`RESAMPLE_POINTS`] by arc length, two-sided mean Chamfer, ego metres.

use satmap_runtime::map_frame::{MapElement, MapFrame};

use super::chamfer::{RESAMPLE_POINTS, chamfer_distance_m, resample_by_arc_length};

/// The deviation of one replay from another, step by step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Deviation {
    /// Steps compared (the shorter run's count).
    pub steps: usize,
    /// f32 elements over all steps.
    pub elements: usize,
    /// Of them, kept (same instance and class in the other run).
    pub kept: usize,
    /// Of them, whose instance is in the other run's top-k only under another class.
    pub flipped: usize,
    /// Of them, whose instance is not in the other run's top-k.
    pub dropped: usize,
    /// Mean Chamfer distance over the kept pairs, metres (0 when none is kept).
    pub mean_chamfer_m: f64,
    /// Largest Chamfer distance over the kept pairs, metres.
    pub max_chamfer_m: f64,
}

impl Deviation {
    /// Share of f32 elements whose class changed or that left the top-k.
    #[must_use]
    pub fn changed_share(&self) -> f64 {
        if self.elements == 0 {
            0.0
        } else {
            (self.flipped + self.dropped) as f64 / self.elements as f64
        }
    }
}

fn polyline_m(e: &MapElement) -> Option<Vec<[f64; 2]>> {
    let points: Vec<[f64; 2]> = e
        .points_m
        .iter()
        .map(|p| [f64::from(p.x), f64::from(p.y)])
        .collect();
    resample_by_arc_length(&points, RESAMPLE_POINTS)
}

/// Compare `other`'s maps with `reference`'s (the f32 run), step by step.
#[must_use]
pub fn deviation(reference: &[MapFrame], other: &[MapFrame]) -> Deviation {
    let mut d = Deviation {
        steps: reference.len().min(other.len()),
        ..Deviation::default()
    };
    let mut chamfer_sum_m = 0.0;
    for (a, b) in reference.iter().zip(other) {
        for e in &a.elements {
            d.elements += 1;
            let same = b
                .elements
                .iter()
                .find(|o| o.instance == e.instance && o.class == e.class);
            match same {
                Some(o) => {
                    d.kept += 1;
                    if let (Some(p), Some(q)) = (polyline_m(e), polyline_m(o)) {
                        let c = chamfer_distance_m(&p, &q);
                        chamfer_sum_m += c;
                        d.max_chamfer_m = d.max_chamfer_m.max(c);
                    }
                }
                None if b.elements.iter().any(|o| o.instance == e.instance) => d.flipped += 1,
                None => d.dropped += 1,
            }
        }
    }
    if d.kept > 0 {
        d.mean_chamfer_m = chamfer_sum_m / d.kept as f64;
    }
    d
}

#[cfg(test)]
mod tests {
    use glam::Vec2;
    use satmap_runtime::capacity::NUM_POINTS;
    use satmap_runtime::map_frame::MapClass;

    use super::*;

    fn element(instance: u16, class: MapClass, shift_m: f32) -> MapElement {
        let mut points_m = [Vec2::ZERO; NUM_POINTS];
        for (i, p) in points_m.iter_mut().enumerate() {
            *p = Vec2::new(shift_m, i as f32);
        }
        MapElement {
            class,
            score: 0.9,
            instance,
            points_m,
        }
    }

    fn frame(elements: &[MapElement]) -> MapFrame {
        let mut f = MapFrame::default();
        for e in elements {
            f.elements.push(*e).unwrap();
        }
        f
    }

    /// One element kept 0.25 m aside, one flipped, one dropped: each counted where it belongs.
    #[test]
    fn kept_flipped_and_dropped_are_told_apart() {
        let reference = [frame(&[
            element(1, MapClass::Divider, 0.0),
            element(2, MapClass::Boundary, 0.0),
            element(3, MapClass::Divider, 0.0),
        ])];
        let other = [frame(&[
            element(1, MapClass::Divider, 0.25),
            element(2, MapClass::PedCrossing, 0.0),
        ])];
        let d = deviation(&reference, &other);
        assert_eq!((d.elements, d.kept, d.flipped, d.dropped), (3, 1, 1, 1));
        assert!(
            (d.mean_chamfer_m - 0.25).abs() < 1e-6,
            "{}",
            d.mean_chamfer_m
        );
        assert!((d.changed_share() - 2.0 / 3.0).abs() < 1e-12);
        let same = deviation(&reference, &reference);
        assert_eq!((same.kept, same.mean_chamfer_m), (3, 0.0));
    }
}
