//! The map element shared by the evaluator, the synthetic ground truth and the pictures: a
//! classed polyline in ego metres with a score.
//!
//! Frame: ego frame of the sample (x right, y forward, metres), the frame MapTR writes its
//! results in. Ground truth carries score 1.0.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The three map classes, in model order (label = index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapClass {
    /// Road and lane divider lines (label 0).
    Divider,
    /// Pedestrian crossings, closed rings (label 1).
    PedCrossing,
    /// Road boundaries, cut open at the patch edge (label 2).
    Boundary,
}

impl MapClass {
    /// All classes in label order.
    pub const ALL: [Self; 3] = [Self::Divider, Self::PedCrossing, Self::Boundary];

    /// Label index (0 divider, 1 ped_crossing, 2 boundary).
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Self::Divider => 0,
            Self::PedCrossing => 1,
            Self::Boundary => 2,
        }
    }

    /// Class of a label index, `None` outside 0..3.
    #[must_use]
    pub const fn from_index(index: usize) -> Option<Self> {
        match index {
            0 => Some(Self::Divider),
            1 => Some(Self::PedCrossing),
            2 => Some(Self::Boundary),
            _ => None,
        }
    }

    /// MapTR's `cls_name`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Divider => "divider",
            Self::PedCrossing => "ped_crossing",
            Self::Boundary => "boundary",
        }
    }

    /// Class of a MapTR `cls_name`, `None` if unknown.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

impl fmt::Display for MapClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One map element: a polyline of one class with a confidence.
#[derive(Clone, Debug, PartialEq)]
pub struct MapVector {
    /// Class of the element.
    pub class: MapClass,
    /// Points in ego metres `[x_m, y_m]`, in order along the element. A closed ring repeats its
    /// first point at the end.
    pub points_m: Vec<[f64; 2]>,
    /// Confidence in [0, 1]; 1.0 for ground truth.
    pub score: f64,
}

impl MapVector {
    /// A ground-truth element (score 1.0).
    #[must_use]
    pub fn ground_truth(class: MapClass, points_m: Vec<[f64; 2]>) -> Self {
        Self {
            class,
            points_m,
            score: 1.0,
        }
    }
}
