//! The receiver's check of a protected map frame, `wire::check`, and `wire::deserialise`: a
//! frame that passes reads back, serialises to the same bytes, and its element count never
//! reaches past the input. The first input byte picks the mode: odd re-seals the CRC after the
//! mutation (so edits reach the field rules behind it), even keeps the bytes as they are.
#![no_main]

use crc::{CRC_32_AUTOSAR, Crc};
use libfuzzer_sys::fuzz_target;
use satmap_runtime::map_frame::wire;

fn reseal(frame: &mut [u8]) {
    if frame.len() < 12 {
        return;
    }
    let crc = Crc::<u32>::new(&CRC_32_AUTOSAR);
    let mut digest = crc.digest();
    digest.update(&frame[..8]);
    digest.update(&frame[12..]);
    let value = digest.finalize();
    frame[8..12].copy_from_slice(&value.to_le_bytes());
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let mut bytes = rest.to_vec();
    if mode & 1 == 1 {
        reseal(&mut bytes);
    }
    let id = wire::DEFAULT_DATA_ID;
    let checked = wire::check(&bytes, id);
    let read = wire::deserialise(&bytes, id);
    assert_eq!(checked.is_ok(), read.is_ok());
    if let Ok(frame) = read {
        let mut out = vec![0u8; wire::MAX_WIRE_BYTES];
        let n = wire::serialise(&frame, id, &mut out).expect("a checked frame serialises");
        assert_eq!(&out[..n], bytes.as_slice());
    }
});
