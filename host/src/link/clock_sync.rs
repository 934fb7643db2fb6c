//! Clock sync over the link: the device clock as an affine function of the host clock,
//! estimated from two-way exchanges (NTP-style) and tracked as it drifts.
//!
//! One exchange: the host writes a request at `t1` (host clock), the device stamps its
//! arrival `t2` and its reply `t3` (device clock), the host reads the reply at `t4`. With
//! `theta` = device minus host clock, `d_f` / `d_b` the forward / backward delays:
//!
//! ```text
//! t2 - t1 = theta + d_f          t3 - t4 = theta - d_b
//! ```
//!
//! Every delay is its floor plus jitter (queues, scheduling, serialisation), never less. So
//! the forward differences `t2 - t1` lie on or above the line `theta(t) + floor_f` and the
//! backward ones `t3 - t4` on or below `theta(t) - floor_b`. The estimator keeps the
//! exchanges of a sliding window ([`ClockSyncOptions::window_ns`]) and fits the convex-hull
//! support lines of both sets with one common slope (the skew): the lower support of the
//! forward points and the upper support of the backward ones, tilted to the slope at which
//! the gap between them (the floor round trip) is widest. Only the least delayed exchanges
//! of each direction touch the lines, chosen separately per direction: a request that waited
//! does not spoil its reply's direction, and heavy-tailed delays never pull a line. The
//! offset is midway: `theta = (A_f + A_g) / 2`, exact when the floors are equal, or differ
//! by a known
//! [`ClockSyncOptions::asymmetry_ns`] (e.g. the serialisation times of the request and reply
//! on a UART).
//!
//! Its uncertainty, [`ClockFit`]: `sigma_ns` from the spread of the same fit on four
//! interleaved quarters of the window (the statistical part), and `asymmetry_bound_ns`, half the floor round
//! trip: how far off the offset is if the floors were as unequal as causality allows. A
//! constant unknown asymmetry cannot be seen by any two-way exchange; it is reported, not
//! estimated.

use std::collections::VecDeque;

/// One two-way exchange: host stamps `t1`, `t4` (host clock), device stamps `t2`, `t3`
/// (device clock), ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exchange {
    /// Host clock when the request was written.
    pub t1_ns: i64,
    /// Device clock when the request arrived.
    pub t2_ns: i64,
    /// Device clock when the reply left.
    pub t3_ns: i64,
    /// Host clock when the reply was read.
    pub t4_ns: i64,
}

impl Exchange {
    /// Round trip minus the device's turnaround, ns.
    pub fn rtt_ns(&self) -> i64 {
        (self.t4_ns - self.t1_ns) - (self.t3_ns - self.t2_ns)
    }
}

/// An exchange the estimator refuses (the estimate is left unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ClockSyncError {
    /// `t4 < t1` or `t3 < t2`: stamps out of order.
    #[error("exchange stamps out of order (t1 {t1_ns}, t2 {t2_ns}, t3 {t3_ns}, t4 {t4_ns})")]
    OutOfOrder {
        /// Host send stamp.
        t1_ns: i64,
        /// Device receive stamp.
        t2_ns: i64,
        /// Device send stamp.
        t3_ns: i64,
        /// Host receive stamp.
        t4_ns: i64,
    },
    /// The device turned around longer than the whole round trip.
    #[error("device turnaround longer than the round trip (round trip {rtt_ns} ns)")]
    NegativeRoundTrip {
        /// Round trip minus turnaround, ns.
        rtt_ns: i64,
    },
    /// The exchange is older than the newest one kept.
    #[error("exchange older than the last one ({t1_ns} ns)")]
    NotNewer {
        /// Its host send stamp.
        t1_ns: i64,
    },
}

/// Tuning of [`ClockSync`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockSyncOptions {
    /// Exchanges older than this (host clock, before the newest) are dropped, ns: long
    /// enough to see the skew, short enough that it stays constant (a crystal's drifts
    /// with temperature over minutes).
    pub window_ns: i64,
    /// Known floor asymmetry `d_f - d_b`, ns (0 when both directions are alike).
    pub asymmetry_ns: i64,
}

impl Default for ClockSyncOptions {
    fn default() -> Self {
        Self {
            window_ns: 30_000_000_000,
            asymmetry_ns: 0,
        }
    }
}

/// The fitted mapping `device = host + offset(host)`, `offset(h) = offset_ns + skew (h -
/// reference_host_ns)`, and its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockFit {
    /// Host time the offset is given at (mean of the envelope points), ns.
    pub reference_host_ns: i64,
    /// Whole part of the offset, ns (the first exchange's `t2 - t1`: the clocks may be
    /// 1e18 ns apart, beyond an f64's ns resolution).
    pub base_offset_ns: i64,
    /// Device minus host clock at the reference, minus `base_offset_ns`, ns.
    pub offset_ns: f64,
    /// Device clock rate minus host clock rate (50 ppm = 5e-5).
    pub skew: f64,
    /// 1-sigma of the offset at the reference, ns (envelope scatter; statistical part).
    pub sigma_ns: f64,
    /// 1-sigma of the skew.
    pub sigma_skew: f64,
    /// Half the floor round trip, ns: the offset error if the floor delays were as
    /// unequal as causality allows (beyond [`ClockSyncOptions::asymmetry_ns`]).
    pub asymmetry_bound_ns: f64,
    /// Exchanges in the window.
    pub exchanges: usize,
    /// Skew fitted (false: the window was too short, skew held at the previous fit's).
    pub skew_fitted: bool,
}

