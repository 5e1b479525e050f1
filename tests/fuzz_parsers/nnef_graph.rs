//! The NNEF structural check harness: `parse_stage_graph` (the graph check, then tract's parse
//! of what passes, then the tensor-size check) on mutated stage tars (slot 0) and on mutated
//! `graph.nnef` texts sealed into the stage with its real tensor files (slot 1). Beyond "no
//! panic": nothing that passes the check may make tract's parser abort or hang (a case that
//! did would end this test binary, not fail a case), and tract's own panics come back as errors.
//!
//! An abort (an allocation tract could not make) ends the process with no case to shrink:
//! `SATMAP_DEBUG_LAST=<file>` writes each stage tar there before it is parsed, so the file left
//! behind is the culprit (how the non-permutation `transpose` was found, under `ulimit -v`).
//!
//! The seed is the committed `test` bundle's `bev_query` stage (159 statements, gathers,
//! reshapes, a tile: most of the attribute rules).

use std::io::Read as _;

use satmap_runtime::bundle::Bundle;
use satmap_runtime::engine::Stage;
use satmap_runtime::engine_tract::parse_stage_graph;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Parsed, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};

type Entries = Vec<(String, Vec<u8>)>;

fn seed_stage() -> Vec<u8> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/bundles/test.satmap");
    let bundle = Bundle::open(path).unwrap();
    bundle.read_stage(Stage::BevQuery).unwrap().into_owned()
}

fn entries(tar_bytes: &[u8]) -> Entries {
    let mut archive = tar::Archive::new(tar_bytes);
    archive
        .entries()
        .unwrap()
        .map(|e| {
            let mut e = e.unwrap();
            let name = e.path().unwrap().to_str().unwrap().to_owned();
            let mut data = Vec::new();
            e.read_to_end(&mut data).unwrap();
            (name, data)
        })
        .collect()
}

/// The stage with `graph.nnef` replaced by `text`.
fn with_text(tensors: &Entries, text: &[u8]) -> Vec<u8> {
    let mut builder = tar::Builder::new(Vec::new());
    let mut append = |name: &str, data: &[u8]| {
        let mut header = tar::Header::new_gnu();
        header.set_size(data.len() as u64);
        header.set_entry_type(tar::EntryType::Regular);
        header.set_path(name).unwrap();
        header.set_cksum();
        builder.append(&header, data).unwrap();
    };
    append("graph.nnef", text);
    for (name, data) in tensors {
        append(name, data);
    }
    builder.into_inner().unwrap()
}

fn graph_case(tensors: &Entries, input: &Input) -> CaseResult {
    let stage = if input.slot == 0 {
        input.bytes.clone()
    } else {
        with_text(tensors, &input.bytes)
    };
    if let Ok(path) = std::env::var("SATMAP_DEBUG_LAST") {
        std::fs::write(path, &stage).unwrap();
    }
    Ok(match parse_stage_graph(Stage::BevQuery, &stage) {
        Ok(()) => Accepted,
        Err(satmap_runtime::bundle::BundleError::Engine { .. }) => Parsed,
        Err(_) => Refused,
    })
}

/// Panics raised inside tract are caught by `parse_stage_graph` and counted as refusals; the
/// default hook would still print each one (thousands in a campaign). Those alone are silenced;
/// any other panic prints as before.
fn quiet_tract_panics() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let in_tract = info
            .location()
            .is_some_and(|l| l.file().contains("/tract-"));
        if !in_tract {
            default(info);
        }
    }));
}

#[test]
fn nnef_graph_check_never_lets_tract_abort() {
    quiet_tract_panics();
    let stage = seed_stage();
    let all = entries(&stage);
    let text = all
        .iter()
        .find(|(n, _)| n == "graph.nnef")
        .unwrap()
        .1
        .clone();
    let tensors: Entries = all.into_iter().filter(|(n, _)| n != "graph.nnef").collect();
    let seeds = vec![stage, text];
    assert_seeds_accepted(&seeds, |input| graph_case(&tensors, input));
    fuzz("nnef_graph", inputs(seeds, true), |input| {
        graph_case(&tensors, input)
    });
}
