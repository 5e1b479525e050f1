//! Tile compression for version 2 packs: each resampled tile is encoded with the pack's codec
//! (JPEG through the `image` crate's encoder, zlib through `miniz_oxide`), then decoded again
//! with the runtime's own decoder ([`decode_tile`]) so a pack whose tiles the vehicle cannot
//! decode is never written, and the tile's PSNR against the raw pixels is measured on the way.

use satmap_runtime::route_pack::{TileCodec, decode_tile};

/// Default JPEG quality: satellite crops at 0.15-0.3 m/px keep lane markings sharp at 85.
pub const DEFAULT_JPEG_QUALITY: u8 = 85;
/// zlib level of the lossless codec (miniz's default trade-off of size and speed).
const DEFLATE_LEVEL: u8 = 6;

/// How the builder stores tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileCompression {
    /// Raw RGB, read in place by the vehicle (a version 1 pack).
    Raw,
    /// JPEG at `quality` (1..=100).
    Jpeg {
        /// Encoder quality, 1..=100.
        quality: u8,
    },
    /// zlib, lossless.
    Deflate,
}

impl TileCompression {
    /// The pack header's codec.
    #[must_use]
    pub const fn codec(self) -> TileCodec {
        match self {
            Self::Raw => TileCodec::Raw,
            Self::Jpeg { .. } => TileCodec::Jpeg,
            Self::Deflate => TileCodec::Deflate,
        }
    }
}

/// One tile as stored, and how close its decode is to the raw tile.
#[derive(Clone, Debug)]
pub struct CompressedTile {
    /// The payload to write.
    pub payload: Vec<u8>,
    /// Sum of squared errors of the decoded tile against the raw one, over all channels.
    pub squared_error: u64,
}

/// Encode `rgb` (`size_px^2 * 3` bytes, row 0 south) with `compression` and decode it back.
///
/// # Errors
/// The encoder's or the round-trip decoder's message.
pub fn compress_tile(
    compression: TileCompression,
    rgb: &[u8],
    size_px: u16,
) -> Result<CompressedTile, String> {
    let side = u32::from(size_px);
    let payload = match compression {
        TileCompression::Raw => rgb.to_vec(),
        TileCompression::Jpeg { quality } => {
            let mut out = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
                .encode(rgb, side, side, image::ExtendedColorType::Rgb8)
                .map_err(|e| e.to_string())?;
            out
        }
        TileCompression::Deflate => miniz_oxide::deflate::compress_to_vec_zlib(rgb, DEFLATE_LEVEL),
    };
    let mut decoded = vec![0u8; rgb.len()];
    decode_tile(compression.codec(), &payload, size_px, &mut decoded)
        .map_err(|fault| format!("the runtime cannot decode it: {fault:?}"))?;
    let squared_error = rgb
        .iter()
        .zip(&decoded)
        .map(|(&a, &b)| {
            let d = u64::from(a.abs_diff(b));
            d * d
        })
        .sum();
    if compression == TileCompression::Deflate && squared_error != 0 {
        return Err("the lossless round trip changed pixels".into());
    }
    Ok(CompressedTile {
        payload,
        squared_error,
    })
}

/// PSNR of 8-bit samples from a sum of squared errors over `samples` values, dB (`inf` for
/// identical).
#[must_use]
pub fn psnr_db(squared_error: u64, samples: u64) -> f64 {
    if squared_error == 0 || samples == 0 {
        return f64::INFINITY;
    }
    let mse = squared_error as f64 / samples as f64;
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(side: usize) -> Vec<u8> {
        (0..side * side * 3)
            .map(|i| ((i * 7 + (i / 96) * 13) % 251) as u8)
            .collect()
    }

    #[test]
    fn deflate_round_trips_exactly() {
        let rgb = tile(32);
        let t = compress_tile(TileCompression::Deflate, &rgb, 32).unwrap();
        assert_eq!(t.squared_error, 0);
        assert!(t.payload.len() < rgb.len());
    }

    #[test]
    fn jpeg_round_trips_close() {
        let rgb: Vec<u8> = (0..64 * 64)
            .flat_map(|i| {
                let (r, c) = (i / 64, i % 64);
                [(r * 4) as u8, (c * 4) as u8, 128]
            })
            .collect();
        let t = compress_tile(TileCompression::Jpeg { quality: 90 }, &rgb, 64).unwrap();
        let psnr = psnr_db(t.squared_error, rgb.len() as u64);
        assert!(psnr > 35.0, "{psnr}");
        assert!(t.payload.len() * 4 < rgb.len());
    }

    #[test]
    fn psnr_of_identical_is_infinite() {
        assert!(psnr_db(0, 10).is_infinite());
        assert!((psnr_db(10, 10) - 48.13).abs() < 0.01);
    }
}
