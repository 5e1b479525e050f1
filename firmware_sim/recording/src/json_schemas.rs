//! The two channels of ours that no published schema covers, as JSON with a JSON Schema (the
//! MCAP `jsonschema` encoding Foxglove reads): the ego motion, and the health of each step.

use serde::{Deserialize, Serialize};

/// Schema name of [`EgoMotionMessage`].
pub const EGO_MOTION: &str = "satmap.EgoMotion";
/// Schema name of the step status channel.
pub const STEP_STATUS: &str = "satmap.StepStatus";
/// Message encoding of both.
pub const JSON: &str = "json";
/// Schema encoding of both.
pub const JSONSCHEMA: &str = "jsonschema";

/// A time as Foxglove's JSON messages write it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JsonTime {
    /// Seconds.
    pub sec: u32,
    /// Nanoseconds within the second.
    pub nsec: u32,
}

impl JsonTime {
    /// Split nanoseconds since the epoch (`None` past `u32::MAX` seconds).
    #[must_use]
    pub fn from_ns(ns: u64) -> Option<Self> {
        Some(Self {
            sec: u32::try_from(ns / 1_000_000_000).ok()?,
            nsec: (ns % 1_000_000_000) as u32,
        })
    }

    /// Nanoseconds since the epoch, or `None` with `nsec` past a second.
    #[must_use]
    pub fn to_ns(self) -> Option<u64> {
        (self.nsec < 1_000_000_000)
            .then(|| u64::from(self.sec) * 1_000_000_000 + u64::from(self.nsec))
    }
}

/// `satmap.EgoMotion`: the ego's motion in the ego frame (x right, y forward, z up), the
/// runtime's `EgoMotion` field for field.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgoMotionMessage {
    /// Measurement time.
    pub timestamp: JsonTime,
    /// Linear acceleration, m/s^2.
    pub acceleration_mps2: [f32; 3],
    /// Angular rate, rad/s.
    pub rotation_rate_radps: [f32; 3],
    /// Linear velocity, m/s.
    pub velocity_mps: [f32; 3],
}

/// JSON Schema of [`EgoMotionMessage`].
pub const EGO_MOTION_SCHEMA: &str = r#"{
  "title": "satmap.EgoMotion",
  "description": "Ego motion in the ego frame (x right, y forward, z up), as the SatMap runtime takes it",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}}, "required": ["sec", "nsec"]},
    "acceleration_mps2": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
    "rotation_rate_radps": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
    "velocity_mps": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
  },
  "required": ["timestamp", "acceleration_mps2", "rotation_rate_radps", "velocity_mps"]
}"#;

/// JSON Schema of the step status channel (the message itself is the harness's: per step its
/// sequence, health, degraded reason, latency per stage and memory use).
pub const STEP_STATUS_SCHEMA: &str = r#"{
  "title": "satmap.StepStatus",
  "description": "One SatMap runtime step: health, why it ran degraded, latency per stage (wall time of the machine that replayed it) and memory use",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "sequence": {"type": "integer"},
    "map_digest": {"type": "string"},
    "degraded": {"type": "boolean"},
    "degraded_reason": {"type": ["string", "null"]},
    "deadline_miss": {"type": "boolean"},
    "cameras_missing": {"type": "array", "items": {"type": "integer"}},
    "latency_us": {"type": "object", "additionalProperties": {"type": "integer"}},
    "memory": {"type": "object", "additionalProperties": {"type": "integer"}}
  },
  "required": ["timestamp", "sequence", "map_digest", "degraded", "latency_us", "memory"]
}"#;
