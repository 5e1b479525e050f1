//! The input strategies: arbitrary bytes, bytes drawn from a seed's alphabet, and stacks of
//! edits of real seeds (bit flips, byte sets, inserts, deletes, truncation, splices from any
//! seed of the parser, little-endian extreme words, repeated chunks, syntax tokens, and number
//! tokens found by `number_spans` replaced by extremes or nudged).

use std::sync::{Arc, LazyLock};

use proptest::prelude::*;
use proptest::sample::Index;

use crate::runner::Input;

/// Edits with `head` land in the first bytes, where headers and top-level keys live (a pack's
/// header, route and index are a small part of it).
const HEAD: usize = 512;
/// Inputs are cut here, so repeats and splices cannot grow a case's cost without bound.
const MAX_INPUT: usize = 256 * 1024;

#[derive(Clone, Copy, Debug)]
struct Pos {
    head: bool,
    raw: usize,
}

impl Pos {
    /// An offset into `len` bytes (`len` itself allowed when `end`: inserting at the end).
    fn at(self, len: usize, end: bool) -> usize {
        let span = if end { len + 1 } else { len };
        let span = if self.head { span.min(HEAD) } else { span };
        if span == 0 { 0 } else { self.raw % span }
    }
}

#[derive(Clone, Debug)]
enum Edit {
    FlipBit(Pos, u8),
    SetByte(Pos, u8),
    Insert(Pos, Vec<u8>),
    Delete(Pos, usize),
    Truncate(Pos),
    /// Copy `len` bytes from seed `donor` at `from` over (or into) the input at `to`.
    Splice {
        donor: usize,
        from: Pos,
        len: usize,
        to: Pos,
        overwrite: bool,
    },
    /// Overwrite with the little-endian bytes of `WORDS[i]`.
    Word(Pos, usize),
    /// Repeat the `len` bytes at a position `times` times.
    Repeat(Pos, usize, usize),
    /// Insert `TOKENS[i]`.
    Token(Pos, usize),
    /// Replace the `nth` number token (mod their count) by `NUMBERS[i]`.
    Number(usize, usize),
    /// Move the `nth` number token by `NUDGES[i]`, keeping its type (an integer stays one), so
    /// the text still parses and the value reaches the checks behind the parser.
    Nudge(usize, usize),
}

/// Integers and floats at the edges of every field type, little-endian.
static WORDS: LazyLock<Vec<Vec<u8>>> = LazyLock::new(|| {
    let mut w: Vec<Vec<u8>> = Vec::new();
    for v in [0u16, 1, 7, 8, 1024, 2048, 0x7fff, 0x8000, u16::MAX] {
        w.push(v.to_le_bytes().to_vec());
    }
    for v in [
        0u32,
        1,
        1_000_000,
        1_000_001,
        0x7fff_ffff,
        0x8000_0000,
        u32::MAX,
    ] {
        w.push(v.to_le_bytes().to_vec());
    }
    for v in [u64::MAX, i64::MIN as u64, 1 << 32] {
        w.push(v.to_le_bytes().to_vec());
    }
    for v in [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        1e308,
        -1e308,
        f64::MIN_POSITIVE,
        f64::from_bits(1),
        90.000_000_1,
        180.5,
        0.001,
        100.000_001,
    ] {
        w.push(v.to_le_bytes().to_vec());
    }
    w
});

/// Syntax of the text formats (TOML, JSON, GeoJSON) and awkward code points.
const TOKENS: &[&str] = &[
    "[",
    "]",
    "{",
    "}",
    "\"",
    "'",
    ",",
    ":",
    "=",
    "\n",
    "\r\n",
    "#",
    "\\",
    "[[",
    "]]",
    "\"\"\"",
    "'''",
    "\\u0000",
    "\\ud800",
    "null",
    "true",
    "-",
    ".",
    "e",
    "\u{feff}",
    "\u{0}",
    "\u{10ffff}",
    "é",
    "1979-05-27T07:32:00Z",
    "[[camera]]\n",
    "[[stage]]\n",
    "[region.x]\n",
    "[model]\n",
    "a.b.c = 1\n",
    "{\"type\":\"LineString\",\"coordinates\":[[0,0],[1,1]]}",
    "[1e308,1e308]",
    "[-180,85]",
    "[]",
    "{}",
];

