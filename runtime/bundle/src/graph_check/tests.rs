//! The committed bundles' stages pass; each rule refuses the edit that breaks it.

use super::*;
use crate::Bundle;
use satmap_core::engine::Stage;

fn committed_graphs() -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for name in ["test", "test-f16", "test-int8"] {
        let path = format!(
            "{}/../../models/bundles/{name}.satmap",
            env!("CARGO_MANIFEST_DIR")
        );
        let bundle = Bundle::open(&path).unwrap();
        for stage in Stage::ALL {
            out.push((
                format!("{name}/{}", stage.name()),
                bundle.read_stage(stage).unwrap().into_owned(),
            ));
        }
    }
    out
}

/// `graph.nnef` of a stage tar.
fn graph_text(stage_tar: &[u8]) -> String {
    let mut archive = tar::Archive::new(stage_tar);
    for entry in archive.entries().unwrap() {
        let mut entry = entry.unwrap();
        if entry.path().unwrap().to_str() == Some("graph.nnef") {
            let mut text = String::new();
            entry.read_to_string(&mut text).unwrap();
            return text;
        }
    }
    panic!("no graph.nnef")
}

#[test]
fn every_committed_stage_passes() {
    for (name, bytes) in committed_graphs() {
        assert_eq!(check_nnef_stage(&bytes), Ok(()), "{name}");
    }
}

fn rule_of(text: &str) -> TextRule {
    text::check(text).unwrap_err().1
}

#[test]
fn each_text_rule_refuses_its_edit() {
    let graphs = committed_graphs();
    let bev_query = graph_text(
        &graphs
            .iter()
            .find(|(n, _)| n == "test/bev_query")
            .unwrap()
            .1,
    );
    assert_eq!(text::check(&bev_query), Ok(()));
    let edit = |from: &str, to: &str| {
        assert!(bev_query.contains(from), "{from}");
        bev_query.replacen(from, to, 1)
    };
    assert!(matches!(
        rule_of(&edit("= squeeze(", "= frobnicate(")),
        TextRule::Operator(op) if op == "frobnicate"
    ));
    assert!(matches!(
        rule_of(&edit("axes = [0]", "axes = [9]")),
        TextRule::Value { attribute, .. } if attribute == "axes"
    ));
    assert!(matches!(
        rule_of(&edit("transposeB = true", "colour = true")),
        TextRule::Attribute(a) if a == "colour"
    ));
    // tract looped allocating on this transpose (found by the nnef_graph fuzz harness).
    assert!(matches!(
        rule_of(&edit("axes = [1, 0, 2]", "axes = [2, 0, 2]")),
        TextRule::List { operator, .. } if operator == "transpose"
    ));
    assert!(matches!(
        rule_of(&edit("axes = [1, 0, 2]", "axes = [1, 0, 3]")),
        TextRule::List { .. }
    ));
    assert!(matches!(
        rule_of(&edit("shape = [18]", "shape = [65536, 65536]")),
        TextRule::ShapeTooLarge
    ));
    assert!(matches!(
        rule_of(&edit("version 1.0;", "version 2.0;")),
        TextRule::Header(_)
    ));
    assert!(matches!(
        rule_of(&edit(
            "extension tract_registry tract_core;",
            "extension tract_registry tract_onnx;"
        )),
        TextRule::Header(_)
    ));
    assert!(matches!(
        rule_of(&edit("fragment tract_core_properties(", "fragment recurse(")),
        TextRule::Fragment(f) if f == "recurse"
    ));
    // A recursive fragment: its declaration is refused, so its call never parses.
    let recursive = edit(
        "graph network(",
        "fragment f(x: tensor<scalar>) -> (y: tensor<scalar>) { y = f(x); }\ngraph network(",
    );
    assert!(matches!(rule_of(&recursive), TextRule::Fragment(f) if f == "f"));
    assert_eq!(
        rule_of(&format!("{bev_query}\ngraph other() -> () {{ }}")),
        TextRule::GraphCount
    );
    // Nesting: 40 nested calls in one statement.
    let nested = format!("{}can_bus{}", "add(".repeat(40), ", can_bus)".repeat(40));
    let deep = edit("unsqueeze(can_bus, axes = [0])", &nested);
    assert_eq!(rule_of(&deep), TextRule::Nesting);
    // 16k statements: refused at the limit, without parsing the rest.
    let chain: String = (0..16_000)
        .map(|i| format!("  c{i} = add(can_bus, can_bus);\n"))
        .collect();
    assert_eq!(
        rule_of(&edit(
            "  can_bus = external(",
            &format!("{chain}  can_bus = external(")
        )),
        TextRule::Statements
    );
    for (from, to) in [("= [0.0];", "= [1e999];"), ("= [0.0];", "= [4294967296];")] {
        assert!(
            matches!(rule_of(&edit(from, to)), TextRule::Value { .. }),
            "{to}"
        );
    }
    assert_eq!(
        rule_of(&edit("axes = [0]", "axes = [0]]")),
        TextRule::Nesting
    );
    assert_eq!(
        rule_of(&edit("axes = [0]", "axes = [0] @")),
        TextRule::Token
    );
}

