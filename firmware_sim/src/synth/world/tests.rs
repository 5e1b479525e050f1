//! Tests of the world's interval and polyline helpers.

use super::markings::subtract;
use super::*;

#[test]
fn subtract_cuts_gaps() {
    let r = subtract(&[(0.0, 100.0)], &[(10.0, 20.0), (50.0, 60.0)]);
    assert_eq!(r, vec![(0.0, 10.0), (20.0, 50.0), (60.0, 100.0)]);
}

#[test]
fn join_makes_one_line() {
    let a = vec![DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0)];
    let b = vec![DVec2::new(2.0, 0.0), DVec2::new(1.0, 0.0)];
    let j = join_polylines(vec![a, b]);
    assert_eq!(j.len(), 1);
    assert_eq!(j[0].len(), 3);
}
