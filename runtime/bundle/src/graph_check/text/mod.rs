//! `graph.nnef` checked in one pass over its tokens, with a bounded bracket stack and no
//! recursion, so that no text can make the check itself deep or slow (tract's parser recurses
//! per nesting level).
//!
//! The accepted shape is the one tract-nnef writes for a tract-core graph:
//! `version 1.0;`, `extension tract_registry tract_core;`, at most one
//! `fragment tract_core_properties(...) -> (...) { ... }`, one `graph network(...) -> (...)
//! { statements }`. Every call names an allowlisted operator; every named attribute is
//! allowlisted and its numbers are range-checked (`vocabulary.rs`); `tokens.rs` splits the text.

mod tokens;
mod vocabulary;

use tokens::{Token, tokens};
use vocabulary::{ATTRIBUTES, OPERATORS, attribute_range};

use super::{MAX_NESTING, MAX_STATEMENTS, MAX_TENSOR_ELEMENTS};

/// What is wrong in `graph.nnef`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TextRule {
    /// Not UTF-8.
    #[error("not UTF-8")]
    NotUtf8,
    /// A character outside NNEF's tokens, an unterminated string or a malformed number.
    #[error("not an NNEF token")]
    Token,
    /// The header is not `version 1.0;` and tract-core's extension.
    #[error("header: `{0}` (only `version 1.0;` and `extension tract_registry tract_core;`)")]
    Header(String),
    /// A fragment other than tract's properties.
    #[error("fragment `{0}`: only tract_core_properties is allowed")]
    Fragment(String),
    /// No graph, or a second one.
    #[error("exactly one graph is allowed")]
    GraphCount,
    /// Brackets nested deeper than [`MAX_NESTING`], or unbalanced.
    #[error("brackets nested deeper than {MAX_NESTING} or unbalanced")]
    Nesting,
    /// More statements than [`MAX_STATEMENTS`].
    #[error("more than {MAX_STATEMENTS} statements")]
    Statements,
    /// A call of an operator not on the allowlist.
    #[error("operator `{0}` is not allowed")]
    Operator(String),
    /// A named attribute not on the allowlist.
    #[error("attribute `{0}` is not allowed")]
    Attribute(String),
    /// A number out of its attribute's range, beyond 2^31, or not finite.
    #[error("`{attribute}` = {value} is out of range")]
    Value {
        /// The attribute (`literal` outside any).
        attribute: String,
        /// The number as written.
        value: String,
    },
    /// An attribute's list breaks a rule over the whole list (no permutation, an axis twice,
    /// more than 16 numbers).
    #[error("{operator}: `{attribute}` = {values:?} is no valid list")]
    List {
        /// The operator.
        operator: String,
        /// The attribute.
        attribute: String,
        /// Its numbers so far.
        values: Vec<i64>,
    },
    /// A declared shape of more than [`MAX_TENSOR_ELEMENTS`] elements.
    #[error("a shape of more than {MAX_TENSOR_ELEMENTS} elements")]
    ShapeTooLarge,
}

/// Where the checker is between top-level items.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Top {
    /// Expecting `version`, `extension`, `fragment` or `graph`.
    Item,
    /// Inside a header line, until `;`.
    Header,
    /// Inside a fragment or graph declaration, until its body closes.
    Declaration,
}

/// What an open bracket is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Open<'a> {
    close: u8,
    /// The operator whose argument list this is (its named attributes are checked).
    call: Option<&'a str>,
}

/// Most numbers one range-checked attribute may hold (a rank-8 padding has 16).
const MAX_ATTRIBUTE_VALUES: usize = 16;

/// The attribute whose value is being read.
struct Reading<'a> {
    name: &'a str,
    /// The operator it belongs to.
    operator: &'a str,
    /// Depth of the call's argument list.
    depth: usize,
    values: heapless::Vec<i64, MAX_ATTRIBUTE_VALUES>,
}

