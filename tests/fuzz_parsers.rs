//! The fuzz pass over every parser that takes outside bytes: route pack, bundle manifest (with
//! its `manifest.sha256`), calibration TOML, `memory_layout.toml`, the scenario folder's files
//! (`scenario.toml`, `frame.toml`, `gt.json`), MapTR results / ground-truth JSON (all three
//! layouts) and the GeoJSON route.
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
//! `make fuzz` is the 1,050,000-input campaign (`ARCHITECTURE.md`, "Fuzzing"). Every parser
//! prints one `fuzz <parser>: inputs run: N ... panics found: 0` line to stderr when it completes.

use std::cell::{Cell, RefCell};
use std::fmt;
use std::path::Path;
use std::sync::{Arc, LazyLock, OnceLock};

use std::time::Instant;
use tempfile::TempDir;

use glam::DVec2;
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestError, TestRunner};
use satmap_layout::MemoryLayout;
use satmap_runtime::bundle::{Manifest, Sha256Digest};
use satmap_runtime::calibration::{Calibration, from_toml_str};
use satmap_runtime::engine::Stage;
use satmap_runtime::geo::Geodetic;
use satmap_runtime::gkt::Lut;
use satmap_runtime::model_dims::ModelDims;
use satmap_runtime::pose::EgoPose;
use satmap_runtime::regions::check_regions;
use satmap_runtime::route_pack::format::HEADER_LEN;
use satmap_runtime::route_pack::{PackSource, RoutePack};
use satmap_runtime::satellite::{CropSpec, SatelliteSource};
use satmap_sim::eval::maptr_json::MAX_COORDINATE_M;
use satmap_sim::eval::{MapVector, ResultsFile, SampleSet, evaluate, read_file, write_maptr_pair};
use satmap_sim::route_pack_builder::imagery::{Gap, Imagery};
use satmap_sim::route_pack_builder::{BuildError, BuildOptions, build_pack, parse_route_geojson};
use satmap_sim::synth::scenario::{Scenario, frame_dir_name, route_geojson};
use satmap_sim::synth::write_scenario;
use satmap_sim::synth::{DriveConfig, LightingPreset, ScenarioPlacement, SyntheticDrive};
use xxhash_rust::xxh3::xxh3_64;

const MANIFEST_TOML: &str = include_str!("../models/bundles/test/manifest.toml");
const MANIFEST_SHA256: &str = include_str!("../models/bundles/test/manifest.sha256");
const CALIBRATION_TOML: &str = include_str!("../models/calibration/nuscenes_like.toml");
const MEMORY_LAYOUT_TOML: &str = include_str!("../memory_layout.toml");

// ---------------------------------------------------------------------------------------------
// Runner: case count and seed from the environment, one summary line per parser.

const DEFAULT_CASES: u32 = 256;
const DEFAULT_SEED: u64 = 0x005a_73a9_f022;

fn cases() -> u32 {
    match std::env::var("SATMAP_FUZZ_CASES") {
        Ok(s) => s
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("SATMAP_FUZZ_CASES={s:?} is not a case count")),
        Err(_) => DEFAULT_CASES,
    }
}

fn rng_seed(parser: &str) -> u64 {
    match std::env::var("SATMAP_FUZZ_SEED").as_deref().map(str::trim) {
        Err(_) | Ok("") => DEFAULT_SEED,
        Ok("random") => {
            // Printed with the summary, so a random run can be repeated.
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64);
            nanos ^ xxh3_64(parser.as_bytes()) ^ u64::from(std::process::id())
        }
        Ok(s) => s
            .parse()
            .unwrap_or_else(|_| panic!("SATMAP_FUZZ_SEED={s:?} is neither a u64 nor `random`")),
    }
}

/// A fresh folder for one test's files, removed when dropped (one per test and process, so a
/// CI run and a campaign can share the target folder).
fn work_dir(name: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("fuzz_{name}_"))
        .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
        .unwrap()
}

