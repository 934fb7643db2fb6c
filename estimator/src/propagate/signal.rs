//! The IMU signal between samples, and what one propagation step needs of it.
//!
//! Samples are instantaneous readings. Between sample `k` (the interval's start) and the
//! look-ahead `k + 1` the signal is the quadratic through samples `k - 1`, `k` and `k + 1`
//! (the straight line through `k` and `k + 1` when there is no sample `k - 1` yet, or when the
//! three are unevenly spaced, e.g. around a dropped sample). The quadratic needs no more
//! look-ahead than the line and takes the trapezoid rule's `dt^3 f'' / 12` error out of every
//! interval's integral: on the hand-held simulator at 200 Hz the two-sample mean drifted
//! 4.3e-5 rad RMS in one second (docs/estimator.md, "Propagation accuracy").

use super::ImuSample;
use crate::scalar::Scalar;
use nalgebra::Vector3;

/// The signal over one step `[t_a, t_b]`: its mean (integral over `dt`, divided by `dt`) and
/// its readings at both ends, raw (biases not removed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuInterval<T: Scalar> {
    /// `t_b - t_a`, s.
    pub dt: T,
    /// Mean angular rate over the interval, rad/s.
    pub gyro_mean: Vector3<T>,
    /// Mean specific force over the interval, m/s^2.
    pub accel_mean: Vector3<T>,
    /// Readings at `t_a`.
    pub start: (Vector3<T>, Vector3<T>),
    /// Readings at `t_b`.
    pub end: (Vector3<T>, Vector3<T>),
}

impl<T: Scalar> ImuInterval<T> {
    /// A constant reading held over `dt` (no change within the interval).
    pub fn constant(gyro: Vector3<T>, accel: Vector3<T>, dt: T) -> Self {
        Self {
            dt,
            gyro_mean: gyro,
            accel_mean: accel,
            start: (gyro, accel),
            end: (gyro, accel),
        }
    }

    /// The straight line between two readings over `dt`.
    pub fn linear(start: (Vector3<T>, Vector3<T>), end: (Vector3<T>, Vector3<T>), dt: T) -> Self {
        let half = T::lit(0.5);
        Self {
            dt,
            gyro_mean: (start.0 + end.0) * half,
            accel_mean: (start.1 + end.1) * half,
            start,
            end,
        }
    }
}

/// Largest ratio between the spacing of samples `k - 1, k` and of `k, k + 1` for which the
/// quadratic is used: beyond it a sample was dropped and the curvature estimate would span a
/// gap.
const MAX_SPACING_RATIO: f64 = 2.0;

/// The signal from sample `start` to the look-ahead `next`, with `before` (the sample before
/// `start`) giving its curvature.
#[derive(Clone, Copy, Debug)]
pub struct ImuSignal<T: Scalar> {
    start: ImuSample<T>,
    next: ImuSample<T>,
    /// `f(t) = f_k + c1 u + c2 u^2`, `u = t - t_k` in s; `(gyro, accel)`.
    c1: (Vector3<T>, Vector3<T>),
    c2: (Vector3<T>, Vector3<T>),
}

impl<T: Scalar> ImuSignal<T> {
    /// The signal over `[start.stamp, next.stamp]` (`next` strictly later than `start`).
    pub fn new(before: Option<&ImuSample<T>>, start: &ImuSample<T>, next: &ImuSample<T>) -> Self {
        let h1 = (next.stamp_ns.saturating_sub(start.stamp_ns)) as f64 * 1e-9;
        let h1_t = T::lit(h1);
        let d1 = (
            (next.gyro - start.gyro) / h1_t,
            (next.accel - start.accel) / h1_t,
        );
        let zero = (Vector3::zeros(), Vector3::zeros());
        let c2 = before
            .filter(|b| b.stamp_ns < start.stamp_ns)
            .map(|b| (b, (start.stamp_ns - b.stamp_ns) as f64 * 1e-9))
            .filter(|(_, h0)| h0 * MAX_SPACING_RATIO >= h1 && *h0 <= h1 * MAX_SPACING_RATIO)
            .map_or(zero, |(b, h0)| {
                let h0_t = T::lit(h0);
                let span = T::lit(h0 + h1);
                (
                    (d1.0 - (start.gyro - b.gyro) / h0_t) / span,
                    (d1.1 - (start.accel - b.accel) / h0_t) / span,
                )
            });
        Self {
            start: *start,
            next: *next,
            c1: (d1.0 - c2.0 * h1_t, d1.1 - c2.1 * h1_t),
            c2,
        }
    }

