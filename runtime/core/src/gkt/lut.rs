//! The GKT look-up table: for every (camera, BEV query, head, kernel point), the feature-map cell
//! the kernel reads. Built from the calibration at init and rebuilt in place on recalibration.
//!
//! Storage is compact: per camera, the ids of the queries it takes part in (ascending) and, per
//! such query, `4 * kernel_points` feature indices (head-major, then kernel point), plus per-query
//! camera counts. Capacity is fixed at the worst case (every camera sees every query), so
//! rebuilding never allocates. The dense form of `ARCHITECTURE.md` is available for comparison.
//!
//! Arithmetic follows the contract to the bit: cell centres in f64 then cast to f32; projections
//! in f32 with the documented association and no FMA; round-half-to-even; clamping.

use alloc::vec::Vec;

use glam::Mat4;

use crate::buffers::Slab;
use crate::calibration::{Calibration, NUM_CAMERAS};
use crate::capacity::NUM_HEADS;
use crate::model_dims::ModelDims;

mod error;
pub use error::{LutCorrupt, LutError};

/// Depth below which a projected point is behind the camera (and the division guard).
const MIN_DEPTH: f32 = 1e-5;

/// Compact GKT look-up table over fixed-capacity storage.
#[derive(Debug)]
pub struct Lut {
    dims: ModelDims,
    lidar2img: [Mat4; NUM_CAMERAS],
    /// `camera_start[c]..camera_start[c + 1]` are camera c's entries.
    camera_start: [usize; NUM_CAMERAS + 1],
    /// Query id of each entry; the first `len` are in use (capacity: every camera, every query).
    queries: Slab<u16>,
    /// `entry_len` feature indices per entry, the first `len * entry_len` in use.
    indices: Slab<u16>,
    /// Participating cameras per query.
    count: Slab<u8>,
    /// Entries in use.
    len: usize,
    /// [`Lut::digest`] when the table was built: the storage may be caller memory, which
    /// nothing else guards.
    built_digest: u64,
}

/// The dense look-up table of `ARCHITECTURE.md` (`lut.safetensors`), for comparison in tests.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseLut {
    /// `[6, Q]`: 1 where the camera takes part for the query.
    pub mask: Vec<u8>,
    /// `[Q]`: participating cameras.
    pub count: Vec<i32>,
    /// `[6, Q, 4, kernel_points]`: feature index, -1 where the camera does not take part.
    pub index: Vec<i32>,
    /// `[6, 4, 4]` row-major projection matrices.
    pub lidar2img: Vec<f32>,
}

/// Projection of one ego point into camera `m`: `(valid, u, v)` in padded-image fractions.
///
/// `p_r = ((m[r,0]*x + m[r,1]*y) + m[r,2]*z) + m[r,3]`, each product and sum rounded to f32.
#[must_use]
pub fn project(m: &Mat4, x: f32, y: f32, z: f32, pad_w: f32, pad_h: f32) -> (bool, f32, f32) {
    let row = |r: usize| {
        let a = m.x_axis[r] * x;
        let b = m.y_axis[r] * y;
        let c = m.z_axis[r] * z;
        ((a + b) + c) + m.w_axis[r]
    };
    let (p0, p1, p2) = (row(0), row(1), row(2));
    let d = if p2 > MIN_DEPTH { p2 } else { MIN_DEPTH };
    let u = (p0 / d) / pad_w;
    let v = (p1 / d) / pad_h;
    let valid = p2 > MIN_DEPTH && u > 0.0 && u < 1.0 && v > 0.0 && v < 1.0;
    (valid, u, v)
}

/// `clamp(round_half_even(x), 0, n - 1)`; NaN maps to 0.
fn cell(x: f32, n: usize) -> u16 {
    let r = libm::roundevenf(x);
    let hi = (n - 1) as f32;
    // `as` saturates and maps NaN to 0; the clamp keeps the in-range values exact.
    r.clamp(0.0, hi) as u16
}

impl Lut {
    /// Allocate the fixed-capacity table for `dims` and build it from `calibration`.
    ///
    /// `dims` must have passed [`ModelDims::validate`].
    ///
    /// # Errors
    /// [`LutError::InvalidCalibration`] for a bad camera, [`LutError::Memory`] when the
    /// storage cannot be reserved.
    pub fn new(dims: &ModelDims, calibration: &Calibration) -> Result<Self, LutError> {
        let (queries, indices, count) = Self::storage_lens(dims);
        Self::with_storage(
            dims,
            calibration,
            Slab::zeroed(queries)?,
            Slab::zeroed(indices)?,
            Slab::zeroed(count)?,
        )
    }