#[test]
fn conv_attributes_are_range_checked() {
    let graphs = committed_graphs();
    let image = graph_text(
        &graphs
            .iter()
            .find(|(n, _)| n == "test/image_encoder")
            .unwrap()
            .1,
    );
    assert_eq!(text::check(&image), Ok(()));
    for (from, to, attribute) in [
        ("stride = [2, 2]", "stride = [0, 2]", "stride"),
        (
            "padding = [(3, 15), (3, 3)]",
            "padding = [(-3, 15), (3, 3)]",
            "padding",
        ),
        ("dilation = [1, 1]", "dilation = [1, 0]", "dilation"),
        ("groups = 1", "groups = 0", "groups"),
    ] {
        assert!(image.contains(from), "{from}");
        assert!(
            matches!(rule_of(&image.replacen(from, to, 1)), TextRule::Value { attribute: a, .. } if a == attribute),
            "{to}"
        );
    }
}

#[test]
fn entry_rules_name_the_entry() {
    let write = |entries: &[(&str, &[u8])]| {
        let mut builder = tar::Builder::new(Vec::new());
        for (name, bytes) in entries {
            let mut header = tar::Header::new_gnu();
            header.set_size(bytes.len() as u64);
            header.set_entry_type(tar::EntryType::Regular);
            // Raw name bytes: `set_path` itself refuses `..`.
            header.as_gnu_mut().unwrap().name[..name.len()].copy_from_slice(name.as_bytes());
            header.set_cksum();
            builder.append(&header, *bytes).unwrap();
        }
        builder.into_inner().unwrap()
    };
    let graphs = committed_graphs();
    let text = graph_text(&graphs[0].1);
    let entry_rule = |bytes: &[u8]| match check_nnef_stage(bytes) {
        Err(GraphCheckError::Entry { rule, .. }) => rule,
        other => panic!("{other:?}"),
    };
    assert_eq!(entry_rule(&write(&[])), EntryRule::GraphMissing);
    assert_eq!(
        entry_rule(&write(&[
            ("graph.nnef", text.as_bytes()),
            ("graph.nnef", text.as_bytes())
        ])),
        EntryRule::GraphTwice
    );
    assert_eq!(
        entry_rule(&write(&[("graph.nnef", text.as_bytes()), ("run.sh", b"x")])),
        EntryRule::UnknownKind
    );
    assert_eq!(
        entry_rule(&write(&[
            ("graph.nnef", text.as_bytes()),
            ("a/../../x.dat", b"x")
        ])),
        EntryRule::NotPlainName
    );
    assert!(matches!(
        check_nnef_stage(&write(&[
            ("graph.nnef", text.as_bytes()),
            ("w.dat", &[0u8; 64])
        ])),
        Err(GraphCheckError::Tensor {
            rule: TensorRule::Header,
            ..
        })
    ));
}
