//! The structural check of a compiled stage (an NNEF tar) before tract parses any of it.
//!
//! A bundle's hashes say the bytes are the ones sealed, not that the graph is one the engine can
//! afford: issue 38's forgeries, re-sealed with valid hashes, made tract panic (an axis past the
//! rank, a stride of 0, negative padding), abort (stack overflow from nested expressions or a
//! recursive fragment, an 8 GiB allocation) or hang (parse time grows ~1.7x per nesting level; a
//! 16k-node chain took 105 s). Signatures ([`super::signature`]) keep strangers' graphs out; this
//! check bounds what even a signed graph may ask, in one linear pass without recursion:
//! - the tar: regular files only, plain relative names, `graph.nnef` once and at most
//!   [`MAX_GRAPH_TEXT_BYTES`], every other entry a `.dat` tensor (`tensor_file.rs`: header
//!   consistent with its bytes, rank <= 8, at most [`MAX_TENSOR_ELEMENTS`]);
//! - the text (`text/`): the one header tract writes, no fragment but its properties, one
//!   graph of at most [`MAX_STATEMENTS`] statements, brackets nested at most [`MAX_NESTING`]
//!   deep, calls to allowlisted operators only, attributes allowlisted with their values in
//!   range (axes inside a rank of 8, strides and sizes >= 1, padding >= 0, no literal beyond
//!   2^31, every float finite).
//!
//! What passes can still be a graph tract refuses or panics on (an axis inside 8 but past its
//! tensor's rank): the engine catches those panics and names the stage (`engine_tract`).

mod tensor_file;
mod text;

use std::io::Read as _;

pub use tensor_file::TensorRule;
pub use text::TextRule;

/// Largest `graph.nnef`, bytes (the `test` bundle's largest, `satellite_encoder`, is 134 KB).
pub const MAX_GRAPH_TEXT_BYTES: usize = 4 << 20;
/// Most entries in a stage tar.
pub const MAX_ENTRIES: usize = 4096;
/// Most statements in the graph body (the `test` bundle's largest has 670).
pub const MAX_STATEMENTS: usize = 8192;
/// Deepest nesting of `( [ {` (tract's own output nests at most 4 deep).
pub const MAX_NESTING: usize = 8;
/// Most elements of one tensor file or declared shape (256 MiB of f32).
pub const MAX_TENSOR_ELEMENTS: u64 = 1 << 26;

/// Why a stage's NNEF tar was refused before tract saw it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GraphCheckError {
    /// The bytes are no tar archive of regular files.
    #[error("not a tar archive of regular files: {0}")]
    Archive(String),
    /// An entry the stage cannot hold.
    #[error("entry `{name}`: {rule}")]
    Entry {
        /// The entry's name.
        name: String,
        /// What is wrong.
        rule: EntryRule,
    },
    /// A tensor file's header.
    #[error("tensor file `{name}`: {rule}")]
    Tensor {
        /// The entry's name.
        name: String,
        /// What is wrong.
        rule: TensorRule,
    },
    /// A tensor of the parsed graph with a symbolic shape or more than
    /// [`MAX_TENSOR_ELEMENTS`] elements (checked on tract's parse, before constants fold).
    #[error(
        "node `{node}`: output shape {shape} is not static within {MAX_TENSOR_ELEMENTS} elements"
    )]
    TensorSize {
        /// The node's name.
        node: String,
        /// Its output shape as tract inferred it.
        shape: String,
    },
    /// `graph.nnef`.
    #[error("graph.nnef line {line}: {rule}")]
    Text {
        /// 1-based line of the offending token.
        line: usize,
        /// What is wrong.
        rule: TextRule,
    },
}

/// What is wrong with a tar entry.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EntryRule {
    /// A link, folder or device entry.
    #[error("not a regular file")]
    NotRegular,
    /// Absolute, with `..`, empty, or not UTF-8.
    #[error("not a plain relative name")]
    NotPlainName,
    /// Neither `graph.nnef` nor `*.dat`.
    #[error("neither graph.nnef nor a .dat tensor")]
    UnknownKind,
    /// More than [`MAX_ENTRIES`].
    #[error("more than {MAX_ENTRIES} entries")]
    TooMany,
    /// `graph.nnef` a second time.
    #[error("graph.nnef twice")]
    GraphTwice,
    /// `graph.nnef` beyond [`MAX_GRAPH_TEXT_BYTES`].
    #[error("{bytes} bytes, at most {MAX_GRAPH_TEXT_BYTES}")]
    GraphTooLarge {
        /// Its size.
        bytes: u64,
    },
    /// No `graph.nnef` at all.
    #[error("the stage has no graph.nnef")]
    GraphMissing,
}

/// Check a compiled stage's bytes (an NNEF tar) as the module doc says.
///
/// # Errors
/// The first rule broken, naming the entry, or the line of `graph.nnef`.
pub fn check_nnef_stage(bytes: &[u8]) -> Result<(), GraphCheckError> {
    let mut archive = tar::Archive::new(bytes);
    let entries = archive
        .entries()
        .map_err(|e| GraphCheckError::Archive(e.to_string()))?;
    let mut graph: Option<String> = None;
    for (index, entry) in entries.enumerate() {
        let mut entry = entry.map_err(|e| GraphCheckError::Archive(e.to_string()))?;
        let name = entry
            .path()
            .ok()
            .and_then(|p| p.to_str().map(str::to_owned))
            .unwrap_or_default();
        let refuse = |rule| GraphCheckError::Entry {
            name: name.clone(),
            rule,
        };
        if index >= MAX_ENTRIES {
            return Err(refuse(EntryRule::TooMany));
        }
        if entry.header().entry_type() != tar::EntryType::Regular {
            return Err(refuse(EntryRule::NotRegular));
        }
        if !plain_name(&name) {
            return Err(refuse(EntryRule::NotPlainName));
        }
        let size = entry.size();
        if name == "graph.nnef" {
            if graph.is_some() {
                return Err(refuse(EntryRule::GraphTwice));
            }
            if size > MAX_GRAPH_TEXT_BYTES as u64 {
                return Err(refuse(EntryRule::GraphTooLarge { bytes: size }));
            }
            let mut text = Vec::new();
            entry
                .read_to_end(&mut text)
                .map_err(|e| GraphCheckError::Archive(e.to_string()))?;
            graph = Some(String::from_utf8(text).map_err(|_| GraphCheckError::Text {
                line: 0,
                rule: TextRule::NotUtf8,
            })?);
        } else if name.ends_with(".dat") {
            let mut header = [0u8; tensor_file::HEADER_BYTES];
            let read = entry.read_exact(&mut header);
            tensor_file::check(&header, size, read.is_ok()).map_err(|rule| {
                GraphCheckError::Tensor {
                    name: name.clone(),
                    rule,
                }
            })?;
        } else {
            return Err(refuse(EntryRule::UnknownKind));
        }
    }
    let graph = graph.ok_or(GraphCheckError::Entry {
        name: "graph.nnef".into(),
        rule: EntryRule::GraphMissing,
    })?;
    text::check(&graph).map_err(|(line, rule)| GraphCheckError::Text { line, rule })
}

/// A relative path of normal components (no `.`, `..`, root or prefix), not empty.
fn plain_name(name: &str) -> bool {
    use std::path::Component;
    !name.is_empty()
        && !name.contains('\\')
        && std::path::Path::new(name)
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
}

#[cfg(test)]
mod tests;
