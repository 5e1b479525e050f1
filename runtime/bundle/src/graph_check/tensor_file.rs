//! The header of an NNEF tensor file (`.dat`), checked against the entry's size before tract
//! reads it: tract slices `dims[..rank]` (a rank above 8 panicked) and sizes buffers from the
//! header.

use super::MAX_TENSOR_ELEMENTS;

/// Bytes of the header (the data follows).
pub const HEADER_BYTES: usize = 128;

/// What is wrong with a tensor file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TensorRule {
    /// Shorter than its header, or not the NNEF magic and version 1.0.
    #[error("no NNEF 1.0 tensor header")]
    Header,
    /// A rank above 8.
    #[error("rank {0}, at most 8")]
    Rank(u32),
    /// Bits per item other than 8, 16, 32 or 64, or an item type tract does not read.
    #[error("item type {item_type} (vendor {vendor}) of {bits} bits")]
    ItemType {
        /// `item_type`.
        item_type: u16,
        /// `item_type_vendor`.
        vendor: u16,
        /// `bits_per_item`.
        bits: u32,
    },
    /// More elements than [`MAX_TENSOR_ELEMENTS`].
    #[error("{0} elements, at most {MAX_TENSOR_ELEMENTS}")]
    TooLarge(u64),
    /// The header's data size disagrees with its shape or with the entry's bytes.
    #[error(
        "header says {header_bytes} data bytes, shape needs {shape_bytes}, entry holds {entry_bytes}"
    )]
    DataSize {
        /// `data_size_bytes`.
        header_bytes: u64,
        /// Elements x bits / 8.
        shape_bytes: u64,
        /// The entry's size minus the header.
        entry_bytes: u64,
    },
}

fn u32_at(header: &[u8; HEADER_BYTES], at: usize) -> u32 {
    u32::from_le_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
}

/// Check `header` (the first bytes of an entry of `entry_size` bytes; `complete` is false when
/// the entry was shorter than a header).
pub fn check(
    header: &[u8; HEADER_BYTES],
    entry_size: u64,
    complete: bool,
) -> Result<(), TensorRule> {
    if !complete || header[..4] != [0x4e, 0xef, 1, 0] {
        return Err(TensorRule::Header);
    }
    let data_bytes = u64::from(u32_at(header, 4));
    let rank = u32_at(header, 8);
    if rank > 8 {
        return Err(TensorRule::Rank(rank));
    }
    let mut elements = 1u64;
    for i in 0..rank as usize {
        elements = elements.saturating_mul(u64::from(u32_at(header, 12 + 4 * i)));
    }
    let bits = u32_at(header, 44);
    let item_type = u16::from_le_bytes([header[48], header[49]]);
    let vendor = u16::from_le_bytes([header[50], header[51]]);
    // Vendor 0 (Khronos): 0 float, 2 unsigned, 3 signed integer, 1 quantized is not written by
    // our compiler; tract's own vendor codes are not either.
    let known = vendor == 0 && matches!(item_type, 0 | 2 | 3) && matches!(bits, 8 | 16 | 32 | 64);
    if !known {
        return Err(TensorRule::ItemType {
            item_type,
            vendor,
            bits,
        });
    }
    if elements > MAX_TENSOR_ELEMENTS {
        return Err(TensorRule::TooLarge(elements));
    }
    let shape_bytes = elements * u64::from(bits / 8);
    let entry_bytes = entry_size.saturating_sub(HEADER_BYTES as u64);
    if data_bytes != shape_bytes || data_bytes != entry_bytes {
        return Err(TensorRule::DataSize {
            header_bytes: data_bytes,
            shape_bytes,
            entry_bytes,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(rank: u32, dims: &[u32], bits: u32, item_type: u16) -> [u8; HEADER_BYTES] {
        let mut h = [0u8; HEADER_BYTES];
        h[..4].copy_from_slice(&[0x4e, 0xef, 1, 0]);
        let n = dims.iter().map(|&d| u64::from(d)).product::<u64>() * u64::from(bits) / 8;
        h[4..8].copy_from_slice(&(n as u32).to_le_bytes());
        h[8..12].copy_from_slice(&rank.to_le_bytes());
        for (i, d) in dims.iter().enumerate() {
            h[12 + 4 * i..16 + 4 * i].copy_from_slice(&d.to_le_bytes());
        }
        h[44..48].copy_from_slice(&bits.to_le_bytes());
        h[48..50].copy_from_slice(&item_type.to_le_bytes());
        h
    }

    #[test]
    fn a_consistent_header_passes_and_each_rule_names_its_fault() {
        let ok = header(2, &[4, 8], 32, 0);
        assert_eq!(check(&ok, 128 + 128, true), Ok(()));
        assert_eq!(
            check(&ok, 128 + 127, true)
                .err()
                .map(|e| matches!(e, TensorRule::DataSize { .. })),
            Some(true)
        );
        assert_eq!(check(&ok, 256, false), Err(TensorRule::Header));
        assert_eq!(
            check(&header(9, &[1; 8], 32, 0), 132, true),
            Err(TensorRule::Rank(9))
        );
        assert!(matches!(
            check(&header(1, &[4], 24, 0), 140, true),
            Err(TensorRule::ItemType { .. })
        ));
        let huge = header(2, &[1 << 16, 1 << 16], 8, 3);
        assert_eq!(check(&huge, 128, true), Err(TensorRule::TooLarge(1 << 32)));
        let mut liar = header(2, &[4, 8], 32, 0);
        liar[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            check(&liar, 256, true),
            Err(TensorRule::DataSize { .. })
        ));
    }
}
