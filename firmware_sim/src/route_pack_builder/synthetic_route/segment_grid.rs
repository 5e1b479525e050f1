//! The hash grid of the route's segments that answers "how far is the road" in constant time.

use super::*;

/// One route segment: start, unit direction, length, and arc length at its start.
#[derive(Clone, Copy, Debug)]
pub(super) struct Segment {
    pub(super) a: DVec2,
    pub(super) dir: DVec2,
    pub(super) len: f64,
    pub(super) s0: f64,
}

/// One slot of the open-addressing cell table; `start == end` is an empty slot (an occupied
/// cell has at least one segment).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Slot {
    pub(super) cx: i32,
    pub(super) cy: i32,
    pub(super) start: u32,
    pub(super) end: u32,
}

/// Route segments by [`CELL_M`] cell: every segment within [`ROAD_REACH_M`] of a cell is
/// listed (copied) under it.
#[derive(Clone, Debug)]
pub(super) struct SegmentGrid {
    pub(super) segments: Vec<Segment>,
    pub(super) slots: Vec<Slot>,
    pub(super) mask: usize,
}

/// Floor of `v` as an `i32`, for |v| < 2^31 (beyond, or for NaN, some `i32`), without a libm
/// call or the saturation checks of `as`: adding 1.5 * 2^52 rounds to an integer in the low
/// mantissa bits (two's complement), then one compare turns the rounding into a floor.
#[inline]
pub(super) fn floor_i32(v: f64) -> i32 {
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let i = (v + MAGIC).to_bits() as u32 as i32;
    i.wrapping_sub(i32::from(f64::from(i) > v))
}

#[inline]
pub(super) fn slot_of(cx: i32, cy: i32, mask: usize) -> usize {
    let key = (u64::from(cx as u32) << 32) | u64::from(cy as u32);
    (key.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32) as usize & mask
}

impl SegmentGrid {
    pub(super) fn new(route_m: &[DVec2]) -> Self {
        let mut entries: Vec<(i32, i32, Segment)> = Vec::new();
        let mut s0 = 0.0;
        for w in route_m.windows(2) {
            let d = w[1] - w[0];
            let len = d.length();
            let seg = Segment {
                a: w[0],
                dir: if len > 0.0 { d / len } else { DVec2::X },
                len,
                s0,
            };
            s0 += len;
            let lo = w[0].min(w[1]) - ROAD_REACH_M;
            let hi = w[0].max(w[1]) + ROAD_REACH_M;
            for cy in floor_i32(lo.y / CELL_M)..=floor_i32(hi.y / CELL_M) {
                for cx in floor_i32(lo.x / CELL_M)..=floor_i32(hi.x / CELL_M) {
                    entries.push((cx, cy, seg));
                }
            }
        }
        entries.sort_unstable_by_key(|&(cx, cy, _)| (cx, cy));
        let cells = entries
            .windows(2)
            .filter(|w| (w[0].0, w[0].1) != (w[1].0, w[1].1))
            .count()
            + 1;
        let capacity = (2 * cells).next_power_of_two().max(16);
        let mask = capacity - 1;
        let mut slots = vec![Slot::default(); capacity];
        let mut start = 0;
        while start < entries.len() {
            let (cx, cy, _) = entries[start];
            let end = entries[start..]
                .iter()
                .position(|&(x, y, _)| (x, y) != (cx, cy))
                .map_or(entries.len(), |n| start + n);
            let mut i = slot_of(cx, cy, mask);
            while slots[i].start != slots[i].end {
                i = (i + 1) & mask;
            }
            slots[i] = Slot {
                cx,
                cy,
                start: start as u32,
                end: end as u32,
            };
            start = end;
        }
        Self {
            segments: entries.into_iter().map(|(_, _, s)| s).collect(),
            slots,
            mask,
        }
    }

    /// The range of [`Self::segments`] listed under cell `(cx, cy)` (empty if none).
    pub(super) fn cell(&self, cx: i32, cy: i32) -> (u32, u32) {
        let mut i = slot_of(cx, cy, self.mask);
        loop {
            let s = self.slots[i];
            if s.start == s.end {
                return (0, 0);
            }
            if s.cx == cx && s.cy == cy {
                return (s.start, s.end);
            }
            i = (i + 1) & self.mask;
        }
    }
}