/// Numbers at and past every edge a parser or a later check meets.
const NUMBERS: &[&str] = &[
    "0",
    "-0",
    "-0.0",
    "+0.0",
    "1",
    "-1",
    "nan",
    "-nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "1e308",
    "-1e308",
    "1e309",
    "-1e309",
    "1.7976931348623157e308",
    "2.2250738585072014e-308",
    "5e-324",
    "1e-400",
    "1e999999999999",
    "18446744073709551615",
    "18446744073709551616",
    "9223372036854775807",
    "9223372036854775808",
    "-9223372036854775808",
    "-9223372036854775809",
    "4611686018427387904",
    "4294967295",
    "4294967296",
    "2147483648",
    "65535",
    "65536",
    "340282366920938463463374607431768211456",
    "123456789012345678901234567890.5",
    "0x7fffffffffffffff",
    "0o777",
    "0b1",
    "1_000",
    "1e",
    "1.",
    ".5",
    "00",
    "--1",
];

/// How one nudge moves an integer token and a float token.
type Nudge = (fn(i128) -> i128, fn(f64) -> f64);

/// Small and large moves of a number (saturating: a token may already be near i128's edge).
const NUDGES: &[Nudge] = &[
    (|v| v.saturating_add(1), |v| v + 1e-4),
    (|v| v.saturating_sub(1), |v| v - 1e-4),
    (|v| v.saturating_mul(2), |v| v * 1.5),
    (|v| v / 2, |v| v * 0.5),
    (|v| v.saturating_mul(1000), |v| v * 1e6),
    (|v| v.saturating_neg(), |v| -v),
    (|_| 0, |_| 0.0),
    (|v| v.saturating_add(2), |v| v + 1.0),
    (|v| v.saturating_pow(2), |v| v / 3.0),
    (|v| v.saturating_add(1 << 32), |v| v * (1.0 + f64::EPSILON)),
];

/// `token` moved by `NUDGES[i]`; `None` when it is not a plain decimal number.
fn nudge(token: &[u8], i: usize) -> Option<String> {
    let text = std::str::from_utf8(token).ok()?;
    let (int, float) = NUDGES[i];
    if let Ok(v) = text.parse::<i128>() {
        return Some(int(v).to_string());
    }
    let v = text.parse::<f64>().ok()?;
    // `{:?}` keeps a point or exponent, so a float stays a float.
    Some(format!("{:?}", float(v)))
}

fn pos() -> impl Strategy<Value = Pos> {
    (any::<bool>(), any::<usize>()).prop_map(|(head, raw)| Pos { head, raw })
}

fn edit(donors: usize, text: bool) -> BoxedStrategy<Edit> {
    let bytes = prop_oneof![
        3 => (pos(), 0u8..8).prop_map(|(p, b)| Edit::FlipBit(p, b)),
        2 => (pos(), any::<u8>()).prop_map(|(p, b)| Edit::SetByte(p, b)),
        2 => (pos(), prop::collection::vec(any::<u8>(), 1..16)).prop_map(|(p, b)| Edit::Insert(p, b)),
        2 => (pos(), 1usize..64).prop_map(|(p, n)| Edit::Delete(p, n)),
        1 => pos().prop_map(Edit::Truncate),
        2 => (0..donors, pos(), 1usize..256, pos(), any::<bool>()).prop_map(
            |(donor, from, len, to, overwrite)| Edit::Splice { donor, from, len, to, overwrite }
        ),
        2 => (pos(), 0..WORDS.len()).prop_map(|(p, i)| Edit::Word(p, i)),
        1 => (pos(), 1usize..9, 2usize..2000).prop_map(|(p, n, t)| Edit::Repeat(p, n, t)),
    ];
    if text {
        prop_oneof![
            10 => bytes,
            3 => (pos(), 0..TOKENS.len()).prop_map(|(p, i)| Edit::Token(p, i)),
            4 => (any::<usize>(), 0..NUMBERS.len()).prop_map(|(n, i)| Edit::Number(n, i)),
            6 => (any::<usize>(), 0..NUDGES.len()).prop_map(|(n, i)| Edit::Nudge(n, i)),
        ]
        .boxed()
    } else {
        bytes.boxed()
    }
}

