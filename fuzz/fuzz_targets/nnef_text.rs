//! The structural check on `graph.nnef` texts: the input is sealed as a stage's only entry, so
//! every byte reaches the text rules (tokens, header, fragments, nesting, statements, operator
//! and attribute allowlists, value ranges).
#![no_main]

use libfuzzer_sys::fuzz_target;
use satmap_runtime::bundle::graph_check::check_nnef_stage;

fuzz_target!(|data: &[u8]| {
    let mut header = tar::Header::new_gnu();
    header.set_size(data.len() as u64);
    header.set_entry_type(tar::EntryType::Regular);
    if header.set_path("graph.nnef").is_err() {
        return;
    }
    header.set_cksum();
    let mut builder = tar::Builder::new(Vec::new());
    if builder.append(&header, data).is_err() {
        return;
    }
    if let Ok(stage) = builder.into_inner() {
        let _ = check_nnef_stage(&stage);
    }
});
