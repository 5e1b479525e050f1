//! Why a model's dimensions cannot run on this runtime (checked when a bundle or engine is
//! opened, before any buffer is sized from them).

use core::fmt;

use crate::pose::Axis;

/// A side of an image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageSide {
    /// Rows.
    Height,
    /// Columns.
    Width,
}

/// Why a [`ModelDims`](super::ModelDims) cannot run on this runtime.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum DimsError {
    /// A size that must be positive is zero.
    Zero {
        /// Field name.
        field: &'static str,
    },
    /// A number is NaN or infinite.
    NonFinite {
        /// Field name.
        field: &'static str,
    },
    /// `embed_dims` does not split into the GKT heads.
    EmbedDimsNotDivisibleByHeads {
        /// The configured channels.
        embed_dims: usize,
        /// Heads the channels must split into.
        heads: usize,
    },
    /// More BEV queries than the look-up table can address.
    TooManyQueries {
        /// `bev_h * bev_w`.
        queries: usize,
        /// Capacity.
        max: usize,
    },
    /// A feature map larger than the look-up table can address.
    TooManyFeatures {
        /// `feat_h * feat_w`.
        features: usize,
        /// Capacity.
        max: usize,
    },
    /// The GKT kernel is larger than the weights buffer allows.
    KernelTooLarge {
        /// `kernel_h * kernel_w`.
        points: usize,
        /// Capacity.
        max: usize,
    },
    /// Points per instance differ from the fixed polyline length.
    PointsMismatch {
        /// Configured points.
        num_pts: usize,
        /// Fixed capacity.
        expected: usize,
    },
    /// `top_k` is larger than the output capacity or than `num_vec * classes`.
    TopKTooLarge {
        /// Configured top-k.
        top_k: usize,
        /// Largest allowed value.
        max: usize,
    },
    /// The padded image is smaller than the image on one side.
    PaddingSmallerThanImage {
        /// The side.
        side: ImageSide,
    },
    /// `pc_range_m` has `min >= max` on an axis of the ego frame.
    EmptyRange {
        /// The axis.
        axis: Axis,
    },
    /// A positive quantity (scale, ground sampling distance) is not positive.
    NotPositive {
        /// Field name.
        field: &'static str,
    },
    /// A quantity above its maximum.
    AboveMax {
        /// Field name.
        field: &'static str,
        /// The largest accepted value (whole units of the field).
        max: u32,
    },
    /// A derived buffer length in bytes does not fit `usize`.
    SizeOverflow,
    /// A GKT reference height lies outside the z range of `pc_range_m`.
    HeightOutsideRange {
        /// The head whose height is outside.
        head: usize,
    },
    /// The satellite crop does not cover the BEV range (`sat_w * sat_gsd_m` against the x
    /// extent, `sat_h * sat_gsd_m` against the y extent).
    SatelliteExtent {
        /// True for the y extent (`sat_h`), false for x (`sat_w`).
        along_y: bool,
    },
}

impl fmt::Display for DimsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Zero { field } => write!(f, "model dimension `{field}` is zero"),
            Self::NonFinite { field } => write!(f, "model field `{field}` is not finite"),
            Self::EmbedDimsNotDivisibleByHeads { embed_dims, heads } => {
                write!(
                    f,
                    "embed_dims {embed_dims} is not divisible by {heads} GKT heads"
                )
            }
            Self::TooManyQueries { queries, max } => {
                write!(
                    f,
                    "{queries} BEV queries exceed the look-up table capacity {max}"
                )
            }
            Self::TooManyFeatures { features, max } => {
                write!(
                    f,
                    "{features} feature cells exceed the look-up table capacity {max}"
                )
            }
            Self::KernelTooLarge { points, max } => {
                write!(
                    f,
                    "GKT kernel of {points} points exceeds the capacity {max}"
                )
            }
            Self::PointsMismatch { num_pts, expected } => {
                write!(
                    f,
                    "num_pts {num_pts} differs from the fixed polyline length {expected}"
                )
            }
            Self::TopKTooLarge { top_k, max } => write!(f, "top_k {top_k} exceeds {max}"),
            Self::PaddingSmallerThanImage {
                side: ImageSide::Height,
            } => write!(f, "pad_h is smaller than image_h"),
            Self::PaddingSmallerThanImage {
                side: ImageSide::Width,
            } => write!(f, "pad_w is smaller than image_w"),
            Self::EmptyRange { axis } => {
                write!(f, "pc_range_m axis {axis} has min >= max")
            }
            Self::NotPositive { field } => write!(f, "model field `{field}` must be positive"),
            Self::SizeOverflow => write!(f, "model dimensions overflow a buffer length"),
            Self::AboveMax { field, max } => {
                write!(f, "model field `{field}` exceeds its maximum {max}")
            }
            Self::HeightOutsideRange { head } => write!(
                f,
                "gkt_heights_m[{head}] lies outside the z range of pc_range_m"
            ),
            Self::SatelliteExtent { along_y: true } => write!(
                f,
                "sat_h * sat_gsd_m differs from the y extent of pc_range_m"
            ),
            Self::SatelliteExtent { along_y: false } => write!(
                f,
                "sat_w * sat_gsd_m differs from the x extent of pc_range_m"
            ),
        }
    }
}

impl core::error::Error for DimsError {}
