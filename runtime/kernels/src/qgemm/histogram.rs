//! What a calibration keeps of one tensor's values: a histogram of their magnitudes, and the
//! range a [`RangeMethod`] takes from it.
//!
//! Bins are the f32 bit patterns' top 14 bits below the sign (the 8 exponent bits and 6 mantissa
//! bits): 64 bins an octave, each within 1.1% of its neighbours, over every finite magnitude, with
//! no parameter to choose and no second pass. A percentile's range is the upper edge of the bin
//! where the share is reached (so at most 1.1% above the exact value), never above the largest
//! magnitude seen.

/// Mantissa bits a bin keeps.
const SUB_BITS: u32 = 6;
/// Bins: every exponent (finite ones below 255) times `2^SUB_BITS`.
const BINS: usize = 255 << SUB_BITS;

/// How a calibration turns what it saw of a tensor into the range its int8 scale covers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RangeMethod {
    /// The largest magnitude seen: nothing the calibration saw is clipped.
    AbsMax,
    /// The magnitude below which this share (percent, `(0, 100]`) of the values lie: the rarest
    /// outliers clipped for a finer step for the rest.
    Percentile(f32),
}

impl core::fmt::Display for RangeMethod {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::AbsMax => f.write_str("abs-max"),
            Self::Percentile(p) => write!(f, "percentile-{p}"),
        }
    }
}

impl core::str::FromStr for RangeMethod {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "abs-max" {
            return Ok(Self::AbsMax);
        }
        let p = s
            .strip_prefix("percentile-")
            .and_then(|p| p.parse::<f32>().ok())
            .filter(|p| *p > 0.0 && *p <= 100.0)
            .ok_or_else(|| {
                format!("{s:?}: a range method is abs-max or percentile-P, 0 < P <= 100")
            })?;
        Ok(Self::Percentile(p))
    }
}

/// Magnitudes of one tensor over every value a calibration showed it.
#[derive(Clone, Debug)]
pub struct MagnitudeHistogram {
    counts: Vec<u64>,
    abs_max: f32,
}

impl Default for MagnitudeHistogram {
    fn default() -> Self {
        Self {
            counts: vec![0; BINS],
            abs_max: 0.0,
        }
    }
}

impl MagnitudeHistogram {
    /// Count `values` (NaNs and infinities are not counted).
    pub fn add(&mut self, values: &[f32]) {
        for &v in values {
            let bits = v.abs().to_bits();
            let bin = (bits >> (23 - SUB_BITS)) as usize;
            if let Some(c) = self.counts.get_mut(bin) {
                *c += 1;
                self.abs_max = self.abs_max.max(v.abs());
            }
        }
    }

    /// The largest finite magnitude counted (0 before any).
    #[must_use]
    pub fn abs_max(&self) -> f32 {
        self.abs_max
    }

    /// The range `method` takes (0 before any value).
    #[must_use]
    pub fn range(&self, method: RangeMethod) -> f32 {
        let RangeMethod::Percentile(p) = method else {
            return self.abs_max;
        };
        let total: u64 = self.counts.iter().sum();
        let target = ((f64::from(p) / 100.0) * total as f64).ceil() as u64;
        let mut seen = 0;
        for (bin, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= target && seen > 0 {
                let upper = f32::from_bits(((bin as u32) + 1) << (23 - SUB_BITS));
                return upper.min(self.abs_max);
            }
        }
        self.abs_max
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_land_within_a_bin_and_abs_max_is_exact() {
        let mut h = MagnitudeHistogram::default();
        let values: Vec<f32> = (1..=10_000).map(|i| i as f32 / 100.0).collect();
        h.add(&values);
        h.add(&[f32::NAN, f32::INFINITY, -0.0]);
        assert_eq!(h.abs_max(), 100.0);
        assert_eq!(h.range(RangeMethod::AbsMax), 100.0);
        let p99 = h.range(RangeMethod::Percentile(99.0));
        assert!((99.0..=99.0 * 1.012).contains(&p99), "{p99}");
        assert_eq!(h.range(RangeMethod::Percentile(100.0)), 100.0);
        assert_eq!(
            MagnitudeHistogram::default().range(RangeMethod::Percentile(50.0)),
            0.0
        );
    }

    #[test]
    fn methods_parse_and_print() {
        for m in [RangeMethod::AbsMax, RangeMethod::Percentile(99.99)] {
            assert_eq!(m.to_string().parse::<RangeMethod>(), Ok(m));
        }
        assert!("percentile-0".parse::<RangeMethod>().is_err());
        assert!("p99".parse::<RangeMethod>().is_err());
    }
}