/// Check `text` as the module doc says; `Err((line, rule))` at the first fault.
pub fn check(text: &str) -> Result<(), (usize, TextRule)> {
    let mut stack: [Open<'_>; MAX_NESTING] = [Open {
        close: 0,
        call: None,
    }; MAX_NESTING];
    let mut depth = 0usize;
    let mut top = Top::Item;
    let mut header: Vec<&str> = Vec::new();
    let (mut graphs, mut fragments, mut statements) = (0usize, 0usize, 0usize);
    // The last identifier (a call's name when `(` follows), and `variable<scalar>(`'s name
    // carried over its type.
    let mut last_ident: Option<&str> = None;
    let mut typed_call: Option<&str> = None;
    let mut attribute: Option<Reading<'_>> = None;
    let mut declared: Option<&str> = None;
    let mut negative = false;
    let mut previous: Option<Token<'_>> = None;
    for token in tokens(text) {
        let (line, token) = token.map_err(|line| (line, TextRule::Token))?;
        let fail = |rule| Err((line, rule));
        match (top, token) {
            (Top::Item, Token::Ident(word @ ("version" | "extension"))) => {
                top = Top::Header;
                header.clear();
                header.push(word);
            }
            (Top::Item, Token::Ident(word @ ("fragment" | "graph"))) => {
                top = Top::Declaration;
                declared = Some(word);
            }
            (Top::Item, _) => return fail(TextRule::Header(format!("{token:?}"))),
            (Top::Header, Token::Punct(b';')) => {
                let line_ok = matches!(
                    header.as_slice(),
                    ["version", "1", ".", "0"] | ["version", "1.0"]
                ) || header.as_slice()
                    == ["extension", "tract_registry", "tract_core"];
                if !line_ok {
                    return fail(TextRule::Header(header.join(" ")));
                }
                top = Top::Item;
            }
            (Top::Header, Token::Ident(w) | Token::Number(w)) if header.len() < 4 => {
                header.push(w);
            }
            (Top::Header, _) => return fail(TextRule::Header(header.join(" "))),
            (Top::Declaration, _) => {
                // The declared name: the identifier right after `fragment` / `graph`.
                if let (Some(kind), Token::Ident(name)) = (declared, token) {
                    match kind {
                        "fragment" if name == "tract_core_properties" && fragments == 0 => {
                            fragments += 1;
                        }
                        "fragment" => return fail(TextRule::Fragment(name.to_owned())),
                        _ if graphs == 0 => graphs += 1,
                        _ => return fail(TextRule::GraphCount),
                    }
                    declared = None;
                    previous = Some(token);
                    continue;
                }
                match token {
                    Token::Punct(open @ (b'(' | b'[' | b'{')) => {
                        if depth == MAX_NESTING {
                            return fail(TextRule::Nesting);
                        }
                        let callee = match (open, previous) {
                            (b'(', Some(Token::Ident(name))) => Some(name),
                            (b'(', Some(Token::Punct(b'>'))) => typed_call.take(),
                            _ => None,
                        };
                        // A call inside a declaration's signature or body (not the declared
                        // name's own parameter list, which `declared` consumed above).
                        let in_body = stack[..depth].iter().any(|o| o.close == b'}');
                        let call = callee.filter(|_| in_body);
                        if let Some(name) = call
                            && !OPERATORS.contains(&name)
                        {
                            return fail(TextRule::Operator(name.to_owned()));
                        }
                        stack[depth] = Open {
                            close: match open {
                                b'(' => b')',
                                b'[' => b']',
                                _ => b'}',
                            },
                            call,
                        };
                        depth += 1;
                    }
                    Token::Punct(close @ (b')' | b']' | b'}')) => {
                        if depth == 0 || stack[depth - 1].close != close {
                            return fail(TextRule::Nesting);
                        }
                        depth -= 1;
                        if attribute.as_ref().is_some_and(|a| a.depth > depth) {
                            end_attribute(attribute.take()).map_err(|rule| (line, rule))?;
                        }
                        if close == b'}' && depth == 0 {
                            top = Top::Item;
                        }
                    }
                    Token::Punct(b',') if attribute.as_ref().is_some_and(|a| a.depth == depth) => {
                        end_attribute(attribute.take()).map_err(|rule| (line, rule))?;
                    }
                    Token::Punct(b';') if depth == 1 => {
                        statements += 1;
                        if statements > MAX_STATEMENTS {
                            return fail(TextRule::Statements);
                        }
                    }
                    Token::Punct(b'=') if depth > 0 && stack[depth - 1].call.is_some() => {
                        let (Some(Token::Ident(name)), Some(operator)) =
                            (previous, stack[depth - 1].call)
                        else {
                            return fail(TextRule::Token);
                        };
                        if !ATTRIBUTES.contains(&name) {
                            return fail(TextRule::Attribute(name.to_owned()));
                        }
                        attribute = Some(Reading {
                            name,
                            operator,
                            depth,
                            values: heapless::Vec::new(),
                        });
                    }
                    Token::Punct(b'<') if matches!(previous, Some(Token::Ident(_))) => {
                        typed_call = last_ident;
                    }
                    Token::Punct(b'-') => {
                        negative = true;
                        previous = Some(token);
                        continue;
                    }
                    Token::Number(digits) => {
                        check_number(attribute.as_mut(), digits, negative)
                            .map_err(|rule| (line, rule))?;
                    }
                    _ => {}
                }
            }
        }
        if let Token::Ident(name) = token {
            last_ident = Some(name);
        }
        negative = false;
        previous = Some(token);
    }
    if depth != 0 || top != Top::Item {
        return Err((0, TextRule::Nesting));
    }
    if graphs != 1 {
        return Err((0, TextRule::GraphCount));
    }
    Ok(())
}

