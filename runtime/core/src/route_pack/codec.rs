//! Tile payload codecs of a version 2 pack (`FORMAT.md`, "Tile payloads"): the codec byte and
//! the decoder that turns one verified payload into the tile's `S * S * 3` RGB bytes.
//!
//! Decoding runs in the no_std + alloc core. JPEG goes through `zune-jpeg` built without its
//! `std` and SIMD features: the scalar integer IDCT and colour conversion give the same bytes
//! on every target (the crop after it is integer too), and the decoder keeps its scratch
//! (Huffman and quantisation tables, one MCU row of coefficients) on the heap for the length
//! of one decode. Deflate goes through `miniz_oxide`'s inflater into the caller's buffer with
//! no allocation. Payloads are only decoded after their checksum matched (`cache.rs`); a
//! payload that still fails to decode, or decodes to another size or colour layout, is a
//! [`DecodeFault`], never a panic.

use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;
use zune_jpeg::JpegDecoder;

use super::format::CHANNELS;

/// How tile payloads are stored (the header's `codec` byte; version 1 packs are always
/// [`TileCodec::Raw`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum TileCodec {
    /// `S * S * 3` bytes of RGB, read in place (no decode, no tile buffer).
    Raw = 0,
    /// One baseline or progressive JPEG (JFIF) of `S x S` pixels per tile, lossy.
    Jpeg = 1,
    /// The raw RGB bytes as one zlib stream (RFC 1950), lossless.
    Deflate = 2,
}

impl TileCodec {
    /// The codec of header byte `code`, if this runtime decodes it.
    #[must_use]
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Self::Raw),
            1 => Some(Self::Jpeg),
            2 => Some(Self::Deflate),
            _ => None,
        }
    }

    /// The header byte of this codec.
    #[must_use]
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// Whether tiles must be decoded into a tile buffer before they are sampled.
    #[must_use]
    pub const fn needs_decode(self) -> bool {
        !matches!(self, Self::Raw)
    }
}

/// Why a verified payload did not decode to its tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeFault {
    /// The JPEG decoder refused the stream (truncated, malformed, unsupported).
    Jpeg,
    /// The JPEG is not `S x S` pixels.
    JpegSize {
        /// Width in the stream, pixels.
        width_px: usize,
        /// Height in the stream, pixels.
        height_px: usize,
    },
    /// The zlib stream is malformed, or inflates to more or fewer than `S * S * 3` bytes.
    Deflate,
    /// The output buffer is not `S * S * 3` bytes (a caller error).
    OutputSize,
}

/// Decode one payload of `codec` into `out` (`size_px * size_px * 3` RGB bytes, row 0 south as
/// in `FORMAT.md`). For [`TileCodec::Raw`] the payload is copied.
///
/// # Errors
/// A [`DecodeFault`]; `out` may then hold partial output and must not be sampled.
pub fn decode_tile(
    codec: TileCodec,
    payload: &[u8],
    size_px: u16,
    out: &mut [u8],
) -> Result<(), DecodeFault> {
    let side = usize::from(size_px);
    if out.len() != side * side * CHANNELS {
        return Err(DecodeFault::OutputSize);
    }
    match codec {
        TileCodec::Raw => {
            if payload.len() != out.len() {
                return Err(DecodeFault::OutputSize);
            }
            out.copy_from_slice(payload);
            Ok(())
        }
        TileCodec::Jpeg => decode_jpeg(payload, side, out),
        TileCodec::Deflate => decode_deflate(payload, out),
    }
}

fn decode_jpeg(payload: &[u8], side: usize, out: &mut [u8]) -> Result<(), DecodeFault> {
    // Strict mode refuses streams a lenient decoder would patch up (a damaged tile must not
    // come out as plausible pixels); the size limits stop a forged header from making the
    // decoder size its scratch for a huge image.
    let options = DecoderOptions::default()
        .jpeg_set_out_colorspace(ColorSpace::RGB)
        .set_max_width(side)
        .set_max_height(side)
        .set_strict_mode(true);
    let mut decoder = JpegDecoder::new_with_options(ZCursor::new(payload), options);
    decoder.decode_headers().map_err(|_| DecodeFault::Jpeg)?;
    let info = decoder.info().ok_or(DecodeFault::Jpeg)?;
    let (width_px, height_px) = (usize::from(info.width), usize::from(info.height));
    if (width_px, height_px) != (side, side) {
        return Err(DecodeFault::JpegSize {
            width_px,
            height_px,
        });
    }
    if decoder.output_buffer_size() != Some(out.len())
        || decoder.output_colorspace() != Some(ColorSpace::RGB)
    {
        return Err(DecodeFault::Jpeg);
    }
    decoder.decode_into(out).map_err(|_| DecodeFault::Jpeg)
}

fn decode_deflate(payload: &[u8], out: &mut [u8]) -> Result<(), DecodeFault> {
    let expected = out.len();
    match miniz_oxide::inflate::decompress_slice_iter_to_slice(
        out,
        core::iter::once(payload),
        true,
        false,
    ) {
        Ok(n) if n == expected => Ok(()),
        _ => Err(DecodeFault::Deflate),
    }
}
