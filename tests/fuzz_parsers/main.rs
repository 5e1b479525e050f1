//! The fuzz pass over every parser that takes outside bytes: route pack, its compressed tile
//! payloads (through the JPEG and zlib decoders), bundle manifest (with
//! its `manifest.sha256`), the compiled bundle archive (and signed: archive and signature), a stage's NNEF graph (the structural check, then tract's parse), calibration TOML, `memory_layout.toml`, the scenario folder's files
//! (`scenario.toml`, `frame.toml`, `gt.json`), MapTR results / ground-truth JSON (all three
//! layouts), the GeoJSON route and MCAP recordings (`drive --recording`).
//!
//! Each case hands one input to the product's public entry point and, when that accepts it, to
//! what the product does next with the value (dims validation, region checks and the GKT table;
//! the LUT of a calibration; the generated constants and map of a layout; a frame read; crops of
//! a pack; an evaluation; a pack build), so a value that parses but breaks a later step is
//! found too. A panic or a broken invariant fails the case; proptest shrinks it and the minimal
//! input is written to `$CARGO_TARGET_TMPDIR/fuzz_parsers_failures/<parser>.bin`.
//!
//! Inputs are arbitrary bytes, bytes drawn from a seed's alphabet, and stacks of edits of real
//! seeds: the committed bundle manifest, calibration and layout, and files the product's own
//! writers produce (a synthetic scenario folder, MapTR files, a pack built from its route).
//! Edits are bit flips, byte sets, inserts, deletes, truncation, splices from any seed of the
//! parser, little-endian extreme words, repeated chunks (deep nesting, long lists), syntax
//! tokens, and number tokens replaced by extremes (1e308, -0, nan, 2^64, huge exponents).
//!
//! `SATMAP_FUZZ_CASES` is the number of cases per parser (default 256, the CI slice);
//! `SATMAP_FUZZ_SEED` the RNG seed (a number, or `random`; default fixed so CI repeats itself).
//! `make fuzz-parsers` is the 1,800,000-input campaign (`ARCHITECTURE.md`, "Fuzzing"). Every parser
//! prints one `fuzz <parser>: inputs run: N ... panics found: 0` line to stderr when it completes.
//!
//! Layout: `runner` (case count and seed, the `fuzz` loop, the summary line, the failure file),
//! `mutate` (the input strategies and edits), `seeds` (seeds and fixtures shared by harnesses),
//! one module per parser, and here the regression tests of the findings.

mod calibration;
mod compiled_bundle;
mod geojson_route;
mod libfuzzer_seeds;
mod manifest;
mod maptr_json;
mod mcap_recording;
mod memory_layout;
mod mutate;
mod nnef_graph;
mod route_pack;
mod runner;
mod scenario;
mod seeds;
mod signed_bundle;
mod tile_decode;

use satmap_sim::eval::maptr_json::MAX_COORDINATE_M;
use satmap_sim::eval::{ResultsFile, SampleSet, evaluate, read_file};
use satmap_sim::synth::scenario::frame_dir_name;

use crate::runner::Input;
use crate::runner::Outcome::Parsed;
use crate::runner::work_dir;
use crate::scenario::{scenario_case, scenario_folder};
use crate::seeds::seed_drive;

/// The first finding of this fuzz pass, kept: `read_frame` sized its buffer from the manifest's
/// image size before reading an image, so `image_width_px = 2^63 - 1` panicked (capacity
/// overflow) and a merely huge size aborted the process on the allocation.
#[test]
fn scenario_with_an_absurd_image_size_is_an_error() {
    let (dir, seeds) = scenario_folder("scenario_regression");
    let manifest = String::from_utf8(seeds[0].clone()).unwrap();
    assert!(manifest.contains("\nimage_width_px = 16\n"));
    for width in ["9223372036854775807", "1000000000"] {
        let bytes = manifest
            .replace(
                "\nimage_width_px = 16\n",
                &format!("\nimage_width_px = {width}\n"),
            )
            .into_bytes();
        let input = Input { slot: 0, bytes };
        assert_eq!(
            scenario_case(&input, dir.path(), &seeds).unwrap(),
            Parsed,
            "width {width}"
        );
    }
}

/// The second finding, kept: a finite but huge coordinate (1e308) passed the reader, the
/// evaluator's arc-length resampling overflowed to NaN and the 2 m buffer (i_overlay) panicked.
/// The reader now refuses coordinates beyond `MAX_COORDINATE_M`; at the bound, evaluation runs.
#[test]
fn maptr_coordinates_beyond_the_bound_are_refused_and_at_it_evaluate() {
    let tmp = work_dir("maptr_regression");
    let gt = SampleSet::from([(frame_dir_name(0), seed_drive().frame(0).ground_truth)]);
    let far = |c: f64| -> SampleSet {
        gt.iter()
            .map(|(token, vs)| {
                let mut vs = vs.clone();
                vs[0].points_m[1][0] = c;
                (token.clone(), vs)
            })
            .collect()
    };
    let file = tmp.path().join("far.json");
    for (c, refused) in [(1e308, true), (-1e7, true), (MAX_COORDINATE_M, false)] {
        ResultsFile::from_samples(&far(c), serde_json::Value::Null, true)
            .write(&file)
            .unwrap();
        let read = read_file(&file);
        assert_eq!(read.is_err(), refused, "coordinate {c}");
        if let Ok(loaded) = read {
            let report = evaluate(&loaded.samples, &gt);
            assert!((0.0..=1.0).contains(&report.mean_ap), "coordinate {c}");
        }
    }
}