impl ClockFit {
    /// Device minus host clock at host time `host_ns`, minus `base_offset_ns`, ns.
    pub fn offset_at(&self, host_ns: i64) -> f64 {
        self.offset_ns + self.skew * (host_ns - self.reference_host_ns) as f64
    }

    /// The device clock at host time `host_ns`, ns.
    pub fn to_device(&self, host_ns: i64) -> i64 {
        host_ns
            .wrapping_add(self.base_offset_ns)
            .wrapping_add(self.offset_at(host_ns).round() as i64)
    }

    /// The host clock at device time `device_ns` (the inverse of [`Self::to_device`]), ns.
    pub fn to_host(&self, device_ns: i64) -> i64 {
        // device = host + base + o + s (host - ref)  =>  host = (device - base - o + s ref) / (1 + s)
        let rel = device_ns
            .wrapping_sub(self.base_offset_ns)
            .wrapping_sub(self.reference_host_ns) as f64;
        let host_rel = (rel - self.offset_ns) / (1.0 + self.skew);
        self.reference_host_ns + host_rel.round() as i64
    }

    /// 1-sigma of the offset at `host_ns` (statistical part), ns.
    pub fn sigma_at(&self, host_ns: i64) -> f64 {
        let dt = (host_ns - self.reference_host_ns) as f64;
        (self.sigma_ns.powi(2) + (self.sigma_skew * dt).powi(2)).sqrt()
    }
}

/// Shortest window span over which the skew is fitted, ns: below it a 1 us scatter of the
/// envelope points would be a > 1 ppm skew.
const MIN_SKEW_SPAN_NS: i64 = 1_000_000_000;

/// The estimator: a window of exchanges and the current fit.
#[derive(Debug, Clone)]
pub struct ClockSync {
    options: ClockSyncOptions,
    window: VecDeque<Exchange>,
    fit: Option<ClockFit>,
}

impl ClockSync {
    /// Empty.
    pub fn new(options: ClockSyncOptions) -> Self {
        Self {
            options,
            window: VecDeque::new(),
            fit: None,
        }
    }

    /// The current fit (none before the first exchange).
    pub fn fit(&self) -> Option<ClockFit> {
        self.fit
    }

    /// Exchanges in the window.
    pub fn len(&self) -> usize {
        self.window.len()
    }

    /// No exchange yet.
    pub fn is_empty(&self) -> bool {
        self.window.is_empty()
    }

    /// Adds an exchange and refits; a refused exchange changes nothing.
    pub fn add(&mut self, e: Exchange) -> Result<ClockFit, ClockSyncError> {
        if e.t4_ns < e.t1_ns || e.t3_ns < e.t2_ns {
            return Err(ClockSyncError::OutOfOrder {
                t1_ns: e.t1_ns,
                t2_ns: e.t2_ns,
                t3_ns: e.t3_ns,
                t4_ns: e.t4_ns,
            });
        }
        if e.rtt_ns() < 0 {
            return Err(ClockSyncError::NegativeRoundTrip { rtt_ns: e.rtt_ns() });
        }
        if self.window.back().is_some_and(|b| e.t1_ns <= b.t1_ns) {
            return Err(ClockSyncError::NotNewer { t1_ns: e.t1_ns });
        }
        self.window.push_back(e);
        while self
            .window
            .front()
            .is_some_and(|f| f.t4_ns < e.t4_ns - self.options.window_ns)
        {
            self.window.pop_front();
        }
        let previous_skew = self.fit.map_or(0.0, |f| f.skew);
        let base = self
            .fit
            .map_or(e.t2_ns.wrapping_sub(e.t1_ns), |f| f.base_offset_ns);
        let fit = fit_window(&self.window, &self.options, previous_skew, base);
        self.fit = Some(fit);
        Ok(fit)
    }
}

/// Forward points `(t1, t2 - t1)` and backward points `(t4, t3 - t4)` of the window,
/// relative to `origin` and `base` (keeps them small and exact in f64).
fn points(window: &VecDeque<Exchange>, (origin, base): (i64, i64)) -> Vec<[f64; 4]> {
    window
        .iter()
        .map(|e| {
            [
                (e.t1_ns - origin) as f64,
                (e.t2_ns - e.t1_ns).wrapping_sub(base) as f64,
                (e.t4_ns - origin) as f64,
                (e.t3_ns - e.t4_ns).wrapping_sub(base) as f64,
            ]
        })
        .collect()
}

