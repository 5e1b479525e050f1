//! The runner every harness goes through: the case count and RNG seed from the environment
//! (`SATMAP_FUZZ_CASES`, `SATMAP_FUZZ_SEED`), the per-test work folder, the generated `Input`
//! and the `Outcome` of a case, the `fuzz` loop with its one summary line per parser and the
//! failure file (`$CARGO_TARGET_TMPDIR/fuzz_parsers_failures/<parser>.bin`), and the check that
//! every seed goes all the way through.

use std::cell::Cell;
use std::fmt;
use std::path::Path;
use std::time::Instant;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestError, TestRunner};
use tempfile::TempDir;
use xxhash_rust::xxh3::xxh3_64;

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
pub fn work_dir(name: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("fuzz_{name}_"))
        .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
        .unwrap()
}

/// How far the product took the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The parser refused it.
    Refused,
    /// Parsed, then refused by a later check.
    Parsed,
    /// Through every step.
    Accepted,
}
use Outcome::{Accepted, Parsed, Refused};

pub type CaseResult = Result<Outcome, TestCaseError>;

/// One generated input: its bytes and the seed slot it stands in for (for multi-file formats,
/// which file it replaces).
#[derive(Clone)]
pub struct Input {
    pub slot: usize,
    pub bytes: Vec<u8>,
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
    pub fn text(&self) -> std::borrow::Cow<'_, str> {
        // Lossy rather than refusing non-UTF-8: the product's read_to_string would stop such
        // bytes earlier, but the parser behind it then sees far more of the generated inputs.
        String::from_utf8_lossy(&self.bytes)
    }
}

/// Run `body` on `cases()` inputs from `strategy`; print the summary line; fail with the
/// shrunk input (also written to the failures folder) if any case panicked or broke an
/// invariant.
pub fn fuzz(parser: &str, strategy: BoxedStrategy<Input>, body: impl Fn(&Input) -> CaseResult) {
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

/// Every seed goes all the way through; otherwise the edits of it would test refusals only.
pub fn assert_seeds_accepted(seeds: &[Vec<u8>], body: impl Fn(&Input) -> CaseResult) {
    for (slot, bytes) in seeds.iter().enumerate() {
        let input = Input {
            slot,
            bytes: bytes.clone(),
        };
        assert_eq!(body(&input).unwrap(), Accepted, "seed {slot}");
    }
}