/// How far the product took the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outcome {
    /// The parser refused it.
    Refused,
    /// Parsed, then refused by a later check.
    Parsed,
    /// Through every step.
    Accepted,
}
use Outcome::{Accepted, Parsed, Refused};

type CaseResult = Result<Outcome, TestCaseError>;

/// One generated input: its bytes and the seed slot it stands in for (for multi-file formats,
/// which file it replaces).
#[derive(Clone)]
struct Input {
    slot: usize,
    bytes: Vec<u8>,
}

impl fmt::Debug for Input {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Input {{ slot: {}, len: {}, text: {:?} }}",
            self.slot,
            self.bytes.len(),
            String::from_utf8_lossy(&self.bytes)
        )
    }
}

impl Input {
    fn text(&self) -> std::borrow::Cow<'_, str> {
        // Lossy rather than refusing non-UTF-8: the product's read_to_string would stop such
        // bytes earlier, but the parser behind it then sees far more of the generated inputs.
        String::from_utf8_lossy(&self.bytes)
    }
}

/// Run `body` on `cases()` inputs from `strategy`; print the summary line; fail with the
/// shrunk input (also written to the failures folder) if any case panicked or broke an
/// invariant.
fn fuzz(parser: &str, strategy: BoxedStrategy<Input>, body: impl Fn(&Input) -> CaseResult) {
    let cases = cases();
    let seed = rng_seed(parser);
    let mut runner = TestRunner::new(Config {
        cases,
        // Regressions are kept as seeds or unit tests, not as a proptest-regressions file.
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(seed),
        max_shrink_time: 120_000,
        ..Config::default()
    });
    let (run, parsed, accepted) = (Cell::new(0u64), Cell::new(0u64), Cell::new(0u64));
    let bump = |c: &Cell<u64>| c.set(c.get() + 1);
    let start = Instant::now();
    let result = runner.run(&strategy, |input| {
        bump(&run);
        match body(&input)? {
            Refused => {}
            Parsed => bump(&parsed),
            Accepted => {
                bump(&parsed);
                bump(&accepted);
            }
        }
        Ok(())
    });
    let secs = start.elapsed().as_secs_f64();
    let (run, parsed, accepted) = (run.get(), parsed.get(), accepted.get());
    match result {
        Ok(()) => eprintln!(
            "fuzz {parser}: inputs run: {run}, parsed: {parsed}, accepted: {accepted}, \
             panics found: 0 ({secs:.1} s, seed {seed})"
        ),
        Err(TestError::Fail(why, input)) => {
            let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz_parsers_failures");
            std::fs::create_dir_all(&dir).unwrap();
            let path = dir.join(format!("{parser}.bin"));
            std::fs::write(&path, &input.bytes).unwrap();
            eprintln!(
                "fuzz {parser}: inputs run: {run} (with shrinking), panics found: 1 \
                 (or a broken invariant) ({secs:.1} s, seed {seed})"
            );
            panic!(
                "fuzz {parser}: {why}\nminimal input (slot {}, bytes in {}): {input:?}",
                input.slot,
                path.display()
            );
        }
        Err(TestError::Abort(why)) => panic!("fuzz {parser}: aborted: {why}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Inputs: arbitrary bytes, seed alphabets and edit stacks.

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
fn inputs(seeds: Vec<Vec<u8>>, text: bool) -> BoxedStrategy<Input> {
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

// ---------------------------------------------------------------------------------------------
// Seeds the product's own writers produce.

/// Every seed goes all the way through; otherwise the edits of it would test refusals only.
fn assert_seeds_accepted(seeds: &[Vec<u8>], body: impl Fn(&Input) -> CaseResult) {
    for (slot, bytes) in seeds.iter().enumerate() {
        let input = Input {
            slot,
            bytes: bytes.clone(),
        };
        assert_eq!(body(&input).unwrap(), Accepted, "seed {slot}");
    }
}

/// A 20-frame synthetic drive with tiny images, made once per test binary.
fn seed_drive() -> &'static SyntheticDrive {
    static DRIVE: OnceLock<SyntheticDrive> = OnceLock::new();
    DRIVE.get_or_init(|| {
        let config = DriveConfig {
            image_width_px: 16,
            image_height_px: 8,
            num_frames: 20,
            lighting: Some(LightingPreset::Day),
            ..DriveConfig::default()
        };
        SyntheticDrive::new(7, config).unwrap()
    })
}

fn seed_route_geojson() -> String {
    route_geojson(seed_drive(), ScenarioPlacement::default().anchor)
}

fn test_dims() -> ModelDims {
    Manifest::parse(MANIFEST_TOML.as_bytes()).unwrap().model
}

fn seed_calibration() -> Calibration {
    from_toml_str(CALIBRATION_TOML).unwrap()
}

/// Imagery of one colour over a small WGS84 box around the seed route, gaps outside: a route
/// that leaves the box is refused like one that leaves real imagery, and one inside it has a
/// bounded corridor, so a case's cost stays bounded.
struct BoxImagery {
    lat: (f64, f64),
    lon: (f64, f64),
}

impl BoxImagery {
    fn around(anchor: Geodetic) -> Self {
        let half = 0.002;
        Self {
            lat: (anchor.lat_deg - half, anchor.lat_deg + half),
            lon: (anchor.lon_deg - half, anchor.lon_deg + half),
        }
    }
}

impl Imagery for BoxImagery {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        DVec2::new(lon_deg, lat_deg)
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        let inside =
            (self.lon.0..=self.lon.1).contains(&p.x) && (self.lat.0..=self.lat.1).contains(&p.y);
        Ok(if inside {
            Ok([90, 120, 60])
        } else {
            Err(Gap::OutsideImage)
        })
    }

    fn gap_error(&self, _gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        BuildError::Option(format!("no imagery at {lat_deg}, {lon_deg}"))
    }
}

/// The crop the packs are built for and cropped with: small, so a case stays cheap.
const CROP: CropSpec = CropSpec {
    height_px: 20,
    width_px: 12,
    gsd_m: 0.4,
    x_min_m: -2.4,
    y_min_m: -4.0,
};

/// Small tiles and a narrow corridor: a pack of a few dozen tiles, cheap to verify per case.
fn pack_options() -> BuildOptions {
    BuildOptions {
        corridor_width_m: 10.0,
        gsd_m: 0.5,
        tile_size_px: 16,
        crop: CROP,
        ..BuildOptions::default()
    }
}

// ---------------------------------------------------------------------------------------------
// Route pack.

/// Recompute both checksums (offsets from `runtime/src/route_pack/FORMAT.md`) so an edit of the
/// header, route or index reaches the field rules behind them.
fn reseal(bytes: &mut [u8]) {
    if bytes.len() < HEADER_LEN {
        return;
    }
    let count = |off: usize| u32::from_le_bytes(bytes[off..off + 4].try_into().unwrap()) as usize;
    let meta_end = HEADER_LEN
        .saturating_add(count(56).saturating_mul(16))
        .saturating_add(count(60).saturating_mul(16));
    if meta_end <= bytes.len() {
        let index = xxh3_64(&bytes[HEADER_LEN..meta_end]);
        bytes[64..72].copy_from_slice(&index.to_le_bytes());
    }
    let header = xxh3_64(&bytes[..72]);
    bytes[72..80].copy_from_slice(&header.to_le_bytes());
}

/// Every tile the index lists is in bounds and found by its key; nothing past the end is.
fn check_pack(pack: &RoutePack<'_>) -> Result<(), TestCaseError> {
    let n = pack.tile_count();
    let tile_bytes = pack.header().tile_bytes();
    for i in 0..n {
        let key = pack.tile_key(i);
        prop_assert!(key.is_some(), "tile {i} of {n} has no key");
        prop_assert_eq!(pack.find_tile(key.unwrap()), Some(i));
        prop_assert_eq!(
            pack.tile_payload_unverified(i).map(<[u8]>::len),
            Some(tile_bytes)
        );
        let _ = pack.verified_tile(i);
    }
    prop_assert!(pack.tile_key(n).is_none() && pack.tile_payload_unverified(n).is_none());
    let r = pack.route_point_count();
    for i in 0..r {
        prop_assert!(pack.route_point(i).is_some_and(|p| p.is_finite()));
    }
    prop_assert!(pack.route_point(r).is_none());
    Ok(())
}

fn route_pack_case(input: &Input) -> CaseResult {
    let mut bytes = input.bytes.clone();
    // Slot 1: the same seed with the checksums recomputed after the edits.
    if input.slot == 1 {
        reseal(&mut bytes);
    }
    let Ok(mut source) = PackSource::from_bytes(&bytes) else {
        return Ok(Refused);
    };
    check_pack(source.pack())?;
    let route: Vec<DVec2> = (0..source.pack().route_point_count())
        .filter_map(|i| source.pack().route_point(i))
        .collect();
    let mut out = [0u8; 20 * 12 * 3];
    let poses = [DVec2::ZERO, DVec2::new(5.0, -3.0)]
        .into_iter()
        .chain(route.first().copied())
        .chain(route.last().copied());
    for (k, p) in poses.enumerate() {
        let _ = source.distance_to_route_m(p);
        source.crop(&EgoPose::new(p, k as f64 * 1.3), &CROP, &mut out);
        let report = source.last_report();
        prop_assert!(report.covered_px <= report.total_px);
    }
    Ok(Accepted)
}

#[test]
fn route_pack_never_panics() {
    let route = parse_route_geojson(&seed_route_geojson(), Path::new("route.geojson")).unwrap();
    let mut imagery = BoxImagery::around(route[0]);
    let pack = build_pack(&mut imagery, &route, &pack_options())
        .unwrap()
        .bytes;
    // Slot 1 is the same pack, resealed after the edits (see `route_pack_case`).
    let seeds = vec![pack.clone(), pack];
    assert_seeds_accepted(&seeds, route_pack_case);
    fuzz("route_pack", inputs(seeds, false), route_pack_case);
}

// ---------------------------------------------------------------------------------------------
// Bundle manifest and its digest file.

fn manifest_case(input: &Input, calibration: &Calibration) -> CaseResult {
    // `manifest.sha256` is read before the manifest: the same bytes as a digest file.
    if let Ok(text) = std::str::from_utf8(&input.bytes)
        && let Ok(digest) = Sha256Digest::parse(text)
    {
        prop_assert_eq!(digest.to_string(), text.strip_suffix('\n').unwrap_or(text));
    }
    let Ok(manifest) = Manifest::parse(&input.bytes) else {
        return Ok(Refused);
    };
    let dims = &manifest.model;
    if dims.validate().is_err() {
        return Ok(Parsed);
    }
    let _ = dims.crop_spec();
    let mut ok = manifest.check_stage_names().is_ok();
    for stage in Stage::ALL {
        match manifest.stage(stage) {
            Ok(entry) => {
                ok &= entry.check_interface(stage, dims).is_ok();
                ok &= Sha256Digest::parse(&entry.sha256).is_ok();
            }
            Err(_) => ok = false,
        }
    }
    // What `SatMap::new` does with dims that passed: the region checks, then the GKT table.
    if check_regions(dims).is_err() || Lut::new(dims, calibration).is_err() {
        return Ok(Parsed);
    }
    Ok(if ok { Accepted } else { Parsed })
}

#[test]
fn manifest_never_panics() {
    let calibration = seed_calibration();
    // The manifest twice: two thirds of the inputs for it, one third for the digest file.
    let seeds = vec![
        MANIFEST_TOML.as_bytes().to_vec(),
        MANIFEST_TOML.as_bytes().to_vec(),
        MANIFEST_SHA256.as_bytes().to_vec(),
    ];
    let body = |input: &Input| manifest_case(input, &calibration);
    assert_seeds_accepted(&seeds[..2], body);
    fuzz("manifest", inputs(seeds, true), body);
}

// ---------------------------------------------------------------------------------------------
// Calibration TOML.

fn calibration_case(input: &Input, dims: &ModelDims) -> CaseResult {
    let Ok(calibration) = from_toml_str(&input.text()) else {
        return Ok(Refused);
    };
    prop_assert!(calibration.is_valid());
    // A calibration the loader accepts is one the runtime builds its table from (`recalibrate`).
    prop_assert!(
        calibration
            .lidar2img(dims.image_scale)
            .iter()
            .all(|m| m.is_finite())
    );
    let lut = Lut::new(dims, &calibration);
    prop_assert!(
        lut.is_ok(),
        "loaded calibration refused by the LUT: {:?}",
        lut.err()
    );
    Ok(Accepted)
}

#[test]
fn calibration_never_panics() {
    let dims = test_dims();
    let seeds = vec![CALIBRATION_TOML.as_bytes().to_vec()];
    let body = |input: &Input| calibration_case(input, &dims);
    assert_seeds_accepted(&seeds, body);
    fuzz("calibration", inputs(seeds, true), body);
}

// ---------------------------------------------------------------------------------------------
// memory_layout.toml.

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
    let seeds = vec![MEMORY_LAYOUT_TOML.as_bytes().to_vec()];
    assert_seeds_accepted(&seeds, layout_case);
    fuzz("memory_layout", inputs(seeds, true), layout_case);
}

// ---------------------------------------------------------------------------------------------
// Scenario folder: scenario.toml, frames/000000/frame.toml, frames/000000/gt.json.

const SCENARIO_FILES: [&str; 3] = [
    "scenario.toml",
    "frames/000000/frame.toml",
    "frames/000000/gt.json",
];

/// The seed drive written as a scenario folder by the product's writer, and its three files.
fn scenario_folder(name: &str) -> (TempDir, Vec<Vec<u8>>) {
    let dir = work_dir(name);
    write_scenario(
        seed_drive(),
        dir.path(),
        &ScenarioPlacement::default(),
        |_| {},
    )
    .unwrap();
    let seeds = SCENARIO_FILES
        .iter()
        .map(|f| std::fs::read(dir.path().join(f)).unwrap())
        .collect();
    (dir, seeds)
}

fn scenario_case(input: &Input, dir: &Path, seeds: &[Vec<u8>]) -> CaseResult {
    // Every file is rewritten, so a case never sees the edits of the one before (a failing case
    // is re-run many times while shrinking).
    for (slot, file) in SCENARIO_FILES.iter().enumerate() {
        let bytes = if slot == input.slot {
            &input.bytes
        } else {
            &seeds[slot]
        };
        std::fs::write(dir.join(file), bytes).unwrap();
    }
    let Ok(scenario) = Scenario::open(dir) else {
        return Ok(Refused);
    };
    let n = scenario.manifest.num_frames;
    prop_assert!(n > 0);
    prop_assert!(scenario.read_frame(n).is_err());
    Ok(match scenario.read_frame(0) {
        Ok(_) => Accepted,
        Err(_) => Parsed,
    })
}

#[test]
fn scenario_never_panics() {
    let (dir, seeds) = scenario_folder("scenario");
    let body = |input: &Input| scenario_case(input, dir.path(), &seeds);
    assert_seeds_accepted(&seeds, body);
    fuzz("scenario", inputs(seeds.clone(), true), body);
}

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

// ---------------------------------------------------------------------------------------------
// MapTR results and ground-truth JSON (ours keyed by token, MapTR's two list layouts).

fn maptr_case(input: &Input, file: &Path, gt: &SampleSet, predictions: &SampleSet) -> CaseResult {
    std::fs::write(file, &input.bytes).unwrap();
    let Ok(loaded) = read_file(file) else {
        return Ok(Refused);
    };
    // `satmap-sim evaluate` next: the file as predictions, and as ground truth.
    for report in [
        evaluate(&loaded.samples, gt),
        evaluate(predictions, &loaded.samples),
    ] {
        for class in &report.classes {
            for ap in &class.ap_per_threshold {
                prop_assert!((0.0..=1.0).contains(ap), "AP {ap} outside [0, 1]");
            }
        }
        prop_assert!(
            (0.0..=1.0).contains(&report.mean_ap),
            "mAP {}",
            report.mean_ap
        );
    }
    Ok(Accepted)
}

#[test]
fn maptr_json_never_panics() {
    let tmp = work_dir("maptr");
    let dir = tmp.path();
    // One sample: the cost of a case grows with the evaluation behind the reader.
    let first = seed_drive().frame(0).ground_truth;
    assert!(!first.is_empty(), "the seed frame needs ground truth");
    let gt = SampleSet::from([(frame_dir_name(0), first)]);
    // Predictions: the ground truth moved 0.3 m with falling scores, so matches are partial.
    let predictions: SampleSet = gt
        .iter()
        .map(|(token, vs)| {
            let moved = vs
                .iter()
                .enumerate()
                .map(|(i, v)| MapVector {
                    points_m: v.points_m.iter().map(|[x, y]| [x + 0.3, *y]).collect(),
                    score: 0.9 - 0.05 * i as f64,
                    ..v.clone()
                })
                .collect();
            (token.clone(), moved)
        })
        .collect();
    let keyed_gt = dir.join("keyed_gt.json");
    let keyed_pred = dir.join("keyed_pred.json");
    let (maptr_pred, maptr_gt) = (dir.join("nuscmap_results.json"), dir.join("map_anns.json"));
    ResultsFile::from_samples(&gt, serde_json::Value::Null, false)
        .write(&keyed_gt)
        .unwrap();
    ResultsFile::from_samples(&predictions, serde_json::json!({"use_camera": true}), true)
        .write(&keyed_pred)
        .unwrap();
    write_maptr_pair(
        &predictions,
        &gt,
        serde_json::Value::Null,
        &maptr_pred,
        &maptr_gt,
    )
    .unwrap();
    let seeds: Vec<Vec<u8>> = [&keyed_gt, &keyed_pred, &maptr_pred, &maptr_gt]
        .iter()
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    let file = dir.join("case.json");
    let body = |input: &Input| maptr_case(input, &file, &gt, &predictions);
    assert_seeds_accepted(&seeds, body);
    fuzz("maptr_json", inputs(seeds, true), body);
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

// ---------------------------------------------------------------------------------------------
// GeoJSON route.

fn geojson_case(input: &Input, imagery: &mut BoxImagery) -> CaseResult {
    let Ok(route) = parse_route_geojson(&input.text(), Path::new("route.geojson")) else {
        return Ok(Refused);
    };
    prop_assert!(route.len() >= 2);
    prop_assert!(route.iter().all(Geodetic::is_valid));
    // `build-pack` next; a pack the builder writes is one the runtime loads.
    let Ok(built) = build_pack(imagery, &route, &pack_options()) else {
        return Ok(Parsed);
    };
    let pack = RoutePack::parse(&built.bytes);
    prop_assert!(pack.is_ok(), "built pack refused: {:?}", pack.err());
    prop_assert_eq!(pack.unwrap().tile_count(), built.tiles);
    Ok(Accepted)
}

#[test]
fn geojson_route_never_panics() {
    let anchor = ScenarioPlacement::default().anchor;
    let (lat, lon) = (anchor.lat_deg, anchor.lon_deg);
    let seeds = vec![
        seed_route_geojson().into_bytes(),
        format!(
            r#"{{"type":"LineString","coordinates":[[{lon},{lat}],[{},{},3.5]]}}"#,
            lon + 1e-4,
            lat + 1e-4
        )
        .into_bytes(),
        format!(
            r#"{{"type":"Feature","properties":{{"name":"r"}},"geometry":{{"type":"LineString","coordinates":[[{lon},{lat}],[{},{lat}],[{},{}]]}}}}"#,
            lon + 2e-4,
            lon + 2e-4,
            lat - 1e-4
        )
        .into_bytes(),
    ];
    let imagery = RefCell::new(BoxImagery::around(anchor));
    let body = |input: &Input| geojson_case(input, &mut imagery.borrow_mut());
    assert_seeds_accepted(&seeds, body);
    fuzz("geojson_route", inputs(seeds, true), body);
}