/// With slope `s`, the lower support line of the forward points and the upper one of the
/// backward points, at abscissa `xm`: `(A_f, A_g)`.
fn supports<'a>(points: impl Iterator<Item = &'a [f64; 4]>, s: f64, xm: f64) -> (f64, f64) {
    points.fold((f64::INFINITY, f64::NEG_INFINITY), |(af, ag), p| {
        (
            af.min(p[1] - s * (p[0] - xm)),
            ag.max(p[3] - s * (p[2] - xm)),
        )
    })
}

/// Largest skew searched (0.2 %: far beyond crystals, and RC oscillators after trimming).
const MAX_SKEW: f64 = 2e-3;

/// The slope that maximises the gap `A_f - A_g` between the two support lines (the floor
/// round trip is seen widest at the true skew; any tilt lowers the forward support and
/// raises the backward one). The gap is concave in the slope: golden-section search.
fn widest_gap_slope(points: &[&[f64; 4]], xm: f64) -> f64 {
    let gap = |s: f64| {
        let (af, ag) = supports(points.iter().copied(), s, xm);
        af - ag
    };
    let (mut lo, mut hi) = (-MAX_SKEW, MAX_SKEW);
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - r * (hi - lo), lo + r * (hi - lo));
    let (mut ga, mut gb) = (gap(a), gap(b));
    for _ in 0..80 {
        if ga < gb {
            lo = a;
            (a, ga) = (b, gb);
            b = lo + r * (hi - lo);
            gb = gap(b);
        } else {
            hi = b;
            (b, gb) = (a, ga);
            a = hi - r * (hi - lo);
            ga = gap(a);
        }
    }
    0.5 * (lo + hi)
}

/// Offset (at `xm`, less the known asymmetry) and slope of one set of points.
fn hull_fit(points: &[&[f64; 4]], xm: f64, skew: Option<f64>, asymmetry: f64) -> (f64, f64, f64) {
    let s = skew.unwrap_or_else(|| widest_gap_slope(points, xm));
    let (af, ag) = supports(points.iter().copied(), s, xm);
    (0.5 * (af + ag - asymmetry), s, af - ag)
}

/// Fits the window: the support lines with the widest gap (the skew held at `skew` when the
/// window spans less than [`MIN_SKEW_SPAN_NS`]); the uncertainty from the spread of the
/// same fit on four interleaved quarters of the window.
fn fit_window(
    window: &VecDeque<Exchange>,
    options: &ClockSyncOptions,
    skew: f64,
    base: i64,
) -> ClockFit {
    let origin = window.back().map_or(0, |e| e.t1_ns);
    let all = points(window, (origin, base));
    let n = all.len().max(1) as f64;
    let xm = all.iter().map(|p| p[0] + p[2]).sum::<f64>() / (2.0 * n);
    let span = window
        .front()
        .zip(window.back())
        .map_or(0, |(a, b)| b.t4_ns - a.t1_ns);
    let skew_fitted = all.len() >= 3 && span >= MIN_SKEW_SPAN_NS;
    let held = (!skew_fitted).then_some(skew);
    let asymmetry = options.asymmetry_ns as f64;
    let refs: Vec<&[f64; 4]> = all.iter().collect();
    let (offset, s, gap) = hull_fit(&refs, xm, held, asymmetry);
    // Quarters: each has a quarter of the points, so its extremes sit further above the
    // floors; their spread / 2 (the 1/sqrt(n) scaling) is a conservative 1-sigma of the
    // whole window's fit (extremes of a density that is finite at the floor tighten as 1/n).
    let (mut sum, mut sum2, mut ssum, mut ssum2, mut k) = (0.0, 0.0, 0.0, 0.0, 0.0);
    if all.len() >= 8 {
        for q in 0..4 {
            let part: Vec<&[f64; 4]> = all.iter().skip(q).step_by(4).collect();
            let (o, sq, _) = hull_fit(&part, xm, held, asymmetry);
            (sum, sum2, ssum, ssum2, k) =
                (sum + o, sum2 + o * o, ssum + sq, ssum2 + sq * sq, k + 1.0);
        }
    }
    let spread = |s1: f64, s2: f64| {
        if k < 2.0 {
            f64::INFINITY
        } else {
            ((s2 - s1 * s1 / k) / (k - 1.0)).max(0.0).sqrt() / 2.0
        }
    };
    ClockFit {
        reference_host_ns: origin + xm.round() as i64,
        base_offset_ns: base,
        offset_ns: offset,
        skew: s,
        sigma_ns: spread(sum, sum2),
        sigma_skew: if skew_fitted {
            spread(ssum, ssum2)
        } else {
            0.0
        },
        asymmetry_bound_ns: 0.5 * (gap - asymmetry).max(0.0),
        exchanges: window.len(),
        skew_fitted,
    }
}

#[cfg(test)]
mod tests;