    /// As [`Lut::new`], in the caller-placed `gkt_lut` region: `queries` and `indices` (u16)
    /// and `count` (u8), each exactly [`Lut::storage_lens`] long.
    pub(crate) fn placed(
        dims: &ModelDims,
        calibration: &Calibration,
        queries: &'static mut [u16],
        indices: &'static mut [u16],
        count: &'static mut [u8],
    ) -> Result<Self, LutError> {
        Self::with_storage(
            dims,
            calibration,
            Slab::placed(queries),
            Slab::placed(indices),
            Slab::placed(count),
        )
    }

    fn with_storage(
        dims: &ModelDims,
        calibration: &Calibration,
        queries: Slab<u16>,
        indices: Slab<u16>,
        count: Slab<u8>,
    ) -> Result<Self, LutError> {
        let mut lut = Self {
            dims: dims.clone(),
            lidar2img: [Mat4::ZERO; NUM_CAMERAS],
            camera_start: [0; NUM_CAMERAS + 1],
            queries,
            indices,
            count,
            len: 0,
            built_digest: 0,
        };
        lut.rebuild(calibration)?;
        Ok(lut)
    }

    /// Element counts of the table's three arrays for `dims`: query ids (u16), feature indices
    /// (u16) and per-query camera counts (u8); [`Lut::capacity_bytes`] in all.
    #[must_use]
    pub const fn storage_lens(dims: &ModelDims) -> (usize, usize, usize) {
        let q = dims.num_queries();
        (
            NUM_CAMERAS * q,
            NUM_CAMERAS * q * NUM_HEADS * dims.kernel_points(),
            q,
        )
    }

    /// Bytes of storage the table reserves for `dims` (its fixed capacity).
    #[must_use]
    pub const fn capacity_bytes(dims: &ModelDims) -> usize {
        let q = dims.num_queries();
        NUM_CAMERAS * q * 2 * (1 + NUM_HEADS * dims.kernel_points()) + q
    }

    /// Rebuild the table in place for a new calibration, without allocating.
    ///
    /// # Errors
    /// [`LutError::InvalidCalibration`]; the table is unchanged in that case.
    pub fn rebuild(&mut self, calibration: &Calibration) -> Result<(), LutError> {
        calibration
            .validate()
            .map_err(|(camera, fault)| LutError::InvalidCalibration { camera, fault })?;
        let d = &self.dims;
        self.lidar2img = calibration.lidar2img(d.image_scale);
        let entry_len = NUM_HEADS * d.kernel_points();
        let (pad_w, pad_h) = (d.pad_w as f32, d.pad_h as f32);
        let (feat_w, feat_h) = (d.feat_w as f32, d.feat_h as f32);
        let [xmin, ymin, _, xmax, ymax, _] = d.pc_range_m.map(f64::from);
        self.count.fill(0);
        let mut len = 0;
        for (c, m) in self.lidar2img.iter().enumerate() {
            self.camera_start[c] = len;
            for i in 0..d.bev_h {
                let y = (ymin + ((i as f64 + 0.5) * (ymax - ymin)) / d.bev_h as f64) as f32;
                for j in 0..d.bev_w {
                    let x = (xmin + ((j as f64 + 0.5) * (xmax - xmin)) / d.bev_w as f64) as f32;
                    let proj = d.gkt_heights_m.map(|z| project(m, x, y, z, pad_w, pad_h));
                    if !proj.iter().any(|p| p.0) {
                        continue;
                    }
                    let q = i * d.bev_w + j;
                    // Capacity is the worst case (every camera, every query): `len` stays in it.
                    self.queries[len] = q as u16;
                    self.count[q] += 1;
                    let mut at = len * entry_len;
                    for &(_, u, v) in &proj {
                        let (su, sv) = (u * feat_w, v * feat_h);
                        for p in 0..d.kernel_points() {
                            let (ix, iy) = (p / d.kernel_h, p % d.kernel_h);
                            let dx = ix as f32 - (d.kernel_w / 2) as f32;
                            let dy = iy as f32 - (d.kernel_h / 2) as f32;
                            let col = cell(su + dx, d.feat_w);
                            let row = cell(sv + dy, d.feat_h);
                            self.indices[at] = row * d.feat_w as u16 + col;
                            at += 1;
                        }
                    }
                    len += 1;
                }
            }
        }
        self.camera_start[NUM_CAMERAS] = len;
        self.len = len;
        self.built_digest = self.digest();
        Ok(())
    }

