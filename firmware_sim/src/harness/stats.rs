//! Latency series and their percentiles.

use serde::Serialize;

/// Samples of one quantity (microseconds), stored in a buffer reserved before the replay so
/// recording never allocates.
#[derive(Clone, Debug, Default)]
pub struct Series {
    samples_us: Vec<u64>,
}

/// Summary of a series.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Percentiles {
    /// Number of samples.
    pub count: usize,
    /// Median (nearest rank), microseconds.
    pub p50_us: u64,
    /// 99th percentile (nearest rank), microseconds.
    pub p99_us: u64,
    /// Largest sample, microseconds.
    pub max_us: u64,
}

impl Series {
    /// An empty series with room for `capacity` samples.
    #[must_use]
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            samples_us: Vec::with_capacity(capacity),
        }
    }

    /// Record one sample; beyond the reserved capacity the sample is dropped (and `false`
    /// returned) rather than growing the buffer mid-replay.
    pub fn record(&mut self, us: u64) -> bool {
        if self.samples_us.len() < self.samples_us.capacity() {
            self.samples_us.push(us);
            true
        } else {
            false
        }
    }

    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.samples_us.len()
    }

    /// True when no sample was recorded.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.samples_us.is_empty()
    }

    /// The samples in recording order.
    #[must_use]
    pub fn samples_us(&self) -> &[u64] {
        &self.samples_us
    }

    /// Nearest-rank percentiles (p = ceil(q * n)-th smallest).
    #[must_use]
    pub fn percentiles(&self) -> Percentiles {
        let mut sorted = self.samples_us.clone();
        sorted.sort_unstable();
        let n = sorted.len();
        let rank = |q: f64| -> u64 {
            if n == 0 {
                return 0;
            }
            let r = ((q * n as f64).ceil() as usize).clamp(1, n);
            sorted[r - 1]
        };
        Percentiles {
            count: n,
            p50_us: rank(0.50),
            p99_us: rank(0.99),
            max_us: sorted.last().copied().unwrap_or(0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let mut s = Series::with_capacity(100);
        for v in (1..=100).rev() {
            assert!(s.record(v));
        }
        assert!(!s.record(7), "full series must refuse, not grow");
        let p = s.percentiles();
        assert_eq!(
            p,
            Percentiles {
                count: 100,
                p50_us: 50,
                p99_us: 99,
                max_us: 100
            }
        );
    }

    #[test]
    fn empty_series_is_zero() {
        assert_eq!(
            Series::with_capacity(0).percentiles(),
            Percentiles::default()
        );
    }
}
