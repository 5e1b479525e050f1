//! The structural check of a compiled stage, `check_nnef_stage`, on whole stage tars: entries,
//! tensor-file headers and `graph.nnef` (tract itself is fuzzed behind the check by
//! `tests/fuzz_parsers/nnef_graph.rs`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use satmap_runtime::bundle::graph_check::check_nnef_stage;

fuzz_target!(|data: &[u8]| {
    let _ = check_nnef_stage(data);
});
