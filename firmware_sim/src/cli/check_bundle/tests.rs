//! Unit tests of `check-bundle`'s comparisons and argument checks.

use super::*;

#[test]
fn a_nan_difference_is_the_worst() {
    assert!(worst_of(0.0, f32::NAN).is_nan());
    assert!(worst_of(f32::NAN, 1e-6).is_nan());
    assert_eq!(worst_of(1e-6, 2e-6), 2e-6);
    let c = compare("x", &[1.0, f32::NAN, 2.0], &[1.0, 0.0, 2.5], 0.0);
    assert!(c.max_abs_diff.is_nan());
}

#[test]
fn a_tolerance_that_cannot_fail_is_refused_before_any_work() {
    for tolerance in [f32::NAN, f32::INFINITY, -1e-4] {
        let args = Args {
            bundles: vec![PathBuf::from("/nonexistent/bundle")],
            tolerance,
            public_key: None,
        };
        let e = run(&args).unwrap_err();
        assert!(
            e.downcast_ref::<crate::cli::drive::BadArgument>().is_some(),
            "{tolerance}: {e:#}"
        );
        assert!(e.to_string().contains("--tolerance"), "{e}");
    }
}