/// Byte ranges of the number tokens of a text: a digit, or a sign or point before one, not
/// inside a word, up to the end of the run of number characters.
fn number_spans(b: &[u8]) -> Vec<(usize, usize)> {
    let word = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let num = |c: u8| c.is_ascii_alphanumeric() || matches!(c, b'_' | b'.' | b'+' | b'-');
    let mut spans = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = b[i].is_ascii_digit()
            || (matches!(b[i], b'-' | b'+' | b'.') && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        if starts && (i == 0 || !word(b[i - 1])) {
            let mut j = i + 1;
            while j < b.len() && num(b[j]) {
                j += 1;
            }
            spans.push((i, j));
            i = j;
        } else {
            i += 1;
        }
    }
    spans
}

fn apply(seeds: &[Vec<u8>], slot: usize, edits: &[Edit]) -> Vec<u8> {
    let mut b = seeds[slot].clone();
    for e in edits {
        let n = b.len();
        match e {
            Edit::FlipBit(p, bit) if n > 0 => b[p.at(n, false)] ^= 1 << bit,
            Edit::SetByte(p, v) if n > 0 => b[p.at(n, false)] = *v,
            Edit::Insert(p, v) => {
                let at = p.at(n, true);
                b.splice(at..at, v.iter().copied());
            }
            Edit::Delete(p, len) if n > 0 => {
                let at = p.at(n, false);
                b.drain(at..(at + len).min(n));
            }
            Edit::Truncate(p) => b.truncate(p.at(n, true)),
            Edit::Splice {
                donor,
                from,
                len,
                to,
                overwrite,
            } => {
                let d = &seeds[*donor];
                let start = from.at(d.len(), false);
                let chunk = &d[start.min(d.len())..(start + len).min(d.len())];
                let at = to.at(n, true);
                let end = if *overwrite {
                    (at + chunk.len()).min(n)
                } else {
                    at
                };
                b.splice(at..end, chunk.iter().copied());
            }
            Edit::Word(p, i) if n > 0 => {
                let at = p.at(n, false);
                let w = &WORDS[*i];
                let end = (at + w.len()).min(n);
                b[at..end].copy_from_slice(&w[..end - at]);
            }
            Edit::Repeat(p, len, times) if n > 0 => {
                let at = p.at(n, false);
                let chunk = b[at..(at + len).min(n)].to_vec();
                let copies = chunk.repeat(*times);
                b.splice(at..at, copies);
            }
            Edit::Token(p, i) => {
                let at = p.at(n, true);
                b.splice(at..at, TOKENS[*i].bytes());
            }
            Edit::Nudge(nth, i) => {
                let spans = number_spans(&b);
                if !spans.is_empty() {
                    let (s, t) = spans[nth % spans.len()];
                    if let Some(moved) = nudge(&b[s..t], *i) {
                        b.splice(s..t, moved.into_bytes());
                    }
                }
            }
            Edit::Number(nth, i) => {
                let spans = number_spans(&b);
                if !spans.is_empty() {
                    let (s, t) = spans[nth % spans.len()];
                    b.splice(s..t, NUMBERS[*i].bytes());
                }
            }
            _ => {}
        }
        b.truncate(MAX_INPUT);
    }
    b
}

/// Mostly one or two edits, so a good share of inputs still parses and reaches the checks
/// behind the parser; sometimes a deep stack.
fn edits(donors: usize, text: bool) -> impl Strategy<Value = Vec<Edit>> {
    prop_oneof![
        3 => prop::collection::vec(edit(donors, text), 1..3),
        1 => prop::collection::vec(edit(donors, text), 3..16),
    ]
}

/// Arbitrary bytes (1 in 10), bytes drawn from a seed (1 in 10), edits of a seed (8 in 10).
pub fn inputs(seeds: Vec<Vec<u8>>, text: bool) -> BoxedStrategy<Input> {
    assert!(seeds.iter().all(|s| !s.is_empty()));
    let seeds = Arc::new(seeds);
    let n = seeds.len();
    let alphabet = Arc::clone(&seeds);
    prop_oneof![
        1 => (0..n, prop::collection::vec(any::<u8>(), 0..1024))
            .prop_map(|(slot, bytes)| Input { slot, bytes }),
        1 => (0..n, prop::collection::vec(any::<Index>(), 0..1024)).prop_map(move |(slot, ix)| {
            let s = &alphabet[slot];
            Input { slot, bytes: ix.iter().map(|i| s[i.index(s.len())]).collect() }
        }),
        8 => (0..n, edits(n, text)).prop_map(move |(slot, edits)| {
            Input { slot, bytes: apply(&seeds, slot, &edits) }
        }),
    ]
    .boxed()
}
