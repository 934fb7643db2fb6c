//! Stamps in `u64` nanoseconds and times in `f64` seconds after the start
//! stamp: the subtraction happens in integers (absolute stamps near 1.7e18 ns
//! do not fit an f64 to the nanosecond), the float conversion after.

/// Converts between absolute stamps and seconds since `start_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Clock {
    /// Absolute stamp of time zero (ns).
    pub start_ns: u64,
}

impl Clock {
    /// The stamp `offset_ns` after the start.
    pub fn stamp(&self, offset_ns: u64) -> u64 {
        self.start_ns.saturating_add(offset_ns)
    }

    /// Seconds from the start to `stamp_ns` (negative before it).
    pub fn seconds(&self, stamp_ns: u64) -> f64 {
        let offset = i128::from(stamp_ns) - i128::from(self.start_ns);
        offset as f64 * 1e-9
    }

    /// Offset (ns) of sample `index` of a stream at `rate_hz`, rounded to the
    /// nanosecond (exact for any run shorter than ~100 days).
    pub fn sample_offset_ns(index: u64, rate_hz: f64) -> u64 {
        (index as f64 * 1e9 / rate_hz).round() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_keep_nanosecond_resolution_near_1e18() {
        let clock = Clock {
            start_ns: 1_700_000_000_000_000_000,
        };
        let t = clock.seconds(clock.stamp(2_500_001));
        assert!((t - 0.002_500_001).abs() < 1e-15);
        assert!((clock.seconds(clock.start_ns - 1_000) + 1e-6).abs() < 1e-18);
        assert_eq!(Clock::sample_offset_ns(3, 300.0), 10_000_000);
    }
}
