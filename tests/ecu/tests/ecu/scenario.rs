//! The committed C-API scenario and this kernel family's digests of it are current: the files
//! the C example compares against (`SATMAP_BLESS=1` rewrites this family's).

use satmap_ecu_tests::scenario::{
    bless, expected_path, rust_run, scenario_bytes, scenario_path, sets,
};
use satmap_runtime::CameraState;

#[test]
fn the_committed_scenario_and_digests_are_current() {
    let sets = sets();
    let bytes = scenario_bytes(&sets);
    let maps = rust_run(&sets);
    let expected: String = maps
        .iter()
        .map(|m| format!("{} {:016x}\n", m.sequence, m.digest))
        .collect();
    if bless() {
        std::fs::write(scenario_path(), &bytes).unwrap();
        std::fs::write(expected_path(), &expected).unwrap();
    }
    assert!(
        std::fs::read(scenario_path()).unwrap() == bytes,
        "examples/c/scenario.bin is stale: rerun with SATMAP_BLESS=1"
    );
    assert_eq!(
        std::fs::read_to_string(expected_path()).unwrap(),
        expected,
        "{} is stale: rerun with SATMAP_BLESS=1",
        expected_path().display()
    );
    // The scenario exercises what it claims: dropout and a degraded step.
    assert_eq!(maps[2].health.cameras[3], CameraState::Missing);
    assert_eq!(maps[3].health.cameras_dropped(), 0b11_1110);
    assert!(maps[3].health.degraded && !maps[0].health.degraded);
    println!("scenario digests:\n{expected}");
}