    /// Seconds from the start sample to `t_ns`, clamped to the interval.
    fn offset(&self, t_ns: u64) -> T {
        let t = t_ns.clamp(self.start.stamp_ns, self.next.stamp_ns);
        T::lit((t - self.start.stamp_ns) as f64 * 1e-9)
    }

    /// The reading at `t_ns` (clamped to the interval; the samples themselves at their stamps,
    /// bit for bit).
    pub fn at(&self, t_ns: u64) -> ImuSample<T> {
        if t_ns >= self.next.stamp_ns {
            return self.next;
        }
        if t_ns <= self.start.stamp_ns {
            return self.start;
        }
        let u = self.offset(t_ns);
        ImuSample {
            stamp_ns: t_ns,
            gyro: self.start.gyro + self.c1.0 * u + self.c2.0 * (u * u),
            accel: self.start.accel + self.c1.1 * u + self.c2.1 * (u * u),
        }
    }

    /// The step from `a_ns` to `b_ns` (both inside the interval, `a_ns <= b_ns`): the exact
    /// mean of the quadratic and its readings at both ends.
    pub fn interval(&self, a_ns: u64, b_ns: u64) -> ImuInterval<T> {
        let (ua, ub) = (self.offset(a_ns), self.offset(b_ns));
        let lin = (ua + ub) * T::lit(0.5);
        let quad = (ua * ua + ua * ub + ub * ub) / T::lit(3.0);
        let (ra, rb) = (self.at(a_ns), self.at(b_ns));
        ImuInterval {
            dt: ub - ua,
            gyro_mean: self.start.gyro + self.c1.0 * lin + self.c2.0 * quad,
            accel_mean: self.start.accel + self.c1.1 * lin + self.c2.1 * quad,
            start: (ra.gyro, ra.accel),
            end: (rb.gyro, rb.accel),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(stamp_ns: u64, f: impl Fn(f64) -> f64) -> ImuSample<f64> {
        let t = stamp_ns as f64 * 1e-9;
        let v = Vector3::new(f(t), 2.0 * f(t), -f(t));
        ImuSample {
            stamp_ns,
            gyro: v,
            accel: v * 3.0,
        }
    }

    #[test]
    fn quadratic_signal_is_integrated_exactly() {
        let f = |t: f64| 1.0 + 40.0 * t - 900.0 * t * t;
        let (b, s, n) = (
            sample(10_000_000, f),
            sample(15_000_000, f),
            sample(21_000_000, f),
        );
        let signal = ImuSignal::new(Some(&b), &s, &n);
        let (a_ns, b_ns) = (16_000_000, 20_000_000);
        let i = signal.interval(a_ns, b_ns);
        // Exact mean of f over [0.016, 0.020].
        let prim = |t: f64| t + 20.0 * t * t - 300.0 * t * t * t;
        let mean = (prim(0.020) - prim(0.016)) / 0.004;
        assert!(
            (i.gyro_mean.x - mean).abs() < 1e-12,
            "{} {mean}",
            i.gyro_mean.x
        );
        assert!((i.accel_mean.y - 6.0 * mean).abs() < 1e-11);
        assert!((i.start.0.x - f(0.016)).abs() < 1e-12);
        assert!((i.end.1.z + 3.0 * f(0.020)).abs() < 1e-11);
        assert_eq!(signal.at(21_000_000), n);
        assert_eq!(signal.at(15_000_000), s);
    }

    #[test]
    fn first_interval_and_gaps_fall_back_to_the_line() {
        let f = |t: f64| 5.0 * t * t;
        let (s, n) = (sample(20_000_000, f), sample(25_000_000, f));
        let line = ImuInterval::linear((s.gyro, s.accel), (n.gyro, n.accel), 0.005);
        let first = ImuSignal::new(None, &s, &n).interval(20_000_000, 25_000_000);
        assert!((first.gyro_mean - line.gyro_mean).norm() < 1e-15);
        // The sample before lies 4 periods back: dropped samples, no curvature from them.
        let gap = ImuSignal::new(Some(&sample(0, f)), &s, &n).interval(20_000_000, 25_000_000);
        assert!((gap.gyro_mean - line.gyro_mean).norm() < 1e-15);
    }
}
