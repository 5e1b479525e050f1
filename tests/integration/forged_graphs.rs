//! The forged-archive generator (issue 38, part 2): the committed compiled bundle re-sealed
//! around an edited stage (graph text or tensor file), with every hash recomputed, so the bundle
//! opens self-consistently and only the graph check, or tract behind `catch_unwind`, stands
//! between the forgery and the engine. Each forgery of the kinds must give a clean
//! error naming the stage: at load, or for a table cut short (valid to every static check) at
//! the step that reads past it, after which the engine still runs.
//!
//! What still reaches tract (passes the structural check): an axis inside rank 8 but past the
//! tensor's own rank (`sum_reduce` axis 7, `concat` axis 6), and tables that are only wrong for
//! the values a step brings. tract errors or panics on those; both are caught. A transpose that
//! is no permutation (`[5, 0, 2]`, `[2, 0, 2]`) no longer reaches it.

use std::io::Read as _;

use satmap_runtime::bundle::archive::write_archive;
use satmap_runtime::bundle::graph_check::{GraphCheckError, TensorRule, TextRule};
use satmap_runtime::bundle::{Bundle, BundleError, Sha256Digest, Trust};
use satmap_runtime::engine::{BackendFault, Engine, EngineErrorKind, Stage};
use satmap_runtime::engine_tract::TractEngine;

use crate::common::root;

type Entries = Vec<(String, Vec<u8>)>;

