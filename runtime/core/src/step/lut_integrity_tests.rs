//! The GKT look-up table's integrity (issue 38, part 3): the table lives in caller memory, so
//! every step checks its digest before the gather. Single-bit flips over the whole in-use table
//! each fail the step with `LutCorrupt` (before, 30 of 200 changed every later map silently);
//! the failure repeats until `recalibrate` rebuilds the table, after which the map is the
//! undisturbed one.

use super::*;
use crate::test_support::{Images, crop, fake_runtime, nuscenes_like};

#[test]
fn every_bit_flip_of_the_table_in_use_fails_the_step_until_recalibrate() {
    let dims = ModelDims::test_config();
    let c = crop(&dims);
    let images = Images::new(&dims, 38);
    let mut clean = fake_runtime(&c);
    let mut rt = fake_runtime(&c);
    let in_use_bytes = rt.lut.indices_in_use_bytes();
    let flips = 200usize;
    for (sequence, k) in (1u64..).zip(0..flips) {
        // Spread over the feature indices in use, each bit position of a byte in turn.
        let at = k * (in_use_bytes / flips) + k % 7;
        let bit = 1u8 << (k % 8);
        let want = clean.step(&images.frame(sequence)).unwrap().clone();
        rt.lut.storage_bytes_mut()[at] ^= bit;
        let e = rt.step(&images.frame(sequence)).unwrap_err();
        assert!(
            matches!(e, StepError::LutCorrupt { .. }),
            "flip {k} at {at}: {e}"
        );
        // Still corrupt: refused again, nothing published.
        assert!(matches!(
            rt.step(&images.frame(sequence)),
            Err(StepError::LutCorrupt { .. })
        ));
        rt.recalibrate(&nuscenes_like()).unwrap();
        assert_eq!(rt.step(&images.frame(sequence)).unwrap(), &want, "flip {k}");
    }
}
