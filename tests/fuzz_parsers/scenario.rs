//! The scenario folder harness: one of `scenario.toml`, `frames/000000/frame.toml` and
//! `frames/000000/gt.json` replaced in a folder the product's writer made, then
//! `Scenario::open` and a frame read.

use std::path::Path;

use proptest::prelude::*;
use satmap_sim::synth::scenario::Scenario;
use satmap_sim::synth::{ScenarioPlacement, write_scenario};
use tempfile::TempDir;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Parsed, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz, work_dir};
use crate::seeds::seed_drive;

const SCENARIO_FILES: [&str; 3] = [
    "scenario.toml",
    "frames/000000/frame.toml",
    "frames/000000/gt.json",
];

/// The seed drive written as a scenario folder by the product's writer, and its three files.
pub fn scenario_folder(name: &str) -> (TempDir, Vec<Vec<u8>>) {
    let dir = work_dir(name);
    write_scenario(
        seed_drive(),
        dir.path(),
        &ScenarioPlacement::default(),
        |_| {},
    )
    .unwrap();
    let seeds = SCENARIO_FILES
        .iter()
        .map(|f| std::fs::read(dir.path().join(f)).unwrap())
        .collect();
    (dir, seeds)
}

pub fn scenario_case(input: &Input, dir: &Path, seeds: &[Vec<u8>]) -> CaseResult {
    // Every file is rewritten, so a case never sees the edits of the one before (a failing case
    // is re-run many times while shrinking).
    for (slot, file) in SCENARIO_FILES.iter().enumerate() {
        let bytes = if slot == input.slot {
            &input.bytes
        } else {
            &seeds[slot]
        };
        std::fs::write(dir.join(file), bytes).unwrap();
    }
    let Ok(scenario) = Scenario::open(dir) else {
        return Ok(Refused);
    };
    let n = scenario.manifest.num_frames;
    prop_assert!(n > 0);
    prop_assert!(scenario.read_frame(n).is_err());
    Ok(match scenario.read_frame(0) {
        Ok(_) => Accepted,
        Err(_) => Parsed,
    })
}

#[test]
fn scenario_never_panics() {
    let (dir, seeds) = scenario_folder("scenario");
    let body = |input: &Input| scenario_case(input, dir.path(), &seeds);
    assert_seeds_accepted(&seeds, body);
    fuzz("scenario", inputs(seeds.clone(), true), body);
}
