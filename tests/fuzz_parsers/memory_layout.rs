//! The `memory_layout.toml` harness: `MemoryLayout::parse`, then the arena budget, the
//! generated constants and the rendered map of a layout that parses.

use proptest::prelude::*;
use satmap_layout::MemoryLayout;

use crate::mutate::inputs;
use crate::runner::Outcome::{Accepted, Refused};
use crate::runner::{CaseResult, Input, assert_seeds_accepted, fuzz};
use crate::seeds::{MEMORY_LAYOUT_TOML, PAPER_LAYOUT_TOML};

fn layout_case(input: &Input) -> CaseResult {
    let Ok(layout) = MemoryLayout::parse(&input.text()) else {
        return Ok(Refused);
    };
    prop_assert!(
        layout
            .runtime_bytes()
            .saturating_add(layout.arena.graph_engine_bytes)
            <= layout.arena.bytes
    );
    // What build.rs and `satmap-sim memory-map` do with a layout that passed.
    let consts = layout.to_rust_consts();
    for name in layout.region.keys() {
        prop_assert!(
            consts.contains(&name.to_uppercase()),
            "no constant for region {name}"
        );
    }
    let _ = layout.render_map();
    Ok(Accepted)
}

#[test]
fn memory_layout_never_panics() {
    let seeds = vec![
        MEMORY_LAYOUT_TOML.as_bytes().to_vec(),
        PAPER_LAYOUT_TOML.as_bytes().to_vec(),
    ];
    assert_seeds_accepted(&seeds, layout_case);
    fuzz("memory_layout", inputs(seeds, true), layout_case);
}