fn tar_entries(bytes: &[u8]) -> Entries {
    let mut archive = tar::Archive::new(bytes);
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

fn tar_of(entries: &Entries) -> Vec<u8> {
    let mut builder = tar::Builder::new(Vec::new());
    for (name, data) in entries {
        let mut header = tar::Header::new_gnu();
        header.set_size(data.len() as u64);
        header.set_mode(0o644);
        header.set_entry_type(tar::EntryType::Regular);
        header.set_path(name).unwrap();
        header.set_cksum();
        builder.append(&header, data.as_slice()).unwrap();
    }
    builder.into_inner().unwrap()
}

/// The committed `test.satmap` with `stage`'s NNEF tar entries passed through `edit`, re-sealed:
/// the stage's SHA-256 in the manifest and the archive digest recomputed.
fn forge(stage: Stage, edit: impl FnOnce(&mut Entries)) -> Vec<u8> {
    let outer = tar_entries(&std::fs::read(root().join("models/bundles/test.satmap")).unwrap());
    let mut manifest = String::from_utf8(outer[0].1.clone()).unwrap();
    let stage_name = format!("{}.nnef.tar", stage.name());
    let mut stages: Entries = outer[1..outer.len() - 1].to_vec();
    let (_, bytes) = stages.iter_mut().find(|(n, _)| *n == stage_name).unwrap();
    let old = Sha256Digest::of(bytes).to_string();
    let mut inner = tar_entries(bytes);
    edit(&mut inner);
    *bytes = tar_of(&inner);
    manifest = manifest.replacen(&old, &Sha256Digest::of(bytes).to_string(), 1);
    let refs: Vec<(&str, &[u8])> = stages
        .iter()
        .map(|(n, d)| (n.as_str(), d.as_slice()))
        .collect();
    write_archive(manifest.as_bytes(), &refs).unwrap()
}

/// `forge` with a text edit of `graph.nnef`: `from` (which must occur) replaced once by `to`.
fn forge_text(stage: Stage, from: &str, to: &str) -> Vec<u8> {
    forge(stage, |entries| {
        let (_, graph) = entries.iter_mut().find(|(n, _)| n == "graph.nnef").unwrap();
        let text = String::from_utf8(graph.clone()).unwrap();
        assert!(text.contains(from), "{}: `{from}`", stage.name());
        *graph = text.replacen(from, to, 1).into_bytes();
    })
}

/// The forgery opens (its hashes agree), then the engine refuses it at load, naming `stage`.
fn load_refused(stage: Stage, bytes: Vec<u8>) -> BundleError {
    let bundle = Bundle::from_archive_bytes("forged.satmap", bytes, &Trust::SelfConsistent, None)
        .expect("a re-sealed forgery is self-consistent");
    let e = TractEngine::load(&bundle).expect_err("the forgery loaded");
    let named = match &e {
        BundleError::Graph { stage: s, .. } | BundleError::Engine { stage: s, .. } => *s,
        other => panic!("{other}"),
    };
    assert_eq!(named, stage.name(), "{e}");
    e
}

fn text_rule(e: BundleError) -> TextRule {
    match e {
        BundleError::Graph {
            source: GraphCheckError::Text { rule, .. },
            ..
        } => rule,
        other => panic!("{other}"),
    }
}

#[test]
fn forged_graph_texts_are_refused_before_tract() {
    let nested = format!("{}can_bus{}", "add(".repeat(30), ", can_bus)".repeat(30));
    let chain: String = (0..16_000)
        .map(|i| format!("  c{i} = add(can_bus, can_bus);\n"))
        .collect();
    let bq = Stage::BevQuery;
    let cases: Vec<(&str, Stage, &str, String)> = vec![
        (
            "conv stride 0",
            Stage::ImageEncoder,
            "stride = [2, 2]",
            "stride = [0, 2]".into(),
        ),
        (
            "negative padding",
            Stage::ImageEncoder,
            "padding = [(3, 15), (3, 3)]",
            "padding = [(-3, 15), (3, 3)]".into(),
        ),
        (
            "reshape axis 9",
            bq,
            "axis_start = 1, axis_count = 1",
            "axis_start = 9, axis_count = 1".into(),
        ),
        (
            "nested expressions",
            bq,
            "unsqueeze(can_bus, axes = [0])",
            nested,
        ),
        (
            "recursive fragment",
            bq,
            "graph network(",
            "fragment f(x: tensor<scalar>) -> (y: tensor<scalar>) { y = f(x); }\ngraph network("
                .into(),
        ),
        (
            "16k-node chain",
            bq,
            "  can_bus = external(",
            format!("{chain}  can_bus = external("),
        ),
        (
            "8 GiB variable",
            bq,
            "label = \"can_bus_mlp.0.weight.0\", shape = [16, 18]",
            "label = \"can_bus_mlp.0.weight.0\", shape = [65536, 32768]".into(),
        ),
        (
            "tile 100000x",
            bq,
            "repeats = [1, 1, 4]",
            "repeats = [1, 1, 100000]".into(),
        ),
        (
            "transpose past the rank",
            bq,
            "axes = [1, 0, 2]",
            "axes = [5, 0, 2]".into(),
        ),
        (
            "unknown operator",
            bq,
            "= squeeze(",
            "= tract_onnx_lstm(".into(),
        ),
        (
            "another registry",
            bq,
            "tract_registry tract_core;",
            "tract_registry tract_onnx;".into(),
        ),
    ];
    for (what, stage, from, to) in cases {
        let rule = text_rule(load_refused(stage, forge_text(stage, from, &to)));
        println!("{what}: {rule}");
    }
}

#[test]
fn forged_tensor_files_are_refused_before_tract() {
    let set_header_u32 = |at: usize, value: u32| {
        move |entries: &mut Entries| {
            let (_, dat) = entries
                .iter_mut()
                .find(|(n, _)| n == "cams_embeds.0.dat")
                .unwrap();
            dat[at..at + 4].copy_from_slice(&value.to_le_bytes());
        }
    };
    for (what, at, value, want) in [
        ("rank 9", 8, 9, TensorRule::Rank(9)),
        (
            "bits u32::MAX",
            44,
            u32::MAX,
            TensorRule::ItemType {
                item_type: 0,
                vendor: 0,
                bits: u32::MAX,
            },
        ),
    ] {
        let e = load_refused(
            Stage::ImageEncoder,
            forge(Stage::ImageEncoder, set_header_u32(at, value)),
        );
        assert!(
            matches!(&e, BundleError::Graph { source: GraphCheckError::Tensor { rule, .. }, .. } if *rule == want),
            "{what}: {e}"
        );
    }
    // 2^32 rows declared over the same bytes.
    let e = load_refused(
        Stage::ImageEncoder,
        forge(Stage::ImageEncoder, set_header_u32(12, u32::MAX)),
    );
    assert!(
        matches!(
            e,
            BundleError::Graph {
                source: GraphCheckError::Tensor { .. },
                ..
            }
        ),
        "{e}"
    );
}

/// Axes inside rank 8 but past the tensor's rank pass the text check; tract refuses them (an
/// error or a caught panic), the stage named either way.
#[test]
fn what_reaches_tract_is_confined_to_an_error() {
    for (stage, from, to) in [
        (
            Stage::BevEncoder,
            "sum_reduce(__Add, axes = [1])",
            "sum_reduce(__Add, axes = [7])",
        ),
        (Stage::BevQuery, "axis = 2);", "axis = 6);"),
    ] {
        let e = load_refused(stage, forge_text(stage, from, to));
        assert!(matches!(e, BundleError::Engine { .. }), "{e}");
        println!("{}: {e}", stage.name());
    }
}

/// The camera-embedding table cut to 3 rows (graph and tensor file agree, every static check
/// passes): cameras 0-2 run, camera 4 reads past the table, and that run is a clean error of
/// `image_encoder`; the engine then runs camera 0 again with the same result as before.
#[test]
fn a_table_cut_short_fails_the_step_that_reads_past_it_and_the_engine_goes_on() {
    let forged = forge(Stage::ImageEncoder, |entries| {
        let (_, graph) = entries.iter_mut().find(|(n, _)| n == "graph.nnef").unwrap();
        let text = String::from_utf8(graph.clone()).unwrap();
        let from = "label = \"cams_embeds.0\", shape = [6, 32]";
        assert!(text.contains(from));
        *graph = text
            .replacen(from, "label = \"cams_embeds.0\", shape = [3, 32]", 1)
            .into_bytes();
        let (_, dat) = entries
            .iter_mut()
            .find(|(n, _)| n == "cams_embeds.0.dat")
            .unwrap();
        dat.truncate(128 + 3 * 32 * 4);
        dat[4..8].copy_from_slice(&(3u32 * 32 * 4).to_le_bytes());
        dat[12..16].copy_from_slice(&3u32.to_le_bytes());
    });
    let bundle =
        Bundle::from_archive_bytes("forged.satmap", forged, &Trust::SelfConsistent, None).unwrap();
    let mut engine = TractEngine::load(&bundle).expect("every static check passes");
    let dims = engine.dims().clone();
    let image = vec![128u8; dims.image_h * dims.image_w * 3];
    let mut value = vec![0f32; dims.value_len()];
    engine.encode_image(0, &image, &mut value).unwrap();
    let first = value.clone();
    let e = engine.encode_image(4, &image, &mut value).unwrap_err();
    assert_eq!(e.stage, Stage::ImageEncoder);
    assert!(
        matches!(
            e.kind,
            EngineErrorKind::Backend(BackendFault::RunPanicked | BackendFault::RunFailed)
        ),
        "{e}"
    );
    println!(
        "camera 4: {e}: {}",
        engine.last_error(Stage::ImageEncoder).unwrap_or("")
    );
    engine.encode_image(0, &image, &mut value).unwrap();
    assert_eq!(value, first);
}