    /// xxh3-64 of everything the gather reads: the entries in use (query ids and feature
    /// indices), the per-query counts and the camera ranges.
    #[must_use]
    pub fn digest(&self) -> u64 {
        let mut h = xxhash_rust::xxh3::Xxh3::new();
        for start in self.camera_start {
            h.update(&(start as u64).to_le_bytes());
        }
        h.update(bytemuck::cast_slice(&self.queries[..self.len]));
        h.update(bytemuck::cast_slice(
            &self.indices[..self.len * self.entry_len()],
        ));
        h.update(&self.count);
        h.digest()
    }

    /// Whether the table still has the digest it was built with: one xxh3 pass over what the
    /// gather reads, 12 us for `test`'s 3,484 entries (`lut_verify` in `benches/gkt_kernel.rs`,
    /// 2-core AMD EPYC with AVX-512), against 172 us for the gather itself; so every step checks.
    ///
    /// # Errors
    /// [`LutCorrupt`] when it changed.
    pub fn verify(&self) -> Result<(), LutCorrupt> {
        let found = self.digest();
        if found == self.built_digest {
            Ok(())
        } else {
            Err(LutCorrupt {
                built: self.built_digest,
                found,
            })
        }
    }

    /// Bytes of feature indices in use: for tests that corrupt the table as a stray write into
    /// caller memory would.
    #[cfg(test)]
    pub(crate) fn indices_in_use_bytes(&self) -> usize {
        2 * self.len * self.entry_len()
    }

    /// The feature indices' storage as bytes, writable (see above).
    #[cfg(test)]
    pub(crate) fn storage_bytes_mut(&mut self) -> &mut [u8] {
        bytemuck::cast_slice_mut(&mut self.indices[..])
    }

    /// The model dimensions the table was built for.
    #[must_use]
    pub const fn dims(&self) -> &ModelDims {
        &self.dims
    }

    /// Projection matrices the table was built from (f32, as in the golden `lidar2img`).
    #[must_use]
    pub const fn lidar2img(&self) -> &[Mat4; NUM_CAMERAS] {
        &self.lidar2img
    }

    /// Feature indices per entry: `4 * kernel_points`, head-major.
    #[must_use]
    pub const fn entry_len(&self) -> usize {
        NUM_HEADS * self.dims.kernel_points()
    }

    /// Camera `camera`'s entries: ascending query ids and their feature indices
    /// (`entry_len()` per query).
    ///
    /// # Panics
    /// If `camera >= 6` (callers iterate `0..NUM_CAMERAS`).
    #[must_use]
    pub fn camera_entries(&self, camera: usize) -> (&[u16], &[u16]) {
        let (a, b) = (self.camera_start[camera], self.camera_start[camera + 1]);
        let n = self.entry_len();
        (&self.queries[a..b], &self.indices[a * n..b * n])
    }

    /// Participating cameras per query, `[Q]`.
    #[must_use]
    pub fn count(&self) -> &[u8] {
        &self.count
    }

    /// Total (camera, query) pairs in the table.
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no camera sees any query.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Expand to the dense form of `ARCHITECTURE.md` (allocates; for tests and tools).
    #[must_use]
    pub fn to_dense(&self) -> DenseLut {
        let q = self.dims.num_queries();
        let n = self.entry_len();
        let mut mask = alloc::vec![0u8; NUM_CAMERAS * q];
        let mut index = alloc::vec![-1i32; NUM_CAMERAS * q * n];
        for c in 0..NUM_CAMERAS {
            let (queries, indices) = self.camera_entries(c);
            for (e, &qid) in queries.iter().enumerate() {
                let qid = usize::from(qid);
                mask[c * q + qid] = 1;
                let dst = &mut index[(c * q + qid) * n..][..n];
                for (d, &s) in dst.iter_mut().zip(&indices[e * n..][..n]) {
                    *d = i32::from(s);
                }
            }
        }
        let count = self.count.iter().map(|&c| i32::from(c)).collect();
        let mut lidar2img = Vec::with_capacity(NUM_CAMERAS * 16);
        for m in &self.lidar2img {
            // Row-major, as numpy stores [6, 4, 4].
            lidar2img.extend_from_slice(&m.transpose().to_cols_array());
        }
        DenseLut {
            mask,
            count,
            index,
            lidar2img,
        }
    }
}

#[cfg(test)]
mod tests;
