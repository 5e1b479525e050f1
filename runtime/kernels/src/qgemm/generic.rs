//! The portable integer tile: the definition of the sums (exact in i32, so of any order).

use super::pack::{LINE, Line};
use super::{IntSums, QNR};

/// The sums of `rows` rows of `a` (row `r` at `r * kp`) against one panel's `lines`.
pub(super) fn tile(a: &[i8], kp: usize, rows: usize, lines: &[Line], sums: &mut IntSums) {
    for (r, row) in sums.iter_mut().enumerate().take(rows) {
        let ar = &a[r * kp..][..kp];
        *row = [0; QNR];
        for (g, line) in lines.iter().enumerate() {
            let ag = &ar[4 * g..4 * g + 4];
            for (c, s) in row.iter_mut().enumerate() {
                let w = &line.0[4 * c..4 * c + 4];
                *s += ag
                    .iter()
                    .zip(w)
                    .map(|(&x, &y)| i32::from(x) * i32::from(y))
                    .sum::<i32>();
            }
        }
    }
    const _: () = assert!(LINE == 4 * QNR);
}
