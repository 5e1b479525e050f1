//! Degraded steps: why a step ran without the satellite prior, and the per-reason counts and
//! shares the report states and judges against `--max-degraded-share`.
//!
//! The runtime's step output says *that* a step ran degraded and whether the prior was missing
//! or corrupt (`Health`); for a missing prior the route-pack source's crop report says whether
//! the crop found no imagery or could not be attempted (e.g. more tiles than the tile cache
//! holds), which the runtime folds into "missing".

use std::fmt;

use satmap_runtime::map_frame::{Health, SatellitePrior};
use satmap_runtime::route_pack::{CropFault, MAX_CROP_TILES};
use serde::Serialize;

/// Default of `--max-degraded-share`: a drive that loses the prior on more than one step in
/// twenty is reported as degraded (the demo drive loses it on none).
pub const DEFAULT_MAX_DEGRADED_SHARE: f64 = 0.05;

/// Why one step ran without the satellite prior.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DegradedReason {
    /// The route pack has no imagery under the crop (off the corridor, another place).
    NoCoverage,
    /// Imagery under the crop failed verification.
    CorruptTile,
    /// The crop spans more pack tiles than the tile cache holds (pack tiles too small).
    CropTooLarge,
    /// The source refused the crop for another reason (pose or crop geometry not usable).
    CropRefused,
    /// The runtime flagged the step degraded with a prior state this harness does not know.
    Other,
}

impl DegradedReason {
    /// Every reason, in report order.
    pub const ALL: [Self; 5] = [
        Self::NoCoverage,
        Self::CorruptTile,
        Self::CropTooLarge,
        Self::CropRefused,
        Self::Other,
    ];

    /// The reason of a step from its published health and the source's crop fault; `None`
    /// when the step was not degraded.
    #[must_use]
    pub const fn of(health: &Health, fault: Option<CropFault>) -> Option<Self> {
        if !health.degraded {
            return None;
        }
        Some(match (health.satellite, fault) {
            (SatellitePrior::Corrupt, _) => Self::CorruptTile,
            (SatellitePrior::Missing, None) => Self::NoCoverage,
            (SatellitePrior::Missing, Some(CropFault::TooManyTiles { .. })) => Self::CropTooLarge,
            (SatellitePrior::Missing, Some(_)) => Self::CropRefused,
            (SatellitePrior::Present | SatellitePrior::Partial { .. }, _) => Self::Other,
        })
    }
}

/// What the reason means, for the text report and error messages.
impl fmt::Display for DegradedReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoCoverage => {
                f.write_str("no coverage (no imagery in the route pack under the crop)")
            }
            Self::CorruptTile => f.write_str("corrupt tile (imagery failed verification)"),
            Self::CropTooLarge => write!(
                f,
                "crop too large for the tile cache (spans more than {MAX_CROP_TILES} pack tiles)"
            ),
            Self::CropRefused => f.write_str("crop refused (pose or crop geometry not usable)"),
            Self::Other => f.write_str("other (flagged degraded by the runtime)"),
        }
    }
}

/// Steps degraded for one reason.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReasonCount {
    /// The reason.
    pub reason: DegradedReason,
    /// Steps.
    pub steps: usize,
    /// Share of all steps, `0..=1`.
    pub share: f64,
}

/// Degraded steps of a replay, judged against the stated share.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DegradedReport {
    /// Steps that ran without the satellite prior.
    pub steps: usize,
    /// Their share of all steps, `0..=1`.
    pub share: f64,
    /// Largest share accepted (`--max-degraded-share`).
    pub max_share: f64,
    /// Per reason, only reasons that occurred, in [`DegradedReason::ALL`] order.
    pub by_reason: Vec<ReasonCount>,
    /// `share > max_share`.
    pub over_limit: bool,
}

impl DegradedReport {
    /// Count `reasons` (one per step, `None` for a normal step) against `max_share`.
    #[must_use]
    pub fn count(reasons: impl Iterator<Item = Option<DegradedReason>>, max_share: f64) -> Self {
        let mut per = [0usize; DegradedReason::ALL.len()];
        let mut total = 0usize;
        for r in reasons {
            total += 1;
            if let Some(r) = r {
                per[r as usize] += 1;
            }
        }
        let share_of = |n: usize| {
            if total == 0 {
                0.0
            } else {
                n as f64 / total as f64
            }
        };
        let steps = per.iter().sum();
        let share = share_of(steps);
        Self {
            steps,
            share,
            max_share,
            by_reason: DegradedReason::ALL
                .iter()
                .zip(per)
                .filter(|(_, n)| *n > 0)
                .map(|(&reason, n)| ReasonCount {
                    reason,
                    steps: n,
                    share: share_of(n),
                })
                .collect(),
            over_limit: share > max_share,
        }
    }

    /// "reason N (p%), ..." for the report and the error message.
    #[must_use]
    pub fn reasons_text(&self) -> String {
        self.by_reason
            .iter()
            .map(|c| format!("{} {} ({:.1}%)", c.reason, c.steps, 100.0 * c.share))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn health(satellite: SatellitePrior, degraded: bool) -> Health {
        Health {
            satellite,
            degraded,
            deadline_overrun: false,
            cameras: Default::default(),
        }
    }

    #[test]
    fn the_reason_comes_from_the_step_health_and_the_crop_fault() {
        let of = DegradedReason::of;
        let too_many = Some(CropFault::TooManyTiles { tiles: 64 });
        assert_eq!(of(&health(SatellitePrior::Present, false), None), None);
        assert_eq!(of(&health(SatellitePrior::Missing, false), too_many), None);
        let missing = health(SatellitePrior::Missing, true);
        assert_eq!(of(&missing, None), Some(DegradedReason::NoCoverage));
        assert_eq!(of(&missing, too_many), Some(DegradedReason::CropTooLarge));
        assert_eq!(
            of(&missing, Some(CropFault::PoseNotFinite)),
            Some(DegradedReason::CropRefused)
        );
        assert_eq!(
            of(&health(SatellitePrior::Corrupt, true), None),
            Some(DegradedReason::CorruptTile)
        );
        assert_eq!(
            of(&health(SatellitePrior::Present, true), None),
            Some(DegradedReason::Other)
        );
    }

    #[test]
    fn counts_and_shares_per_reason_against_the_limit() {
        use DegradedReason::{CorruptTile, NoCoverage};
        let steps = [
            None,
            Some(CorruptTile),
            None,
            Some(NoCoverage),
            Some(CorruptTile),
        ];
        let r = DegradedReport::count(steps.into_iter(), 0.5);
        assert_eq!(r.steps, 3);
        assert_eq!(r.share, 0.6);
        assert!(r.over_limit);
        assert_eq!(
            r.by_reason,
            [
                ReasonCount {
                    reason: NoCoverage,
                    steps: 1,
                    share: 0.2
                },
                ReasonCount {
                    reason: CorruptTile,
                    steps: 2,
                    share: 0.4
                },
            ]
        );
        assert_eq!(
            r.reasons_text(),
            "no coverage (no imagery in the route pack under the crop) 1 (20.0%), corrupt tile \
             (imagery failed verification) 2 (40.0%)"
        );
        // Exactly at the limit is accepted; a limit of 0 refuses one degraded step.
        assert!(!DegradedReport::count(steps.into_iter(), 0.6).over_limit);
        let one = DegradedReport::count([None, Some(NoCoverage)].into_iter(), 0.0);
        assert!(one.over_limit);
        let none = DegradedReport::count([None, None].into_iter(), 0.0);
        assert!(!none.over_limit && none.by_reason.is_empty() && none.share == 0.0);
    }
}