/// The attribute's value ended: the rules over its whole list (a shape's size, a transpose's
/// permutation, distinct axes).
fn end_attribute(reading: Option<Reading<'_>>) -> Result<(), TextRule> {
    let Some(reading) = reading else {
        return Ok(());
    };
    let values = reading.values.as_slice();
    let refuse = || TextRule::List {
        operator: reading.operator.to_owned(),
        attribute: reading.name.to_owned(),
        values: values.to_vec(),
    };
    match reading.name {
        "shape" => {
            let elements = values
                .iter()
                .fold(1u64, |n, &d| n.saturating_mul(d.unsigned_abs().max(1)));
            if elements > MAX_TENSOR_ELEMENTS {
                return Err(TextRule::ShapeTooLarge);
            }
        }
        "axes" => {
            // tract loops on a transpose that is no permutation (it allocated 8 GiB on
            // `[2, 0, 2]`), and an axis named twice means nothing to a reduction.
            let distinct = values
                .iter()
                .enumerate()
                .all(|(i, a)| !values[..i].contains(a));
            let permutation = reading.operator != "transpose"
                || (0..values.len()).all(|i| values.contains(&(i as i64)));
            if !distinct || !permutation {
                return Err(refuse());
            }
        }
        _ => {}
    }
    Ok(())
}

/// One number, under the attribute being read (if any).
fn check_number(
    reading: Option<&mut Reading<'_>>,
    digits: &str,
    negative: bool,
) -> Result<(), TextRule> {
    let attribute = reading.as_ref().map_or("literal", |r| r.name);
    let refuse = || TextRule::Value {
        attribute: attribute.to_owned(),
        value: format!("{}{digits}", if negative { "-" } else { "" }),
    };
    let range = attribute_range(attribute);
    if digits.contains(['.', 'e', 'E']) {
        let value: f64 = digits.parse().map_err(|_| refuse())?;
        return if value.is_finite() && range.is_none() {
            Ok(())
        } else {
            Err(refuse())
        };
    }
    let magnitude: i64 = digits.parse().map_err(|_| refuse())?;
    let value = if negative { -magnitude } else { magnitude };
    let (low, high) = range.unwrap_or((-(1 << 31), 1 << 31));
    if !(low..=high).contains(&value) {
        return Err(refuse());
    }
    if let (Some(reading), Some(_)) = (reading, range) {
        reading.values.push(value).map_err(|_| TextRule::List {
            operator: reading.operator.to_owned(),
            attribute: attribute.to_owned(),
            values: reading.values.to_vec(),
        })?;
    }
    Ok(())
}
