//! The graph engine on a private pool of 2 threads computes exactly what it computes on the
//! calling thread alone: every stage's outputs bit for bit on the bundle's reference inputs.
//! The pool really exists (its workers are named threads of this process). Speed is the
//! benches' business, not a test's.

use std::num::NonZeroUsize;

use satmap_ecu_tests::golden::compiled_engine;
use satmap_ecu_tests::stages::{ReferenceInputs, StageOutputs};
use satmap_runtime::Stage;
use satmap_runtime::engine_tract::TractEngine;

const TWO: NonZeroUsize = NonZeroUsize::new(2).unwrap();

/// Every stage's outputs on the reference inputs, as raw bits, in stage order.
fn stage_outputs(engine: &mut TractEngine) -> Vec<Vec<u32>> {
    let r = ReferenceInputs::load();
    let mut out = StageOutputs::new(engine);
    for stage in Stage::ALL {
        out.run(engine, stage, &r).unwrap();
    }
    out.bits()
}

fn engine_threads() -> Vec<String> {
    std::fs::read_dir("/proc/self/task")
        .unwrap()
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("comm")).ok())
        .map(|s| s.trim().to_owned())
        .filter(|s| s.starts_with("satmap-engine-"))
        .collect()
}

#[test]
fn every_stage_is_bit_identical_on_one_and_two_threads() {
    let mut engine = compiled_engine();
    assert_eq!(engine.threads(), NonZeroUsize::MIN);
    let one = stage_outputs(&mut engine);
    engine.set_threads(TWO).unwrap();
    assert_eq!(engine.threads(), TWO);
    let two = stage_outputs(&mut engine);
    // rayon starts its workers asynchronously: give them up to 10 s to show up (no timing is
    // asserted, only that the pool exists).
    let mut names = engine_threads();
    for _ in 0..100 {
        if names.len() == 2 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
        names = engine_threads();
    }
    names.sort();
    assert_eq!(names, ["satmap-engine-0", "satmap-engine-1"]);
    let again = stage_outputs(&mut engine);
    for (i, ((a, b), c)) in one.iter().zip(&two).zip(&again).enumerate() {
        assert!(a.iter().any(|&x| x != 0), "output {i} is all zeros");
        assert!(a == b, "output {i} differs between 1 and 2 threads");
        assert!(b == c, "output {i} differs between two runs on 2 threads");
    }
    // Back to one thread: the pool is dropped with the executor, the outputs stay.
    engine.set_threads(NonZeroUsize::MIN).unwrap();
    assert_eq!(stage_outputs(&mut engine), one);
}
